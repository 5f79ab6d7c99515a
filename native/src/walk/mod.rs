//! `portico walk`: the walkthrough client's frame loop (Funkhouser Ch. 6).
//!
//! Each frame: take what the IO stage delivered into the byte-budgeted cache → observer from
//! the path → eye-to-object visibility → candidates → detail elision at the frame budget over
//! RESIDENT LODs only → render → publish the observer and the held set to the IO stage. The
//! loop never waits for the network: what has not arrived is skipped and counted (§5.2.4).
//!
//! This file holds the configuration, the summary and the path-driven [`walk`]; `session`
//! holds the connected [`Session`] a path or a window drives, `walker` the frame loop's state
//! and the draws of one frame.

use crate::io::Catalogue;
use anyhow::{Context, Result};
use portico_client::cost::CostModel;
use portico_client::elision::Algorithm;
use portico_client::stats::Series;
use portico_data::cells::{CellGraph, StabList};
use portico_data::format::Header;
use portico_data::path::CameraPath;
use portico_protocol::Policy;
use portico_render::{GpuImpostor, GpuMesh, GpuTexture};
use serde::Serialize;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

mod session;
mod walker;

pub use session::Session;

/// Everything `portico walk` can be told.
#[derive(Debug, Clone)]
pub struct WalkConfig {
    /// Server base URL.
    pub server: String,
    /// Bearer token, if the server wants one.
    pub token: Option<String>,
    /// The path to replay.
    pub path: CameraPath,
    /// Frame-time budget in seconds.
    pub budget_s: f64,
    /// Cache byte budget.
    pub cache_bytes: u64,
    /// Image size.
    pub size: (u32, u32),
    /// Detail elision algorithm.
    pub elision: Algorithm,
    /// Prefetch policy (its `cache_bytes`, `screen` and `frame_time_s` are set from the above).
    pub policy: Policy,
    /// Output directory (frames.csv, summary.json, PNGs).
    pub out: Option<PathBuf>,
    /// Save every n-th frame as PNG (0 = none).
    pub png_every: u64,
    /// Stop after this many frames.
    pub max_frames: Option<u64>,
    /// Hold each frame to the budget, as a display at that rate would (path time stays in step
    /// with wall time). Off: frames run back to back.
    pub pace: bool,
    /// Vertical field of view in radians.
    pub fovy: f32,
    /// Maximum observer speed (m/s) and turn rate (rad/s) announced to the server.
    pub max_speed: f32,
    /// See `max_speed`.
    pub max_turn: f32,
    /// How the IO stage gets segments: server push (the default, falling back to pull) or
    /// HTTP pull.
    pub transport: crate::stream::Transport,
    /// Start from the core manifest and learn the model page by page with the stab lists
    /// ([`crate::pages`]); `false` reads the whole manifest first (as does a server without
    /// pages).
    pub paged: bool,
}

/// The first complete frame of a walk: how soon, and how many bytes it took.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FirstComplete {
    /// Frame number (0-based).
    pub frame: u64,
    /// Bytes read from the server up to and including that frame.
    pub bytes: u64,
}

/// The result of a walk (`summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct WalkSummary {
    /// GPU adapter the frames were drawn on.
    pub adapter: String,
    /// Server URL.
    pub server: String,
    /// Model name and database id.
    pub model: String,
    /// Database id (content hash).
    pub database_id: String,
    /// Path kind and hash.
    pub path: String,
    /// Path hash.
    pub path_hash: String,
    /// Elision algorithm.
    pub elision: String,
    /// Frame budget (s).
    pub budget_s: f64,
    /// Frames drawn.
    pub frames: u64,
    /// Frame time.
    pub frame_s: Series,
    /// Render time alone.
    pub render_s: Series,
    /// Frames whose frame time exceeded the budget.
    pub frames_over_budget: u64,
    /// LODs skipped per frame.
    pub lods_skipped: Series,
    /// Objects skipped per frame.
    pub objects_skipped: Series,
    /// Objects visible per frame.
    pub visible_objects: Series,
    /// Triangles drawn per frame.
    pub drawn_triangles: Series,
    /// Triangles of the whole model at the finest LOD.
    pub model_triangles: u64,
    /// Mean drawn triangles as a fraction of the whole model.
    pub drawn_fraction: f64,
    /// Frames whose eye cell stab list was not resident.
    pub visibility_fallback_frames: u64,
    /// Cache budget (bytes).
    pub cache_budget: u64,
    /// Most bytes the cache ever charged (never above the budget).
    pub cache_peak_bytes: u64,
    /// Most GPU memory held at the end of a frame by every mesh and impostor box alive, counted
    /// by the renderer where they are created and dropped: the cache's content, arrivals waiting
    /// in the IO queue, and the average-colour boxes drawn as stand-ins.
    pub gpu_held_peak_bytes: u64,
    /// Segments released.
    pub evictions: u64,
    /// The first frame that drew something for every visible object (none skipped), and the
    /// bytes read up to and including it; `None` if no frame did.
    pub first_complete: Option<FirstComplete>,
    /// Segments and bytes read from the server.
    pub segments_read: u64,
    /// Bytes read.
    pub bytes_read: u64,
    /// Seconds from the prefetch request listing a segment to its arrival.
    pub fetch_latency_s: Series,
    /// IO failures (logged, not fatal).
    pub io_failures: u64,
    /// The server stopped serving the walk's database (rebuilt and reloaded): reading stopped
    /// there, and the rest of the walk drew what it held.
    #[serde(default)]
    pub database_changed: bool,
    /// Calibrated cost model.
    pub cost_model: CostModel,
    /// Final online correction factor.
    pub cost_factor: f64,
    /// Wall-clock seconds of the whole walk.
    pub wall_s: f64,
    /// How the walk learnt the model: `"paged"` (the core manifest, then pages) or `"whole"`.
    pub manifest: String,
    /// Seconds from the start until the model documents (manifest or core, cell graph) were
    /// read and decoded: the part of the cold start before the first frame.
    pub startup_s: f64,
    /// Bytes of those documents as decoded (on the wire less, where gzip-coded).
    pub startup_bytes: u64,
}

/// A cached segment.
enum Resident {
    Mesh(GpuMesh),
    Stab(Arc<StabList>),
    Impostor(GpuImpostor),
    Texture(GpuTexture),
}

impl portico_client::frame::MaybeStab for Resident {
    fn stab_list(&self) -> Option<&Arc<StabList>> {
        match self {
            Resident::Stab(l) => Some(l),
            _ => None,
        }
    }
}

/// The model as the client knows it.
struct Model {
    /// Started from the core manifest: a sparse header, growing page by page.
    header: Header,
    graph: Option<CellGraph>,
    bounds: Vec<portico_data::geometry::Aabb>,
    database_id: String,
    model_triangles: u64,
    catalogue: Catalogue,
    /// Texture segments cut into parts, and the parts that came (shared with the IO thread,
    /// which joins them).
    parts: std::sync::Arc<std::sync::Mutex<portico_client::parts::Parts>>,
    /// `"paged"` or `"whole"`, the seconds and decoded bytes it took ([`WalkSummary::manifest`]).
    startup: (String, f64, u64),
}

/// Runs a walk; `on_frame(done, total)` reports progress.
pub fn walk(cfg: &WalkConfig, on_frame: &mut dyn FnMut(u64, u64)) -> Result<WalkSummary> {
    cfg.path
        .validate()
        .map_err(anyhow::Error::msg)
        .context("the walk path")?;
    let mut session = Session::open(cfg)?;
    let dt = cfg.budget_s.max(1e-3);
    let total = ((cfg.path.duration() as f64 / dt).ceil() as u64 + 1)
        .min(cfg.max_frames.unwrap_or(u64::MAX));
    if let Some(out) = &cfg.out {
        std::fs::create_dir_all(out.join("frames"))
            .with_context(|| format!("creating {}", out.display()))?;
    }
    let mut outcome = Ok(());
    for frame in 0..total {
        let t0 = Instant::now();
        let t = frame as f64 * dt;
        let obs = session.path_observer(t);
        let png = cfg.png_every > 0 && frame % cfg.png_every == 0;
        if png {
            session.want_picture();
        }
        if let Err(e) = session.frame(t, &obs) {
            outcome = Err(e);
            break;
        }
        on_frame(frame + 1, total);
        if png {
            session.save_png(frame)?;
        }
        if cfg.pace {
            std::thread::sleep(Duration::from_secs_f64(dt).saturating_sub(t0.elapsed()));
        }
    }
    outcome?;
    session.finish()
}
