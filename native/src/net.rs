//! The client side of the HTTP API: manifest, cell graph, segments and prefetch answers, over
//! reqwest (plain HTTP/1.1; put TLS in front with nginx). Every call names the URL in its error.

use anyhow::{Context, Result, bail};
use bytes::Bytes;
use portico_data::cells::CellGraph;
use portico_data::cells::paged::GraphCore;
use portico_data::format::{CellPage, Header};
use portico_protocol::{BINCODE_MIME, CoreManifest, Manifest, PrefetchRequest, PrefetchResponse};
use std::time::Duration;

/// The server no longer serves the database the client's URLs name (it was rebuilt and
/// reloaded): `410 Gone`. Asking again cannot help; the walk must start over on the new one.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Stale(pub String);

/// A server the client talks to.
#[derive(Debug, Clone)]
pub struct Remote {
    base: String,
    token: Option<String>,
    http: reqwest::Client,
    /// The database id of the manifest fetched (segment URLs name it, so no cache serves
    /// another file's bytes); `None` before any manifest.
    database: std::sync::Arc<std::sync::RwLock<Option<String>>>,
}

impl Remote {
    /// A client for the server at `base` (e.g. `http://127.0.0.1:7878`).
    pub fn new(base: &str, token: Option<String>) -> Result<Remote> {
        let http = reqwest::Client::builder()
            .timeout(Duration::from_secs(30))
            .connect_timeout(Duration::from_secs(10))
            .pool_max_idle_per_host(16)
            .build()
            .context("building the HTTP client")?;
        Ok(Remote {
            base: base.trim_end_matches('/').to_string(),
            token,
            http,
            database: Default::default(),
        })
    }

    /// The server's base URL.
    pub fn base(&self) -> &str {
        &self.base
    }

    /// The push transport's address: `ws://…/v1/db/{database_id}/stream` once a manifest named
    /// the database (the server closes a session on another database with
    /// [`portico_protocol::CLOSE_STALE`]), `…/v1/stream` before; `wss://` for `https://`, with
    /// the token as `?token=` when there is one. Errors: a base that is not an `http(s)://` URL.
    pub fn stream_url(&self) -> Result<String> {
        let mut url = reqwest::Url::parse(&format!("{}{}/stream", self.base, self.segments_base()))
            .with_context(|| format!("{}: not a URL", self.base))?;
        let scheme = match url.scheme() {
            "https" => "wss",
            "http" => "ws",
            other => bail!("{}: a {other} address, not http(s)", self.base),
        };
        url.set_scheme(scheme)
            .map_err(|()| anyhow::anyhow!("{}: cannot be a WebSocket address", self.base))?;
        if let Some(t) = &self.token {
            url.query_pairs_mut().append_pair("token", t);
        }
        Ok(url.into())
    }

    fn get(&self, path: &str) -> reqwest::RequestBuilder {
        let r = self
            .http
            .get(format!("{}{path}", self.base))
            .header("accept", BINCODE_MIME);
        match &self.token {
            Some(t) => r.bearer_auth(t),
            None => r,
        }
    }

    async fn fetch(&self, req: reqwest::RequestBuilder, what: &str) -> Result<Bytes> {
        self.fetch_found(req, what)
            .await?
            .map_err(|msg| anyhow::anyhow!("{}: {what}: 404 Not Found: {msg}", self.base))
    }

    /// [`Remote::fetch`], with a 404's message as `Ok(Err(_))`.
    async fn fetch_found(
        &self,
        req: reqwest::RequestBuilder,
        what: &str,
    ) -> Result<Result<Bytes, String>> {
        let resp = req
            .send()
            .await
            .map_err(|e| send_error(&self.base, what, &e))?;
        let status = resp.status();
        let body = resp
            .bytes()
            .await
            .with_context(|| format!("{}: reading {what}", self.base))?;
        if !status.is_success() {
            let msg = serde_json::from_slice::<portico_protocol::ApiError>(&body)
                .map(|e| e.message)
                .unwrap_or_else(|_| String::from_utf8_lossy(&body).into_owned());
            if status == reqwest::StatusCode::GONE {
                return Err(Stale(format!("{}: {what}: {msg}", self.base)).into());
            }
            if status == reqwest::StatusCode::NOT_FOUND {
                return Ok(Err(msg));
            }
            bail!("{}: {what}: {status}: {msg}", self.base);
        }
        Ok(Ok(body))
    }

    /// Where segments are read and prefetch asked: `/v1/db/{database_id}` once a manifest named
    /// the database (content-named URLs: immutable, and 410 Gone once the server has moved on
    /// to a rebuilt file), `/v1` before.
    fn segments_base(&self) -> String {
        match self.database.read().ok().and_then(|d| d.clone()) {
            Some(id) => format!("/v1/db/{id}"),
            None => "/v1".to_string(),
        }
    }

    /// `GET /v1/manifest`.
    pub async fn manifest(&self) -> Result<Manifest<Header>> {
        let b = self.fetch(self.get("/v1/manifest"), "manifest").await?;
        let m: Manifest<Header> = portico_protocol::manifest_from_bincode(&b)
            .with_context(|| format!("{}: manifest does not decode", self.base))?;
        if let Ok(mut d) = self.database.write() {
            *d = Some(m.database_id.clone());
        }
        Ok(m)
    }

    /// `GET /v1/manifest/core` ([`CoreManifest`]); `Ok(None)` from a server without it (404:
    /// one older than the paged manifest), whose whole manifest is read instead.
    pub async fn core(&self) -> Result<Option<CoreManifest<Header, GraphCore>>> {
        let Ok(b) = self
            .fetch_found(self.get("/v1/manifest/core"), "core manifest")
            .await?
        else {
            return Ok(None);
        };
        let m: CoreManifest<Header, GraphCore> = portico_protocol::from_bincode(&b)
            .with_context(|| format!("{}: core manifest does not decode", self.base))?;
        if let Ok(mut d) = self.database.write() {
            *d = Some(m.database_id.clone());
        }
        Ok(Some(m))
    }

    /// `GET /v1/db/{database_id}/pages/{cell}`: the cell's page.
    pub async fn page(&self, cell: u32) -> Result<CellPage> {
        let url = format!("{}/pages/{cell}", self.segments_base());
        let what = format!("page of cell {cell}");
        let b = self.fetch(self.get(&url), &what).await?;
        portico_protocol::from_bincode(&b)
            .with_context(|| format!("{}: {what} does not decode", self.base))
    }

    /// `GET /v1/cells` (ask only when the manifest's header has cells).
    pub async fn cells(&self) -> Result<CellGraph> {
        let b = self.fetch(self.get("/v1/cells"), "cells").await?;
        portico_data::format::decode_segment(&b)
            .map_err(|e| anyhow::anyhow!("{}: cell graph {e}", self.base))
    }

    /// What every client needs before its first frame: the manifest and, when the model has
    /// cells, the cell graph.
    pub async fn model(&self) -> Result<(Manifest<Header>, Option<CellGraph>)> {
        let m = self.manifest().await?;
        let graph = match m.header.cells {
            Some(_) => Some(self.cells().await?),
            None => None,
        };
        Ok((m, graph))
    }

    /// `GET /v1/db/{database_id}/segments/{id}`.
    pub async fn segment(&self, id: u32) -> Result<Bytes> {
        let url = format!("{}/segments/{id}", self.segments_base());
        self.fetch(self.get(&url), &format!("segment {id}")).await
    }

    /// `GET /v1/db/{database_id}/batch?ids=...`: several segments in one round trip, in the
    /// order asked; a segment the server could not read fails alone.
    pub async fn batch(&self, ids: &[u32]) -> Result<Vec<(u32, Result<Bytes>)>> {
        let list: Vec<String> = ids.iter().map(u32::to_string).collect();
        let what = format!("batch of {} segments", ids.len());
        let url = format!("{}/batch?ids={}", self.segments_base(), list.join(","));
        let body = self.fetch(self.get(&url), &what).await?;
        let parts = portico_protocol::batch::parse(&body)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("{}: {what}", self.base))?;
        Ok(parts
            .into_iter()
            .map(|(id, range)| {
                let bytes = range.map(|r| body.slice(r)).with_context(|| {
                    format!("{}: segment {id} is damaged on the server", self.base)
                });
                (id, bytes)
            })
            .collect())
    }

    /// `POST /v1/db/{database_id}/prefetch`.
    pub async fn prefetch(&self, req: &PrefetchRequest) -> Result<PrefetchResponse> {
        let body = portico_protocol::to_bincode(req)?;
        let mut r = self
            .http
            .post(format!("{}{}/prefetch", self.base, self.segments_base()))
            .header("content-type", BINCODE_MIME)
            .header("accept", BINCODE_MIME)
            .body(body);
        if let Some(t) = &self.token {
            r = r.bearer_auth(t);
        }
        let b = self.fetch(r, "prefetch").await?;
        Ok(portico_protocol::from_bincode(&b)?)
    }
}

/// [`Remote::model`] from synchronous code (e.g. to make a path before a walk), on a
/// current-thread runtime of its own.
pub fn model_blocking(remote: &Remote) -> Result<(Manifest<Header>, Option<CellGraph>)> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    rt.block_on(remote.model())
}

/// What a client needs before its first frame, paged: the core manifest alone (one round
/// trip; the cell graph comes page by page too); `Ok(None)` from a server without it.
pub fn core_blocking(remote: &Remote) -> Result<Option<CoreManifest<Header, GraphCore>>> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    rt.block_on(remote.core())
}

/// A request that got no answer, in one line: the innermost cause (what the OS said) and,
/// when nothing listens, how to start a server, instead of reqwest's chain of wrappers.
fn send_error(base: &str, what: &str, e: &reqwest::Error) -> anyhow::Error {
    let mut root: &dyn std::error::Error = e;
    while let Some(next) = root.source() {
        root = next;
    }
    if e.is_connect() {
        anyhow::anyhow!(
            "{base}: cannot connect ({root}); is `portico serve FILE.portico` running there?"
        )
    } else if e.is_timeout() {
        anyhow::anyhow!("{base}: {what}: no answer in time ({root})")
    } else {
        anyhow::anyhow!("{base}: {what}: {root}")
    }
}
