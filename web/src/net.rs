//! The HTTP API from a page: the core manifest and cells' pages (or the whole manifest and cell
//! graph), the standard tour, prefetch answers and segment batches, over
//! the browser's `fetch` (same origin by default, so a page served by `portico serve` or by an
//! nginx in front of it needs no CORS). Every error names the URL; `410 Gone` (the server now
//! serves a rebuilt file) is [`Stale`].

use anyhow::{Result, anyhow, bail};
use js_sys::Uint8Array;
use portico_data::cells::CellGraph;
use portico_data::cells::paged::GraphCore;
use portico_data::format::{CellPage, Header};
use portico_data::path::CameraPath;
use portico_protocol::{BINCODE_MIME, CoreManifest, Manifest, PrefetchRequest, PrefetchResponse};
use std::cell::RefCell;
use wasm_bindgen::{JsCast, JsValue};
use wasm_bindgen_futures::JsFuture;
use web_sys::{Request, RequestInit, Response};

/// Longest a request may take before it is given up (and counted as failed).
const TIMEOUT_MS: u32 = 30_000;

/// The server no longer serves the database the page reads: walking on needs a reload.
#[derive(Debug)]
pub struct Stale(pub String);

impl std::fmt::Display for Stale {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Stale {}

/// A Portico server seen from the page.
#[derive(Debug)]
pub struct Remote {
    base: String,
    /// `Authorization: Bearer` for a server started with `--token`.
    token: Option<String>,
    /// `/v1/db/{id}` once the manifest named the database (content-named segment URLs).
    database: RefCell<Option<String>>,
    /// Bytes of prefetch requests and answers so far (bodies).
    prefetch_bytes: std::cell::Cell<u64>,
}

/// A JavaScript exception or rejection in one line.
pub fn js_error(e: &JsValue) -> String {
    e.dyn_ref::<js_sys::Error>()
        .map(|e| String::from(e.message()))
        .or_else(|| e.as_string())
        .unwrap_or_else(|| format!("{e:?}"))
}

impl Remote {
    /// The server at `base` (`""`: the page's own origin), with its token if it has one.
    pub fn new(base: &str, token: Option<String>) -> Remote {
        Remote {
            base: base.trim_end_matches('/').to_string(),
            token,
            database: RefCell::new(None),
            prefetch_bytes: Default::default(),
        }
    }

    /// Bytes of the prefetch requests sent and answers received so far (their bodies).
    pub fn prefetch_bytes(&self) -> u64 {
        self.prefetch_bytes.get()
    }

    /// The database id of the manifest read (`None` before it).
    pub fn database(&self) -> Option<String> {
        self.database.borrow().clone()
    }

    /// The server's base URL (`""`: the page's origin).
    pub fn base(&self) -> &str {
        &self.base
    }

    /// The server's token, if it has one.
    pub fn token(&self) -> Option<&str> {
        self.token.as_deref()
    }

    fn segments_base(&self) -> String {
        match self.database.borrow().as_ref() {
            Some(id) => format!("{}/v1/db/{id}", self.base),
            None => format!("{}/v1", self.base),
        }
    }

    async fn send(&self, url: &str, body: Option<&[u8]>, what: &str) -> Result<Vec<u8>> {
        self.fetch(url, body, what, false)
            .await?
            .ok_or_else(|| anyhow!("{url}: {what}: not found"))
    }

    /// [`Remote::send`], with `Ok(None)` for `404 Not Found`.
    async fn send_found(
        &self,
        url: &str,
        body: Option<&[u8]>,
        what: &str,
    ) -> Result<Option<Vec<u8>>> {
        self.fetch(url, body, what, true).await
    }

    /// The request; with `missing_ok`, `Ok(None)` for `404 Not Found` (else its error, with the
    /// server's message).
    async fn fetch(
        &self,
        url: &str,
        body: Option<&[u8]>,
        what: &str,
        missing_ok: bool,
    ) -> Result<Option<Vec<u8>>> {
        let init = RequestInit::new();
        // A request the network never answers must not hold its slot forever.
        init.set_signal(Some(&web_sys::AbortSignal::timeout_with_u32(TIMEOUT_MS)));
        if let Some(b) = body {
            init.set_method("POST");
            let array = Uint8Array::from(b);
            init.set_body(&array.into());
        }
        let req = Request::new_with_str_and_init(url, &init)
            .map_err(|e| anyhow!("{url}: {}", js_error(&e)))?;
        let headers = req.headers();
        let _ = headers.set("accept", BINCODE_MIME);
        if let Some(t) = &self.token {
            let _ = headers.set("authorization", &format!("Bearer {t}"));
        }
        if body.is_some() {
            let _ = headers.set("content-type", BINCODE_MIME);
        }
        let window = web_sys::window().ok_or_else(|| anyhow!("no window"))?;
        let resp: Response = JsFuture::from(window.fetch_with_request(&req))
            .await
            .map_err(|e| {
                anyhow!(
                    "{url}: no answer ({}): is the server running?",
                    js_error(&e)
                )
            })?
            .dyn_into()
            .map_err(|_| anyhow!("{url}: {what}: not a response"))?;
        let buffer = resp
            .array_buffer()
            .map_err(|e| anyhow!("{url}: {what}: {}", js_error(&e)))?;
        let buffer = JsFuture::from(buffer)
            .await
            .map_err(|e| anyhow!("{url}: reading {what}: {}", js_error(&e)))?;
        let bytes = Uint8Array::new(&buffer).to_vec();
        if missing_ok && resp.status() == 404 {
            return Ok(None);
        }
        if !resp.ok() {
            let msg = serde_json::from_slice::<portico_protocol::ApiError>(&bytes)
                .map(|e| e.message)
                .unwrap_or_else(|_| String::from_utf8_lossy(&bytes).into_owned());
            if resp.status() == 410 {
                return Err(Stale(format!("{url}: {what}: {msg}")).into());
            }
            bail!("{url}: {what}: {} {msg}", resp.status());
        }
        Ok(Some(bytes))
    }

    /// `GET /v1/manifest/core`; `Ok(None)` from a server without it (404: the model has no
    /// cells, or the server is older than the paged manifest), whose whole manifest is read
    /// instead.
    pub async fn core(&self) -> Result<Option<CoreManifest<Header, GraphCore>>> {
        let url = format!("{}/v1/manifest/core", self.base);
        let Some(b) = self.send_found(&url, None, "core manifest").await? else {
            return Ok(None);
        };
        let m: CoreManifest<Header, GraphCore> = portico_protocol::from_bincode(&b)
            .map_err(|e| anyhow!("{url}: the core manifest does not decode: {e}"))?;
        *self.database.borrow_mut() = Some(m.database_id.clone());
        Ok(Some(m))
    }

    /// `GET /v1/db/{id}/pages/{cell}`: the cell's page.
    pub async fn page(&self, cell: u32) -> Result<CellPage> {
        let url = format!("{}/pages/{cell}", self.segments_base());
        let b = self
            .send(&url, None, &format!("page of cell {cell}"))
            .await?;
        portico_protocol::from_bincode(&b).map_err(|e| anyhow!("{url}: the page: {e}"))
    }

    /// `GET /v1/tour`: the model's standard tour (asked beside the core manifest, before the
    /// database is known); `Ok(None)` when it has none.
    pub async fn tour(&self) -> Result<Option<CameraPath>> {
        let url = format!("{}/v1/tour", self.base);
        let Some(b) = self.send_found(&url, None, "tour").await? else {
            return Ok(None);
        };
        serde_json::from_slice(&b).map_err(|e| anyhow!("{url}: the tour: {e}"))
    }

    /// `GET /v1/manifest`, then `GET /v1/cells` when the model has cells.
    pub async fn model(&self) -> Result<(Manifest<Header>, Option<CellGraph>)> {
        let url = format!("{}/v1/manifest", self.base);
        let b = self.send(&url, None, "manifest").await?;
        let m: Manifest<Header> = portico_protocol::manifest_from_bincode(&b)
            .map_err(|e| anyhow!("{url}: the manifest does not decode: {e}"))?;
        *self.database.borrow_mut() = Some(m.database_id.clone());
        let graph = match m.header.cells {
            Some(_) => {
                let url = format!("{}/v1/cells", self.base);
                let b = self.send(&url, None, "cells").await?;
                Some(
                    portico_data::format::decode_segment(&b)
                        .map_err(|e| anyhow!("{url}: the cell graph: {e}"))?,
                )
            }
            None => None,
        };
        Ok((m, graph))
    }

    /// `POST /v1/db/{id}/prefetch`.
    pub async fn prefetch(&self, req: &PrefetchRequest) -> Result<PrefetchResponse> {
        let url = format!("{}/prefetch", self.segments_base());
        let body = portico_protocol::to_bincode(req)?;
        let b = self.send(&url, Some(&body), "prefetch").await?;
        let sent = (body.len() + b.len()) as u64;
        self.prefetch_bytes.set(self.prefetch_bytes.get() + sent);
        portico_protocol::from_bincode(&b).map_err(|e| anyhow!("{url}: the answer: {e}"))
    }

    /// `GET /v1/db/{id}/batch?ids=…`: the segments in the order asked; one the server could not
    /// read fails alone.
    pub async fn batch(&self, ids: &[u32]) -> Result<Vec<(u32, Result<Vec<u8>>)>> {
        let list: Vec<String> = ids.iter().map(u32::to_string).collect();
        let url = format!("{}/batch?ids={}", self.segments_base(), list.join(","));
        let what = format!("batch of {} segments", ids.len());
        let body = self.send(&url, None, &what).await?;
        let parts = portico_protocol::batch::parse(&body).map_err(|e| anyhow!("{url}: {e}"))?;
        Ok(parts
            .into_iter()
            .map(|(id, range)| {
                let bytes = range
                    .map(|r| body[r].to_vec())
                    .ok_or_else(|| anyhow!("{url}: segment {id} is damaged on the server"));
                (id, bytes)
            })
            .collect())
    }
}
