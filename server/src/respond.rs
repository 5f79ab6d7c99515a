//! What every handler's answer is made of: the Cache-Control of named and unnamed URLs, the
//! encoding a client asked for, revalidated documents with their ETags, the 410 of a stale
//! database URL, request bodies and segment ids, and responses built or answered as a logged 500.

use crate::conditional::not_modified;
use crate::encoding::Precompressed;
use crate::error::Error;
use crate::state::AppState;
use axum::body::{Body, Bytes};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use portico_protocol::{BINCODE_MIME, JSON_MIME};

/// Cache-Control of answers whose URL names the database they come from
/// (`/v1/db/{database_id}/…`): they never change, so any cache may keep them for ever.
pub const IMMUTABLE: &str = "public, max-age=31536000, immutable";
/// Cache-Control of answers whose URL does not name the database (the manifest, the cell graph,
/// `/v1/segments/{id}`): a rebuild changes them, so caches must revalidate (ETag, 304).
pub const REVALIDATE: &str = "no-cache";
/// Whether the client asked for bincode: an `Accept` naming bincode or JSON decides; otherwise
/// (`*/*` or none) the answer matches the request's `Content-Type`.
pub(crate) fn wants_bincode(headers: &HeaderMap) -> bool {
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

/// `bytes` as bincode or JSON, with `etag` (quoted) when given.
pub(crate) fn encoded(bincode: bool, bytes: Bytes, etag: Option<&str>) -> Response {
    let mime = if bincode { BINCODE_MIME } else { JSON_MIME };
    let mut r = ([(header::CONTENT_TYPE, mime)], bytes).into_response();
    if let Some(tag) = etag.and_then(|t| HeaderValue::from_str(&format!("\"{t}\"")).ok()) {
        r.headers_mut().insert(header::ETAG, tag);
        r.headers_mut()
            .insert(header::VARY, HeaderValue::from_static("accept"));
    }
    r
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

/// A segment id from a URL, checked against the database.
pub(crate) fn parse_id(raw: &str, s: &AppState) -> Result<u32, Error> {
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

/// Decodes a request body by its `Content-Type`.
pub(crate) fn decode_body<T: serde::de::DeserializeOwned>(
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

/// A response from its builder; a builder that fails (a header that does not encode) is a
/// logged 500, never an empty 200.
pub(crate) fn built(r: Result<Response<Body>, axum::http::Error>) -> Result<Response, Error> {
    r.map_err(|e| Error::internal("the response does not build", e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_response_that_does_not_build_is_a_500_not_an_empty_200() {
        let broken = Response::builder()
            .header(header::CACHE_CONTROL, "no\ncache")
            .body(Body::empty());
        let r = built(broken).unwrap_err().into_response();
        assert_eq!(r.status(), StatusCode::INTERNAL_SERVER_ERROR);
        let fine = built(Response::builder().body(Body::from("x"))).unwrap();
        assert_eq!(fine.status(), StatusCode::OK);
    }
}
