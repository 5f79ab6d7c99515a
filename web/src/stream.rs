//! Server push over `/v1/db/{database_id}/stream` from a page: one WebSocket, a thin shell
//! around the client engine's push session ([`portico_client::engine::push`], which says what
//! to send each frame and what a pushed frame is). Frames arrive on the socket's callback and
//! wait in an inbox for the next animation frame.

use portico_protocol::StreamClient;
use std::cell::{Cell, RefCell};
use std::collections::VecDeque;
use std::rc::Rc;
use std::time::Duration;
use wasm_bindgen::prelude::*;
use web_sys::{BinaryType, CloseEvent, MessageEvent, WebSocket};

/// Most bytes waiting in the socket's send buffer before an observer is skipped (the server
/// only computes the latest one anyway).
const SEND_BACKLOG: u32 = 64 << 10;

/// One WebSocket to the server.
pub struct Stream {
    ws: WebSocket,
    /// The address, for messages (never the token).
    url: String,
    inbox: Rc<RefCell<VecDeque<Vec<u8>>>>,
    open: Rc<Cell<bool>>,
    /// Half the handshake, once it is open: the round trip the server counts deadlines with.
    rtt_ms: Rc<Cell<f64>>,
    /// The close frame's code and reason, once it has closed.
    closed: Rc<RefCell<Option<(u16, String)>>>,
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
    /// Opens a socket to the server at `base` on database `db`.
    /// `token`: the server's `--token`, given as `?token=` (a browser cannot set headers on a
    /// WebSocket).
    pub fn open(base: &str, db: Option<&str>, token: Option<&str>) -> Result<Stream, String> {
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
        let rtt_ms = Rc::new(Cell::new(0.0));
        let closed = Rc::new(RefCell::new(None));
        let mut callbacks = Vec::new();

        // The handshake took a TCP and an HTTP round trip: half of it is the round trip.
        let opened = js_sys::Date::now();
        let (o, r) = (open.clone(), rtt_ms.clone());
        let on_open = Closure::<dyn FnMut(JsValue)>::new(move |_| {
            r.set(((js_sys::Date::now() - opened) / 2.0).clamp(0.0, 10_000.0));
            o.set(true);
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
            i.borrow_mut()
                .push_back(js_sys::Uint8Array::new(&buf).to_vec());
        });
        ws.set_onmessage(Some(on_message.as_ref().unchecked_ref()));
        callbacks.push(on_message);

        let (o, c) = (open.clone(), closed.clone());
        let on_close = Closure::<dyn FnMut(JsValue)>::new(move |e: JsValue| {
            o.set(false);
            let close = e
                .dyn_into::<CloseEvent>()
                .map(|e| (e.code(), e.reason()))
                .unwrap_or((0, String::new()));
            c.borrow_mut().get_or_insert(close);
        });
        ws.set_onclose(Some(on_close.as_ref().unchecked_ref()));
        callbacks.push(on_close);

        Ok(Stream {
            ws,
            url,
            inbox,
            open,
            rtt_ms,
            closed,
            _callbacks: callbacks,
        })
    }

    /// The address (without the token).
    pub fn url(&self) -> &str {
        &self.url
    }

    /// Whether the socket is open.
    pub fn is_open(&self) -> bool {
        self.open.get()
    }

    /// Half the handshake's time (known once open).
    pub fn rtt(&self) -> Duration {
        Duration::from_secs_f64(self.rtt_ms.get() / 1000.0)
    }

    /// The close frame's code and reason, once the socket has closed.
    pub fn closed(&self) -> Option<(u16, String)> {
        self.closed.borrow().clone()
    }

    /// The frames that arrived since the last call, oldest first, up to about `budget` bytes
    /// (at least one); the rest stays for the next call.
    pub fn take(&self, budget: u64) -> Vec<Vec<u8>> {
        let mut inbox = self.inbox.borrow_mut();
        let mut out = Vec::new();
        let mut taken = 0u64;
        while let Some(f) = inbox.front() {
            let bytes = f.len() as u64;
            if !out.is_empty() && taken + bytes > budget {
                break;
            }
            taken += bytes;
            out.extend(inbox.pop_front());
        }
        out
    }

    /// Sends a message; an observer is skipped while the socket's send buffer is backed up.
    pub fn send(&self, msg: &StreamClient) {
        if !self.is_open()
            || matches!(msg, StreamClient::Observer(_)) && self.ws.buffered_amount() >= SEND_BACKLOG
        {
            return;
        }
        if let Ok(bytes) = portico_protocol::to_bincode(msg) {
            let _ = self.ws.send_with_u8_array(&bytes);
        }
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
