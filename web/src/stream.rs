//! Server push over `/v1/db/{database_id}/stream` from a page: one WebSocket; `Hello` with the policy when it
//! opens, the observer every frame, and the segments the client's cache released as
//! `Evicted`, so the server's mirror of the cache stays true and nothing is sent twice. The
//! server pushes segments in need order (Funkhouser §5.2.3) no further than the cache holds.
//! Frames arrive on the socket's callback and wait in an inbox for the next animation frame.

use portico_protocol::{
    Observer, PROTOCOL_VERSION, Policy, ServerFrame, StreamClient, StreamServer, parse_server_frame,
};
use std::cell::{Cell, RefCell};
use std::collections::VecDeque;
use std::rc::Rc;
use wasm_bindgen::prelude::*;
use web_sys::{BinaryType, CloseEvent, MessageEvent, WebSocket};

/// Most bytes waiting in the socket's send buffer before an observer is skipped (the server
/// only computes the latest one anyway).
const SEND_BACKLOG: u32 = 64 << 10;

/// What the socket brought.
pub enum Pushed {
    /// A segment (unchecked).
    Segment(u32, Vec<u8>),
    /// The server reported a problem with a message; the session goes on.
    Error(String),
}

/// One stream session.
pub struct Stream {
    ws: WebSocket,
    inbox: Rc<RefCell<VecDeque<Pushed>>>,
    open: Rc<Cell<bool>>,
    /// Why the socket closed, once it has.
    closed: Rc<RefCell<Option<String>>>,
    /// Whether it closed because the server serves another database now.
    stale: Rc<Cell<bool>>,
    /// Segments the cache released before the session opened: sent right after `Holding`.
    evicted_early: Rc<RefCell<Vec<u32>>>,
    _callbacks: Vec<Closure<dyn FnMut(JsValue)>>,
}

/// The stream's URL for an API base (`""`: the page's origin) and the database the page's
/// manifest describes (the server closes a session on another with
/// [`portico_protocol::CLOSE_STALE`]).
fn url(base: &str, db: Option<&str>) -> Result<String, String> {
    let http = if base.is_empty() {
        web_sys::window()
            .ok_or("no window")?
            .location()
            .origin()
            .map_err(|e| crate::net::js_error(&e))?
    } else {
        base.to_string()
    };
    let ws = if let Some(rest) = http.strip_prefix("https://") {
        format!("wss://{rest}")
    } else if let Some(rest) = http.strip_prefix("http://") {
        format!("ws://{rest}")
    } else {
        return Err(format!("{http}: not an http(s) address"));
    };
    let path = db.map_or("/v1/stream".to_string(), |d| format!("/v1/db/{d}/stream"));
    Ok(format!("{}{path}", ws.trim_end_matches('/')))
}

impl Stream {
    /// Opens a session with the server at `base` on database `db`; `Hello` goes as soon as it
    /// opens, then `Holding` with what the cache holds (`holding`: a session opened again after
    /// one ended), so the server does not push it again.
    /// `token`: the server's `--token`, given as `?token=` (a browser cannot set headers on a
    /// WebSocket).
    pub fn open(
        base: &str,
        db: Option<&str>,
        token: Option<&str>,
        policy: Policy,
        holding: &[u32],
    ) -> Result<Stream, String> {
        // Messages name `url`; only the socket gets the token.
        let url = url(base, db)?;
        let with_token = match token {
            Some(t) => format!(
                "{url}?token={}",
                String::from(js_sys::encode_uri_component(t))
            ),
            None => url.clone(),
        };
        let ws = WebSocket::new(&with_token)
            .map_err(|e| format!("{url}: {}", crate::net::js_error(&e)))?;
        ws.set_binary_type(BinaryType::Arraybuffer);
        let inbox = Rc::new(RefCell::new(VecDeque::new()));
        let open = Rc::new(Cell::new(false));
        let closed = Rc::new(RefCell::new(None));
        let mut callbacks = Vec::new();

        let evicted_early = Rc::new(RefCell::new(Vec::new()));
        let (o, socket, early) = (open.clone(), ws.clone(), evicted_early.clone());
        // The handshake took a TCP and an HTTP round trip: half of it is the round trip the
        // server counts its push deadlines with.
        let opened = js_sys::Date::now();
        let holding = (!holding.is_empty())
            .then(|| {
                let deltas = portico_protocol::encode_held(holding.iter().copied());
                portico_protocol::to_bincode(&StreamClient::Holding(deltas)).ok()
            })
            .flatten();
        let on_open = Closure::<dyn FnMut(JsValue)>::new(move |_| {
            let rtt_ms = ((js_sys::Date::now() - opened) / 2.0).clamp(0.0, 10_000.0) as u32;
            let hello = portico_protocol::to_bincode(&StreamClient::Hello {
                version: PROTOCOL_VERSION,
                policy,
                rate_bytes_per_s: u64::MAX / 2,
                rtt_ms,
            });
            let sent = hello.is_ok_and(|h| socket.send_with_u8_array(&h).is_ok());
            if sent && let Some(h) = &holding {
                let _ = socket.send_with_u8_array(h);
            }
            let early = std::mem::take(&mut *early.borrow_mut());
            if sent && !early.is_empty() {
                let evicted = portico_protocol::to_bincode(&StreamClient::Evicted(early));
                let _ = evicted.map(|e| socket.send_with_u8_array(&e));
            }
            o.set(sent);
        });
        ws.set_onopen(Some(on_open.as_ref().unchecked_ref()));
        callbacks.push(on_open);

        let i = inbox.clone();
        let on_message = Closure::<dyn FnMut(JsValue)>::new(move |e: JsValue| {
            let Ok(e) = e.dyn_into::<MessageEvent>() else {
                return;
            };
            let Ok(buf) = e.data().dyn_into::<js_sys::ArrayBuffer>() else {
                return;
            };
            let bytes = js_sys::Uint8Array::new(&buf).to_vec();
            let pushed = match parse_server_frame(&bytes) {
                Ok(ServerFrame::Segment(id, b)) => Pushed::Segment(id, b.to_vec()),
                Ok(ServerFrame::Control(StreamServer::Dropped(_))) => return,
                // This client reads the whole manifest and never asks for pages.
                Ok(ServerFrame::Page(_)) => {
                    Pushed::Error("stream: a page came unasked for".to_string())
                }
                Ok(ServerFrame::Control(StreamServer::Error(e))) => {
                    Pushed::Error(format!("stream: {}: {}", e.code, e.message))
                }
                Err(e) => Pushed::Error(format!("stream: a frame does not decode: {e}")),
            };
            i.borrow_mut().push_back(pushed);
        });
        ws.set_onmessage(Some(on_message.as_ref().unchecked_ref()));
        callbacks.push(on_message);

        let stale = Rc::new(Cell::new(false));
        let (o, c, u, st) = (open.clone(), closed.clone(), url.clone(), stale.clone());
        let on_close = Closure::<dyn FnMut(JsValue)>::new(move |e: JsValue| {
            o.set(false);
            let (code, why) = e
                .dyn_into::<CloseEvent>()
                .map(|e| {
                    let why = format!("{u}: closed ({}{})", e.code(), reason(&e.reason()));
                    (e.code(), why)
                })
                .unwrap_or_else(|_| (0, format!("{u}: closed")));
            st.set(code == portico_protocol::CLOSE_STALE);
            c.borrow_mut().get_or_insert(why);
        });
        ws.set_onclose(Some(on_close.as_ref().unchecked_ref()));
        callbacks.push(on_close);

        Ok(Stream {
            ws,
            inbox,
            open,
            closed,
            stale,
            evicted_early,
            _callbacks: callbacks,
        })
    }

    /// Whether the session is open (Hello sent).
    pub fn is_open(&self) -> bool {
        self.open.get()
    }

    /// Why the session ended, once it has.
    pub fn closed(&self) -> Option<String> {
        self.closed.borrow().clone()
    }

    /// Whether the server closed it because it serves another database now
    /// ([`portico_protocol::CLOSE_STALE`]): opening it again cannot help.
    pub fn stale(&self) -> bool {
        self.stale.get()
    }

    /// What arrived since the last call, oldest first, up to about `budget` bytes (at least
    /// one message); the rest stays for the next call.
    pub fn take(&self, budget: u64) -> Vec<Pushed> {
        let mut inbox = self.inbox.borrow_mut();
        let mut out = Vec::new();
        let mut taken = 0u64;
        while let Some(p) = inbox.front() {
            let bytes = match p {
                Pushed::Segment(_, b) => b.len() as u64,
                Pushed::Error(_) => 0,
            };
            if !out.is_empty() && taken + bytes > budget {
                break;
            }
            taken += bytes;
            out.extend(inbox.pop_front());
        }
        out
    }

    fn send(&self, msg: &StreamClient) {
        if let Ok(bytes) = portico_protocol::to_bincode(msg) {
            let _ = self.ws.send_with_u8_array(&bytes);
        }
    }

    /// This frame's observer (skipped while the socket's send buffer is backed up).
    pub fn observe(&self, obs: Observer) {
        if self.is_open() && self.ws.buffered_amount() < SEND_BACKLOG {
            self.send(&StreamClient::Observer(obs));
        }
    }

    /// Segments the cache released: the server's mirror forgets them (released before the
    /// session opened: told right after `Holding`).
    pub fn evicted(&self, ids: Vec<u32>) {
        if ids.is_empty() {
            return;
        }
        if self.is_open() {
            self.send(&StreamClient::Evicted(ids));
        } else if self.closed().is_none() {
            self.evicted_early.borrow_mut().extend(ids);
        }
    }
}

fn reason(r: &str) -> String {
    if r.is_empty() {
        String::new()
    } else {
        format!(", {r}")
    }
}

impl Drop for Stream {
    fn drop(&mut self) {
        self.ws.set_onopen(None);
        self.ws.set_onmessage(None);
        self.ws.set_onclose(None);
        let _ = self.ws.close();
    }
}
