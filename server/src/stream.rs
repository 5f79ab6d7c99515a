//! `GET /v1/stream`: a WebSocket session per client. The client sends its observer every frame;
//! the server recomputes the lookahead (Funkhouser §5.2) against a mirror of what it already
//! sent, pushes segments in need order paced to the session's byte rate, tells the client which
//! queued items it dropped because their need vanished, and forgets segments the client reports
//! evicted. No round trip per frame is needed.
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
use portico_protocol::{
    FRAME_CONTROL, NeedItem, Observer, PROTOCOL_VERSION, Policy, PrefetchResponse, StreamClient,
    StreamServer, segment_frame,
};
use std::collections::{HashSet, VecDeque};
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
    ws.max_message_size(s.config.max_body_bytes)
        .on_upgrade(move |socket| async move {
            s.metrics.sessions.fetch_add(1, Relaxed);
            s.metrics.sessions_total.fetch_add(1, Relaxed);
            Session::new(s.clone()).run(socket).await;
            s.metrics.sessions.fetch_sub(1, Relaxed);
            drop(permit);
        })
}

/// A prefetch answer being computed for the session.
type Computing = Pin<Box<dyn Future<Output = Result<PrefetchResponse, Error>> + Send>>;

/// One client's session state.
struct Session {
    state: Arc<AppState>,
    policy: Policy,
    rate: u64,
    /// Segments the client holds (sent and not evicted).
    mirror: HashSet<u32>,
    /// Items waiting to be pushed, in need order.
    queue: VecDeque<NeedItem>,
    /// When the paced link is free for the next push.
    next_free: Instant,
    /// The latest observer not yet computed (older ones are dropped: only the latest matters).
    pending: Option<Observer>,
}

impl Session {
    fn new(state: Arc<AppState>) -> Session {
        let rate = state.config.max_session_rate;
        Session {
            state,
            policy: Policy::default(),
            rate,
            mirror: HashSet::new(),
            queue: VecDeque::new(),
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
        let mut computing: Option<Computing> = None;
        loop {
            if computing.is_none()
                && let Some(obs) = self.pending.take()
            {
                computing = Some(self.compute(obs));
            }
            let push_at = (!self.queue.is_empty()).then_some(self.next_free);
            let outgoing = tokio::select! {
                msg = rx.next() => {
                    let Some(Ok(msg)) = msg else { break };
                    idle_deadline = Instant::now() + idle;
                    match self.on_message(msg) {
                        Ok(reply) => reply,
                        Err(()) => break,
                    }
                }
                done = async { computing.as_mut().expect("guarded").await }, if computing.is_some() => {
                    computing = None;
                    self.on_answer(done)
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

    /// Starts computing the need list for `obs` against a snapshot of the mirror.
    fn compute(&self, obs: Observer) -> Computing {
        let state = self.state.clone();
        let (policy, held) = (self.policy, self.mirror.clone());
        Box::pin(async move {
            let s = state.clone();
            state
                .compute
                .run(move |budget| {
                    s.prefetcher
                        .answer_within(&obs, &policy, &held, &budget)
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
                self.policy = policy;
                self.rate = rate_bytes_per_s.clamp(1, self.state.config.max_session_rate);
                Ok(None)
            }
            Ok(StreamClient::Observer(obs)) => {
                if let Err(e) = crate::routes::validate_observer(&obs) {
                    return error(e);
                }
                self.pending = Some(obs);
                Ok(None)
            }
            Ok(StreamClient::Evicted(ids)) => {
                for id in ids {
                    self.mirror.remove(&id);
                }
                Ok(None)
            }
            Err(e) => error(Error::bad_request(format!("message does not decode: {e}"))),
        }
    }

    /// Takes a computed need list; reports queued items whose need vanished. A computation
    /// stopped by its deadline keeps the previous list.
    fn on_answer(&mut self, answer: Result<PrefetchResponse, Error>) -> Option<Message> {
        let answer = match answer {
            Ok(a) => a,
            Err(e) if e.status() == StatusCode::SERVICE_UNAVAILABLE => return None,
            Err(e) => return Some(control(&StreamServer::Error(e.to_api()))),
        };
        self.state.metrics.prefetch_answers.fetch_add(1, Relaxed);
        let now: HashSet<u32> = answer.items.iter().map(|i| i.segment).collect();
        let dropped: Vec<u32> = self
            .queue
            .iter()
            .map(|i| i.segment)
            .filter(|s| !now.contains(s))
            .collect();
        self.queue = answer.items.into();
        if dropped.is_empty() {
            return None;
        }
        self.state
            .metrics
            .stream_dropped
            .fetch_add(dropped.len() as u64, Relaxed);
        Some(control(&StreamServer::Dropped(dropped)))
    }

    /// The next queued segment as a frame (or an error for a segment that cannot be read), and
    /// the pacing clock advanced by its size.
    fn next_push(&mut self) -> Option<Message> {
        let item = self.queue.pop_front()?;
        if self.mirror.contains(&item.segment) {
            return None;
        }
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
