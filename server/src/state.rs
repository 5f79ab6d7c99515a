//! What every handler shares: the database (through the prefetcher), precomputed answers for
//! the immutable documents, limits, the compute slots, metrics, and the session gate.

use crate::compute::Compute;
use crate::config::Config;
use crate::encoding::Precompressed;
use crate::metrics::Metrics;
use bytes::Bytes;
use portico_data::prefetch::Prefetcher;
use portico_data::{DataError, Database};
use portico_protocol::{Manifest, PROTOCOL_VERSION};
use std::sync::{Arc, OnceLock};
use tokio::sync::{Semaphore, watch};

/// Shared server state (one per served file).
pub struct AppState {
    /// Prefetch answers over the database (owns the `Arc<Database>`).
    pub prefetcher: Prefetcher,
    /// Limits and options.
    pub config: Config,
    /// Where prefetch answers are computed (off the async workers, within a deadline).
    pub compute: Compute,
    /// The CPU observers' own answers may take before answers are shared.
    pub exact: crate::answers::ExactBudget,
    /// The shared need lists being computed now (one computation per list: `crate::inflight`).
    pub lists: crate::inflight::InFlight<portico_data::prefetch::shared::ShareKey>,
    /// Counters and histograms (kept across reloads: [`AppState::open_after`]).
    pub metrics: Arc<Metrics>,
    /// Strong identifier of the file's contents (the manifest's ETag).
    pub database_id: String,
    /// The manifest, bincode-encoded and gzip-compressed once at start-up.
    pub manifest_bincode: Precompressed,
    /// The paged manifest's core (the `pages` module), bincode and gzip, made at start-up.
    pub core_bincode: Precompressed,
    /// Cells' pages made so far (the `pages` module).
    pub pages: crate::pages::Pages,
    /// The cell of each stab list segment.
    pub stab_cells: std::collections::HashMap<u32, u32>,
    /// The stored cell graph segment and its gzip coding, when the model has cells.
    pub cells_bincode: Option<Precompressed>,
    /// Each segment's strong ETag (its xxh3, quoted), made once at start-up.
    pub etags: Vec<axum::http::HeaderValue>,
    manifest_json: OnceLock<Precompressed>,
    cells_json: OnceLock<Precompressed>,
    /// The model's standard tour as JSON, made on first use (`None`: the model has none).
    pub tour: OnceLock<Option<Precompressed>>,
    /// One permit per allowed stream session.
    pub sessions: Arc<Semaphore>,
    /// Turns for the large stream messages decoded on the blocking pool (one per compute
    /// slot, across all sessions: the `stream` module).
    pub heavy: Semaphore,
    /// Flips to `true` when the server shuts down; stream sessions watch it and close.
    pub shutdown: watch::Sender<bool>,
}

impl std::fmt::Debug for AppState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AppState")
            .field("database_id", &self.database_id)
            .finish()
    }
}

impl AppState {
    /// Whether an observer asking for an answer now gets the shared list of its place rather
    /// than its own (sharing on, and own answers for everyone would take more than their
    /// share of the compute slots: `crate::answers`). Counts the ask.
    pub fn sharing_now(&self) -> bool {
        self.config.shared_answers && !self.exact.own_answer(std::time::Instant::now())
    }

    /// Opens the file read-only (memory-mapped), validates it, and prepares the manifest.
    pub fn open(path: &std::path::Path, config: Config) -> Result<Arc<AppState>, DataError> {
        let db = Arc::new(Database::open(path)?);
        Self::new(db, config)
    }

    /// [`AppState::open`] for a reload: the counters go on from `previous`'s.
    pub fn open_after(
        path: &std::path::Path,
        config: Config,
        previous: &AppState,
    ) -> Result<Arc<AppState>, DataError> {
        let db = Arc::new(Database::open(path)?);
        Self::with_metrics(db, config, previous.metrics.clone())
    }

    /// Wraps an already open database.
    pub fn new(db: Arc<Database>, config: Config) -> Result<Arc<AppState>, DataError> {
        Self::with_metrics(db, config, Arc::default())
    }

    fn with_metrics(
        db: Arc<Database>,
        config: Config,
        metrics: Arc<Metrics>,
    ) -> Result<Arc<AppState>, DataError> {
        let p = db.prologue();
        let database_id = format!("{:016x}{:016x}", p.header_checksum, p.index_checksum);
        let manifest = manifest(&db, &database_id);
        let manifest_bincode = portico_protocol::to_bincode(&manifest)
            .map(|b| Precompressed::new(Bytes::from(b)))
            .map_err(|e| DataError::NotFound(format!("manifest does not encode: {e}")))?;
        let stab_cells = db
            .header()
            .cells
            .as_ref()
            .map(|c| c.stab_cells())
            .unwrap_or_default();
        let cells_bincode = match &db.header().cells {
            Some(c) => Some(Precompressed::new(db.segment(c.graph_segment)?)),
            None => None,
        };
        let sessions = Arc::new(Semaphore::new(config.max_sessions));
        let etags = db
            .segments()
            .iter()
            .map(|e| {
                axum::http::HeaderValue::from_str(&format!("\"{:016x}\"", e.checksum))
                    .expect("hex digits are a valid header value")
            })
            .collect();
        let prefetcher = Prefetcher::new(db)?;
        let config_slots = config.compute_slots.max(1);
        let core_bincode =
            crate::pages::core_bincode(prefetcher.database(), prefetcher.graph(), &database_id)
                .map(|b| Precompressed::new(Bytes::from(b)))
                .map_err(|e| DataError::NotFound(format!("core manifest does not encode: {e}")))?;
        prefetcher
            .shared_answers()
            .set_capacity(config.shared_cache_bytes);
        Ok(Arc::new(AppState {
            etags,
            prefetcher,
            compute: Compute::new(config.compute_slots, config.compute_deadline),
            exact: crate::answers::ExactBudget::new(
                config.exact_share,
                config_slots,
                std::time::Instant::now(),
            ),
            lists: Default::default(),
            config,
            metrics,
            database_id,
            manifest_bincode,
            core_bincode,
            pages: Default::default(),
            stab_cells,
            cells_bincode,
            manifest_json: OnceLock::new(),
            cells_json: OnceLock::new(),
            tour: OnceLock::new(),
            sessions,
            heavy: Semaphore::new(config_slots),
            shutdown: watch::channel(false).0,
        }))
    }

    /// Stream sessions open on this database (the gauge in the metrics counts every
    /// generation's).
    pub fn sessions_open(&self) -> u64 {
        self.config
            .max_sessions
            .saturating_sub(self.sessions.available_permits()) as u64
    }

    /// The database.
    pub fn db(&self) -> &Database {
        self.prefetcher.database()
    }

    /// The manifest as JSON, with its gzip coding (encoded on first use: it is large for big
    /// models).
    pub fn manifest_json(&self) -> &Precompressed {
        self.manifest_json.get_or_init(|| {
            let m = manifest(self.db(), &self.database_id);
            Precompressed::new(Bytes::from(serde_json::to_vec(&m).unwrap_or_default()))
        })
    }

    /// The cell graph as JSON, with its gzip coding (bincode clients get the stored segment
    /// bytes unchanged, or their gzip coding: [`AppState::cells_bincode`]).
    pub fn cells_json(&self) -> &Precompressed {
        self.cells_json.get_or_init(|| {
            Precompressed::new(Bytes::from(
                serde_json::to_vec(&self.prefetcher.graph()).unwrap_or_default(),
            ))
        })
    }
}

fn manifest<'a>(db: &'a Database, id: &str) -> Manifest<&'a portico_data::format::Header> {
    Manifest {
        protocol_version: PROTOCOL_VERSION,
        database_id: id.to_string(),
        file_bytes: db.file_len(),
        segments: db.rows(),
        header: db.header(),
    }
}
