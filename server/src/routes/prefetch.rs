//! `POST /v1/db/{database_id}/prefetch` and `POST /v1/prefetch`: Funkhouser §5.2's lookahead
//! for one observer, on a compute slot: its own while the server has CPU to spare
//! (`crate::answers`), else the shared list of its place (`portico_data::prefetch::shared`) cut
//! for what the client holds; always its own under `portico serve --exact-answers`.

use super::Shared;
use crate::error::Error;
use crate::inflight::Turn;
use crate::respond::{current, decode_body, encoded, wants_bincode};
use crate::validate::validate;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use portico_protocol::PrefetchRequest;

/// `POST /v1/db/{database_id}/prefetch`: [`prefetch`] for a client that reads that database
/// (its answer names that database's segments); 410 Gone once it is no longer served.
pub async fn prefetch_in(
    State(s): Shared,
    Path(db): Path<String>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, Error> {
    current(&s, &db)?;
    prefetch(State(s), headers, body).await
}

/// Requests at most this large whose place's need list is cached are answered on the async
/// worker: decoding them, one lookup and one pass over the list cost less than handing them to
/// a compute slot (on a crowd, the thread hand-off was most of the server's time per answer).
pub const INLINE_BYTES: usize = 16 << 10;

/// `POST /v1/prefetch`: Funkhouser §5.2's lookahead for one observer. A small request whose
/// place's shared list is cached is answered at once ([`INLINE_BYTES`]), and one whose list
/// another request is computing waits for it without a compute slot; otherwise decoding,
/// checking, answering and encoding run on a compute slot within the prefetch deadline
/// ([`crate::compute`]), never on the async workers.
pub async fn prefetch(
    State(s): Shared,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, Error> {
    let body = body.map_err(|e| Error::new(e.status(), "body", e.body_text()))?;
    let b = wants_bincode(&headers);
    let until = s.compute.deadline_from_now();
    let mut decoded = None;
    // Held while this request computes its place's list (moved into the computation, so it
    // is let go the moment that ends): others of the place wait for it without a compute
    // slot (`crate::inflight`).
    let mut lead = None;
    if body.len() <= INLINE_BYTES {
        let req: PrefetchRequest = decode_body(&headers, &body)?;
        let held = validate(&req, s.db().segments().len())?;
        let sharing = s.sharing_now();
        let p = &s.prefetcher;
        let key = sharing
            .then(|| p.share_key(&req.observer, &req.policy))
            .flatten();
        if let Some(k) = &key {
            match s.lists.turn(k, until, || p.shared_cached(k)).await {
                None => return Err(s.compute.busy()),
                Some(Turn::Ready(list)) => {
                    let t0 = std::time::Instant::now();
                    let mut answer = list.cut(&held, req.policy.read_bytes);
                    answer.micros = t0.elapsed().as_micros().min(u32::MAX as u128) as u32;
                    return Ok(encoded(b, Bytes::from(encode(&s, &answer, b)?), None));
                }
                Some(Turn::Lead(l)) => lead = Some(l),
            }
        }
        decoded = Some((req, held, key));
    }
    let state = s.clone();
    let bytes = s
        .compute
        .run_until(until, move |budget| {
            let _lead = lead;
            let (req, held, key) = match decoded {
                Some(d) => d,
                None => {
                    let req: PrefetchRequest = decode_body(&headers, &body)?;
                    let held = validate(&req, state.db().segments().len())?;
                    let key = state
                        .sharing_now()
                        .then(|| state.prefetcher.share_key(&req.observer, &req.policy))
                        .flatten();
                    (req, held, key)
                }
            };
            let p = &state.prefetcher;
            // The shared list of the observer's place, cut for what this client holds (one
            // pass over the list); an observer with no shared place is answered alone.
            let answer = match key {
                Some(k) => {
                    let t0 = std::time::Instant::now();
                    let list = p.shared_list(&k, &req.observer, &req.policy, &budget)?;
                    let mut answer = list.cut(&held, req.policy.read_bytes);
                    answer.micros = t0.elapsed().as_micros().min(u32::MAX as u128) as u32;
                    answer
                }
                None => {
                    let t0 = std::time::Instant::now();
                    let own = p.answer_within(&req.observer, &req.policy, &held, &budget);
                    state.exact.charge(t0.elapsed().as_secs_f64());
                    own?
                }
            };
            encode(&state, &answer, b)
        })
        .await?;
    Ok(encoded(b, Bytes::from(bytes), None))
}

/// Counts an answer and encodes it (bincode when `bincode`, else JSON).
fn encode(
    state: &crate::AppState,
    answer: &portico_protocol::PrefetchResponse,
    bincode: bool,
) -> Result<Vec<u8>, Error> {
    state
        .metrics
        .prefetch_answers
        .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    if bincode {
        portico_protocol::to_bincode(answer)
            .map_err(|e| Error::internal("the answer does not encode", e))
    } else {
        serde_json::to_vec(answer).map_err(|e| Error::internal("the answer does not encode", e))
    }
}
