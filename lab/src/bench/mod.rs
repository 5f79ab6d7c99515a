//! `portico bench` (issue 7, DESIGN §7): frame rate and image fidelity of the detail elision
//! algorithms on one model and one path, measured as Funkhouser measured them (§4.2.4, Table 4.3
//! and Fig. 4.22: frame time per observer viewpoint for no elision, static, feedback and
//! optimisation) and scored as the RRB framework scores multi-resolution rendering (Yuan 2001,
//! §5.2 frame-rate measures, §5.3 spatial and temporal image fidelity Es and Et at critical
//! vertices).
//!
//! ## What runs
//!
//! The model is opened locally ([`portico_data::Database::open`]) and **everything is resident**:
//! every LOD of every instance is uploaded once, every stab list decoded, so no run ever skips
//! a LOD for want of data. Each run replays the **same frame-indexed path** (RRB §5.3.2: frame
//! `i` of every run shows the viewpoint at path time `i·dt`, whatever the frame took):
//!
//! * `regular`: RRB's baseline and the fidelity reference: the finest LOD of every visible
//!   object, no budget, no elision work;
//! * `none`, `static`, `feedback`, `optimize`: [`portico_client::elision::Elider`] with the frame budget,
//!   fed the measured frame times and the online-corrected, start-up-calibrated cost model
//!   exactly as the walk client does (`portico_native::walk`);
//! * `coarsest` (optional): the coarsest LOD of everything, a lower bound on fidelity.
//!
//! The runs advance in **lockstep**: for each frame the Regular frame is drawn first, then every
//! other run draws the same frame, so all runs see the same machine state and a frame's
//! reference is at hand (no stored image sequences). Each run keeps its own elider, cost
//! correction and last frame time.
//!
//! A frame's **time** is measured as RRB's "trap" bracket (§5.2) and Funkhouser's frame time:
//! visibility (eye-to-cell/eye-to-object with the stab lists, §4.1.2) + detail elision + render
//! until the GPU has finished (`Renderer::render` waits). Reading the frame back and scoring it
//! are outside the bracket.
//!
//! ## Measures
//!
//! Per run (see [`RunSummary`]): frame time mean, min, max, mean absolute deviation (RRB eq.
//! 5.2), sd, p50/p95/p99 ([`portico_client::stats::Series`]), frames over budget, polygons drawn, Es and
//! Et (formulas in [`fidelity`]), PSNR against the Regular frame with the same index. Critical
//! vertices are chosen per geometry segment once ([`critical`]), transformed by each instance,
//! and tested for visibility against a CPU depth buffer of the reference frame ([`depth`]).
//!
//! **Self-test** (RRB §5.2, notes §6 item 3): the Regular sequence scored against itself through
//! the same code must give Es = Et = 0 and PSNR = ∞; the report prints the line and
//! [`BenchSummary::self_test`] records it.
//!
//! Output in [`BenchConfig::out`]: `summary.json` ([`BenchSummary`]), `report.md` (a table in
//! the layout of Funkhouser Table 4.3 plus the RRB columns), `frames.csv` (one row per run and
//! frame), `frame_time.png` (Fig. 4.22) and `fidelity.png` (Es and Et per frame).

pub mod critical;
pub mod depth;
pub mod fidelity;
pub mod plot;
pub mod report;
pub mod scene;

use anyhow::{Context, Result, bail, ensure};
use critical::{CriticalCounts, CriticalParams};
use depth::DepthBuffer;
use fidelity::{FidelityAccumulator, RefPoint};
use glam::Mat4;
use image::RgbaImage;
use portico_client::cluster::Stand;
use portico_client::cost::{CostModel, OnlineCost};
use portico_client::elision::Algorithm;
use portico_client::frame::Decider;
use portico_client::stats::Series;
use portico_client::view::{self, NEAR};
use portico_data::path::CameraPath;
use portico_render::GpuImpostor;
use portico_render::{Draw, Renderer};
use scene::Scene;
use serde::Serialize;
use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Instant;

/// One run of the benchmark: what decides the LODs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RunKind {
    /// The reference: finest LOD of every visible object, no budget (RRB's Regular).
    Regular,
    /// A detail elision algorithm with the frame budget.
    Elision(Algorithm),
    /// The coarsest LOD of every visible object (a fidelity lower bound).
    Coarsest,
    /// Maciel's cluster traversal with the frame budget: far clusters as textured or
    /// average-colour boxes, the rest as objects ([`portico_client::cluster`]).
    Impostors,
}

impl RunKind {
    /// Regular plus Funkhouser's four algorithms, in the order of Table 4.3.
    pub const DEFAULT: [RunKind; 5] = [
        RunKind::Regular,
        RunKind::Elision(Algorithm::None),
        RunKind::Elision(Algorithm::Static),
        RunKind::Elision(Algorithm::Feedback),
        RunKind::Elision(Algorithm::Optimize),
    ];

    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            RunKind::Regular => "regular",
            RunKind::Elision(a) => a.name(),
            RunKind::Coarsest => "coarsest",
            RunKind::Impostors => "impostors",
        }
    }

    /// Parses a comma-separated list such as `regular,none,static,feedback,optimize`.
    pub fn parse_list(s: &str) -> Result<Vec<RunKind>, ParseRunError> {
        s.split(',')
            .filter(|p| !p.trim().is_empty())
            .map(str::parse)
            .collect()
    }
}

impl fmt::Display for RunKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An unknown run name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown run `{0}` (expected regular, none, static, feedback, optimize, impostors or coarsest)"
)]
pub struct ParseRunError(pub String);

impl FromStr for RunKind {
    type Err = ParseRunError;

    /// `regular`, `coarsest`, or an elision algorithm name (case-insensitive).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "regular" => Ok(RunKind::Regular),
            "coarsest" => Ok(RunKind::Coarsest),
            "impostors" => Ok(RunKind::Impostors),
            other => other
                .parse::<Algorithm>()
                .map(RunKind::Elision)
                .map_err(|_| ParseRunError(s.trim().to_owned())),
        }
    }
}

/// Everything `portico bench` can be told.
#[derive(Debug, Clone)]
pub struct BenchConfig {
    /// The display database (`.portico`).
    pub db: PathBuf,
    /// The path every run replays.
    pub path: CameraPath,
    /// Frame-time budget of the elision algorithms, in seconds.
    pub budget_s: f64,
    /// Image size in pixels.
    pub size: (u32, u32),
    /// Stop after this many frames.
    pub max_frames: Option<u64>,
    /// The runs; `regular` is always run first (it is the reference) even if not listed.
    pub algorithms: Vec<RunKind>,
    /// Output directory.
    pub out: PathBuf,
    /// Path time between frames, in seconds (frame `i` shows the path at `i·dt_s`).
    pub dt_s: f64,
    /// Vertical field of view, radians.
    pub fovy: f32,
    /// Side of the square area of interest around each critical vertex, 1–10 px.
    pub patch_px: u32,
    /// Critical-vertex selection.
    pub critical: CriticalParams,
}

impl BenchConfig {
    /// A configuration with the defaults: 320×240, all frames, regular + the four algorithms,
    /// `dt` = 50 ms, 60° field of view, 5-px areas of interest.
    pub fn new(db: PathBuf, path: CameraPath, budget_s: f64, out: PathBuf) -> Self {
        BenchConfig {
            db,
            path,
            budget_s,
            size: (320, 240),
            max_frames: None,
            algorithms: RunKind::DEFAULT.to_vec(),
            out,
            dt_s: 0.05,
            fovy: 60f32.to_radians(),
            patch_px: fidelity::DEFAULT_PATCH,
            critical: CriticalParams::default(),
        }
    }

    /// Checks the numbers before anything expensive starts.
    fn validate(&self) -> Result<()> {
        self.path
            .validate()
            .map_err(anyhow::Error::msg)
            .context("the benchmark path")?;
        ensure!(
            self.budget_s.is_finite() && self.budget_s > 0.0,
            "the frame budget must be a positive number of seconds, not {}",
            self.budget_s
        );
        ensure!(
            self.dt_s.is_finite() && self.dt_s > 0.0,
            "the frame step dt must be positive, not {}",
            self.dt_s
        );
        ensure!(
            self.size.0 > 0 && self.size.1 > 0,
            "the image size must not be zero"
        );
        ensure!(
            (1..=fidelity::MAX_PATCH).contains(&self.patch_px),
            "the area of interest must be 1 to 10 pixels wide (RRB §5.3.4), not {}",
            self.patch_px
        );
        ensure!(
            self.fovy.is_finite() && self.fovy > 0.0 && self.fovy < std::f32::consts::PI,
            "the field of view must be between 0 and 180 degrees"
        );
        if self.max_frames == Some(0) {
            bail!("--max-frames 0 leaves nothing to measure");
        }
        Ok(())
    }

    /// Number of frames: the whole path at `dt`, capped by `max_frames`.
    pub fn frame_count(&self) -> u64 {
        let n = (f64::from(self.path.duration()) / self.dt_s).floor() as u64 + 1;
        n.min(self.max_frames.unwrap_or(u64::MAX))
    }

    /// The runs in order, Regular first and no run twice.
    pub fn runs(&self) -> Vec<RunKind> {
        let mut out = vec![RunKind::Regular];
        for k in &self.algorithms {
            if !out.contains(k) {
                out.push(*k);
            }
        }
        out
    }
}

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

/// Runs the benchmark and writes its outputs; `progress(done, total)` is called after every
/// frame (all runs of that frame drawn and scored).
pub fn run(cfg: &BenchConfig, progress: &mut dyn FnMut(u64, u64)) -> Result<BenchSummary> {
    cfg.validate()?;
    let start = Instant::now();
    std::fs::create_dir_all(&cfg.out).with_context(|| format!("creating {}", cfg.out.display()))?;
    let mut renderer = Renderer::new(cfg.size.0, cfg.size.1).context("starting the renderer")?;
    let scene = Scene::load(&cfg.db, &renderer, &cfg.critical)?;
    // Funkhouser §4.2.3: C1, C2, C3 from timed sample draws at start-up, as the walk client.
    let cost = portico_render::calibrate(&mut renderer)?;
    let mut bench = Bench::new(cfg, &scene, cost);
    bench.run(&mut renderer, progress)?;
    let mut summary = bench.summarise(&renderer, start.elapsed().as_secs_f64());
    summary.files = report::FILES.iter().map(|f| (*f).to_owned()).collect();
    report::write_all(&cfg.out, &summary, &bench.runs_rows())?;
    Ok(summary)
}

/// A run's choice for one frame: `(instance, lod)` pairs to draw, clusters drawn as boxes, and
/// the predicted render time.
/// Where frame `i` is seen from.
struct FrameView {
    frame: u64,
    t: f64,
    view: view::Viewpoint,
}

/// One run's state across frames.
struct Run {
    kind: RunKind,
    decider: Decider,
    online: OnlineCost,
    last_frame_s: Option<f64>,
    fidelity: FidelityAccumulator,
    rows: Vec<FrameRecord>,
}

impl RunKind {
    /// The frame decision's algorithm for this run: Regular is every object at its finest LOD
    /// with everything resident (`none`), the reference the others are scored against.
    fn algorithm(self) -> Algorithm {
        match self {
            RunKind::Regular => Algorithm::None,
            RunKind::Coarsest => Algorithm::Coarsest,
            RunKind::Impostors => Algorithm::Impostors,
            RunKind::Elision(a) => a,
        }
    }

    /// Whether the run's choice depends on the frame budget (and learns from its frame times).
    fn budgeted(self) -> bool {
        matches!(self, RunKind::Elision(_) | RunKind::Impostors)
    }
}

/// Everything in the benchmark is resident: its runs differ in what they choose, not in what
/// they have.
struct Everything<'a>(&'a Scene);

impl portico_client::frame::Resident for Everything<'_> {
    fn has(&self, _: u32) -> bool {
        true
    }

    fn stab(&self, cell: u32) -> Option<std::sync::Arc<portico_data::cells::StabList>> {
        self.0.stabs.get(cell as usize).cloned().flatten()
    }
}

/// The benchmark in progress.
struct Bench<'a> {
    cfg: &'a BenchConfig,
    scene: &'a Scene,
    cost: CostModel,
    runs: Vec<Run>,
    depth: DepthBuffer,
}

impl<'a> Bench<'a> {
    fn new(cfg: &'a BenchConfig, scene: &'a Scene, cost: CostModel) -> Self {
        let runs = cfg
            .runs()
            .into_iter()
            .map(|kind| Run {
                kind,
                decider: Decider::new(kind.algorithm(), cfg.budget_s, None),
                online: OnlineCost::default(),
                last_frame_s: None,
                fidelity: FidelityAccumulator::new(cfg.patch_px),
                rows: Vec::new(),
            })
            .collect();
        Bench {
            cfg,
            scene,
            cost,
            runs,
            depth: DepthBuffer::new(cfg.size.0, cfg.size.1, NEAR),
        }
    }

    /// All frames of all runs, in lockstep.
    fn run(&mut self, r: &mut Renderer, progress: &mut dyn FnMut(u64, u64)) -> Result<()> {
        let total = self.cfg.frame_count();
        self.warm_up(r)?;
        for frame in 0..total {
            let view = self.view_at(frame);
            let mut reference: Option<(RgbaImage, Vec<RefPoint>)> = None;
            for k in 0..self.runs.len() {
                let (mut row, drawn) = self.draw(r, k, &view)?;
                let img = r.read_pixels().context("reading the frame back")?;
                if k == 0 {
                    let points = self.reference_points(&drawn, &view, &img);
                    reference = Some((img.clone(), points));
                }
                let Some((ref_img, points)) = reference.as_ref() else {
                    bail!("the regular run must come first");
                };
                self.score(k, &mut row, ref_img, points, &img);
                self.runs[k].rows.push(row);
            }
            progress(frame + 1, total);
        }
        Ok(())
    }

    /// One untimed Regular frame, so that first-use costs (shader compilation, buffer growth)
    /// do not land in frame 0 of the first run.
    fn warm_up(&mut self, r: &mut Renderer) -> Result<()> {
        let view = self.view_at(0);
        let d = Decider::new(Algorithm::None, self.cfg.budget_s, None).decide(
            &self.scene.frame_scene(),
            &view.view,
            &Everything(self.scene),
            &self.cost,
            None,
        );
        let drawn: Vec<(u32, usize)> = d.drawn.iter().map(|o| (o.instance, o.lod)).collect();
        let draws = self.draws(&drawn);
        r.render(&view.view.camera, &draws)?;
        Ok(())
    }

    fn view_at(&self, frame: u64) -> FrameView {
        let t = frame as f64 * self.cfg.dt_s;
        let (eye, dir) = self.cfg.path.sample(t as f32);
        FrameView {
            frame,
            t,
            view: view::Viewpoint::new(eye, dir, self.cfg.fovy, self.cfg.size, self.scene.far()),
        }
    }

    /// The frame decision ([`portico_client::frame`]) and render of run `k`'s frame; returns its record
    /// and the drawn `(instance, lod)` pairs sorted by instance.
    fn draw(
        &mut self,
        r: &mut Renderer,
        k: usize,
        v: &FrameView,
    ) -> Result<(FrameRecord, Vec<(u32, usize)>)> {
        let t0 = Instant::now();
        let run = &mut self.runs[k];
        let cost = run.online.apply(&self.cost);
        let d = run.decider.decide(
            &self.scene.frame_scene(),
            &v.view,
            &Everything(self.scene),
            &cost,
            run.last_frame_s,
        );
        let mut drawn: Vec<(u32, usize)> = d.drawn.iter().map(|o| (o.instance, o.lod)).collect();
        drawn.sort_unstable();
        let mut draws = self.draws(&drawn);
        let textured = self.boxes(&d.boxes, &mut draws);
        let timing = r.render_with_boxes(&v.view.camera, &draws, &textured)?;
        let frame_s = t0.elapsed().as_secs_f64();
        let run = &mut self.runs[k];
        run.last_frame_s = Some(frame_s);
        if run.kind.budgeted() {
            run.online.observe(d.frame.predicted_s, timing.total_s);
        }
        let row = FrameRecord {
            frame: v.frame,
            t: v.t,
            frame_s,
            visibility_s: d.visibility_s,
            elision_s: d.elision_s,
            render_s: timing.total_s,
            predicted_s: d.frame.predicted_s,
            visible_objects: d.visible.objects.len() as u32,
            drawn_objects: timing.draws,
            triangles: timing.triangles,
            ..FrameRecord::default()
        };
        Ok((row, drawn))
    }

    /// Adds the average-colour boxes to `draws`; returns the textured boxes.
    fn boxes(&self, boxes: &[(u32, Stand)], draws: &mut Vec<Draw<'a>>) -> Vec<&'a GpuImpostor> {
        let scene = self.scene;
        let mut textured = Vec::new();
        for &(n, stand) in boxes {
            match (stand, scene.textured.get(&n)) {
                (Stand::Textured, Some(t)) => textured.push(t),
                _ => {
                    if let Some(mesh) = scene.colour_boxes.get(n as usize) {
                        draws.push(Draw {
                            mesh,
                            transform: Mat4::IDENTITY,
                            color: [1.0; 4],
                        });
                    }
                }
            }
        }
        textured
    }

    fn draws(&self, drawn: &[(u32, usize)]) -> Vec<Draw<'a>> {
        let scene = self.scene;
        drawn
            .iter()
            .filter_map(|&(o, l)| {
                let mesh = scene.meshes.get(&scene.segment(o, l)?)?;
                Some(Draw {
                    mesh,
                    transform: scene.transforms[o as usize],
                    color: scene.colours[o as usize],
                })
            })
            .collect()
    }

    /// The critical vertices visible in the reference frame, with their intensities `I0`.
    fn reference_points(
        &mut self,
        drawn: &[(u32, usize)],
        v: &FrameView,
        img: &RgbaImage,
    ) -> Vec<RefPoint> {
        let scene = self.scene;
        let vp = v.view.view_proj;
        self.depth.clear();
        let finest = |o: u32| scene.finest_segment(o);
        for &(o, _) in drawn {
            if let Some(mesh) = finest(o).and_then(|s| scene.cpu.get(&s)) {
                let mvp = vp * scene.transforms[o as usize];
                self.depth.draw_mesh(&mvp, &mesh.positions, &mesh.indices);
            }
        }
        let mut visible = Vec::new();
        for &(o, _) in drawn {
            let Some(set) = finest(o).and_then(|s| scene.critical.get(&s)) else {
                continue;
            };
            let mvp: Mat4 = vp * scene.transforms[o as usize];
            let base = scene.cv_base[o as usize];
            for (j, cv) in set.vertices.iter().enumerate() {
                if let Some((x, y)) = self.depth.visible_pixel(mvp * cv.position.extend(1.0)) {
                    visible.push((base + j as u32, x, y));
                }
            }
        }
        fidelity::reference_points(img, &visible, self.cfg.patch_px)
    }

    /// Es, Et and PSNR of run `k`'s frame against the reference frame.
    fn score(
        &mut self,
        k: usize,
        row: &mut FrameRecord,
        ref_img: &RgbaImage,
        points: &[RefPoint],
        img: &RgbaImage,
    ) {
        let f = self.runs[k].fidelity.frame(points, img);
        row.critical_visible = points.len() as u32;
        row.es = f.es;
        row.et = f.et;
        row.mse = fidelity::mse(ref_img, img);
        row.psnr = fidelity::psnr_of_mse(row.mse);
    }

    fn runs_rows(&self) -> Vec<(String, &[FrameRecord])> {
        self.runs
            .iter()
            .map(|r| (r.kind.name().to_owned(), r.rows.as_slice()))
            .collect()
    }

    fn summarise(&self, r: &Renderer, wall_s: f64) -> BenchSummary {
        let cfg = self.cfg;
        let scene = self.scene;
        let regular_polys = self
            .runs
            .first()
            .map_or(0.0, |r| mean_of(&r.rows, |x| x.triangles as f64));
        let runs: Vec<RunSummary> = self
            .runs
            .iter()
            .map(|run| summarise_run(run, cfg.budget_s, regular_polys, scene.cv_counts.critical))
            .collect();
        let self_test = self_test(&runs[0]);
        let visible = self.runs.first().map_or(Vec::new(), |r| {
            r.rows
                .iter()
                .map(|x| f64::from(x.critical_visible))
                .collect()
        });
        let counts = scene.cv_counts;
        BenchSummary {
            machine: machine(),
            adapter: r.adapter_info(),
            cpu_adapter: r.is_cpu_adapter(),
            model: ModelInfo {
                name: scene.header.name.clone(),
                file: cfg.db.display().to_string(),
                database_id: scene.database_id.clone(),
                instances: scene.header.instances.len(),
                triangles: scene.model_triangles,
                gpu_bytes: scene.gpu_bytes,
            },
            path: PathInfo {
                kind: cfg.path.kind.clone(),
                hash: format!("{:016x}", cfg.path.hash()),
                keyframes: cfg.path.keyframes.len(),
                duration_s: cfg.path.duration(),
            },
            parameters: Parameters {
                budget_s: cfg.budget_s,
                size: cfg.size,
                frames: cfg.frame_count(),
                max_frames: cfg.max_frames,
                dt_s: cfg.dt_s,
                fov_deg: cfg.fovy.to_degrees(),
                patch_px: cfg.patch_px,
                intensity: fidelity::INTENSITY_FORMULA.to_owned(),
                critical: cfg.critical,
                visibility_test: "CPU depth buffer of the Regular frame (farthest of 3x3 nearest \
                                  surfaces, +1% +1 cm)"
                    .to_owned(),
                runs: cfg.runs().iter().map(|k| k.name().to_owned()).collect(),
            },
            critical: CriticalSummary {
                counts,
                fraction: counts.critical as f64 / counts.vertices.max(1) as f64,
                visible_per_frame: Series::of(&visible),
            },
            cost_model: self.cost,
            self_test,
            runs,
            files: Vec::new(),
            wall_s,
        }
    }
}

fn mean_of(rows: &[FrameRecord], f: impl Fn(&FrameRecord) -> f64) -> f64 {
    if rows.is_empty() {
        0.0
    } else {
        rows.iter().map(f).sum::<f64>() / rows.len() as f64
    }
}

fn series_of(rows: &[FrameRecord], f: impl Fn(&FrameRecord) -> f64) -> Series {
    Series::of(&rows.iter().map(f).collect::<Vec<_>>())
}

/// Summarises one run's frames.
fn summarise_run(run: &Run, budget_s: f64, regular_polys: f64, total_critical: u64) -> RunSummary {
    let rows = &run.rows;
    let fid = run.fidelity.finish(total_critical);
    let psnrs: Vec<f64> = rows.iter().filter_map(|x| x.psnr).collect();
    let polygons = series_of(rows, |x| x.triangles as f64);
    RunSummary {
        name: run.kind.name().to_owned(),
        budget: budget_s,
        budgeted: matches!(run.kind, RunKind::Elision(_) | RunKind::Impostors),
        frames: rows.len() as u64,
        frame_time: series_of(rows, |x| x.frame_s),
        render_time: series_of(rows, |x| x.render_s),
        elision_time: series_of(rows, |x| x.elision_s),
        frames_over_budget: rows.iter().filter(|x| x.frame_s > budget_s).count() as u64,
        polygons_mean: polygons.mean,
        polygons,
        polygons_vs_regular: if regular_polys > 0.0 {
            polygons.mean / regular_polys
        } else {
            0.0
        },
        es_mean: fid.es,
        es_max: rows.iter().map(|x| x.es).fold(0.0, f64::max),
        et_mean: fid.et,
        et_max: rows.iter().filter_map(|x| x.et).fold(0.0, f64::max),
        es_rrb: fid.es_rrb,
        et_rrb: fid.et_rrb,
        psnr_mean: (!psnrs.is_empty()).then(|| psnrs.iter().sum::<f64>() / psnrs.len() as f64),
        psnr_min: psnrs.iter().copied().reduce(f64::min),
        psnr_of_mean_mse: fidelity::psnr_of_mse(mean_of(rows, |x| x.mse)),
        identical_frames: (rows.len() - psnrs.len()) as u64,
    }
}

/// Regular scored against itself: the RRB sanity check.
fn self_test(regular: &RunSummary) -> SelfTest {
    let psnr = regular.psnr_of_mean_mse;
    SelfTest {
        es: regular.es_mean,
        et: regular.et_mean,
        psnr,
        passed: regular.es_mean == 0.0 && regular.et_mean == 0.0 && psnr.is_none(),
    }
}

/// Host name, cores and OS of this machine.
fn machine() -> Machine {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_lists_parse_and_regular_always_comes_first() {
        let list = RunKind::parse_list("optimize, static,coarsest,").unwrap();
        assert_eq!(
            list,
            [
                RunKind::Elision(Algorithm::Optimize),
                RunKind::Elision(Algorithm::Static),
                RunKind::Coarsest
            ]
        );
        assert!(
            RunKind::parse_list("none,fast")
                .unwrap_err()
                .to_string()
                .contains("`fast`")
        );
        let path = CameraPath {
            kind: "test".into(),
            keyframes: vec![
                portico_data::path::Keyframe {
                    t: 0.0,
                    eye: [0.0; 3],
                    dir: [0.0, 0.0, -1.0],
                },
                portico_data::path::Keyframe {
                    t: 1.0,
                    eye: [1.0, 0.0, 0.0],
                    dir: [0.0, 0.0, -1.0],
                },
            ],
        };
        let mut cfg = BenchConfig::new("x.portico".into(), path, 0.05, "out".into());
        cfg.algorithms = list;
        let runs = cfg.runs();
        assert_eq!(runs[0], RunKind::Regular);
        assert_eq!(runs.len(), 4);
        assert_eq!(cfg.frame_count(), 21, "1 s at 50 ms, both ends");
        cfg.max_frames = Some(5);
        assert_eq!(cfg.frame_count(), 5);
        assert!(cfg.validate().is_ok());
        cfg.patch_px = 11;
        assert!(cfg.validate().unwrap_err().to_string().contains("1 to 10"));
        cfg.patch_px = 5;
        cfg.budget_s = 0.0;
        assert!(cfg.validate().is_err());
    }
}
