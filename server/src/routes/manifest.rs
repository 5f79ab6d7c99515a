//! `GET /v1/manifest`: the whole manifest.

use super::Shared;
use crate::respond::{document, wants_bincode};
use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::Response;

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
