//! The paged manifest ([`portico_protocol::CoreManifest`], [`portico_protocol::Page`]): the core
//! made once at start-up, each cell's page made on first request on a compute slot (never on an
//! async worker) and kept in an LRU bounded by bytes. A cold start on flattened `mega` costs the 31 KB core where the whole
//! manifest is 9.6 MB and the cell graph 0.9 MB, then with each stab list the page its cell
//! sees (median 10 KB).

use crate::encoding::Precompressed;
use crate::error::Error;
use crate::routes::{IMMUTABLE, current, document, wants_bincode};
use crate::state::AppState;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::Response;
use bytes::Bytes;
use portico_data::Database;
use portico_data::cells::CellGraph;
use portico_protocol::{CoreManifest, PROTOCOL_VERSION, SegmentInfo};
use std::sync::{Arc, Mutex};

/// Most bytes the encoded pages kept may take (bincode, gzip and the push frame of each; a
/// page of flattened `mega` is 40 KB in all at the median, 1.2 MB at most).
pub const PAGE_CACHE_BYTES: usize = 64 << 20;

/// A cell's page, encoded every way it is sent.
pub struct EncodedPage {
    /// Bincode, and its gzip coding (`GET /v1/db/{db}/pages/{cell}`).
    pub coded: Precompressed,
    /// The push stream's [`portico_protocol::FRAME_PAGE`] (tag byte, then deflated bincode).
    pub frame: Bytes,
}

impl EncodedPage {
    fn bytes(&self) -> usize {
        self.coded.identity.len() + self.coded.gzip.len() + self.frame.len()
    }
}

/// The pages made so far, by cell, least recently used dropped past [`PAGE_CACHE_BYTES`].
pub struct Pages {
    cache: Mutex<(lru::LruCache<u32, Arc<EncodedPage>>, usize)>,
}

impl Default for Pages {
    fn default() -> Pages {
        Pages {
            cache: Mutex::new((lru::LruCache::unbounded(), 0)),
        }
    }
}

impl Pages {
    fn get(&self, cell: u32) -> Option<Arc<EncodedPage>> {
        let mut c = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        c.0.get(&cell).cloned()
    }

    fn put(&self, cell: u32, page: Arc<EncodedPage>) {
        let mut c = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        c.1 += page.bytes();
        if let Some(old) = c.0.put(cell, page) {
            c.1 -= old.bytes();
        }
        while c.1 > PAGE_CACHE_BYTES && c.0.len() > 1 {
            match c.0.pop_lru() {
                Some((_, old)) => c.1 -= old.bytes(),
                None => break,
            }
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

/// The core manifest of `db` (with `graph`'s frame), bincode-encoded.
pub fn core_bincode(
    db: &Database,
    graph: Option<&CellGraph>,
    database_id: &str,
) -> Result<Vec<u8>, String> {
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
        graph: graph.map(CellGraph::core),
    };
    portico_protocol::to_bincode(&core).map_err(|e| e.to_string())
}

impl AppState {
    /// Cell `cell`'s page, encoded, made on first use (CPU work: callers run it on a compute
    /// slot, [`crate::compute`]).
    ///
    /// # Errors
    /// 404 for a cell that does not exist or has no stab list (dead, or no cells at all); 500
    /// when its stab list cannot be read.
    pub fn page(&self, cell: u32) -> Result<Arc<EncodedPage>, Error> {
        if let Some(p) = self.pages.get(cell) {
            return Ok(p);
        }
        let seg = self.prefetcher.stab_segment(cell).ok_or_else(|| {
            Error::not_found(format!(
                "cell {cell} has no page: it is not a live cell of this database"
            ))
        })?;
        let graph = self
            .prefetcher
            .graph()
            .ok_or_else(|| Error::not_found("this database has no cells"))?;
        let stab = self.prefetcher.stab(cell)?;
        let db = self.db();
        let page = db.header().page(cell, seg, &stab, &|s| row(db, s), graph);
        let bincode = portico_protocol::to_bincode(&page)
            .map_err(|e| Error::internal("page does not encode", e))?;
        let frame = Bytes::from(portico_protocol::deflate_page(&bincode));
        let p = Arc::new(EncodedPage {
            coded: Precompressed::new(Bytes::from(bincode)),
            frame,
        });
        self.pages.put(cell, p.clone());
        Ok(p)
    }

    /// Cell `cell`'s page if it is made already (the push stream warms its pages on the compute
    /// slot that makes its need list, and never makes one on an async worker).
    pub fn page_made(&self, cell: u32) -> Option<Arc<EncodedPage>> {
        self.pages.get(cell)
    }
}

/// `GET /v1/manifest/core`: the [`CoreManifest`] (bincode only: JSON clients read the whole
/// manifest), revalidated like the manifest. 404 for a database without cells, which has no
/// pages: its clients read the whole manifest.
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
    // Pages are cut along the stab lists: without cells there are none, and a client that
    // started from the core would never learn an instance. It reads the whole manifest instead.
    if s.cells_bincode.is_none() {
        return Err(Error::not_found(
            "this database has no cells (built with --no-cells), so no pages: read /v1/manifest",
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
    let p = s.compute.run(move |_| state.page(cell)).await?;
    let mut r = document(&headers, true, &p.coded, &format!("p-{cell}"));
    r.headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static(IMMUTABLE));
    Ok(r)
}
