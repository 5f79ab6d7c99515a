//! The paged manifest ([`portico_protocol::CoreManifest`], [`portico_protocol::Page`]): the core
//! made once at start-up, each cell's page made on first request on a compute slot (never on an
//! async worker) and kept in an LRU bounded by bytes. A cold start on flattened `mega` costs the 31 KB core where the whole
//! manifest is 9.6 MB and the cell graph 0.9 MB, then with each stab list the page its cell
//! sees (median 10 KB).

use crate::encoding::Precompressed;
use crate::error::Error;
use crate::state::AppState;
use bytes::Bytes;
use portico_data::Database;
use portico_data::cells::CellGraph;
use portico_protocol::{CoreManifest, PROTOCOL_VERSION};
use std::sync::{Arc, Mutex, OnceLock};

/// Most bytes the pages kept may take (counted at twice their bincode: the gzip coding and
/// the push frame, each made on first use, are about a third of it each; a page of flattened
/// `mega` is 31 KB of bincode at the median, 1.2 MB at most).
pub const PAGE_CACHE_BYTES: usize = 64 << 20;

/// A cell's page: its bincode, and each coding it is sent in, made when first sent (CPU work:
/// on a compute slot).
pub struct EncodedPage {
    bincode: Bytes,
    /// Bincode and its gzip coding (`GET /v1/db/{db}/pages/{cell}`).
    coded: OnceLock<Precompressed>,
    /// The push stream's [`portico_protocol::FRAME_PAGE`] (tag byte, then deflated bincode).
    frame: OnceLock<Bytes>,
}

impl EncodedPage {
    fn bytes(&self) -> usize {
        2 * self.bincode.len()
    }

    /// The page as `GET /v1/db/{db}/pages/{cell}` sends it (gzip made on first use).
    pub fn coded(&self) -> &Precompressed {
        self.coded
            .get_or_init(|| Precompressed::new(self.bincode.clone()))
    }

    /// The page as the push stream sends it (deflated on first use).
    pub fn frame(&self) -> &Bytes {
        self.frame
            .get_or_init(|| Bytes::from(portico_protocol::deflate_page(&self.bincode)))
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
    /// Pages kept now.
    pub fn len(&self) -> usize {
        self.cache.lock().unwrap_or_else(|e| e.into_inner()).0.len()
    }

    /// Whether no page is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

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
            .map(|s| (s, db.row(s)))
            .collect(),
        header: h.core(),
        graph: graph.map(CellGraph::core),
    };
    portico_protocol::to_bincode(&core).map_err(|e| e.to_string())
}

impl AppState {
    /// Cell `cell`'s page, bincode-encoded, made on first use (CPU work: callers run it on a
    /// compute slot, `compute`, and make the coding they send there too).
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
        let page = db.header().page(cell, seg, &stab, &|s| db.row(s), graph);
        let bincode = portico_protocol::to_bincode(&page)
            .map_err(|e| Error::internal("page does not encode", e))?;
        let p = Arc::new(EncodedPage {
            bincode: Bytes::from(bincode),
            coded: OnceLock::new(),
            frame: OnceLock::new(),
        });
        self.pages.put(cell, p.clone());
        Ok(p)
    }

    /// Cell `cell`'s push frame if it is made already (the push stream makes its pages on the
    /// compute slot that makes its need list, and never makes one on an async worker).
    pub fn page_frame(&self, cell: u32) -> Option<Bytes> {
        self.pages.get(cell)?.frame.get().cloned()
    }
}
