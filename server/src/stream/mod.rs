//! `GET /v1/db/{database_id}/stream` (and `GET /v1/stream` for scripts): a WebSocket session
//! per client. The client sends its observer every frame;
//! the server pushes the segments of the observer's need list (Funkhouser §5.2) that a mirror of
//! what it already sent lacks, in need order, paced to the session's byte rate; tells the client
//! which queued items it dropped because their need vanished; and forgets segments the client
//! reports evicted. No round trip per frame is needed.
//!
//! Under the predicted lookahead (the default policy) what an observer will see depends on its
//! velocity and turn as well as its cell and view, so its places are finer (the metre of the
//! cell it is in, and buckets of its view, velocity and turn: `portico_data::prefetch::swept`),
//! and the session pushes an item
//! only when leaving it to the next observer's list would make it late
//! ([`portico_data::deadline`]): the lead is the list's age (counted from when the client sent
//! the observer, half its round trip before it arrived), a frame until the next observer, the
//! round trip and the margin, and what is queued is the push clock's backlog at the session's
//! rate. What is not due yet stays in the list for the next push, or for the next list.
//!
//! Answers are shared and incremental: under Funkhouser's range lookahead the need list
//! depends only on the eye cell and a direction bucket (`portico_data::prefetch::shared`), and
//! under the predicted one on the finer place above, so an observer that stays in its place
//! costs a k-D descent and nothing else, a new place whose list some session already
//! computed costs a cache lookup, and only a new place nobody has asked for is computed. What
//! is left to push is the list past a cursor, minus the mirror: no per-session copy of it.
//! A database without cells falls back to one computation per observer. A shared list is wider
//! than an observer's own, so while the server could answer every observer with its own within
//! a share of its compute slots, each gets its own (`crate::answers`); a crowd shares.
//!
//! A session cannot take more than its share:
//! - observers are coalesced: only the latest one is computed, on a compute slot within the
//!   prefetch deadline, never on the async workers, so a flood of messages costs one
//!   computation at a time; a computation of half the deadline or more makes the session wait
//!   as long before its next (at most about half a slot each), and one whose session ended is
//!   cancelled; one update makes at most [`PAGES_PER_UPDATE`] pages;
//! - every send races the shutdown signal, and the connection's write timeout
//!   ([`crate::timed`]) fails a send the client takes nothing of: a client that never reads
//!   loses its slot, and a stop or reload ends the session whatever the client does;
//! - a silent client is closed after the idle timeout;
//! - Hello, observers and id lists are checked, every number before it reaches time arithmetic
//!   ([`crate::validate::validate_policy`], and every wait clamped);
//! - what a client sends is read at most at [`INBOUND_RATE`], and a large message is decoded
//!   and applied on the blocking pool, never on an async worker;
//! - a session that ends for any reason, a panic included, releases its slot.
//!
//! The URL names the database the client's manifest describes: a session opened on another
//! (the file was rebuilt and reloaded between the client's manifest and its stream) is closed
//! at once with [`portico_protocol::CLOSE_STALE`] and a reason, never fed the other file's
//! segments. Every close carries a code and a reason ([`End`]).

mod messages;
mod push;

pub use push::PAGES_PER_UPDATE;

use crate::error::Error;
use crate::state::AppState;
use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade, close_code};
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use futures_util::{FutureExt, SinkExt, StreamExt};
use portico_data::prefetch::NeedList;
use portico_data::prefetch::shared::{SharePlace, encode_policy};
use portico_protocol::{CLOSE_STALE, FRAME_CONTROL, Observer, Policy, StreamServer};
use std::collections::HashSet;
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use tokio::sync::OwnedSemaphorePermit;
use tokio::time::{Duration, Instant, sleep_until};

/// How far behind the pacing clock may fall before the time is lost (a push burst's length).
const PACING_BURST: Duration = Duration::from_millis(10);

/// Most bytes per second a session reads from its client, on average: observers, Lacking and
/// Evicted lists of a real client are a few KB per second; a client sending more waits (TCP
/// pushes back), so no client can make the server decode megabytes per second for it.
pub const INBOUND_RATE: u64 = 256 << 10;

/// How far ahead of [`INBOUND_RATE`] a client may send at once: one largest message (a
/// reopened session's `Holding` list).
const INBOUND_BURST: Duration = Duration::from_secs(4);

/// Client messages at least this large are decoded and applied on the blocking pool.
const HEAVY_BYTES: usize = 16 << 10;

/// How long a closing session waits for the client's close frame.
const CLOSING: Duration = Duration::from_millis(500);

/// Longest wait a session's clocks may be set to (seconds): a pacing or recheck time computed
/// from a client's numbers never overflows the clock.
const MAX_WAIT_S: f64 = 3600.0;

/// `GET /v1/stream`: a session over whatever database is served now (for scripts and older
/// clients; clients name theirs, [`upgrade_in`]).
pub async fn upgrade(State(s): State<Arc<AppState>>, ws: WebSocketUpgrade) -> Response {
    open(s, ws)
}

/// `GET /v1/db/{database_id}/stream`: a session over the database the client's manifest
/// describes. Another database id gets the upgrade and at once a close with [`CLOSE_STALE`]
/// saying that database is no longer served (a browser sees no HTTP status on a WebSocket,
/// only the close).
pub async fn upgrade_in(
    State(s): State<Arc<AppState>>,
    Path(db): Path<String>,
    ws: WebSocketUpgrade,
) -> Response {
    if db == s.database_id {
        return open(s, ws);
    }
    s.metrics.stream_stale.fetch_add(1, Relaxed);
    // A close reason is at most 123 bytes: an id is 32 hex digits; anything else is not
    // echoed.
    let hex = db.len() <= 32 && db.bytes().all(|b| b.is_ascii_hexdigit());
    let shown = if hex { db.as_str() } else { "named" };
    let reason = format!("database {shown} is no longer served; read /v1/manifest again");
    ws.on_upgrade(move |mut socket| async move {
        let close = Message::Close(Some(CloseFrame {
            code: CLOSE_STALE,
            reason: reason.into(),
        }));
        if let Ok(Ok(())) = tokio::time::timeout(Duration::from_secs(1), socket.send(close)).await {
            // The closing handshake: read what the client sent (its Hello, an observer) up to
            // its close, so the socket does not end in a reset that could lose ours.
            let _ = tokio::time::timeout(CLOSING, async {
                while let Some(Ok(m)) = socket.next().await {
                    if matches!(m, Message::Close(_)) {
                        break;
                    }
                }
            })
            .await;
        }
    })
}

/// A session's slot: the permit and the open-sessions gauge, both given back when it is
/// dropped, however the session ended (a panic unwinds through it).
struct Slot {
    state: Arc<AppState>,
    _permit: OwnedSemaphorePermit,
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.state.metrics.sessions.fetch_sub(1, Relaxed);
    }
}

/// Upgrades to a session if a session slot is free (else 503).
fn open(s: Arc<AppState>, ws: WebSocketUpgrade) -> Response {
    let Ok(permit) = s.sessions.clone().try_acquire_owned() else {
        return Error::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "sessions",
            "too many stream sessions; retry later",
        )
        .into_response();
    };
    // Clients send small messages: a 128 KiB read buffer per session (tungstenite's default)
    // would be most of a session's memory. Frames are written as they come, not batched.
    ws.max_message_size(s.config.max_body_bytes)
        .read_buffer_size(4 << 10)
        .write_buffer_size(0)
        .on_upgrade(move |socket| async move {
            s.metrics.sessions.fetch_add(1, Relaxed);
            s.metrics.sessions_total.fetch_add(1, Relaxed);
            let _slot = Slot {
                state: s.clone(),
                _permit: permit,
            };
            let run = std::panic::AssertUnwindSafe(Session::new(s.clone()).run(socket));
            if let Err(p) = run.catch_unwind().await {
                let what = p
                    .downcast_ref::<String>()
                    .map(String::as_str)
                    .or_else(|| p.downcast_ref::<&str>().copied())
                    .unwrap_or("a panic");
                tracing::error!("a stream session failed: {what}");
            }
        })
}

/// Why a session ended, and the close frame that says so.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum End {
    /// The client closed or dropped the connection.
    Gone,
    /// The client sent nothing for the idle timeout.
    Idle,
    /// The server is stopping or reloading its database.
    Shutdown,
    /// The client did not take a message within the write timeout.
    Slow,
    /// A message larger than the server takes.
    TooBig,
    /// A message the WebSocket protocol does not allow.
    Protocol(String),
}

impl End {
    /// The close frame to send (`None`: the connection is gone or stuck).
    fn frame(&self) -> Option<CloseFrame> {
        let (code, reason) = match self {
            End::Gone | End::Slow => return None,
            End::Idle => (
                close_code::NORMAL,
                "idle: no message within the idle timeout",
            ),
            End::Shutdown => (
                close_code::AWAY,
                "the server is stopping or reloading: open the stream again",
            ),
            End::TooBig => (
                close_code::SIZE,
                "a message is larger than the server takes",
            ),
            End::Protocol(_) => (close_code::PROTOCOL, "a WebSocket protocol error"),
        };
        Some(CloseFrame {
            code,
            reason: reason.into(),
        })
    }

    /// The end a read error means.
    fn of(e: &axum::Error) -> End {
        let text = e.to_string();
        if text.contains("Space limit") || text.contains("too long") {
            End::TooBig
        } else {
            End::Protocol(text)
        }
    }
}

/// A need list being computed for the session.
/// Its output: the list, and how long the computation held a compute slot (zero when it
/// took another session's list).
type Computing =
    Pin<Box<dyn Future<Output = (Result<Arc<NeedList>, Error>, std::time::Duration)> + Send>>;

/// An observer waiting for its need list.
#[derive(Clone, Copy)]
struct Pending {
    obs: Observer,
    /// Its place (`None`: without cells, or answers not shared).
    place: Option<SharePlace>,
    /// When the oldest observer it replaced arrived (latency counts from there).
    arrived: Instant,
    /// When this observer arrived (its list's deadlines count from there).
    at: Instant,
    /// Observers it stands for (it and those it replaced).
    updates: u64,
    /// The session's policy generation when it arrived.
    generation: u64,
}

/// One client's session state.
struct Session {
    state: Arc<AppState>,
    policy: Policy,
    /// The policy's bytes, the shared lists' key part that stays for the session.
    policy_bytes: Arc<[u8]>,
    rate: u64,
    /// The client's round trip (seconds) as it reported it in Hello.
    rtt_s: f64,
    /// Segments the client holds (sent and not evicted).
    mirror: HashSet<u32>,
    /// The need list being pushed.
    list: Arc<NeedList>,
    /// Items of `list` before this are pushed, held or skipped.
    cursor: usize,
    /// What the client's latest frame lacked, pushed first; and how far it has been pushed.
    lacking: Vec<u32>,
    lacking_at: usize,
    /// The place `list` was made for (`None`: for one observer, or nothing yet).
    place: Option<SharePlace>,
    /// The place of the latest observer: a list computed for another is stale on arrival.
    want: Option<SharePlace>,
    /// Bumped when Hello changes the policy: lists computed under an older one are stale.
    generation: u64,
    /// When the observer of `list` arrived.
    observed: Instant,
    /// When the paced link is free for the next push.
    next_free: Instant,
    /// With deadlines, when to look for a due item again (nothing in the list was due).
    recheck: Instant,
    /// The latest observer not yet served (older ones are dropped: only the latest matters).
    pending: Option<Pending>,
    /// No computation starts before this (one that ran past its deadline makes the session
    /// wait as long as it took, so a policy too wide for the deadline takes half a slot).
    compute_after: Instant,
    /// When the client's next message may be read ([`INBOUND_RATE`]).
    inbound_free: Instant,
    /// Whether the client started from the core manifest ([`portico_protocol::StreamClient::Pages`]):
    /// each cell's page goes before its stab list.
    paged: bool,
    /// Cells whose page was sent.
    pages_sent: HashSet<u32>,
    /// A stab list whose page went first: it is pushed next.
    after_page: Option<u32>,
}

impl Session {
    fn new(state: Arc<AppState>) -> Session {
        let rate = state.config.max_session_rate;
        let policy = Policy::default();
        let now = Instant::now();
        Session {
            state,
            policy_bytes: encode_policy(&policy),
            policy,
            rate,
            rtt_s: 0.0,
            mirror: HashSet::new(),
            list: Arc::new(NeedList::default()),
            cursor: 0,
            lacking: Vec::new(),
            lacking_at: 0,
            place: None,
            want: None,
            generation: 0,
            observed: now,
            next_free: now,
            recheck: now,
            pending: None,
            compute_after: now,
            // A new session starts with its whole burst (a reopened one's Holding list).
            inbound_free: now.checked_sub(INBOUND_BURST).unwrap_or(now),
            paged: false,
            pages_sent: HashSet::new(),
            after_page: None,
        }
    }

    async fn run(mut self, socket: WebSocket) {
        let (mut tx, mut rx) = socket.split();
        let mut shutdown = self.state.shutdown.subscribe();
        if *shutdown.borrow() {
            let _ = tx.send(Message::Close(End::Shutdown.frame())).await;
            return;
        }
        let idle = self.state.config.idle_timeout;
        let mut idle_deadline = Instant::now() + idle;
        let mut computing: Option<(Computing, Pending)> = None;
        let end = loop {
            let now = Instant::now();
            if computing.is_none()
                && now >= self.compute_after
                && let Some(p) = self.pending.take()
            {
                computing = Some((self.compute(p.obs, p.place), p));
            }
            let waiting = computing.is_none() && self.pending.is_some();
            let reading = self.inbound_free <= now;
            let pending = self.after_page.is_some()
                || self.cursor < self.list.items.len()
                || self.lacking_at < self.lacking.len();
            let push_at = pending.then_some(self.next_free.max(self.recheck));
            let outgoing = tokio::select! {
                msg = rx.next(), if reading => {
                    let msg = match msg {
                        None => break End::Gone,
                        Some(Err(e)) => break End::of(&e),
                        Some(Ok(m)) => m,
                    };
                    idle_deadline = Instant::now() + idle;
                    match self.on_message(msg).await {
                        Ok(reply) => reply,
                        Err(end) => break end,
                    }
                }
                _ = sleep_until(self.inbound_free), if !reading => None,
                _ = sleep_until(self.compute_after), if waiting => None,
                done = async { computing.as_mut().expect("guarded").0.as_mut().await }, if computing.is_some() => {
                    let (_, p) = computing.take().expect("guarded");
                    self.on_computed(done, p)
                }
                _ = sleep_until(push_at.unwrap_or(idle_deadline)), if push_at.is_some() => {
                    self.next_push()
                }
                // Not while the server itself holds back the client's messages.
                _ = sleep_until(idle_deadline.max(self.inbound_free)) => break End::Idle,
                _ = shutdown.changed() => break End::Shutdown,
            };
            let Some(message) = outgoing else { continue };
            // A client that takes nothing for the write timeout fails the send (the
            // connection's own timeout, `crate::timed`, counts from the last byte it took, so a
            // large segment to a slow but reading client is not cut off).
            let sent = tokio::select! {
                r = tx.send(message) => r.is_ok(),
                _ = shutdown.changed() => break End::Shutdown,
            };
            if !sent {
                break End::Slow;
            }
        };
        // The computation in flight, if any, is dropped here: that cancels it.
        drop(computing);
        if let Some(frame) = end.frame() {
            let close = tx.send(Message::Close(Some(frame)));
            if tokio::time::timeout(Duration::from_millis(100), close)
                .await
                .is_ok_and(|r| r.is_ok())
            {
                // The closing handshake: what the client sent meanwhile is read, so the socket
                // does not end in a reset that could lose the close frame.
                let _ = tokio::time::timeout(CLOSING, async {
                    while let Some(Ok(m)) = rx.next().await {
                        if matches!(m, Message::Close(_)) {
                            break;
                        }
                    }
                })
                .await;
            }
        }
    }

    /// Counts `bytes` read from the client against [`INBOUND_RATE`].
    fn took(&mut self, bytes: usize) {
        let now = Instant::now();
        let floor = now.checked_sub(INBOUND_BURST).unwrap_or(now);
        self.inbound_free = self.inbound_free.max(floor) + secs(bytes as f64 / INBOUND_RATE as f64);
    }
}

/// `s` seconds as a duration, within `[0, MAX_WAIT_S]` (NaN: zero).
fn secs(s: f64) -> Duration {
    Duration::try_from_secs_f64(s.clamp(0.0, MAX_WAIT_S)).unwrap_or(Duration::ZERO)
}

fn control(msg: &StreamServer) -> Message {
    let mut frame = vec![FRAME_CONTROL];
    frame.extend(portico_protocol::to_bincode(msg).unwrap_or_default());
    Message::Binary(frame.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waits_from_client_numbers_stay_on_the_clock() {
        assert_eq!(secs(f64::NAN), Duration::ZERO);
        assert_eq!(secs(-1.0), Duration::ZERO);
        assert_eq!(secs(1e30), Duration::from_secs_f64(MAX_WAIT_S));
        assert_eq!(secs(f64::INFINITY), Duration::from_secs_f64(MAX_WAIT_S));
        assert_eq!(secs(0.25), Duration::from_millis(250));
        // The furthest wait still fits the clock.
        let _ = Instant::now() + secs(1e300);
    }

    #[test]
    fn every_end_but_a_lost_connection_closes_with_a_code() {
        let codes: Vec<_> = [
            End::Idle,
            End::Shutdown,
            End::TooBig,
            End::Protocol("x".into()),
        ]
        .iter()
        .map(|e| e.frame().expect("a close frame").code)
        .collect();
        assert_eq!(codes, [1000, 1001, 1009, 1002]);
        assert!(End::Gone.frame().is_none() && End::Slow.frame().is_none());
    }
}
