//! `GET /v1/db/{database_id}/segments/{id}` and `GET /v1/segments/{id}`: one segment, straight
//! from the map (no copy), with conditional requests and single byte ranges.

use super::Shared;
use crate::conditional::{Unsatisfiable, if_range_holds, not_modified, parse_range};
use crate::error::Error;
use crate::respond::{IMMUTABLE, REVALIDATE, built, current, parse_id};
use crate::state::AppState;
use axum::body::Body;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::Response;

/// `GET /v1/db/{database_id}/segments/{id}`: the segment's bytes straight from the map, with a
/// strong ETag (its xxh3), immutable caching, conditional requests and single byte ranges. The
/// URL names the database, so no cache can ever serve another file's bytes for it.
pub async fn segment_in(
    State(s): Shared,
    Path((db, raw)): Path<(String, String)>,
    req: axum::extract::Request,
) -> Result<Response, Error> {
    current(&s, &db)?;
    segment_answer(&s, &raw, req.headers(), IMMUTABLE)
}

/// `GET /v1/segments/{id}`: the same bytes under a URL that a rebuild reuses, so caches must
/// revalidate it (`no-cache` with the ETag). For people and scripts; clients use
/// [`segment_in`].
pub async fn segment(
    State(s): Shared,
    Path(raw): Path<String>,
    req: axum::extract::Request,
) -> Result<Response, Error> {
    segment_answer(&s, &raw, req.headers(), REVALIDATE)
}

fn segment_answer(
    s: &AppState,
    raw: &str,
    headers: &HeaderMap,
    cache: &'static str,
) -> Result<Response, Error> {
    let id = parse_id(raw, s)?;
    let entry = s.db().segments()[id as usize];
    let etag = &s.etags[id as usize];
    let mut builder = Response::builder()
        .header(header::ETAG, etag.clone())
        .header(header::CACHE_CONTROL, HeaderValue::from_static(cache))
        .header(header::ACCEPT_RANGES, HeaderValue::from_static("bytes"))
        .header("x-portico-kind", HeaderValue::from(entry.kind));
    if not_modified(headers, etag.to_str().unwrap_or("")) {
        return built(builder.status(StatusCode::NOT_MODIFIED).body(Body::empty()));
    }
    let bytes = s.db().segment(id)?;
    let len = bytes.len() as u64;
    let asked = headers
        .get(header::RANGE)
        .and_then(|v| v.to_str().ok())
        .filter(|_| if_range_holds(headers, etag.to_str().unwrap_or(""), None));
    let range = match asked {
        None => None,
        Some(v) => parse_range(v, len).map_err(|Unsatisfiable| {
            Error::new(
                StatusCode::RANGE_NOT_SATISFIABLE,
                "range",
                format!("range {v:?} is outside the segment's {len} bytes"),
            )
        })?,
    };
    builder = builder.header(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/octet-stream"),
    );
    let (status, body) = match range {
        Some((a, b)) => {
            builder = builder.header(header::CONTENT_RANGE, format!("bytes {a}-{b}/{len}"));
            (
                StatusCode::PARTIAL_CONTENT,
                bytes.slice(a as usize..=b as usize),
            )
        }
        None => (StatusCode::OK, bytes),
    };
    s.metrics.sent(body.len() as u64);
    built(builder.status(status).body(Body::from(body)))
}
