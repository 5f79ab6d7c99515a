//! What a load test reports (`summary.json`): the machine, the run's settings, and each policy's
//! and each client's figures, after Funkhouser's prefetch measurements (Funkhouser 1993
//! §5.2–5.3, Tables 5.1–5.10).

use super::link::Link;
use super::sim::FrameStat;
use portico_protocol::Policy;
use serde::Serialize;

/// The machine the load test ran on.
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    /// Host name.
    pub hostname: String,
    /// CPU cores available to this process.
    pub cores: usize,
}

/// The result of a load test (`summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct LoadtestSummary {
    /// Where it ran.
    pub machine: Machine,
    /// Server URL.
    pub server: String,
    /// Model name.
    pub model: String,
    /// Database id (content hash).
    pub database_id: String,
    /// Path kind (`tour`, `spin`, `revisit`, `recorded`).
    pub path: String,
    /// Path hash.
    pub path_hash: String,
    /// Frames in one pass over the path.
    pub path_frames: usize,
    /// Frames each client played.
    pub frames_per_client: u64,
    /// The emulated link.
    pub link: Link,
    /// The link as a spec string.
    pub link_spec: String,
    /// Simulated clients.
    pub clients: usize,
    /// Cache budget per client (bytes).
    pub cache_bytes: u64,
    /// Frame budget (s).
    pub budget_s: f64,
    /// Frames the oracle looked ahead.
    pub oracle_lookahead_frames: u64,
    /// Static size threshold (pixels per triangle) capping every client's detail.
    pub size_threshold_px: f32,
    /// How `server_cpu_s` was measured.
    pub server_cpu_source: String,
    /// Whether the plots have text (a font was found).
    pub plot_text: bool,
    /// PNG files written.
    pub plots: Vec<String>,
    /// Wall-clock seconds of the whole load test.
    pub wall_s: f64,
    /// One entry per policy and baseline, in run order.
    pub policies: Vec<PolicyResult>,
    /// MB of what an omniscient client draws at each of client 0's frames (Funkhouser Fig.
    /// 5.11's "0 frames" curve; empty without baselines; not in the JSON).
    #[serde(skip)]
    pub visible_mb_client0: Vec<f64>,
}

impl LoadtestSummary {
    /// A policy's result by name.
    pub fn get(&self, name: &str) -> Option<&PolicyResult> {
        self.policies.iter().find(|p| p.name == name)
    }

    /// The prefetch policy with the fewest LODs skipped per frame (ties: smaller deficit).
    pub fn best_prefetch(&self) -> Option<&PolicyResult> {
        self.policies
            .iter()
            .filter(|p| p.kind == "prefetch")
            .min_by(|a, b| {
                (a.lods_skipped_mean, a.lod_deficit_mean)
                    .partial_cmp(&(b.lods_skipped_mean, b.lod_deficit_mean))
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
    }
}

/// The figures of one policy (or baseline) over all its clients' frames.
#[derive(Debug, Clone, Serialize)]
pub struct PolicyResult {
    /// Name (the policy spec, `demand` or `oracle`).
    pub name: String,
    /// `prefetch`, `demand` or `oracle`.
    pub kind: String,
    /// The policy sent to the server (prefetch runs).
    pub policy: Option<Policy>,
    /// `pull` or `push` (the baselines always pull).
    pub transport: String,
    /// Frames played, all clients together.
    pub frames: u64,
    /// LODs skipped per frame (Funkhouser §5.2.4), mean.
    pub lods_skipped_mean: f64,
    /// LODs skipped per frame, max.
    pub lods_skipped_max: f64,
    /// Objects skipped per frame (wanted, nothing resident), mean.
    pub objects_skipped_mean: f64,
    /// Objects skipped per frame, max.
    pub objects_skipped_max: f64,
    /// LOD levels short per frame: LODs skipped plus, per skipped object, the levels from the
    /// wanted one to the coarsest; mean.
    pub lod_deficit_mean: f64,
    /// LOD levels short per frame, max.
    pub lod_deficit_max: f64,
    /// LODs skipped per frame after each client's first [`WARMUP_S`](super::WARMUP_S) seconds
    /// (`None` when no frame is that late), mean.
    pub lods_skipped_warm_mean: Option<f64>,
    /// Objects skipped per frame after the warm-up, mean.
    pub objects_skipped_warm_mean: Option<f64>,
    /// LOD deficit per frame after the warm-up, mean.
    pub lod_deficit_warm_mean: Option<f64>,
    /// Objects visible per frame, mean.
    pub visible_objects_mean: f64,
    /// Frames drawn with frustum culling because the eye cell's stab list was not resident
    /// (including `outside_frames`).
    pub fallback_frames: u64,
    /// Frames whose eye was in no live cell (frustum culling whatever the cache holds: the
    /// client then wants objects no cell-based lookahead lists).
    pub outside_frames: u64,
    /// Segment bytes fetched, all clients together.
    pub bytes_fetched: u64,
    /// Segment bytes fetched per client (`bytes_fetched` over the clients), mean.
    pub bytes_fetched_per_client: u64,
    /// Segments fetched, all clients together.
    pub segments_fetched: u64,
    /// Fetched bytes never drawn (released, left at the end, or fetched twice), all clients
    /// together.
    pub bytes_wasted: u64,
    /// Fetched bytes never drawn per client, mean.
    pub bytes_wasted_per_client: u64,
    /// `bytes_wasted_per_client` by reason.
    pub waste_per_client: super::waste::Waste,
    /// Of the LODs the elider wanted, the fraction resident.
    pub cache_hit_rate: f64,
    /// Seconds from a segment's first listing (prefetch answer, demand or oracle list) to its
    /// residency: median.
    pub latency_p50_s: f64,
    /// 95th percentile.
    pub latency_p95_s: f64,
    /// 99th percentile.
    pub latency_p99_s: f64,
    /// Mean.
    pub latency_mean_s: f64,
    /// Prefetch requests answered.
    pub prefetch_requests: u64,
    /// Prefetch requests per second, all clients together.
    pub prefetch_rps: f64,
    /// Segment fetches per second, all clients together.
    pub segment_rps: f64,
    /// Lookahead set (MB, from `PrefetchResponse.lookahead_bytes`) per frame, mean.
    pub lookahead_mb_mean: f64,
    /// Lookahead set per frame, max.
    pub lookahead_mb_max: f64,
    /// Range cells per prefetch answer, mean.
    pub range_cells_mean: f64,
    /// Range cells per answer, max.
    pub range_cells_max: f64,
    /// Lookahead objects per answer, mean.
    pub lookahead_objects_mean: f64,
    /// Lookahead objects per answer, max.
    pub lookahead_objects_max: f64,
    /// Server compute time per prefetch answer (ms), mean (Funkhouser's "compute time").
    pub answer_ms_mean: f64,
    /// Server compute time per answer (ms), max.
    pub answer_ms_max: f64,
    /// Server CPU seconds during the run (see `server_cpu_source` in the summary).
    pub server_cpu_s: Option<f64>,
    /// Server CPU seconds per wall second (cores busy).
    pub server_cpu_cores: Option<f64>,
    /// Seconds inside the server's request handlers, from `/metrics`.
    pub server_handler_s: Option<f64>,
    /// Cache budget per client.
    pub cache_budget_bytes: u64,
    /// Most bytes any client's cache ever held (never above the budget).
    pub cache_peak_bytes: u64,
    /// Segments released, all clients.
    pub evictions: u64,
    /// Failed requests (logged).
    pub io_failures: u64,
    /// Wall seconds of the run.
    pub wall_s: f64,
    /// Wall seconds per frame (the frame budget when the simulator kept up).
    pub frame_period_s: f64,
    /// Clients that reached a frame with every visible object represented (its own LOD, or
    /// with impostors a box above it).
    pub complete_clients: u64,
    /// The first such frame, mean over those clients.
    pub first_complete_frame_mean: Option<f64>,
    /// Bytes that had arrived by then, mean over those clients.
    pub first_complete_bytes_mean: Option<f64>,
    /// Demand fetch's mean LODs skipped divided by this run's (`None` if this one is 0).
    pub lods_skipped_vs_demand: Option<f64>,
    /// Demand fetch's mean LOD deficit divided by this run's.
    pub lod_deficit_vs_demand: Option<f64>,
    /// The same ratio of LODs skipped after the warm-up.
    pub lods_skipped_warm_vs_demand: Option<f64>,
    /// Each client's own figures.
    pub per_client: Vec<ClientFigures>,
    /// Client 0's frames (for the plots and `frames.csv`; not in the JSON).
    #[serde(skip)]
    pub client0: Vec<FrameStat>,
}

/// One simulated client's figures within a run.
#[derive(Debug, Clone, Serialize)]
pub struct ClientFigures {
    /// Path frame it started at.
    pub start_frame: usize,
    /// LODs skipped per frame, mean.
    pub lods_skipped_mean: f64,
    /// Objects skipped per frame, mean.
    pub objects_skipped_mean: f64,
    /// LOD deficit per frame, mean.
    pub lod_deficit_mean: f64,
    /// Frames drawn with frustum culling (eye cell's stab list not resident).
    pub fallback_frames: u64,
    /// Segment bytes fetched.
    pub bytes_fetched: u64,
    /// Failed requests.
    pub io_failures: u64,
    /// Its first complete frame (every visible object drawn) and the bytes that had arrived by
    /// then; `None` if it never had one.
    pub first_complete: Option<(u64, u64)>,
}
