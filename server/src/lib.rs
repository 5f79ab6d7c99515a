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

pub use config::Config;
pub use state::AppState;

use axum::Router;
use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::http::{StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use std::sync::Arc;
use std::time::Instant;
use tower_http::timeout::TimeoutLayer;

/// The whole HTTP API over one database.
pub fn router(state: Arc<AppState>) -> Router {
    let timeout =
        TimeoutLayer::with_status_code(StatusCode::REQUEST_TIMEOUT, state.config.request_timeout);
    let api = Router::new()
        .route("/v1/manifest", get(routes::manifest))
        .route("/v1/cells", get(routes::cells))
        .route("/v1/segments/{id}", get(routes::segment))
        .route("/v1/batch", get(routes::batch))
        .route("/v1/prefetch", post(routes::prefetch))
        .layer(timeout)
        .route("/v1/stream", get(stream::upgrade))
        .route_layer(middleware::from_fn_with_state(state.clone(), auth));
    Router::new()
        .route("/healthz", get(routes::healthz))
        .route("/metrics", get(routes::metrics))
        .merge(api)
        .fallback(routes::fallback)
        .layer(DefaultBodyLimit::max(state.config.max_body_bytes))
        .layer(middleware::from_fn_with_state(state.clone(), track))
        .with_state(state)
}

/// Records each request's route, status and latency.
async fn track(State(s): State<Arc<AppState>>, req: Request, next: Next) -> Response {
    let t0 = Instant::now();
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map(|m| route_name(m.as_str()))
        .unwrap_or("other");
    let resp = next.run(req).await;
    let route = if resp.status() == StatusCode::UNAUTHORIZED {
        "denied"
    } else {
        route
    };
    s.metrics.record(
        metrics::route_index(route),
        resp.status().as_u16(),
        t0.elapsed().as_secs_f64(),
    );
    resp
}

fn route_name(path: &str) -> &'static str {
    match path {
        "/healthz" => "healthz",
        "/metrics" => "metrics",
        "/v1/manifest" => "manifest",
        "/v1/cells" => "cells",
        "/v1/segments/{id}" => "segment",
        "/v1/batch" => "batch",
        "/v1/prefetch" => "prefetch",
        "/v1/stream" => "stream",
        _ => "other",
    }
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
