//! The IO stage over server push (`GET /v1/stream`, one WebSocket), the client's default
//! transport, with HTTP pull ([`crate::drive`]) as its fallback.
//!
//! The session opens with `Hello` (the policy, the byte rate, the round trip: 0 at first, then
//! what a ping measured), and from then on the client sends only its observer each frame, what
//! the frame lacked (`Lacking`, pushed ahead of the server's list, as pull reads it ahead of
//! the answer) and what its cache released (`Evicted`, so the server's mirror of the cache
//! stays true and nothing is sent twice). The server pushes the observer's need list in need order, each item
//! when it can no longer wait for a later list (Funkhouser §5.2.3 with deadlines:
//! `portico_data::deadline`). No round trip per frame: a segment the view needs leaves the
//! server as soon as the observer that needs it arrives.
//!
//! When no session opens (a proxy that does not upgrade, a server at its session limit) or the
//! session ends (the server stopped or reloaded its database), the stage says why in a
//! [`Event::Failed`] and goes on over HTTP pull with the same frame states.
//!
//! Messages go out, and pushed frames come in, through the [`Fetcher`]'s link
//! ([`Fetcher::reaches_server`], [`Fetcher::reaches_client`]): the real client's is the
//! network itself, the load tester's an emulated link, so both transports are measured over
//! the same one.

use crate::drive::{Ask, Event, Fetcher, drive_after};
use futures_util::{SinkExt, StreamExt};
use portico_client::engine::pull::Fault;
use portico_client::engine::push::{Push, Pushed};
use portico_protocol::{Policy, StreamClient};
use std::fmt;
use std::str::FromStr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::http;

/// How the IO stage gets its segments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Transport {
    /// Server push over `/v1/stream`, falling back to pull when no session opens or it ends.
    #[default]
    Push,
    /// `POST /v1/prefetch` and `GET /v1/batch`, one answer per round trip.
    Pull,
}

impl fmt::Display for Transport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Transport::Push => "push",
            Transport::Pull => "pull",
        })
    }
}

impl FromStr for Transport {
    type Err = String;

    fn from_str(s: &str) -> Result<Transport, String> {
        match s {
            "push" | "stream" => Ok(Transport::Push),
            "pull" | "http" => Ok(Transport::Pull),
            other => Err(format!("transport {other:?}: expected push or pull")),
        }
    }
}

pub use portico_client::engine::reopen::{OPEN_TIMEOUT, OPEN_WAIT, REOPEN_FIRST, REOPEN_MAX};
use portico_client::engine::switch::{Carrier, Switch};

/// Runs the IO stage until the frame loop goes away: over push when `transport` says so (at
/// `rate_bytes_per_s`, which the server may cap), over pull ([`crate::drive::drive`], with
/// `parallel` and `window`) otherwise. Which one carries the segments is the engine's
/// [`Switch`]: the first session holds pull back [`OPEN_WAIT`] at most; when a session ends or
/// does not open, pull reads while sessions are tried again in the background, with back-off
/// ([`REOPEN_FIRST`] doubling to [`REOPEN_MAX`]); the first that opens takes over, told what
/// the cache holds. A session refused because the server now serves another database
/// ([`portico_protocol::CLOSE_STALE`] or `410 Gone`) is [`Event::Stale`], as pull's 410 is:
/// the IO stage stops.
#[allow(clippy::too_many_arguments)]
pub async fn run<F: Fetcher>(
    fetcher: F,
    policy: Policy,
    transport: Transport,
    rate_bytes_per_s: u64,
    parallel: usize,
    window: u64,
    mut state: watch::Receiver<Option<Ask>>,
    tx: mpsc::Sender<Event<F::Body>>,
) {
    let mut switch = Switch::new(transport == Transport::Push);
    let mut events = 0;
    // The session being opened (polled here, so that it goes when the stage does), and the
    // one open.
    let mut opening = None;
    let mut socket = None;
    loop {
        if switch.open_now(Instant::now()) {
            opening = Some(Box::pin(open(fetcher.clone())));
        }
        let mut settled = None;
        match switch.carrier(Instant::now()) {
            Carrier::Stopped => return,
            Carrier::Push => {
                let Some(ws) = socket.take() else { return };
                let (ended, sent) = push(
                    ws,
                    &fetcher,
                    policy,
                    rate_bytes_per_s,
                    events,
                    &mut state,
                    &tx,
                )
                .await;
                events = sent;
                let Ended::Failed(why) = ended else {
                    return stop(ended, &tx).await;
                };
                switch.failed(Instant::now());
                let msg = format!("{why}; reading over HTTP pull, opening the stream again");
                if tx.send(Event::Failed(msg)).await.is_err() {
                    return;
                }
                events += 1;
            }
            Carrier::Waiting => {
                // The first session: pull waits for it a moment.
                if let Some(o) = opening.as_mut() {
                    settled = tokio::time::timeout(OPEN_WAIT, o).await.ok();
                }
            }
            Carrier::Pull => {
                // Pull until a session opens (tried in the background after each back-off,
                // so reads go on meanwhile), the first try fails, or the database is stale.
                let until = async {
                    loop {
                        let Some(o) = opening.as_mut() else {
                            match switch.next_try(Instant::now()) {
                                Some(at) => tokio::time::sleep_until(at.into()).await,
                                None => std::future::pending::<()>().await,
                            }
                            if switch.open_now(Instant::now()) {
                                opening = Some(Box::pin(open(fetcher.clone())));
                            }
                            continue;
                        };
                        let result = o.await;
                        opening = None;
                        match result {
                            Err(Ended::Failed(why)) if switch.tries() > 1 => {
                                switch.failed(Instant::now());
                                tracing::debug!("stream: {why}");
                            }
                            other => {
                                settled = Some(other);
                                return;
                            }
                        }
                    }
                };
                let pulled = drive_after(
                    events,
                    fetcher.clone(),
                    policy,
                    parallel,
                    window,
                    state.clone(),
                    tx.clone(),
                    until,
                )
                .await;
                let Some(n) = pulled else { return };
                events = n;
            }
        }
        let Some(result) = settled else { continue };
        opening = None;
        match result {
            Ok(ws) => {
                switch.opened(Instant::now());
                socket = Some(ws);
            }
            Err(Ended::Failed(why)) => {
                // The first try (later ones fail quietly while pull reads).
                switch.failed(Instant::now());
                let msg = format!("{why}; reading over HTTP pull instead");
                if tx.send(Event::Failed(msg)).await.is_err() {
                    return;
                }
                events += 1;
            }
            Err(end) => return stop(end, &tx).await,
        }
    }
}

/// Ends the IO stage: a stale database is said so ([`Event::Stale`]).
async fn stop<B>(end: Ended, tx: &mpsc::Sender<Event<B>>) {
    if let Ended::Stale(why) = end {
        let _ = tx.send(Event::Stale(why)).await;
    }
}

/// An open WebSocket to the server.
type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// Opens a session (the handshake within [`OPEN_TIMEOUT`]).
async fn open<F: Fetcher>(f: F) -> Result<Socket, Ended> {
    let url = f
        .stream_url()
        .map_err(|e| Ended::Failed(format!("{e:#}")))?;
    // Messages name the address, never the token.
    let shown = url.split('?').next().unwrap_or_default().to_string();
    // Nagle's algorithm would hold each small message (an observer, a Lacking) until the
    // server acknowledged the one before: tens of milliseconds of delayed ACK per frame.
    let handshake = tokio_tungstenite::connect_async_with_config(&url, None, true);
    match tokio::time::timeout(OPEN_TIMEOUT, handshake).await {
        Ok(Ok((ws, _))) => Ok(ws),
        Ok(Err(tokio_tungstenite::tungstenite::Error::Http(r)))
            if r.status() == http::StatusCode::GONE =>
        {
            Err(Ended::Stale(format!(
                "{shown}: 410 Gone: the server serves another database"
            )))
        }
        Ok(Err(e)) => Err(Ended::Failed(format!("{shown}: no session: {e}"))),
        Err(_) => Err(Ended::Failed(format!(
            "{shown}: no session within {} s",
            OPEN_TIMEOUT.as_secs()
        ))),
    }
}

/// Why a session ended.
enum Ended {
    /// The frame loop went away.
    Gone,
    /// The server serves another database now: why.
    Stale(String),
    /// The session did not open, or ended: why.
    Failed(String),
}

/// What came off the socket, on its way to the frame loop.
enum Incoming {
    Segment {
        id: u32,
        bytes: Vec<u8>,
        listed_at: Instant,
    },
    /// A cell's page (deflated), taken before the segments after it.
    Page(Vec<u8>),
    Failed(String),
}

/// One push session on `ws`, after `events` handed on before it; returns why it ended and how
/// many events were handed on in all.
async fn push<F: Fetcher>(
    ws: Socket,
    f: &F,
    policy: Policy,
    rate: u64,
    events: u64,
    state: &mut watch::Receiver<Option<Ask>>,
    tx: &mpsc::Sender<Event<F::Body>>,
) -> (Ended, u64) {
    let shown = f
        .stream_url()
        .map(|u| u.split('?').next().unwrap_or_default().to_string())
        .unwrap_or_default();
    let (mut sink, mut socket) = ws.split();

    // Out: each message leaves when the link has taken it there (order kept).
    let (out, mut out_rx) = mpsc::unbounded_channel::<(Instant, Message)>();
    let sender = tokio::spawn(async move {
        while let Some((at, m)) = out_rx.recv().await {
            tokio::time::sleep_until(at.into()).await;
            if sink.send(m).await.is_err() {
                break;
            }
        }
        let _ = sink.close().await;
    });
    // The session's state (what to send each frame, what was handed on): the engine's.
    let held: Vec<u32> = state
        .borrow()
        .as_ref()
        .map(|a| a.held.clone())
        .unwrap_or_default();
    let (session, opening) = Push::open(
        &shown,
        policy,
        rate,
        Duration::ZERO,
        f.paged(),
        held,
        events,
    );
    let session = Arc::new(Mutex::new(session));
    // In: each frame is the client's when the link has brought it; decoded, then handed on.
    let (inbox, mut in_rx) = mpsc::unbounded_channel::<(Instant, Incoming)>();
    let (fd, txd, h, outd) = (f.clone(), tx.clone(), session.clone(), out.clone());
    let mut delivery = tokio::spawn(async move {
        while let Some((at, got)) = in_rx.recv().await {
            tokio::time::sleep_until(at.into()).await;
            let (event, segment) = match got {
                Incoming::Segment {
                    id,
                    bytes,
                    listed_at,
                } => match fd.settle(id).await.and_then(|()| fd.decode(id, &bytes)) {
                    Ok(body) => {
                        let e = Event::Segment {
                            id,
                            body,
                            bytes: bytes.len() as u64,
                            listed_at,
                        };
                        (e, Some(id))
                    }
                    // Pushed before any page brought its row (a policy whose list names what
                    // no pushed stab list does): given back, the server pushes it again later.
                    Err(e) if e.is::<crate::io::Unready>() => {
                        tracing::debug!("stream: {e:#}");
                        let back =
                            portico_protocol::to_bincode(&Push::rejected(id)).unwrap_or_default();
                        let _ = outd.send((fd.reaches_server(), Message::Binary(back.into())));
                        continue;
                    }
                    // Rejected (a checksum, a damaged frame): the server's mirror must not
                    // count it held, or it would never come again.
                    Err(e) => {
                        let back =
                            portico_protocol::to_bincode(&Push::rejected(id)).unwrap_or_default();
                        let _ = outd.send((fd.reaches_server(), Message::Binary(back.into())));
                        (Event::Failed(format!("segment {id}: {e:#}")), None)
                    }
                },
                Incoming::Page(bytes) => match fd.take_page(&bytes) {
                    Ok(()) => continue,
                    Err(e) => (Event::Failed(format!("{e:#}")), None),
                },
                Incoming::Failed(why) => (Event::Failed(why), None),
            };
            if txd.send(event).await.is_err() {
                return;
            }
            lock(&h).handed(segment);
        }
    });
    let send = |m: &StreamClient| {
        let bytes = portico_protocol::to_bincode(m).unwrap_or_default();
        let _ = out.send((f.reaches_server(), Message::Binary(bytes.into())));
    };
    for m in &opening {
        send(m);
    }
    let pinged = Instant::now();
    let _ = out.send((f.reaches_server(), Message::Ping(Vec::new().into())));
    let ended = loop {
        tokio::select! {
            changed = state.changed() => {
                if changed.is_err() {
                    break Ended::Gone;
                }
                let Some(ask) = state.borrow_and_update().clone() else { continue };
                for m in lock(&session).frame(&ask.frame_state(), Instant::now()) {
                    send(&m);
                }
            }
            msg = socket.next() => {
                let frame = match msg {
                    Some(Ok(Message::Binary(b))) => b,
                    Some(Ok(Message::Pong(_))) => {
                        let rtt = f.reaches_client(0).saturating_duration_since(pinged);
                        send(&lock(&session).measured(rtt));
                        continue;
                    }
                    Some(Ok(Message::Close(c))) => {
                        let close = c.as_ref().map(|c| (u16::from(c.code), c.reason.as_str()));
                        break match lock(&session).closed(close) {
                            Fault::Stale(why) => Ended::Stale(why),
                            Fault::Failed(why) => Ended::Failed(why),
                        };
                    }
                    Some(Ok(_)) => continue,
                    Some(Err(e)) => break Ended::Failed(format!("{shown}: the session broke: {e}")),
                    None => break Ended::Failed(format!("{shown}: the session ended")),
                };
                let at = f.reaches_client(frame.len() as u64);
                let got = match lock(&session).incoming(&frame, at) {
                    Pushed::Segment { id, bytes, listed_at } => Incoming::Segment {
                        id,
                        bytes: bytes.to_vec(),
                        listed_at,
                    },
                    Pushed::Page(bytes) => Incoming::Page(bytes.to_vec()),
                    Pushed::Failed(why) => Incoming::Failed(why),
                    Pushed::Nothing => continue,
                };
                if inbox.send((at, got)).is_err() {
                    break Ended::Gone;
                }
            }
            _ = &mut delivery => break Ended::Gone,
        }
    };
    drop(out);
    sender.abort();
    // What is on its way is delivered before pull takes over, so the events stay counted.
    drop(inbox);
    if !delivery.is_finished() {
        let _ = (&mut delivery).await;
    }
    let events = lock(&session).events();
    (ended, events)
}

/// The session's state, whoever panicked holding it.
fn lock(s: &Mutex<Push>) -> std::sync::MutexGuard<'_, Push> {
    s.lock().unwrap_or_else(|e| e.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transports_parse_and_print_back() {
        for t in [Transport::Push, Transport::Pull] {
            assert_eq!(t.to_string().parse::<Transport>(), Ok(t));
        }
        assert_eq!("stream".parse::<Transport>(), Ok(Transport::Push));
        assert_eq!(Transport::default(), Transport::Push);
        let e = "udp".parse::<Transport>().unwrap_err();
        assert!(e.contains("\"udp\"") && e.contains("push or pull"), "{e}");
    }
}
