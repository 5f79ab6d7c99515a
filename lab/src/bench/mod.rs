//! `portico bench`: frame rate and image fidelity of the detail elision
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
//! * `none`, `static`, `feedback`, `optimize`: [`portico_client::elision::Elider`] with the frame
//!   budget, fed the measured frame times and the online-corrected, start-up-calibrated cost model
//!   exactly as the walk client does (`portico_native::walk`);
//! * `coarsest` (optional): the coarsest LOD of everything, a lower bound on fidelity;
//! * replays (`--replay drawn/<run>.json`, [`crate::drawn`]): the frames a load test's client
//!   drew with what its cache and link let it have, each LOD, texture level and box as it drew
//!   them, so the PSNR is that of streamed frames.
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
//! 5.2), sd, p50/p95/p99 ([`portico_client::stats::Series`]), frames over budget, polygons
//! drawn, Es and Et (formulas in [`fidelity`]), PSNR against the Regular frame with the same index. Critical
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
//!
//! This file holds the runs, the configuration and [`run`]; the summary's types are in
//! `summary`, and the benchmark in progress (every run's state, the lockstep frames, their
//! scores and each run's summary) in `lockstep`.

pub mod critical;
pub mod depth;
pub mod fidelity;
pub mod plot;
pub mod report;
pub mod scene;

mod lockstep;
mod summary;

pub use summary::{
    BenchSummary, CriticalSummary, FrameRecord, Machine, ModelInfo, Parameters, PathInfo,
    RunSummary, SelfTest,
};

use crate::drawn::{DrawnLog, Expected};
use anyhow::{Context, Result, bail, ensure};
use critical::CriticalParams;
use lockstep::Bench;
use portico_client::elision::Algorithm;
use portico_data::path::CameraPath;
use portico_render::Renderer;
use scene::Scene;
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
    /// The frames a load test's client drew, replayed from [`BenchConfig::replays`]`[i]`
    /// ([`crate::drawn`]): what it had resident, not everything.
    Replay(u16),
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
            RunKind::Replay(_) => "replay",
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
    /// Drawn-frames logs of load test runs ([`crate::drawn::DrawnLog`]) to draw and score as
    /// runs of their own, after the others.
    pub replays: Vec<PathBuf>,
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
            fovy: portico_client::defaults::fov_y(),
            patch_px: fidelity::DEFAULT_PATCH,
            critical: CriticalParams::default(),
            replays: Vec::new(),
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

    /// The runs in order, Regular first and no run twice, then the replays.
    pub fn runs(&self) -> Vec<RunKind> {
        let mut out = vec![RunKind::Regular];
        for k in &self.algorithms {
            if !out.contains(k) && !matches!(k, RunKind::Replay(_)) {
                out.push(*k);
            }
        }
        // `run` refuses more than u16::MAX replays.
        let replays = u16::try_from(self.replays.len()).unwrap_or(u16::MAX);
        out.extend((0..replays).map(RunKind::Replay));
        out
    }
}

/// Runs the benchmark and writes its outputs; `progress(done, total)` is called after every
/// frame (all runs of that frame drawn and scored).
pub fn run(cfg: &BenchConfig, progress: &mut dyn FnMut(u64, u64)) -> Result<BenchSummary> {
    cfg.validate()?;
    let start = Instant::now();
    std::fs::create_dir_all(&cfg.out).with_context(|| format!("creating {}", cfg.out.display()))?;
    ensure!(
        cfg.replays.len() <= usize::from(u16::MAX),
        "at most {} replays",
        u16::MAX
    );
    // Read before the scene loads, so a typo fails at once.
    let logs = cfg
        .replays
        .iter()
        .map(|p| DrawnLog::read(p))
        .collect::<Result<Vec<_>>>()?;
    let mut renderer = Renderer::new(cfg.size.0, cfg.size.1).context("starting the renderer")?;
    let scene = Scene::load(&cfg.db, &renderer, &cfg.critical, !logs.is_empty())?;
    let path_hash = format!("{:016x}", cfg.path.hash());
    let expected = Expected {
        database_id: &scene.database_id,
        path_hash: &path_hash,
        dt_s: cfg.dt_s,
        frames: cfg.frame_count(),
        size: cfg.size,
        fovy_deg: cfg.fovy.to_degrees(),
    };
    for (log, path) in logs.iter().zip(&cfg.replays) {
        log.check(path, &expected)?;
        log.validate(path, &scene.header)?;
    }
    // Funkhouser §4.2.3: C1..C4 from timed sample draws at start-up, as the walk client.
    let cost = portico_render::calibrate(&mut renderer)?;
    let mut bench = Bench::new(cfg, &scene, cost, logs);
    bench.run(&mut renderer, progress)?;
    let mut summary = bench.summarise(&renderer, start.elapsed().as_secs_f64());
    summary.files = report::FILES.iter().map(|f| (*f).to_owned()).collect();
    report::write_all(&cfg.out, &summary, &bench.runs_rows())?;
    Ok(summary)
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
