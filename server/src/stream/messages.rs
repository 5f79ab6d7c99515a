//! What a stream session does with each client message: decoded by its frame type (binary:
//! bincode, text: JSON), checked, and applied. A large one (at least 16 KB) is decoded, and its
//! id list applied to the mirror, on the blocking pool, at most one per core at a time across
//! all sessions (`AppState::heavy`), so that no client can make an async worker, or the pool,
//! spend long on it.

use super::{End, HEAVY_BYTES, Session, control, secs};
use crate::error::Error;
use axum::extract::ws::Message;
use portico_data::prefetch::shared::encode_policy;
use portico_protocol::{MAX_LACKING, PROTOCOL_VERSION, StreamClient, StreamServer};
use std::collections::HashSet;
use tokio::time::Instant;

/// The least a client frame is charged against [`super::INBOUND_RATE`] (bytes).
const MIN_CHARGE: usize = 256;

/// A decoded client message, or why it does not decode (named by its parser).
type Decoded = Result<StreamClient, String>;

fn decode(bytes: &[u8], text: bool) -> Decoded {
    if text {
        portico_protocol::from_json(bytes).map_err(|e| format!("JSON message does not decode: {e}"))
    } else {
        portico_protocol::from_bincode(bytes)
            .map_err(|e| format!("bincode message does not decode: {e}"))
    }
}

impl Session {
    /// Handles one client message; returns a control reply, or why the session ends.
    pub(super) async fn on_message(&mut self, msg: Message) -> Result<Option<Message>, End> {
        // Every frame is charged, at least MIN_CHARGE bytes: a flood of tiny ones (pings
        // included, which tungstenite answers) costs its loop turns too.
        let len = match &msg {
            Message::Binary(b) => b.len(),
            Message::Text(t) => t.len(),
            Message::Ping(b) | Message::Pong(b) => b.len(),
            Message::Close(_) => 0,
        };
        self.took(len.max(MIN_CHARGE));
        let (bytes, text) = match msg {
            Message::Binary(b) => (b, false),
            Message::Text(t) => (
                axum::body::Bytes::from(t.as_str().as_bytes().to_vec()),
                true,
            ),
            Message::Close(_) => return Err(End::Gone),
            Message::Ping(_) | Message::Pong(_) => return Ok(None),
        };
        let heavy = bytes.len() >= HEAVY_BYTES;
        let decoded = if heavy {
            let _turn = self.state.heavy.acquire().await;
            tokio::task::spawn_blocking(move || decode(&bytes, text))
                .await
                .unwrap_or_else(|e| Err(format!("message decoding failed: {e}")))
        } else {
            decode(&bytes, text)
        };
        let error = |e: Error| Ok(Some(control(&StreamServer::Error(e.to_api()))));
        let n = self.state.db().segments().len();
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
                if let Err(e) = crate::validate::validate_policy(&policy) {
                    return error(e);
                }
                if policy != self.policy {
                    self.policy = policy;
                    self.policy_bytes = encode_policy(&policy);
                    self.generation += 1; // what is being computed is for the old policy
                    self.place = None; // the next observer gets the new policy's list
                    // Not started: it will use the new policy, and the place that one gives.
                    if let Some(mut p) = self.pending.take() {
                        p.generation = self.generation;
                        p.place = self.place_of(&p.obs);
                        self.want = p.place;
                        self.pending = Some(p);
                    }
                }
                let rate = rate_bytes_per_s.clamp(1, self.state.config.max_session_rate.max(1));
                // What the pacing clock still owes was charged at the old rate: owed at the new
                // one, it is the same bytes (a zero rate's hours become milliseconds; a Hello
                // cannot wipe what is owed and so get past the cap).
                let now = Instant::now();
                let owed = self.next_free.saturating_duration_since(now).as_secs_f64();
                self.next_free = now + secs(owed * self.rate as f64 / rate as f64);
                self.recheck = now;
                self.rate = rate;
                self.rtt_s = f64::from(rtt_ms.min(10_000)) / 1e3;
                Ok(None)
            }
            Ok(StreamClient::Observer(obs)) => {
                if let Err(e) = crate::validate::validate_observer(&obs) {
                    return error(e);
                }
                Ok(self.on_observer(obs))
            }
            Ok(StreamClient::Evicted(ids)) => {
                if ids.len() > n {
                    return error(Error::bad_request(format!(
                        "Evicted: {} ids; the database has {n} segments",
                        ids.len()
                    )));
                }
                let needed = self.apply(ids, false, heavy).await;
                if needed {
                    self.cursor = 0; // push them again, in their place in the order
                    self.recheck = Instant::now();
                }
                Ok(None)
            }
            Ok(StreamClient::Holding(deltas)) => {
                let Some(ids) = portico_protocol::decode_held(&deltas) else {
                    return error(Error::bad_request(
                        "Holding: not a valid delta-coded id list",
                    ));
                };
                if ids.len() > n || ids.last().is_some_and(|&id| id as usize >= n) {
                    return error(Error::bad_request(format!(
                        "Holding: ids past the database's {n} segments"
                    )));
                }
                self.apply(ids, true, heavy).await;
                Ok(None)
            }
            Ok(StreamClient::Pages) => {
                self.paged = true;
                Ok(None)
            }
            Ok(StreamClient::Lacking(ids)) => {
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
            Err(e) => error(Error::bad_request(e)),
        }
    }

    /// Adds `ids` to the mirror (`hold`) or takes them out; returns whether the need list
    /// names any of them. A long list is applied on the blocking pool.
    async fn apply(&mut self, ids: Vec<u32>, hold: bool, heavy: bool) -> bool {
        let list = self.list.clone();
        let work = move |mut mirror: HashSet<u32>| {
            let mut needed = false;
            for id in ids {
                if hold {
                    mirror.insert(id);
                } else {
                    mirror.remove(&id);
                    needed |= list.segments.contains(&id);
                }
            }
            (mirror, needed)
        };
        let mirror = std::mem::take(&mut self.mirror);
        let (mirror, needed) = if heavy {
            let _turn = self.state.heavy.acquire().await;
            match tokio::task::spawn_blocking(move || work(mirror)).await {
                Ok(done) => done,
                // Cannot happen short of a panic in a set insert; the mirror is then empty,
                // which only makes the server push again what the client may hold.
                Err(_) => (HashSet::new(), true),
            }
        } else {
            work(mirror)
        };
        self.mirror = mirror;
        needed
    }
}
