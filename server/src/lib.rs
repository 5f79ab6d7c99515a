//! The Portico server (DESIGN §4): axum + tokio over a memory-mapped, read-only display
//! database. It serves the immutable parts of the file (manifest, cell graph, segments) as
//! zero-copy slices of the map with strong ETags, answers predictive prefetch requests
//! (Funkhouser §5.2) over HTTP, and pushes segments in need order over a WebSocket.
//!
//! Stateless apart from stream sessions, so any number of replicas can serve one file behind a
//! load balancer or cache. No global lock on the hot path: the database is read-only, decoded
//! stab lists sit in `OnceLock`s, and metrics are atomics.

pub mod config;
pub mod error;
pub mod metrics;
pub mod routes;
pub mod state;
pub mod stream;
pub mod track;

pub use config::Config;
pub use state::AppState;

use axum::Router;
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use std::sync::Arc;
use tower_http::timeout::TimeoutLayer;

/// The whole HTTP API over one database.
pub fn router(state: Arc<AppState>) -> Router {
    let timeout =
        TimeoutLayer::with_status_code(StatusCode::REQUEST_TIMEOUT, state.config.request_timeout);
    // Only requests with a body can be slow on the way in; answers from the map are immediate
    // (and a timer per segment request costs measurable throughput).
    let api = Router::new()
        .route("/v1/prefetch", post(routes::prefetch))
        .layer(timeout)
        .route("/v1/manifest", get(routes::manifest))
        .route("/v1/cells", get(routes::cells))
        .route("/v1/segments/{id}", get(routes::segment))
        .route("/v1/batch", get(routes::batch))
        .route("/v1/stream", get(stream::upgrade));
    // Without a token there is nothing to check: no layer at all on the hot path.
    let api = match state.config.token {
        Some(_) => api.route_layer(middleware::from_fn_with_state(state.clone(), auth)),
        None => api,
    };
    Router::new()
        .route("/healthz", get(routes::healthz))
        .route("/metrics", get(routes::metrics))
        .merge(api)
        .fallback(routes::fallback)
        .layer(DefaultBodyLimit::max(state.config.max_body_bytes))
        .layer(track::TrackLayer::new(state.clone()))
        .with_state(state)
}

/// Bearer-token check for `/v1/*` when a token is configured.
async fn auth(State(s): State<Arc<AppState>>, req: Request, next: Next) -> Response {
    let Some(token) = &s.config.token else {
        return next.run(req).await;
    };
    let from_header = req
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    let from_query = req
        .uri()
        .query()
        .and_then(|q| q.split('&').find_map(|kv| kv.strip_prefix("token=")));
    let given = from_header.or(from_query).unwrap_or("");
    if constant_time_eq(given.as_bytes(), token.as_bytes()) {
        next.run(req).await
    } else {
        error::Error::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "a valid bearer token is required",
        )
        .into_response()
    }
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Serves until `shutdown` completes, then closes stream sessions and drains requests.
pub async fn serve(
    state: Arc<AppState>,
    listener: tokio::net::TcpListener,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let app = router(state.clone());
    let notify = state.clone();
    axum::serve(listener, app)
        .with_graceful_shutdown(async move {
            shutdown.await;
            let _ = notify.shutdown.send(true);
        })
        .await
}
