//! `GET /metrics`: Prometheus text, the server's own CPU and memory included.

use super::Shared;
use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;

/// `GET /metrics` (Prometheus text).
pub async fn metrics(State(s): Shared) -> impl IntoResponse {
    let mut text = s.metrics.render();
    crate::process::render(
        &mut text,
        s.prefetcher.shared_answers(),
        s.prefetcher.region_sight(),
        s.config.shared_answers,
    );
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], text)
}
