//! The client side of the HTTP API: manifest, cell graph, segments and prefetch answers, over
//! reqwest (plain HTTP/1.1; put TLS in front with nginx). Every call names the URL in its error.

use anyhow::{Context, Result, bail};
use bytes::Bytes;
use portico_data::cells::CellGraph;
use portico_data::format::Header;
use portico_protocol::{BINCODE_MIME, Manifest, PrefetchRequest, PrefetchResponse};
use std::time::Duration;

/// A server the client talks to.
#[derive(Debug, Clone)]
pub struct Remote {
    base: String,
    token: Option<String>,
    http: reqwest::Client,
}

impl Remote {
    /// A client for the server at `base` (e.g. `http://127.0.0.1:7878`).
    pub fn new(base: &str, token: Option<String>) -> Result<Remote> {
        let http = reqwest::Client::builder()
            .timeout(Duration::from_secs(30))
            .pool_max_idle_per_host(16)
            .build()
            .context("building the HTTP client")?;
        Ok(Remote {
            base: base.trim_end_matches('/').to_string(),
            token,
            http,
        })
    }

    /// The server's base URL.
    pub fn base(&self) -> &str {
        &self.base
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
        let resp = req
            .send()
            .await
            .with_context(|| format!("{}: {what}", self.base))?;
        let status = resp.status();
        let body = resp
            .bytes()
            .await
            .with_context(|| format!("{}: reading {what}", self.base))?;
        if !status.is_success() {
            let msg = serde_json::from_slice::<portico_protocol::ApiError>(&body)
                .map(|e| e.message)
                .unwrap_or_else(|_| String::from_utf8_lossy(&body).into_owned());
            bail!("{}: {what}: {status}: {msg}", self.base);
        }
        Ok(body)
    }

    /// `GET /v1/manifest`.
    pub async fn manifest(&self) -> Result<Manifest<Header>> {
        let b = self.fetch(self.get("/v1/manifest"), "manifest").await?;
        portico_protocol::manifest_from_bincode(&b)
            .with_context(|| format!("{}: manifest does not decode", self.base))
    }

    /// `GET /v1/cells` (ask only when the manifest's header has cells).
    pub async fn cells(&self) -> Result<CellGraph> {
        let b = self.fetch(self.get("/v1/cells"), "cells").await?;
        portico_data::format::decode_segment(&b)
            .map_err(|e| anyhow::anyhow!("{}: cell graph {e}", self.base))
    }

    /// `GET /v1/segments/{id}`.
    pub async fn segment(&self, id: u32) -> Result<Bytes> {
        self.fetch(
            self.get(&format!("/v1/segments/{id}")),
            &format!("segment {id}"),
        )
        .await
    }

    /// `POST /v1/prefetch`.
    pub async fn prefetch(&self, req: &PrefetchRequest) -> Result<PrefetchResponse> {
        let body = portico_protocol::to_bincode(req)?;
        let mut r = self
            .http
            .post(format!("{}/v1/prefetch", self.base))
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

/// Fetches a server's cell graph from synchronous code (e.g. to make a path before a walk).
pub fn cells_blocking(remote: &Remote) -> Result<CellGraph> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    rt.block_on(remote.cells())
}
