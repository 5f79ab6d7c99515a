//! Per-route request counts, error classes and latency histograms for `/metrics`, as a tower
//! layer around every route. It runs on every request, segment reads included, so its future is
//! a plain wrapper (no boxing, no allocation): `axum::middleware::from_fn` cost 15 % of the
//! segment throughput (`bench/segments.sh`).

use crate::state::AppState;
use axum::extract::{MatchedPath, Request};
use axum::http::StatusCode;
use axum::response::Response;
use pin_project_lite::pin_project;
use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll, ready};
use std::time::Instant;
use tower::{Layer, Service};

/// Wraps each route's service in a [`Track`].
#[derive(Clone)]
pub struct TrackLayer {
    state: Arc<AppState>,
}

impl TrackLayer {
    /// Records into `state.metrics`.
    pub fn new(state: Arc<AppState>) -> TrackLayer {
        TrackLayer { state }
    }
}

impl<S> Layer<S> for TrackLayer {
    type Service = Track<S>;

    fn layer(&self, inner: S) -> Track<S> {
        Track {
            inner,
            state: self.state.clone(),
        }
    }
}

/// Times one route's requests and records route, status and latency.
#[derive(Clone)]
pub struct Track<S> {
    inner: S,
    state: Arc<AppState>,
}

impl<S> Service<Request> for Track<S>
where
    S: Service<Request, Response = Response>,
{
    type Response = Response;
    type Error = S::Error;
    type Future = TrackFuture<S::Future>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), S::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, req: Request) -> Self::Future {
        let route = req
            .extensions()
            .get::<MatchedPath>()
            .map_or("other", |m| route_name(m.as_str()));
        TrackFuture {
            inner: self.inner.call(req),
            start: Instant::now(),
            route,
            state: self.state.clone(),
        }
    }
}

pin_project! {
    /// The wrapped response future.
    pub struct TrackFuture<F> {
        #[pin]
        inner: F,
        start: Instant,
        route: &'static str,
        state: Arc<AppState>,
    }
}

impl<F, E> Future for TrackFuture<F>
where
    F: Future<Output = Result<Response, E>>,
{
    type Output = Result<Response, E>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        let this = self.project();
        let out = ready!(this.inner.poll(cx));
        if let Ok(resp) = &out {
            let route = if resp.status() == StatusCode::UNAUTHORIZED {
                "denied"
            } else {
                this.route
            };
            this.state.metrics.record(
                crate::metrics::route_index(route),
                resp.status().as_u16(),
                this.start.elapsed().as_secs_f64(),
            );
        }
        Poll::Ready(out)
    }
}

/// The metrics name of a matched route.
fn route_name(path: &str) -> &'static str {
    match path {
        "/healthz" => "healthz",
        "/metrics" => "metrics",
        "/v1/manifest" => "manifest",
        "/v1/manifest/core" => "core",
        "/v1/db/{db}/pages/{cell}" => "page",
        "/" | "/index.html" | "/portico_web.js" | "/portico_web_bg.wasm" => "viewer",
        "/v1/cells" => "cells",
        "/v1/segments/{id}" | "/v1/db/{db}/segments/{id}" => "segment",
        "/v1/batch" | "/v1/db/{db}/batch" => "batch",
        "/v1/prefetch" | "/v1/db/{db}/prefetch" => "prefetch",
        "/v1/stream" | "/v1/db/{db}/stream" => "stream",
        _ => "other",
    }
}
