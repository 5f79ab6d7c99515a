//! The HTTP handlers: health, metrics, manifest, cells, segments (single, ranged, batched) and
//! prefetch. Segment bytes go out as `Bytes` slices of the memory map: no copy. Segment URLs
//! name the database they come from (`/v1/db/{database_id}/…`), so they are immutable and no
//! cache anywhere can serve stale bytes after a rebuild.

use crate::conditional::{Unsatisfiable, if_range_holds, not_modified, parse_range};
use crate::encoding::Precompressed;
use crate::error::Error;
use crate::state::AppState;
use axum::body::{Body, Bytes};
use axum::extract::rejection::{BytesRejection, QueryRejection};
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use portico_protocol::{BINCODE_MIME, JSON_MIME, PROTOCOL_VERSION, PrefetchRequest, batch};
use std::collections::HashSet;
use std::sync::Arc;

/// Cache-Control of answers whose URL names the database they come from
/// (`/v1/db/{database_id}/…`): they never change, so any cache may keep them for ever.
pub const IMMUTABLE: &str = "public, max-age=31536000, immutable";
/// Cache-Control of answers whose URL does not name the database (the manifest, the cell graph,
/// `/v1/segments/{id}`): a rebuild changes them, so caches must revalidate (ETag, 304).
pub const REVALIDATE: &str = "no-cache";
/// Largest read budget a prefetch request may ask for (bytes).
pub const MAX_READ_BYTES: u64 = 1 << 30;
/// Longest frame time a policy may give (seconds): a frame is a person's step at most, and
/// the server counts deadlines and pacing in frames (a huge one overflowed its clock).
pub const MAX_FRAME_TIME_S: f32 = 10.0;

type Shared = State<Arc<AppState>>;

/// `GET /healthz`.
pub async fn healthz(State(s): Shared) -> impl IntoResponse {
    let db = s.db();
    axum::Json(serde_json::json!({
        "status": "ok",
        "database_id": s.database_id,
        "model": db.header().name,
        "segments": db.segments().len(),
    }))
}

/// `GET /metrics` (Prometheus text).
pub async fn metrics(State(s): Shared) -> impl IntoResponse {
    let mut text = s.metrics.render();
    crate::process::render(
        &mut text,
        s.prefetcher.shared_answers(),
        s.config.shared_answers,
    );
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], text)
}

/// Whether the client asked for bincode: an `Accept` naming bincode or JSON decides; otherwise
/// (`*/*` or none) the answer matches the request's `Content-Type`.
pub fn wants_bincode(headers: &HeaderMap) -> bool {
    let get = |h: header::HeaderName| headers.get(h).and_then(|v| v.to_str().ok()).unwrap_or("");
    let accept = get(header::ACCEPT);
    if accept.contains(BINCODE_MIME) {
        true
    } else if accept.contains("json") {
        false
    } else {
        get(header::CONTENT_TYPE).contains(BINCODE_MIME)
    }
}

fn encoded(bincode: bool, bytes: Bytes, etag: Option<&str>) -> Response {
    let mime = if bincode { BINCODE_MIME } else { JSON_MIME };
    let mut r = ([(header::CONTENT_TYPE, mime)], bytes).into_response();
    if let Some(tag) = etag.and_then(|t| HeaderValue::from_str(&format!("\"{t}\"")).ok()) {
        r.headers_mut().insert(header::ETAG, tag);
        r.headers_mut()
            .insert(header::VARY, HeaderValue::from_static("accept"));
    }
    r
}

/// `GET /v1/manifest`: the segment table and the model header. Short-lived: a rebuild changes it,
/// so it is revalidated (`no-cache`, an ETag per encoding and coding, 304); gzip-coded for
/// clients that accept it.
pub async fn manifest(State(s): Shared, headers: HeaderMap) -> Response {
    let b = wants_bincode(&headers);
    let doc = if b {
        &s.manifest_bincode
    } else {
        // Encoded and compressed on first use, off the async workers (seconds on a big model).
        let first = s.clone();
        let _ = tokio::task::spawn_blocking(move || {
            first.manifest_json();
        })
        .await;
        s.manifest_json()
    };
    document(&headers, b, doc, &format!("m-{}", s.database_id))
}

/// `GET /v1/cells`: the compact cell graph (cell boxes, portals, adjacency, k-D tree). Bincode
/// clients get the stored segment bytes as they are (or gzip of them). Revalidated like the
/// manifest.
pub async fn cells(State(s): Shared, headers: HeaderMap) -> Result<Response, Error> {
    let Some(stored) = &s.cells_bincode else {
        return Err(Error::not_found(
            "this database has no cells (built with --no-cells)",
        ));
    };
    let b = wants_bincode(&headers);
    let doc = if b {
        stored
    } else {
        let first = s.clone();
        let _ = tokio::task::spawn_blocking(move || {
            first.cells_json();
        })
        .await;
        s.cells_json()
    };
    Ok(document(&headers, b, doc, &format!("c-{}", s.database_id)))
}

/// A revalidated document (the manifest, the cell graph) in the coding the client accepts: gzip
/// when `Accept-Encoding` allows it, made once ([`Precompressed`]: the bincode documents at
/// start-up, the JSON ones on first use). Each encoding
/// and coding is its own representation with its own strong ETag (`"{name}-b-gzip"`).
pub(crate) fn document(
    headers: &HeaderMap,
    bincode: bool,
    doc: &Precompressed,
    name: &str,
) -> Response {
    let (body, coding) = doc.pick(headers);
    let tag = format!(
        "\"{name}-{}{}\"",
        if bincode { "b" } else { "j" },
        coding.map_or(String::new(), |c| format!("-{c}"))
    );
    if not_modified(headers, &tag) {
        return revalidated(StatusCode::NOT_MODIFIED.into_response(), &tag);
    }
    let mut r = revalidated(encoded(bincode, body, None), &tag);
    if let Some(c) = coding {
        r.headers_mut()
            .insert(header::CONTENT_ENCODING, HeaderValue::from_static(c));
    }
    r
}

/// Adds a (quoted) ETag and `no-cache`, and `Vary: Accept, Accept-Encoding` (the encoding and
/// the content coding depend on them).
pub(crate) fn revalidated(mut r: Response, tag: &str) -> Response {
    if let Ok(v) = HeaderValue::from_str(tag) {
        r.headers_mut().insert(header::ETAG, v);
    }
    let h = r.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static(REVALIDATE));
    h.insert(
        header::VARY,
        HeaderValue::from_static("accept, accept-encoding"),
    );
    r
}

/// Checks that a content-named URL names the database being served: a client or cache still
/// on a rebuilt file's URLs gets 410 Gone, never another file's bytes.
pub(crate) fn current(s: &AppState, db: &str) -> Result<(), Error> {
    if db == s.database_id {
        return Ok(());
    }
    Err(Error::new(
        StatusCode::GONE,
        "stale",
        format!(
            "database {db} is no longer served (now {}); fetch /v1/manifest again",
            s.database_id
        ),
    ))
}

fn parse_id(raw: &str, s: &AppState) -> Result<u32, Error> {
    let id: u32 = raw
        .parse()
        .map_err(|_| Error::bad_request(format!("segment id {raw:?} is not a number")))?;
    if id as usize >= s.db().segments().len() {
        return Err(Error::not_found(format!(
            "segment {id} does not exist (the database has {})",
            s.db().segments().len()
        )));
    }
    Ok(id)
}

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
        return Ok(builder
            .status(StatusCode::NOT_MODIFIED)
            .body(Body::empty())
            .unwrap_or_default());
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
    Ok(builder
        .status(status)
        .body(Body::from(body))
        .unwrap_or_default())
}

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
    Ok(Response::builder()
        .header(header::CONTENT_TYPE, "application/x-portico-batch")
        .header(header::CONTENT_LENGTH, total)
        .header(header::CACHE_CONTROL, cache)
        .body(body)
        .unwrap_or_default())
}

/// Decodes a request body by its `Content-Type`.
pub fn decode_body<T: serde::de::DeserializeOwned>(
    headers: &HeaderMap,
    body: &[u8],
) -> Result<T, Error> {
    let ct = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    let r = if ct.contains(BINCODE_MIME) {
        portico_protocol::from_bincode(body)
    } else if ct.contains("json") {
        portico_protocol::from_json(body)
    } else {
        return Err(Error::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "content_type",
            format!("Content-Type must be {BINCODE_MIME} or {JSON_MIME}, not {ct:?}"),
        ));
    };
    r.map_err(|e| Error::bad_request(format!("request body does not decode: {e}")))
}

/// Checks a prefetch request's numbers, so hostile values cannot make the answer huge or slow:
/// finite, non-negative observer and policy numbers, a bounded depth, screen and read budget, and
/// a held set of at most `segments` ids, each below `segments`.
pub fn validate(req: &PrefetchRequest, segments: usize) -> Result<HashSet<u32>, Error> {
    if req.version != PROTOCOL_VERSION {
        return Err(Error::bad_request(format!(
            "protocol version {} is not supported (server speaks {PROTOCOL_VERSION})",
            req.version
        )));
    }
    validate_observer(&req.observer)?;
    validate_policy(&req.policy)?;
    let held = portico_protocol::decode_held(&req.held)
        .ok_or_else(|| Error::bad_request("held set is not a valid delta-coded id list"))?;
    if held.len() > segments {
        return Err(Error::bad_request(format!(
            "the held set lists {} ids; the database has {segments} segments",
            held.len()
        )));
    }
    if let Some(bad) = held.iter().find(|&&id| id as usize >= segments) {
        return Err(Error::bad_request(format!(
            "held segment {bad} does not exist (the database has {segments})"
        )));
    }
    Ok(held.into_iter().collect())
}

/// An observer's numbers are finite, its angles and speeds not negative.
pub fn validate_observer(o: &portico_protocol::Observer) -> Result<(), Error> {
    let floats = (o.eye.iter().chain(&o.dir).chain(&o.up)).chain(o.velocity.iter().chain(&o.turn));
    let scalars = [o.half_fov_x, o.half_fov_y, o.max_speed, o.max_turn];
    if floats.chain(&scalars).any(|x| !x.is_finite()) || scalars.iter().any(|&x| x < 0.0) {
        return Err(Error::bad_request(
            "observer numbers must be finite, its angles and speeds not negative",
        ));
    }
    Ok(())
}

/// A policy's numbers are finite and within bounds (a frame time of at most
/// [`MAX_FRAME_TIME_S`]).
pub fn validate_policy(p: &portico_protocol::Policy) -> Result<(), Error> {
    let scalars = [p.frame_time_s, p.size_threshold_px];
    if scalars.iter().any(|x| !x.is_finite() || *x < 0.0) {
        return Err(Error::bad_request(
            "policy numbers must be finite and not negative",
        ));
    }
    if p.frame_time_s > MAX_FRAME_TIME_S {
        return Err(Error::bad_request(format!(
            "frame_time_s {} is more than {MAX_FRAME_TIME_S} s",
            p.frame_time_s
        )));
    }
    if p.depth_frames > 100_000 || p.screen.iter().any(|&d| d == 0 || d > 32_768) {
        return Err(Error::bad_request(
            "depth_frames ≤ 100000 and a screen of 1..=32768 pixels per side",
        ));
    }
    if p.read_bytes > MAX_READ_BYTES {
        return Err(Error::bad_request(format!(
            "read_bytes {} is more than {MAX_READ_BYTES}",
            p.read_bytes
        )));
    }
    Ok(())
}

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

/// Any other path.
pub async fn fallback() -> Error {
    Error::not_found(
        "no such endpoint; see / (the browser viewer), /healthz, /metrics, /v1/manifest, /v1/cells, /v1/db/{database_id}/segments/{id}, /v1/db/{database_id}/batch, /v1/db/{database_id}/prefetch, /v1/segments/{id}, /v1/batch, /v1/prefetch, /v1/stream",
    )
}
