//! The paged manifest ([`portico_protocol::CoreManifest`], [`portico_protocol::Page`]): the core
//! made once at start-up, each cell's page made on first request (off the async workers) and
//! kept in a small LRU. A cold start on flattened `mega` costs the 31 KB core where the whole
//! manifest is 9.6 MB, then with each stab list the page its cell sees (median 9 KB).

use crate::encoding::Precompressed;
use crate::error::Error;
use crate::routes::{IMMUTABLE, current, document, wants_bincode};
use crate::state::AppState;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::Response;
use bytes::Bytes;
use portico_data::Database;
use portico_protocol::{CoreManifest, PROTOCOL_VERSION, SegmentInfo};
use std::num::NonZeroUsize;
use std::sync::{Arc, Mutex};

/// Pages kept encoded (bincode and gzip): about 40 KB each on flattened `mega`.
const PAGE_CACHE: usize = 512;

/// The pages made so far, by cell.
pub struct Pages {
    cache: Mutex<lru::LruCache<u32, Arc<Precompressed>>>,
}

impl Default for Pages {
    fn default() -> Pages {
        Pages {
            cache: Mutex::new(lru::LruCache::new(
                NonZeroUsize::new(PAGE_CACHE).expect("nonzero"),
            )),
        }
    }
}

/// A segment's manifest row.
pub fn row(db: &Database, id: u32) -> SegmentInfo {
    db.segments()
        .get(id as usize)
        .map_or(portico_data::format::UNKNOWN_ROW, |e| SegmentInfo {
            kind: e.kind,
            bytes: e.length,
            checksum: e.checksum,
        })
}

/// The core manifest of `db`, bincode-encoded.
pub fn core_bincode(db: &Database, database_id: &str) -> Result<Vec<u8>, String> {
    let h = db.header();
    let core = CoreManifest {
        protocol_version: PROTOCOL_VERSION,
        database_id: database_id.to_string(),
        file_bytes: db.file_len(),
        segment_count: db.segments().len() as u32,
        instance_count: h.instances.len() as u32,
        triangles: h.finest_triangles(),
        rows: h
            .unowned_segments()
            .into_iter()
            .map(|s| (s, row(db, s)))
            .collect(),
        header: h.core(),
    };
    portico_protocol::to_bincode(&core).map_err(|e| e.to_string())
}

impl AppState {
    /// Cell `cell`'s page as bincode with its gzip coding, made on first use.
    ///
    /// # Errors
    /// 404 for a cell that does not exist or has no stab list (dead, or no cells at all); 500
    /// when its stab list cannot be read.
    pub fn page(&self, cell: u32) -> Result<Arc<Precompressed>, Error> {
        if let Some(p) = self
            .pages
            .cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&cell)
        {
            return Ok(p.clone());
        }
        let seg = self.prefetcher.stab_segment(cell).ok_or_else(|| {
            Error::not_found(format!(
                "cell {cell} has no page: it is not a live cell of this database"
            ))
        })?;
        let stab = self.prefetcher.stab(cell)?;
        let db = self.db();
        let page = db.header().page(cell, seg, &stab, &|s| row(db, s));
        let bincode = portico_protocol::to_bincode(&page)
            .map_err(|e| Error::internal("page does not encode", e))?;
        let p = Arc::new(Precompressed::new(Bytes::from(bincode)));
        self.pages
            .cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .put(cell, p.clone());
        Ok(p)
    }
}

/// `GET /v1/manifest/core`: the [`CoreManifest`] (bincode only: JSON clients read the whole
/// manifest), revalidated like the manifest.
pub async fn core(State(s): State<Arc<AppState>>, headers: HeaderMap) -> Result<Response, Error> {
    if !wants_bincode(&headers) {
        return Err(Error::new(
            axum::http::StatusCode::NOT_ACCEPTABLE,
            "not_acceptable",
            format!(
                "/v1/manifest/core is bincode only (Accept: {})",
                portico_protocol::BINCODE_MIME
            ),
        ));
    }
    Ok(document(
        &headers,
        true,
        &s.core_bincode,
        &format!("k-{}", s.database_id),
    ))
}

/// `GET /v1/db/{database_id}/pages/{cell}`: the cell's [`portico_protocol::Page`] (bincode,
/// gzip-coded where accepted). The URL names the database, so the answer is immutable.
pub async fn page(
    State(s): State<Arc<AppState>>,
    Path((db, raw)): Path<(String, String)>,
    headers: HeaderMap,
) -> Result<Response, Error> {
    current(&s, &db)?;
    let cell: u32 = raw
        .parse()
        .map_err(|_| Error::bad_request(format!("cell {raw:?} is not a number")))?;
    if !wants_bincode(&headers) {
        return Err(Error::new(
            axum::http::StatusCode::NOT_ACCEPTABLE,
            "not_acceptable",
            format!(
                "pages are bincode only (Accept: {})",
                portico_protocol::BINCODE_MIME
            ),
        ));
    }
    let state = s.clone();
    let p = tokio::task::spawn_blocking(move || state.page(cell))
        .await
        .map_err(|e| Error::internal("page task", e))??;
    let mut r = document(&headers, true, &p, &format!("p-{cell}"));
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static(IMMUTABLE));
    Ok(r)
}
