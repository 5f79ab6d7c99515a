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

    /// `GET /v1/batch?ids=...`: several segments in one round trip, in the order asked.
    pub async fn batch(&self, ids: &[u32]) -> Result<Vec<(u32, Bytes)>> {
        let list: Vec<String> = ids.iter().map(u32::to_string).collect();
        let what = format!("batch of {} segments", ids.len());
        let body = self
            .fetch(
                self.get(&format!("/v1/batch?ids={}", list.join(","))),
                &what,
            )
            .await?;
        parse_batch(&body).with_context(|| format!("{}: {what}", self.base))
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

/// Splits a `/v1/batch` body: per segment its id (`u32` LE), its length (`u64` LE) and its
/// bytes (slices of the body, not copies).
pub fn parse_batch(body: &Bytes) -> Result<Vec<(u32, Bytes)>> {
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < body.len() {
        let head = body
            .get(at..at + 12)
            .context("batch body truncated in a segment header")?;
        let id = u32::from_le_bytes(head[..4].try_into()?);
        let len = usize::try_from(u64::from_le_bytes(head[4..].try_into()?))?;
        let start = at + 12;
        let end = start
            .checked_add(len)
            .filter(|&e| e <= body.len())
            .with_context(|| format!("batch body truncated in segment {id}"))?;
        out.push((id, body.slice(start..end)));
        at = end;
    }
    Ok(out)
}

/// Fetches a server's cell graph from synchronous code (e.g. to make a path before a walk).
pub fn cells_blocking(remote: &Remote) -> Result<CellGraph> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    rt.block_on(remote.cells())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batch_bodies_split_into_their_segments_and_truncation_is_an_error() {
        let mut b = Vec::new();
        for (id, data) in [(7u32, &b"abc"[..]), (2, &b""[..]), (9, &b"xy"[..])] {
            b.extend_from_slice(&id.to_le_bytes());
            b.extend_from_slice(&(data.len() as u64).to_le_bytes());
            b.extend_from_slice(data);
        }
        let body = Bytes::from(b);
        let parts = parse_batch(&body).unwrap();
        let ids: Vec<u32> = parts.iter().map(|p| p.0).collect();
        assert_eq!(ids, vec![7, 2, 9]);
        assert_eq!(&parts[0].1[..], b"abc");
        assert_eq!(&parts[2].1[..], b"xy");
        assert!(parse_batch(&body.slice(..body.len() - 1)).is_err());
        assert!(parse_batch(&body.slice(..5)).is_err());
        assert!(parse_batch(&Bytes::new()).unwrap().is_empty());
    }
}
