//! `GET /v1/stream`: a WebSocket session per client. The client sends its observer every frame;
//! the server pushes the segments of the observer's need list (Funkhouser §5.2) that a mirror of
//! what it already sent lacks, in need order, paced to the session's byte rate; tells the client
//! which queued items it dropped because their need vanished; and forgets segments the client
//! reports evicted. No round trip per frame is needed.
//!
//! Answers are shared and incremental: the need list depends only on the eye cell and a
//! direction bucket (`portico_data::prefetch::shared`), so an observer that stays in its cell
//! and bucket costs a k-D descent and nothing else, a new place whose list some session already
//! computed costs a cache lookup, and only a new place nobody has asked for is computed. What
//! is left to push is the list past a cursor, minus the mirror: no per-session copy of it.
//! A database without cells falls back to one computation per observer.
//!
//! A session cannot take more than its share: observers are coalesced (only the latest one is
//! computed, on a compute slot within the prefetch deadline, never on the async workers, so a
//! flood of messages costs one computation at a time); every send races the write timeout and
//! the shutdown signal (a client that never reads loses its slot, and a stop or reload ends the
//! session whatever the client does); a silent client is closed after the idle timeout; Hello,
//! observers and eviction notices are checked.

use crate::error::Error;
use crate::state::AppState;
use axum::extract::State;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use futures_util::{SinkExt, StreamExt};
use portico_data::prefetch::NeedList;
use portico_data::prefetch::shared::{ShareKey, SharePlace, encode_policy};
use portico_protocol::{
    FRAME_CONTROL, Observer, PROTOCOL_VERSION, Policy, StreamClient, StreamServer, segment_frame,
};
use std::collections::HashSet;
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use tokio::time::{Duration, Instant, sleep, sleep_until};

/// Upgrades to a session if a session slot is free (else 503).
pub async fn upgrade(State(s): State<Arc<AppState>>, ws: WebSocketUpgrade) -> Response {
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
            Session::new(s.clone()).run(socket).await;
            s.metrics.sessions.fetch_sub(1, Relaxed);
            drop(permit);
        })
}

/// A need list being computed for the session.
type Computing = Pin<Box<dyn Future<Output = Result<Arc<NeedList>, Error>> + Send>>;

/// An observer waiting for its need list.
#[derive(Clone, Copy)]
struct Pending {
    obs: Observer,
    /// Its place (`None`: without cells, or answers not shared).
    place: Option<SharePlace>,
    /// When the oldest observer it replaced arrived (latency counts from there).
    arrived: Instant,
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
    /// Segments the client holds (sent and not evicted).
    mirror: HashSet<u32>,
    /// The need list being pushed.
    list: Arc<NeedList>,
    /// Items of `list` before this are pushed, held or skipped.
    cursor: usize,
    /// The place `list` was made for (`None`: for one observer, or nothing yet).
    place: Option<SharePlace>,
    /// The place of the latest observer: a list computed for another is stale on arrival.
    want: Option<SharePlace>,
    /// Bumped when Hello changes the policy: lists computed under an older one are stale.
    generation: u64,
    /// When the paced link is free for the next push.
    next_free: Instant,
    /// The latest observer not yet served (older ones are dropped: only the latest matters).
    pending: Option<Pending>,
}

impl Session {
    fn new(state: Arc<AppState>) -> Session {
        let rate = state.config.max_session_rate;
        let policy = Policy::default();
        Session {
            state,
            policy_bytes: encode_policy(&policy),
            policy,
            rate,
            mirror: HashSet::new(),
            list: Arc::new(NeedList::default()),
            cursor: 0,
            place: None,
            want: None,
            generation: 0,
            next_free: Instant::now(),
            pending: None,
        }
    }

    async fn run(mut self, socket: WebSocket) {
        let (mut tx, mut rx) = socket.split();
        let mut shutdown = self.state.shutdown.subscribe();
        if *shutdown.borrow() {
            return;
        }
        let idle = self.state.config.idle_timeout;
        let write_timeout = self.state.config.write_timeout;
        let mut idle_deadline = Instant::now() + idle;
        let mut computing: Option<(Computing, Pending)> = None;
        loop {
            if computing.is_none()
                && let Some(p) = self.pending.take()
            {
                computing = Some((self.compute(p.obs, p.place), p));
            }
            let push_at = (self.cursor < self.list.items.len()).then_some(self.next_free);
            let outgoing = tokio::select! {
                msg = rx.next() => {
                    let Some(Ok(msg)) = msg else { break };
                    idle_deadline = Instant::now() + idle;
                    match self.on_message(msg) {
                        Ok(reply) => reply,
                        Err(()) => break,
                    }
                }
                done = async { computing.as_mut().expect("guarded").0.as_mut().await }, if computing.is_some() => {
                    let (_, p) = computing.take().expect("guarded");
                    self.on_computed(done, p)
                }
                _ = sleep_until(push_at.unwrap_or(idle_deadline)), if push_at.is_some() => {
                    self.next_push()
                }
                _ = sleep_until(idle_deadline) => break,
                _ = shutdown.changed() => break,
            };
            let Some(message) = outgoing else { continue };
            let sent = tokio::select! {
                r = tx.send(message) => r.is_ok(),
                _ = sleep(write_timeout) => false,
                _ = shutdown.changed() => false,
            };
            if !sent {
                break;
            }
        }
        let _ =
            tokio::time::timeout(Duration::from_millis(100), tx.send(Message::Close(None))).await;
    }

    /// Starts computing the need list for `obs`: the shared list of its place, or (without
    /// cells) its own.
    fn compute(&self, obs: Observer, place: Option<SharePlace>) -> Computing {
        let state = self.state.clone();
        let policy = self.policy;
        let key = place.map(|p| ShareKey::new(p, self.policy_bytes.clone()));
        Box::pin(async move {
            let s = state.clone();
            state
                .compute
                .run(move |budget| {
                    let p = &s.prefetcher;
                    match &key {
                        Some(k) => p.shared_list(k, &obs, &policy, &budget),
                        None => p.need_list_within(&obs, &policy, &budget).map(Arc::new),
                    }
                    .map_err(Error::from)
                })
                .await
        })
    }

    /// Handles one client message; returns a control reply, or `Err` to end the session.
    fn on_message(&mut self, msg: Message) -> Result<Option<Message>, ()> {
        let bytes = match msg {
            Message::Binary(b) => b,
            Message::Text(t) => axum::body::Bytes::from(t.as_str().as_bytes().to_vec()),
            Message::Close(_) => return Err(()),
            Message::Ping(_) | Message::Pong(_) => return Ok(None),
        };
        let decoded = portico_protocol::from_bincode::<StreamClient>(&bytes)
            .or_else(|_| portico_protocol::from_json::<StreamClient>(&bytes));
        let error = |e: Error| Ok(Some(control(&StreamServer::Error(e.to_api()))));
        match decoded {
            Ok(StreamClient::Hello { version, .. }) if version != PROTOCOL_VERSION => error(
                Error::bad_request(format!("protocol version {version} is not supported")),
            ),
            Ok(StreamClient::Hello {
                policy,
                rate_bytes_per_s,
                ..
            }) => {
                if let Err(e) = crate::routes::validate_policy(&policy) {
                    return error(e);
                }
                if policy != self.policy {
                    self.policy = policy;
                    self.policy_bytes = encode_policy(&policy);
                    self.generation += 1; // what is being computed is for the old policy
                    self.place = None; // the next observer gets the new policy's list
                    if let Some(p) = &mut self.pending {
                        p.generation = self.generation; // not started: it will use the new one
                    }
                }
                self.rate = rate_bytes_per_s.clamp(1, self.state.config.max_session_rate);
                Ok(None)
            }
            Ok(StreamClient::Observer(obs)) => {
                if let Err(e) = crate::routes::validate_observer(&obs) {
                    return error(e);
                }
                Ok(self.on_observer(obs))
            }
            Ok(StreamClient::Evicted(ids)) => {
                let mut needed = false;
                for id in ids {
                    self.mirror.remove(&id);
                    needed |= self.list.segments.contains(&id);
                }
                if needed {
                    self.cursor = 0; // push them again, in their place in the order
                }
                Ok(None)
            }
            Err(e) => error(Error::bad_request(format!("message does not decode: {e}"))),
        }
    }

    /// A new observer: nothing to do while it stays in its place; the cached list of a place
    /// another session computed; otherwise a computation (only the latest observer waits).
    fn on_observer(&mut self, obs: Observer) -> Option<Message> {
        let arrived = Instant::now();
        let m = &self.state.metrics;
        m.stream_updates.fetch_add(1, Relaxed);
        let place = if self.state.config.shared_answers {
            self.state.prefetcher.share_place(&obs)
        } else {
            None
        };
        self.want = place;
        // A replaced observer's wait counts in the one that replaces it.
        let (arrived, updates) = match self.pending.take() {
            Some(p) => (p.arrived, p.updates + 1),
            None => (arrived, 1),
        };
        if place.is_some() && place == self.place {
            m.update(arrived.elapsed().as_secs_f64(), updates);
            return None;
        }
        if let Some(p) = place {
            let key = ShareKey::new(p, self.policy_bytes.clone());
            if let Some(list) = self.state.prefetcher.shared_cached(&key) {
                m.update(arrived.elapsed().as_secs_f64(), updates);
                return self.take_list(list, place);
            }
        }
        self.pending = Some(Pending {
            obs,
            place,
            arrived,
            updates,
            generation: self.generation,
        });
        None
    }

    /// A computation finished: its list is taken unless it is stale (another place is wanted
    /// now, or the policy changed); past its deadline the previous list stays.
    fn on_computed(&mut self, list: Result<Arc<NeedList>, Error>, p: Pending) -> Option<Message> {
        self.state
            .metrics
            .update(p.arrived.elapsed().as_secs_f64(), p.updates);
        let stale = p.generation != self.generation || (p.place.is_some() && p.place != self.want);
        match list {
            Ok(_) if stale => None,
            Ok(l) => self.take_list(l, p.place),
            Err(e) if e.status() == StatusCode::SERVICE_UNAVAILABLE => None,
            Err(e) => Some(control(&StreamServer::Error(e.to_api()))),
        }
    }

    /// Puts a need list in place; reports queued items whose need vanished.
    fn take_list(&mut self, list: Arc<NeedList>, place: Option<SharePlace>) -> Option<Message> {
        let m = &self.state.metrics;
        m.prefetch_answers.fetch_add(1, Relaxed);
        let end = self.list.fit.max(self.cursor).min(self.list.items.len());
        let dropped: Vec<u32> = self.list.items[self.cursor.min(end)..end]
            .iter()
            .map(|i| i.segment)
            .filter(|s| !self.mirror.contains(s) && !list.segments.contains(s))
            .collect();
        self.list = list;
        self.cursor = 0;
        self.place = place;
        if dropped.is_empty() {
            return None;
        }
        m.stream_dropped.fetch_add(dropped.len() as u64, Relaxed);
        Some(control(&StreamServer::Dropped(dropped)))
    }

    /// The next segment of the list the client lacks, as a frame (or an error for a segment
    /// that cannot be read), and the pacing clock advanced by its size.
    fn next_push(&mut self) -> Option<Message> {
        let item = loop {
            let i = self.cursor;
            let item = *self.list.items.get(i)?;
            self.cursor += 1;
            // Past what the client's cache holds only the mandatory items go.
            let wanted = i < self.list.fit || self.list.must[i];
            if wanted && !self.mirror.contains(&item.segment) {
                break item;
            }
        };
        let bytes = match self.state.db().segment(item.segment) {
            Ok(b) => b,
            Err(e) => return Some(control(&StreamServer::Error(Error::from(e).to_api()))),
        };
        self.state.metrics.sent(bytes.len() as u64);
        self.mirror.insert(item.segment);
        let cost = Duration::from_secs_f64(bytes.len() as f64 / self.rate as f64);
        self.next_free = self.next_free.max(Instant::now()) + cost;
        Some(Message::Binary(segment_frame(item.segment, &bytes).into()))
    }
}

fn control(msg: &StreamServer) -> Message {
    let mut frame = vec![FRAME_CONTROL];
    frame.extend(portico_protocol::to_bincode(msg).unwrap_or_default());
    Message::Binary(frame.into())
}
