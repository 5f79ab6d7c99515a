//! `GET /v1/stream`: a WebSocket session per client (DESIGN §4). The client sends its observer
//! every frame; the server recomputes the lookahead (Funkhouser §5.2) against a mirror of what it
//! already sent, pushes segments in need order paced to the session's byte rate, tells the client
//! which queued items it dropped because their need vanished, and forgets segments the client
//! reports evicted. No round trip per frame is needed. A client that vanishes ends its session.

use crate::error::Error;
use crate::state::AppState;
use axum::extract::State;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use portico_protocol::{
    FRAME_CONTROL, NeedItem, Observer, PROTOCOL_VERSION, Policy, StreamClient, StreamServer,
    segment_frame,
};
use std::collections::{HashSet, VecDeque};
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use tokio::time::{Duration, Instant, sleep_until};

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
        }
    }

    async fn run(mut self, mut socket: WebSocket) {
        let mut shutdown = self.state.shutdown.subscribe();
        let idle = self.state.config.idle_timeout;
        let mut idle_deadline = Instant::now() + idle;
        loop {
            let push_at = (!self.queue.is_empty()).then_some(self.next_free);
            tokio::select! {
                msg = socket.recv() => {
                    let Some(Ok(msg)) = msg else { break };
                    idle_deadline = Instant::now() + idle;
                    match self.on_message(msg) {
                        Ok(Some(reply)) => if socket.send(reply).await.is_err() { break },
                        Ok(None) => {}
                        Err(()) => break,
                    }
                }
                _ = sleep_until(push_at.unwrap_or(idle_deadline)), if push_at.is_some() => {
                    if self.push_next(&mut socket).await.is_err() { break }
                }
                _ = sleep_until(idle_deadline) => break,
                _ = shutdown.changed() => break,
            }
        }
        let _ = socket.send(Message::Close(None)).await;
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
        match decoded {
            Ok(StreamClient::Hello { version, .. }) if version != PROTOCOL_VERSION => {
                Ok(Some(control(&StreamServer::Error(
                    Error::bad_request(format!("protocol version {version} is not supported"))
                        .to_api(),
                ))))
            }
            Ok(StreamClient::Hello {
                policy,
                rate_bytes_per_s,
                ..
            }) => {
                self.policy = policy;
                self.rate = rate_bytes_per_s.clamp(1, self.state.config.max_session_rate);
                Ok(None)
            }
            Ok(StreamClient::Observer(obs)) => Ok(self.on_observer(&obs)),
            Ok(StreamClient::Evicted(ids)) => {
                for id in ids {
                    self.mirror.remove(&id);
                }
                Ok(None)
            }
            Err(e) => Ok(Some(control(&StreamServer::Error(
                Error::bad_request(format!("message does not decode: {e}")).to_api(),
            )))),
        }
    }

    /// Recomputes the need list; reports queued items whose need vanished.
    fn on_observer(&mut self, obs: &Observer) -> Option<Message> {
        let req = portico_protocol::PrefetchRequest {
            version: PROTOCOL_VERSION,
            observer: *obs,
            policy: self.policy,
            held: Vec::new(),
        };
        if let Err(e) = crate::routes::validate(&req) {
            return Some(control(&StreamServer::Error(e.to_api())));
        }
        let answer = match self
            .state
            .prefetcher
            .answer(obs, &self.policy, &self.mirror)
        {
            Ok(a) => a,
            Err(e) => return Some(control(&StreamServer::Error(Error::from(e).to_api()))),
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

    /// Sends the first queued segment and advances the pacing clock.
    async fn push_next(&mut self, socket: &mut WebSocket) -> Result<(), axum::Error> {
        let Some(item) = self.queue.pop_front() else {
            return Ok(());
        };
        if self.mirror.contains(&item.segment) {
            return Ok(());
        }
        let bytes = match self.state.db().segment(item.segment) {
            Ok(b) => b,
            Err(e) => {
                let msg = control(&StreamServer::Error(Error::from(e).to_api()));
                return socket.send(msg).await;
            }
        };
        socket
            .send(Message::Binary(segment_frame(item.segment, &bytes).into()))
            .await?;
        self.state.metrics.sent(bytes.len() as u64);
        self.mirror.insert(item.segment);
        let cost = Duration::from_secs_f64(bytes.len() as f64 / self.rate as f64);
        self.next_free = self.next_free.max(Instant::now()) + cost;
        Ok(())
    }
}

fn control(msg: &StreamServer) -> Message {
    let mut frame = vec![FRAME_CONTROL];
    frame.extend(portico_protocol::to_bincode(msg).unwrap_or_default());
    Message::Binary(frame.into())
}
