//! `GET /v1/manifest/core`: the core manifest a paged client starts from.

use super::Shared;
use crate::error::Error;
use crate::respond::{document, wants_bincode};
use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::Response;

/// `GET /v1/manifest/core`: the [`portico_protocol::CoreManifest`] (bincode only: JSON clients read the whole
/// manifest), revalidated like the manifest. 404 for a database without cells, which has no
/// pages: its clients read the whole manifest.
pub async fn core(State(s): Shared, headers: HeaderMap) -> Result<Response, Error> {
    if !wants_bincode(&headers) {
        return Err(Error::new(
            axum::http::StatusCode::NOT_ACCEPTABLE,
            "not_acceptable",
            format!(
                "/v1/manifest/core is bincode only (Accept: {})",
                portico_protocol::BINCODE_MIME
            ),
        ));
    }
    // Pages are cut along the stab lists: without cells there are none, and a client that
    // started from the core would never learn an instance. It reads the whole manifest instead.
    if s.cells_bincode.is_none() {
        return Err(Error::not_found(
            "this database has no cells (built with --no-cells), so no pages: read /v1/manifest",
        ));
    }
    Ok(document(
        &headers,
        true,
        &s.core_bincode,
        &format!("k-{}", s.database_id),
    ))
}
