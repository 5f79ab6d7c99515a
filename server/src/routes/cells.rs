//! `GET /v1/cells`: the whole cell graph.

use super::Shared;
use crate::error::Error;
use crate::respond::{document, wants_bincode};
use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::Response;

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
