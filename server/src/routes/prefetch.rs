//! `POST /v1/db/{database_id}/prefetch` and `POST /v1/prefetch`: Funkhouser §5.2's lookahead
//! for one observer, on a compute slot.

use super::Shared;
use crate::error::Error;
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

/// `POST /v1/prefetch`: Funkhouser §5.2's lookahead for one observer. Decoding, checking,
/// answering and encoding run on a compute slot within the prefetch deadline
/// ([`crate::compute`]), never on the async workers.
pub async fn prefetch(
    State(s): Shared,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, Error> {
    let body = body.map_err(|e| Error::new(e.status(), "body", e.body_text()))?;
    let b = wants_bincode(&headers);
    let state = s.clone();
    let bytes = s
        .compute
        .run(move |budget| {
            let req: PrefetchRequest = decode_body(&headers, &body)?;
            let held = validate(&req, state.db().segments().len())?;
            let answer =
                state
                    .prefetcher
                    .answer_within(&req.observer, &req.policy, &held, &budget)?;
            state
                .metrics
                .prefetch_answers
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if b {
                portico_protocol::to_bincode(&answer)
                    .map_err(|e| Error::internal("the answer does not encode", e))
            } else {
                serde_json::to_vec(&answer)
                    .map_err(|e| Error::internal("the answer does not encode", e))
            }
        })
        .await?;
    Ok(encoded(b, Bytes::from(bytes), None))
}
