//! `GET /v1/stream`: a WebSocket session per client. The client sends its observer every frame;
//! the server pushes the segments of the observer's need list (Funkhouser §5.2) that a mirror of
//! what it already sent lacks, in need order, paced to the session's byte rate; tells the client
//! which queued items it dropped because their need vanished; and forgets segments the client
//! reports evicted. No round trip per frame is needed.
//!
//! Under the predicted lookahead (the default policy) every observer gets its own need list,
//! since what it will see depends on its velocity and turn, and the session pushes an item
//! only when leaving it to the next observer's list would make it late
//! ([`portico_data::deadline`]): the lead is the list's age (counted from when the client sent
//! the observer, half its round trip before it arrived), a frame until the next observer, the
//! round trip and the margin, and what is queued is the push clock's backlog at the session's
//! rate. What is not due yet stays in the list for the next push, or for the next list.
//!
//! Under Funkhouser's range lookahead answers are shared and incremental: the need list depends only on the eye cell and a
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
use portico_data::deadline::{MARGIN_FRAMES, cannot_wait};
use portico_data::prefetch::NeedList;
use portico_data::prefetch::shared::{ShareKey, SharePlace, encode_policy};
use portico_protocol::{
    FRAME_CONTROL, LookaheadCull, MAX_LACKING, NeedKind, Observer, PROTOCOL_VERSION, Policy,
    StreamClient, StreamServer, segment_frame,
};
use std::collections::HashSet;
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use tokio::time::{Duration, Instant, sleep, sleep_until};

/// How far behind the pacing clock may fall before the time is lost (a push burst's length).
const PACING_BURST: Duration = Duration::from_millis(10);

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
    /// Whether the client started from the core manifest ([`StreamClient::Pages`]): each
    /// cell's page goes before its stab list.
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
            observed: Instant::now(),
            next_free: Instant::now(),
            recheck: Instant::now(),
            pending: None,
            paged: false,
            pages_sent: HashSet::new(),
            after_page: None,
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
            let pending = self.after_page.is_some()
                || self.cursor < self.list.items.len()
                || self.lacking_at < self.lacking.len();
            let push_at = pending.then_some(self.next_free.max(self.recheck));
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
        let paged = self.paged;
        Box::pin(async move {
            let s = state.clone();
            state
                .compute
                .run(move |budget| {
                    let p = &s.prefetcher;
                    let list = match &key {
                        Some(k) => p.shared_list(k, &obs, &policy, &budget),
                        None => {
                            s.metrics.stream_own_lists.fetch_add(1, Relaxed);
                            p.need_list_within(&obs, &policy, &budget).map(Arc::new)
                        }
                    }
                    .map_err(Error::from)?;
                    // The pages of the list's stab lists, made here on the compute slot so that
                    // pushing them costs the async worker nothing ([`crate::paged`]).
                    if paged {
                        for item in list.items.iter().filter(|i| i.kind == NeedKind::Stab) {
                            if let Some(&cell) = s.stab_cells.get(&item.segment)
                                && let Err(e) = s.page(cell)
                            {
                                tracing::warn!("page of cell {cell}: {}", e.to_api().message);
                            }
                        }
                    }
                    Ok(list)
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
                rtt_ms,
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
                self.rtt_s = f64::from(rtt_ms.min(10_000)) / 1e3;
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
                    self.recheck = Instant::now();
                }
                Ok(None)
            }
            Ok(StreamClient::Pages) => {
                self.paged = true;
                Ok(None)
            }
            Ok(StreamClient::Lacking(ids)) => {
                let n = self.state.db().segments().len();
                if ids.len() > MAX_LACKING {
                    return error(Error::bad_request(format!(
                        "Lacking: {} ids, at most {MAX_LACKING}",
                        ids.len()
                    )));
                }
                if let Some(bad) = ids.iter().find(|&&id| id as usize >= n) {
                    return error(Error::bad_request(format!(
                        "Lacking: segment {bad} does not exist (the database has {n})"
                    )));
                }
                self.lacking = ids;
                self.lacking_at = 0;
                self.recheck = Instant::now();
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
        // A predicted lookahead depends on the observer's motion: no two observers share it.
        let shared = self.state.config.shared_answers && !self.deadlines();
        let place = if shared {
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
            // A paged session takes a cached list only once its stab lists' pages are made
            // (else the computation, on a compute slot, makes them).
            if let Some(list) = self.state.prefetcher.shared_cached(&key)
                && (!self.paged || self.pages_made(&list))
            {
                m.update(arrived.elapsed().as_secs_f64(), updates);
                return self.take_list(list, place, arrived);
            }
        }
        self.pending = Some(Pending {
            obs,
            place,
            arrived,
            at: Instant::now(),
            updates,
            generation: self.generation,
        });
        None
    }

    /// Whether the pages of every stab list in `list` are made ([`AppState::page_made`]).
    fn pages_made(&self, list: &NeedList) -> bool {
        list.items
            .iter()
            .filter(|i| i.kind == NeedKind::Stab)
            .filter_map(|i| self.state.stab_cells.get(&i.segment))
            .all(|&c| self.state.page_made(c).is_some())
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
            Ok(l) => self.take_list(l, p.place, p.at),
            Err(e) if e.status() == StatusCode::SERVICE_UNAVAILABLE => None,
            Err(e) => Some(control(&StreamServer::Error(e.to_api()))),
        }
    }

    /// Puts a need list in place; reports queued items whose need vanished.
    fn take_list(
        &mut self,
        list: Arc<NeedList>,
        place: Option<SharePlace>,
        observed: Instant,
    ) -> Option<Message> {
        let m = &self.state.metrics;
        m.prefetch_answers.fetch_add(1, Relaxed);
        // With deadlines nothing past the push in flight is queued: nothing to report.
        let end = if self.deadlines() {
            0
        } else {
            self.list.fit.max(self.cursor).min(self.list.items.len())
        };
        let dropped: Vec<u32> = self.list.items[self.cursor.min(end)..end]
            .iter()
            .map(|i| i.segment)
            .filter(|s| !self.mirror.contains(s) && !list.segments.contains(s))
            .collect();
        self.list = list;
        self.cursor = 0;
        self.place = place;
        self.observed = observed;
        self.recheck = Instant::now();
        if dropped.is_empty() {
            return None;
        }
        m.stream_dropped.fetch_add(dropped.len() as u64, Relaxed);
        Some(control(&StreamServer::Dropped(dropped)))
    }

    /// The next segment of the list the client lacks, as a frame (or an error for a segment
    /// that cannot be read), and the pacing clock advanced by its size.
    /// A paged session gets a stab list's page first ([`crate::paged`]), then the stab list.
    fn next_push(&mut self) -> Option<Message> {
        let segment = match self.after_page.take() {
            Some(s) => s,
            None => self.next_due(Instant::now())?,
        };
        if self.paged
            && let Some(&cell) = self.state.stab_cells.get(&segment)
            && !self.pages_sent.contains(&cell)
        {
            // Made on the compute slot with the need list; one that is not (an LRU eviction in
            // between, or it failed there) is left to the client, which reads it over HTTP.
            if let Some(p) = self.state.page_made(cell) {
                self.pages_sent.insert(cell);
                self.after_page = Some(segment);
                self.pace(p.frame.len());
                return Some(Message::Binary(p.frame.clone()));
            }
        }
        let bytes = match self.state.db().segment(segment) {
            Ok(b) => b,
            Err(e) => return Some(control(&StreamServer::Error(Error::from(e).to_api()))),
        };
        self.state.metrics.sent(bytes.len() as u64);
        self.mirror.insert(segment);
        self.pace(bytes.len());
        Some(Message::Binary(segment_frame(segment, &bytes).into()))
    }

    /// Advances the pacing clock by a frame of `len` bytes.
    fn pace(&mut self, len: usize) {
        let cost = Duration::from_secs_f64(len as f64 / self.rate as f64);
        // A token bucket PACING_BURST deep: a timer that wakes late (they tick in whole
        // milliseconds, longer than a small segment takes at a few MB/s) lets the next pushes
        // go at once rather than losing the time, which halved the rate on small segments.
        let now = Instant::now();
        let floor = now.checked_sub(PACING_BURST).unwrap_or(now);
        self.next_free = self.next_free.max(floor) + cost;
    }
}

impl Session {
    /// Whether the session's pushes wait for their deadlines (the predicted lookahead).
    fn deadlines(&self) -> bool {
        self.policy.lookahead_cull == LookaheadCull::Predicted
    }

    /// The segment to push next: what the client's frame lacked and it does not hold, first;
    /// then the first item past the cursor that the client lacks, is wanted (past what the
    /// client's cache holds only the mandatory items are) and, with deadlines, cannot wait for
    /// the next list; the cursor moves past every item settled before it. `None`: nothing to
    /// push now (and `recheck` says when to look again).
    fn next_due(&mut self, now: Instant) -> Option<u32> {
        while let Some(&id) = self.lacking.get(self.lacking_at) {
            self.lacking_at += 1;
            if !self.mirror.contains(&id) {
                return Some(id);
            }
        }
        let dt = f64::from(self.policy.frame_time_s).max(1e-3);
        let lead = self.deadlines().then(|| {
            let age = now.saturating_duration_since(self.observed).as_secs_f64() + self.rtt_s / 2.0;
            age + dt + self.rtt_s + MARGIN_FRAMES * dt
        });
        let rate = self.rate as f64;
        let queued = self.next_free.saturating_duration_since(now).as_secs_f64() * rate;
        let mut settled = true;
        for i in self.cursor..self.list.items.len() {
            let item = self.list.items[i];
            let wanted = i < self.list.fit || self.list.must[i];
            // A paged client can check nothing before the stab lists' pages have come: they go
            // first, whatever their deadlines.
            let due = (self.paged && item.kind == NeedKind::Stab)
                || lead.is_none_or(|l| {
                    cannot_wait(item.frames, dt, l, queued, item.bytes as f64, rate)
                });
            if !wanted || self.mirror.contains(&item.segment) || due {
                if settled {
                    self.cursor = i + 1;
                }
                if wanted && due && !self.mirror.contains(&item.segment) {
                    return Some(item.segment);
                }
                continue;
            }
            settled = false;
        }
        self.recheck = now + Duration::from_secs_f64(dt / 2.0);
        None
    }
}

fn control(msg: &StreamServer) -> Message {
    let mut frame = vec![FRAME_CONTROL];
    frame.extend(portico_protocol::to_bincode(msg).unwrap_or_default());
    Message::Binary(frame.into())
}
