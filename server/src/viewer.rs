//! The browser viewer's static files at `/` (the page, its JavaScript glue and the wasm
//! module that `web/build.sh` builds), served from a folder with tower-http's file service
//! (content types, Last-Modified, ranges), gzipped where the build left a `.gz` beside a file
//! and the browser accepts it (the wasm module shrinks to about a third). They are static:
//! nginx or a CDN can serve the same folder. Without a built viewer, `/` is a page saying how
//! to build one.

use crate::AppState;
use axum::Router;
use axum::http::{HeaderValue, header};
use axum::response::{Html, IntoResponse};
use axum::routing::get;
use std::path::Path;
use std::sync::Arc;
use tower_http::services::ServeFile;
use tower_http::set_header::SetResponseHeaderLayer;

/// The files of a built viewer, each served at `/{name}`.
pub const FILES: [&str; 2] = ["portico_web.js", "portico_web_bg.wasm"];

/// `/` and the viewer's files when `dir` holds a built viewer; otherwise `/` is a page naming
/// the command that builds it (200: an error status would be turned into the API's JSON).
pub fn routes(dir: Option<&Path>) -> Router<Arc<AppState>> {
    match dir.filter(|d| is_built(d)) {
        Some(d) => {
            let file = |name: &str| ServeFile::new(d.join(name)).precompressed_gzip();
            let mut r = Router::new()
                .route_service("/", file("index.html"))
                .route_service("/index.html", file("index.html"));
            for f in FILES {
                r = r.route_service(&format!("/{f}"), file(f));
            }
            // The names carry no hash: a browser must revalidate (Last-Modified), or it could
            // pair a cached page with a rebuilt module.
            // Gzipped or not by Accept-Encoding: a shared cache must keep both.
            r.layer(SetResponseHeaderLayer::overriding(
                header::CACHE_CONTROL,
                HeaderValue::from_static("no-cache"),
            ))
            .layer(SetResponseHeaderLayer::overriding(
                header::VARY,
                HeaderValue::from_static("accept-encoding"),
            ))
        }
        None => Router::new().route("/", get(not_built)),
    }
}

/// Whether `dir` holds the page and both of its files.
pub fn is_built(dir: &Path) -> bool {
    dir.join("index.html").is_file() && FILES.iter().all(|f| dir.join(f).is_file())
}

async fn not_built() -> impl IntoResponse {
    (
        [(header::CACHE_CONTROL, "no-store")],
        Html(
            "<!doctype html><title>Portico</title><h1>The browser viewer is not built</h1>\
             <p>In the repository run <code>bash web/build.sh</code> (it writes \
             <code>target/viewer/</code>), then restart <code>portico serve</code> from the \
             repository, or give it <code>--viewer DIR</code> (<code>bash web/build.sh DIR</code> \
             builds into DIR). The API is at <code>/v1/manifest</code>.</p>",
        ),
    )
}
