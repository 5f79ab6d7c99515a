//! `GET /v1/db/{database_id}/batch?ids=…` and `GET /v1/batch?ids=…`: several segments in one
//! answer, streamed from the map.

use super::Shared;
use crate::error::Error;
use crate::respond::{IMMUTABLE, REVALIDATE, built, current, parse_id};
use crate::state::AppState;
use axum::body::{Body, Bytes};
use axum::extract::rejection::QueryRejection;
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::Response;
use portico_protocol::batch;

/// Query of the batch reads.
#[derive(Debug, serde::Deserialize)]
pub struct BatchQuery {
    /// Comma-separated segment ids.
    pub ids: String,
}

type BatchParams = Result<Query<BatchQuery>, QueryRejection>;

/// `GET /v1/db/{database_id}/batch?ids=3,4,9`: several segments in one answer (framed as
/// [`portico_protocol::batch`] says), streamed from the map without copying; immutable. A segment
/// the server cannot read (damaged on disk) is marked missing and fails alone.
pub async fn batch_in(
    State(s): Shared,
    Path(db): Path<String>,
    q: BatchParams,
) -> Result<Response, Error> {
    current(&s, &db)?;
    batch_answer(&s, q, IMMUTABLE)
}

/// `GET /v1/batch?ids=…`: the same under a URL a rebuild reuses (revalidated).
pub async fn batch(State(s): Shared, q: BatchParams) -> Result<Response, Error> {
    batch_answer(&s, q, REVALIDATE)
}

fn batch_answer(s: &AppState, q: BatchParams, cache: &'static str) -> Result<Response, Error> {
    let Query(q) = q.map_err(|e| Error::bad_request(e.body_text()))?;
    let ids: Vec<u32> = q
        .ids
        .split(',')
        .filter(|t| !t.is_empty())
        .map(|t| parse_id(t.trim(), s))
        .collect::<Result<_, _>>()?;
    if ids.is_empty() || ids.len() > s.config.max_batch {
        return Err(Error::bad_request(format!(
            "a batch holds 1 to {} segment ids, not {}",
            s.config.max_batch,
            ids.len()
        )));
    }
    let mut chunks = Vec::with_capacity(ids.len() * 2);
    let mut total = 0u64;
    for id in ids {
        match s.db().segment(id) {
            Ok(bytes) => {
                total += (batch::HEAD_BYTES + bytes.len()) as u64;
                s.metrics.sent(bytes.len() as u64);
                let head = batch::entry_head(id, bytes.len() as u64);
                chunks.push(Ok::<_, std::io::Error>(Bytes::copy_from_slice(&head)));
                chunks.push(Ok(bytes));
            }
            Err(e) => {
                // Logged with its detail; the client learns only that this one is missing.
                let _ = Error::from(e);
                total += batch::HEAD_BYTES as u64;
                let head = batch::entry_head(id, batch::MISSING);
                chunks.push(Ok(Bytes::copy_from_slice(&head)));
            }
        }
    }
    let body = Body::from_stream(futures_util::stream::iter(chunks));
    built(
        Response::builder()
            .header(header::CONTENT_TYPE, "application/x-portico-batch")
            .header(header::CONTENT_LENGTH, total)
            .header(header::CACHE_CONTROL, cache)
            .body(body),
    )
}
