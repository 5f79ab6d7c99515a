//! The Portico server: axum + tokio over a memory-mapped, read-only display database. It serves
//! the file's parts (manifest, cell graph, segments) as zero-copy slices of the map with strong
//! ETags under URLs that name the database, answers predictive prefetch requests (Funkhouser
//! §5.2) over HTTP, and pushes segments in need order over a WebSocket.
//!
//! Stateless apart from stream sessions, so any number of replicas can serve one file behind a
//! load balancer or cache. No global lock on the hot path: the database is read-only, decoded
//! stab lists sit in `OnceLock`s, and metrics are atomics. Hostile or unlucky clients are
//! bounded everywhere: CPU work runs on compute slots with a deadline (`compute`), connections
//! are capped and must send their headers in time (`listen`) and take their answers in time
//! (`timed`), stream sessions compute only their latest observer and name their database
//! (`stream`), static files hold no descriptor (`viewer`), and every error is JSON
//! (`guard`).

// Unsafe code only where each use is allowed by name, with its SAFETY note (memory maps,
// C decoders and libc calls).
#![deny(unsafe_code)]

mod answers;
mod compute;
mod conditional;
mod config;
mod encoding;
mod error;
mod guard;
mod inflight;
mod listen;
mod metrics;
mod pages;
mod process;
mod respond;
mod routes;
mod state;
mod stream;
mod timed;
mod track;
mod validate;
mod viewer;

pub use config::Config;
pub use listen::{Control, Drained, run as serve_with_control};
pub use respond::IMMUTABLE;
pub use state::AppState;
pub use stream::{INBOUND_RATE, PAGES_PER_UPDATE};
pub use validate::validate as validate_prefetch;
pub use viewer::{FILES as VIEWER_FILES, is_built as viewer_is_built};

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
        .route("/v1/db/{db}/prefetch", post(routes::prefetch_in))
        .layer(timeout)
        .route("/v1/manifest", get(routes::manifest))
        .route("/v1/manifest/core", get(routes::core))
        .route("/v1/db/{db}/pages/{cell}", get(routes::page))
        .route("/v1/db/{db}/tour", get(routes::tour_in))
        .route("/v1/tour", get(routes::tour))
        .route("/v1/cells", get(routes::cells))
        .route("/v1/db/{db}/segments/{id}", get(routes::segment_in))
        .route("/v1/db/{db}/batch", get(routes::batch_in))
        .route("/v1/segments/{id}", get(routes::segment))
        .route("/v1/batch", get(routes::batch))
        .route("/v1/stream", get(stream::upgrade))
        .route("/v1/db/{db}/stream", get(stream::upgrade_in));
    // Without a token there is nothing to check: no layer at all on the hot path.
    let api = match state.config.token {
        Some(_) => api.route_layer(middleware::from_fn_with_state(state.clone(), auth)),
        None => api,
    };
    Router::new()
        .merge(viewer::routes(state.config.viewer.as_deref()))
        .route("/healthz", get(routes::healthz))
        .route("/metrics", get(routes::metrics))
        .merge(api)
        .fallback(routes::fallback)
        .layer(DefaultBodyLimit::max(state.config.max_body_bytes))
        .layer(track::TrackLayer::new(state.clone()))
        .layer(guard::GuardLayer)
        .with_state(state)
}

/// Bearer-token check for `/v1/*` when a token is configured: the `Authorization` header, and
/// for the WebSocket upgrade of the stream only (browsers cannot set headers there) a
/// `?token=` query. A query token anywhere else is refused: query strings end up in access logs.
async fn auth(State(s): State<Arc<AppState>>, req: Request, next: Next) -> Response {
    let Some(token) = &s.config.token else {
        return next.run(req).await;
    };
    let from_header = req
        .headers()
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    let path = req.uri().path();
    let named = path
        .strip_prefix("/v1/db/")
        .and_then(|p| p.strip_suffix("/stream"));
    let stream =
        path == "/v1/stream" || named.is_some_and(|db| !db.is_empty() && !db.contains('/'));
    let upgrade = stream && req.headers().contains_key(header::UPGRADE);
    let from_query = upgrade
        .then(|| req.uri().query())
        .flatten()
        .and_then(|q| q.split('&').find_map(|kv| kv.strip_prefix("token=")))
        // Browsers percent-encode it (`encodeURIComponent`): `+`, `/` and `=` arrive escaped.
        .map(|t| percent_encoding::percent_decode_str(t).decode_utf8_lossy());
    let given = from_header
        .map(std::borrow::Cow::Borrowed)
        .or(from_query)
        .unwrap_or_default();
    if constant_time_eq(given.as_bytes(), token.as_bytes()) {
        next.run(req).await
    } else {
        error::Error::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "a valid bearer token is required in the Authorization header",
        )
        .into_response()
    }
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Serves until `shutdown` completes, then drains (see [`serve_with_control`]): for tests and
/// embedders that need no reload.
pub async fn serve(
    state: Arc<AppState>,
    listener: tokio::net::TcpListener,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    tokio::spawn(async move {
        shutdown.await;
        let _ = tx.send(listen::Control::Stop);
    });
    listen::run(listener, state, rx, |_, _| {}).await
}
