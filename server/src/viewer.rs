//! The browser viewer's static files at `/` (the page, its JavaScript glue and the wasm
//! module that `web/build.sh` builds), gzipped where the build left a `.gz` beside a file and
//! the browser accepts it (the wasm module shrinks to about a third). They are static: nginx or
//! a CDN can serve the same folder. Without a built viewer, `/` is a page saying how to build
//! one.
//!
//! The files are served from memory, read when first asked for and again when a `stat` shows
//! that the build replaced them: an answer holds no file descriptor, so a client that never
//! reads cannot take the descriptors the connection cap counts on ([`crate::listen`]). Each
//! answer has a strong ETag (the bytes' xxh3) and Last-Modified, and honours `If-None-Match`,
//! `If-Modified-Since`, single byte ranges and `If-Range` (RFC 9110 §13, §14).

use crate::AppState;
use crate::conditional::{Unsatisfiable, if_range_holds, not_modified, parse_range};
use crate::encoding::accepts_gzip;
use crate::error::Error;
use axum::Router;
use axum::body::Body;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use bytes::Bytes;
use std::path::{Path, PathBuf};
use std::sync::{Arc, RwLock};
use std::time::SystemTime;

/// The files of a built viewer, each served at `/{name}`.
pub const FILES: [&str; 2] = ["portico_web.js", "portico_web_bg.wasm"];

/// `/` and the viewer's files when `dir` holds a built viewer; otherwise `/` is a page naming
/// the command that builds it (200: an error status would be turned into the API's JSON).
pub fn routes(dir: Option<&Path>) -> Router<Arc<AppState>> {
    match dir.filter(|d| is_built(d)) {
        Some(d) => {
            let mut r = Router::new();
            let pages = [("/", "index.html"), ("/index.html", "index.html")];
            let files = FILES.map(|f| (format!("/{f}"), f));
            for (path, name) in pages
                .map(|(p, n)| (p.to_string(), n))
                .into_iter()
                .chain(files)
            {
                let file = Arc::new(StaticFile::new(d.join(name)));
                r = r.route(
                    &path,
                    get(move |h: HeaderMap| async move { file.answer(&h).await }),
                );
            }
            r
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

/// One viewer file, its `.gz` beside it if the build left one.
struct StaticFile {
    path: PathBuf,
    mime: &'static str,
    loaded: RwLock<Option<Arc<Loaded>>>,
}

/// A file's bytes as read, and what tells whether they are still the file's.
struct Loaded {
    stamp: Stamp,
    body: Bytes,
    gzip: Option<Bytes>,
    etag: String,
    modified: SystemTime,
}

/// Modification times and lengths of a file and its `.gz` (`None`: no `.gz`).
type Stamp = ((SystemTime, u64), Option<(SystemTime, u64)>);

fn stamp_of(path: &Path) -> std::io::Result<(SystemTime, u64)> {
    let m = std::fs::metadata(path)?;
    Ok((m.modified()?, m.len()))
}

impl StaticFile {
    fn new(path: PathBuf) -> StaticFile {
        let mime = match path.extension().and_then(|e| e.to_str()) {
            Some("html") => "text/html; charset=utf-8",
            Some("js") => "text/javascript; charset=utf-8",
            Some("wasm") => "application/wasm",
            _ => "application/octet-stream",
        };
        StaticFile {
            path,
            mime,
            loaded: RwLock::new(None),
        }
    }

    fn gz(&self) -> PathBuf {
        let mut p = self.path.clone().into_os_string();
        p.push(".gz");
        PathBuf::from(p)
    }

    /// The file's bytes, read again when its stamp changed (blocking: on the blocking pool).
    fn current(&self) -> std::io::Result<Arc<Loaded>> {
        let stamp: Stamp = (stamp_of(&self.path)?, stamp_of(&self.gz()).ok());
        if let Some(l) = self
            .loaded
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .as_ref()
            && l.stamp == stamp
        {
            return Ok(l.clone());
        }
        let body = Bytes::from(std::fs::read(&self.path)?);
        let gzip = stamp
            .1
            .and_then(|_| std::fs::read(self.gz()).ok())
            .map(Bytes::from);
        let l = Arc::new(Loaded {
            etag: format!("{:016x}", xxhash_rust::xxh3::xxh3_64(&body)),
            modified: stamp.0.0,
            stamp,
            body,
            gzip,
        });
        *self.loaded.write().unwrap_or_else(|e| e.into_inner()) = Some(l.clone());
        Ok(l)
    }

    async fn answer(self: Arc<Self>, headers: &HeaderMap) -> Response {
        let me = self.clone();
        let loaded = match tokio::task::spawn_blocking(move || me.current()).await {
            Ok(Ok(l)) => l,
            Ok(Err(e)) => {
                let what = self.path.file_name().unwrap_or_default().to_string_lossy();
                return Error::not_found(format!("viewer file {what}: {e}")).into_response();
            }
            Err(e) => return Error::internal("reading a viewer file", e).into_response(),
        };
        self.respond(&loaded, headers)
    }

    fn respond(&self, l: &Loaded, headers: &HeaderMap) -> Response {
        let range = headers.get(header::RANGE).and_then(|v| v.to_str().ok());
        // A range is of the file's own bytes; the gzip coding is for whole answers.
        let gzip = l
            .gzip
            .as_ref()
            .filter(|_| range.is_none() && accepts_gzip(headers));
        let etag = match gzip {
            Some(_) => format!("\"{}-gzip\"", l.etag),
            None => format!("\"{}\"", l.etag),
        };
        let modified = httpdate::fmt_http_date(l.modified);
        let mut r = Response::builder()
            .header(header::CACHE_CONTROL, "no-cache")
            .header(header::VARY, "accept-encoding")
            .header(header::ETAG, &etag)
            .header(header::LAST_MODIFIED, &modified)
            .header(header::ACCEPT_RANGES, "bytes")
            .header(header::CONTENT_TYPE, self.mime);
        // The names carry no hash: a browser revalidates, or it could pair a cached page with
        // a rebuilt module. If-None-Match decides when present (RFC 9110 §13.1.3).
        let unchanged = if headers.contains_key(header::IF_NONE_MATCH) {
            not_modified(headers, &etag)
        } else {
            headers
                .get(header::IF_MODIFIED_SINCE)
                .and_then(|v| v.to_str().ok())
                .and_then(|v| httpdate::parse_http_date(v).ok())
                .is_some_and(|since| {
                    httpdate::HttpDate::from(l.modified) <= httpdate::HttpDate::from(since)
                })
        };
        if unchanged {
            return r
                .status(StatusCode::NOT_MODIFIED)
                .body(Body::empty())
                .unwrap_or_default();
        }
        if let Some(g) = gzip {
            r = r.header(header::CONTENT_ENCODING, "gzip");
            return r.body(Body::from(g.clone())).unwrap_or_default();
        }
        let len = l.body.len() as u64;
        let asked = range.filter(|_| if_range_holds(headers, &etag, Some(l.modified)));
        match asked.map(|v| (v, parse_range(v, len))) {
            Some((_, Ok(Some((a, b))))) => r
                .status(StatusCode::PARTIAL_CONTENT)
                .header(header::CONTENT_RANGE, format!("bytes {a}-{b}/{len}"))
                .body(Body::from(l.body.slice(a as usize..=b as usize)))
                .unwrap_or_default(),
            Some((v, Err(Unsatisfiable))) => {
                let mut e = Error::new(
                    StatusCode::RANGE_NOT_SATISFIABLE,
                    "range",
                    format!("range {v:?} is outside the file's {len} bytes"),
                )
                .into_response();
                if let Ok(h) = HeaderValue::from_str(&format!("bytes */{len}")) {
                    e.headers_mut().insert(header::CONTENT_RANGE, h);
                }
                e
            }
            _ => r.body(Body::from(l.body.clone())).unwrap_or_default(),
        }
    }
}
