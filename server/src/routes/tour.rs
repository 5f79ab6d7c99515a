//! `GET /v1/db/{database_id}/tour`: the model's standard tour (Funkhouser §7's recorded path
//! stand-in: through the doors from room to room at eye height, `portico_data::path`), so that
//! a client that starts from the core manifest, without the whole cell graph, can walk it.

use super::Shared;
use crate::conditional::not_modified;
use crate::encoding::Precompressed;
use crate::error::Error;
use crate::respond::{IMMUTABLE, REVALIDATE, built, current};
use axum::body::{Body, Bytes};
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::Response;
use portico_data::path::{PathKind, standard};
use portico_data::person::{TURN_DEGREES, WALK_SPEED};

/// Legs of the tour (rooms visited).
pub const LEGS: usize = 6;

/// `GET /v1/db/{database_id}/tour`: the standard tour as JSON (`portico_data::path::CameraPath`),
/// made once on a compute slot; immutable (the URL names the database). 404 for a model with
/// no tour (nothing to walk through).
pub async fn tour_in(
    State(s): Shared,
    Path(db): Path<String>,
    headers: HeaderMap,
) -> Result<Response, Error> {
    current(&s, &db)?;
    answer(s, IMMUTABLE, &headers).await
}

/// `GET /v1/tour`: the same under a URL a rebuild reuses (revalidated), for a client that asks
/// for it before it knows the database (beside the core manifest).
/// Revalidated with the database's ETag (`"t-{database_id}"`, `"t-{database_id}-gzip"` for the
/// gzip coding; 304 when it matches).
pub async fn tour(State(s): Shared, headers: HeaderMap) -> Result<Response, Error> {
    answer(s, REVALIDATE, &headers).await
}

async fn answer(
    s: std::sync::Arc<crate::state::AppState>,
    cache: &'static str,
    headers: &HeaderMap,
) -> Result<Response, Error> {
    // Made once: after that no request waits for a compute slot (a revalidation least of all).
    let made = match s.tour.get() {
        Some(made) => made.clone(),
        None => made_on_a_slot(&s).await?,
    };
    let Some(json) = made else {
        return Err(Error::not_found(
            "this model has no tour (nothing to walk through)",
        ));
    };
    // Gzip where the client takes it: a long tour is hundreds of kilobytes of JSON, which a
    // page reads before its first frame.
    let (body, coding) = json.pick(headers);
    // Each coding is its own representation, with its own strong ETag.
    let tag = format!(
        "\"t-{}{}\"",
        s.database_id,
        coding.map_or(String::new(), |c| format!("-{c}"))
    );
    let status = if not_modified(headers, &tag) {
        StatusCode::NOT_MODIFIED
    } else {
        StatusCode::OK
    };
    // A 304 carries the headers the 200 does (RFC 9111 §4.3.4: they update the cached ones).
    let mut r = Response::builder()
        .status(status)
        .header(header::CACHE_CONTROL, cache)
        .header(header::ETAG, tag)
        .header(header::VARY, "accept-encoding");
    if status == StatusCode::NOT_MODIFIED {
        return built(r.body(Body::empty()));
    }
    r = r.header(header::CONTENT_TYPE, portico_protocol::JSON_MIME);
    if let Some(c) = coding {
        r = r.header(header::CONTENT_ENCODING, c);
    }
    built(r.body(Body::from(body)))
}

/// The tour, made on a compute slot the first time it is asked for.
async fn made_on_a_slot(
    s: &std::sync::Arc<crate::state::AppState>,
) -> Result<Option<Precompressed>, Error> {
    let state = s.clone();
    s.compute
        .run(move |_| {
            let tour = state.tour.get_or_init(|| {
                let db = state.db();
                let h = db.header();
                let bounds: Vec<_> = h.instances.iter().map(|i| i.bounds).collect();
                let graph = state.prefetcher.graph();
                let turn = TURN_DEGREES.to_radians();
                let path = standard(
                    graph,
                    &h.bounds,
                    &bounds,
                    PathKind::Tour,
                    LEGS,
                    1,
                    WALK_SPEED,
                    turn,
                );
                path.and_then(|p| serde_json::to_vec(&p).ok())
                    .map(|j| Precompressed::new(Bytes::from(j)))
            });
            Ok(tour.clone())
        })
        .await
}
