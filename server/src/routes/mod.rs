//! The HTTP handlers: health, metrics, the manifest (whole, or its core and each cell's page),
//! the cell graph, segments (single, ranged, batched), the standard tour and prefetch. Segment bytes go out as `Bytes` slices of the memory map: no copy. Segment URLs
//! name the database they come from (`/v1/db/{database_id}/…`), so they are immutable and no
//! cache anywhere can serve stale bytes after a rebuild.

//!
//! One endpoint per file; what their answers are made of is in [`crate::respond`].

mod batch;
mod cells;
mod core;
mod health;
mod manifest;
mod metrics;
mod page;
mod prefetch;
mod segment;
mod tour;

pub(crate) use batch::{batch, batch_in};
pub(crate) use cells::cells;
pub(crate) use core::core;
pub(crate) use health::healthz;
pub(crate) use manifest::manifest;
pub(crate) use metrics::metrics;
pub(crate) use page::page;
pub(crate) use prefetch::{prefetch, prefetch_in};
pub(crate) use segment::{segment, segment_in};
pub(crate) use tour::{tour, tour_in};

use crate::error::Error;
use crate::state::AppState;
use axum::extract::State;
use std::sync::Arc;

/// The state every handler reads.
type Shared = State<Arc<AppState>>;

/// Any other path.
pub async fn fallback() -> Error {
    Error::not_found(
        "no such endpoint; see / (the browser viewer), /healthz, /metrics, /v1/manifest, /v1/cells, /v1/db/{database_id}/segments/{id}, /v1/db/{database_id}/batch, /v1/db/{database_id}/prefetch, /v1/db/{database_id}/pages/{cell}, /v1/db/{database_id}/tour, /v1/tour, /v1/segments/{id}, /v1/batch, /v1/prefetch, /v1/stream",
    )
}
