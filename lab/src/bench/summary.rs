//! What the benchmark reports (`summary.json` and `frames.csv`): each run's frame times
//! (Funkhouser 1993 §4.2.4, Table 4.3; Yuan 2001 §5.2) and image fidelity Es, Et and PSNR
//! (Yuan 2001 §5.3), the machine, model, path and parameters (Yuan 2001 §6.3), and the
//! Regular-against-itself self-test.

use super::critical::{CriticalCounts, CriticalParams};
use portico_client::cost::CostModel;
use portico_client::stats::Series;
use serde::Serialize;

/// One run's results (a row of the report's table).
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// Run name (`regular`, `none`, `static`, `feedback`, `optimize`, `coarsest`).
    pub name: String,
    /// The frame budget frames were counted against, seconds.
    pub budget: f64,
    /// Whether the run's LOD choice uses the budget (only the elision algorithms do).
    pub budgeted: bool,
    /// Frames drawn.
    pub frames: u64,
    /// Frame time (visibility + elision + render), seconds.
    pub frame_time: Series,
    /// Render time alone (submit to GPU done), seconds.
    pub render_time: Series,
    /// Detail elision time, seconds.
    pub elision_time: Series,
    /// Frames whose frame time exceeded the budget.
    pub frames_over_budget: u64,
    /// Triangles drawn per frame, mean.
    pub polygons_mean: f64,
    /// Triangles drawn per frame.
    pub polygons: Series,
    /// Mean triangles drawn as a fraction of the Regular run's.
    pub polygons_vs_regular: f64,
    /// Es (visible-only form; RRB eq. 5.5–5.7).
    pub es_mean: f64,
    /// Largest per-frame Es.
    pub es_max: f64,
    /// Et (visible-only per-frame form).
    pub et_mean: f64,
    /// Largest per-frame Et.
    pub et_max: f64,
    /// Es with RRB's `n_v = |V|` (every critical vertex of the model).
    pub es_rrb: f64,
    /// Et exactly per RRB eq. 5.8–5.10.
    pub et_rrb: f64,
    /// Mean PSNR (dB) over the frames that differ from the reference; `null` if none differ (∞).
    pub psnr_mean: Option<f64>,
    /// Lowest per-frame PSNR (dB); `null` if every frame equals the reference.
    pub psnr_min: Option<f64>,
    /// PSNR of the mean squared error over all frames; `null` when it is 0 (∞).
    pub psnr_of_mean_mse: Option<f64>,
    /// Frames identical to the reference (PSNR ∞).
    pub identical_frames: u64,
}

/// The machine the benchmark ran on.
#[derive(Debug, Clone, Serialize)]
pub struct Machine {
    /// Host name.
    pub hostname: String,
    /// Logical CPUs available to the process.
    pub cores: usize,
    /// Operating system and architecture.
    pub os: String,
}

/// Which model was measured.
#[derive(Debug, Clone, Serialize)]
pub struct ModelInfo {
    /// Model name.
    pub name: String,
    /// The database file.
    pub file: String,
    /// Content hash: the prologue's header and index checksums in hex (the server's id).
    pub database_id: String,
    /// Instances.
    pub instances: usize,
    /// Triangles of all instances at the finest LOD.
    pub triangles: u64,
    /// GPU bytes of every LOD uploaded.
    pub gpu_bytes: u64,
}

/// Which path was replayed.
#[derive(Debug, Clone, Serialize)]
pub struct PathInfo {
    /// Path kind (`tour`, `spin`, ...).
    pub kind: String,
    /// Hash of the path JSON.
    pub hash: String,
    /// Keyframes.
    pub keyframes: usize,
    /// Length in seconds.
    pub duration_s: f32,
}

/// The task parameters (RRB §6.3).
#[derive(Debug, Clone, Serialize)]
pub struct Parameters {
    /// Frame budget, seconds.
    pub budget_s: f64,
    /// Image width and height.
    pub size: (u32, u32),
    /// Frames per run.
    pub frames: u64,
    /// The cap asked for.
    pub max_frames: Option<u64>,
    /// Path time between frames, seconds.
    pub dt_s: f64,
    /// Vertical field of view, degrees.
    pub fov_deg: f32,
    /// Area-of-interest side, pixels.
    pub patch_px: u32,
    /// The intensity formula.
    pub intensity: String,
    /// Critical-vertex selection parameters.
    pub critical: CriticalParams,
    /// How hidden vertices are found.
    pub visibility_test: String,
    /// Runs in order.
    pub runs: Vec<String>,
}

/// The critical vertices of the model and how many each frame saw.
#[derive(Debug, Clone, Serialize)]
pub struct CriticalSummary {
    /// Counts over all instances; `critical` is RRB's `|V|`.
    pub counts: CriticalCounts,
    /// `critical / vertices`.
    pub fraction: f64,
    /// Critical vertices visible per reference frame.
    pub visible_per_frame: Series,
}

/// The Regular-against-itself check.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SelfTest {
    /// Es of Regular against Regular.
    pub es: f64,
    /// Et of Regular against Regular.
    pub et: f64,
    /// PSNR of Regular against Regular (`null` = ∞).
    pub psnr: Option<f64>,
    /// `es == 0 && et == 0 && psnr is ∞`.
    pub passed: bool,
}

/// The whole result (`summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct BenchSummary {
    /// Where it ran.
    pub machine: Machine,
    /// GPU adapter and backend.
    pub adapter: String,
    /// Whether the adapter is a software rasteriser (llvmpipe, lavapipe).
    pub cpu_adapter: bool,
    /// What was measured.
    pub model: ModelInfo,
    /// Along which path.
    pub path: PathInfo,
    /// With which parameters.
    pub parameters: Parameters,
    /// The critical vertices.
    pub critical: CriticalSummary,
    /// The start-up calibrated cost model every budgeted run starts from.
    pub cost_model: CostModel,
    /// Regular against itself.
    pub self_test: SelfTest,
    /// One entry per run, Regular first.
    pub runs: Vec<RunSummary>,
    /// Files written (relative to the output directory).
    pub files: Vec<String>,
    /// Wall-clock seconds of the whole benchmark.
    pub wall_s: f64,
}

/// One frame of one run (a row of `frames.csv`).
#[derive(Debug, Clone, Default, Serialize)]
pub struct FrameRecord {
    /// Frame index.
    pub frame: u64,
    /// Path time, seconds.
    pub t: f64,
    /// Frame time (visibility + elision + render), seconds.
    pub frame_s: f64,
    /// Visibility time.
    pub visibility_s: f64,
    /// Elision time.
    pub elision_s: f64,
    /// Render time.
    pub render_s: f64,
    /// Render time the cost model predicted (elision runs only).
    pub predicted_s: f64,
    /// Objects found visible.
    pub visible_objects: u32,
    /// Objects drawn.
    pub drawn_objects: u32,
    /// Triangles drawn.
    pub triangles: u64,
    /// Critical vertices visible in the reference frame.
    pub critical_visible: u32,
    /// `Es_i`.
    pub es: f64,
    /// `Et_i` (`None` on the first frame).
    pub et: Option<f64>,
    /// PSNR against the reference frame, dB (`None` = identical).
    pub psnr: Option<f64>,
    /// Mean squared error against the reference frame.
    pub mse: f64,
}

/// Regular scored against itself: the RRB sanity check.
pub(super) fn self_test(regular: &RunSummary) -> SelfTest {
    let psnr = regular.psnr_of_mean_mse;
    SelfTest {
        es: regular.es_mean,
        et: regular.et_mean,
        psnr,
        passed: regular.es_mean == 0.0 && regular.et_mean == 0.0 && psnr.is_none(),
    }
}

/// Host name, cores and OS of this machine.
pub(super) fn machine() -> Machine {
    let hostname = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .map(|s| s.trim().to_owned())
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .unwrap_or_else(|| "unknown".to_owned());
    Machine {
        hostname,
        cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        os: format!("{} {}", std::env::consts::OS, std::env::consts::ARCH),
    }
}
