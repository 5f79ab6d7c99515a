//! `portico loadtest` (DESIGN §7, issue 7): many simulated clients against a real server, to
//! measure a prefetch policy the way Funkhouser §5.2–5.3 measured his (Tables 5.1–5.10,
//! Figures 5.11–5.13), but over a network.
//!
//! Each client is a tokio task playing the real client's frame loop without a GPU
//! ([`sim`]): the same byte-budgeted [`portico_client::cache::ObjectCache`], the same visibility and
//! candidates ([`portico_client::view`]), the same `optimize` elider with the default cost model, frames
//! at the frame budget in real time, and the render never waits: what is not resident is
//! skipped and counted. Clients replay one path, client `i` starting `i/N` of the way along it
//! (wrapping), and talk HTTP to the server (`/v1/prefetch`, `/v1/segments/{id}`) through an
//! emulated link each ([`link`]: round-trip time per request, a token bucket at the link rate).
//!
//! Policies run one after another with fresh clients (empty caches) on the same path and link.
//! Two baselines run in the same session: **demand** fetch (no lookahead: each frame fetch the
//! missing LODs the elider wanted) and an **oracle** that knows the future path (fetches what
//! an omniscient client draws in the next [`ORACLE_LOOKAHEAD_FRAMES`] frames, nearest first).
//!
//! [`run`] writes `summary.json`, `report.md` (tables in Funkhouser's layout, [`report`]),
//! `frames.csv` (client 0's frames per policy) and two PNG plots ([`plot`]).

pub mod cpu;
pub mod link;
pub mod plot;
pub mod report;
pub mod sim;
pub mod stress;
pub mod sweep;
pub mod world;

pub use link::{Link, LinkError};
pub use sweep::{UnknownSweep, grid};

use anyhow::{Context, Result, bail};
use portico_client::stats::Series;
use portico_data::path::CameraPath;
use portico_native::net::Remote;
use portico_protocol::Policy;
use serde::Serialize;
use sim::{ClientResult, FrameStat, Mode};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};
use world::{Plan, World};

/// How many frames ahead the oracle looks (capped at the frames its client has left).
pub const ORACLE_LOOKAHEAD_FRAMES: u64 = 64;
/// Seconds at the start of each client's run counted as warm-up (cold cache) in the `*_warm_*`
/// figures, which leave them out.
pub const WARMUP_S: f64 = 2.0;

/// Everything `portico loadtest` can be told.
#[derive(Debug, Clone)]
pub struct LoadtestConfig {
    /// Server base URL.
    pub server: String,
    /// Bearer token, if the server wants one.
    pub token: Option<String>,
    /// Number of simulated clients.
    pub clients: usize,
    /// The path every client replays (client `i` starts `i/clients` of the way along).
    pub path: CameraPath,
    /// Named prefetch policies to measure, in order (their `cache_bytes`, `frame_time_s` and
    /// `screen` are set from this config).
    pub policies: Vec<(String, Policy)>,
    /// Also run the demand-fetch and oracle baselines.
    pub baselines: bool,
    /// Each client's emulated link.
    pub link: Link,
    /// Each client's cache budget (bytes).
    pub cache_bytes: u64,
    /// Frame budget and frame time (seconds).
    pub budget_s: f64,
    /// Frames each client plays (default: one pass over the path).
    pub max_frames: Option<u64>,
    /// Output directory.
    pub out: PathBuf,
}

impl LoadtestConfig {
    /// Frames in one pass over the path at the frame budget.
    pub fn path_frames(&self) -> usize {
        (self.path.duration() as f64 / self.budget_s.max(1e-3)).ceil() as usize + 1
    }

    /// Frames each client plays.
    pub fn frames(&self) -> u64 {
        self.max_frames.unwrap_or(self.path_frames() as u64)
    }

    /// The static size threshold capping every client's detail (Funkhouser §5.3's setup): the
    /// first policy's, which the server also uses to cap the lookahead.
    pub fn size_threshold_px(&self) -> f32 {
        self.policies
            .first()
            .map_or(Policy::default().size_threshold_px, |(_, p)| {
                p.size_threshold_px
            })
    }

    /// The runs in order: the policies, then the baselines.
    fn runs(&self) -> Vec<(String, Mode)> {
        let mut runs: Vec<(String, Mode)> = self
            .policies
            .iter()
            .map(|(name, p)| {
                let policy = Policy {
                    cache_bytes: self.cache_bytes,
                    frame_time_s: self.budget_s as f32,
                    screen: [world::SCREEN.0, world::SCREEN.1],
                    ..*p
                };
                (name.clone(), Mode::Prefetch(policy))
            })
            .collect();
        if self.baselines {
            runs.push(("demand".into(), Mode::Demand));
            runs.push((
                "oracle".into(),
                Mode::Oracle {
                    lookahead: ORACLE_LOOKAHEAD_FRAMES,
                },
            ));
        }
        runs
    }

    fn check(&self) -> Result<()> {
        self.path
            .validate()
            .map_err(anyhow::Error::msg)
            .context("the load test path")?;
        if self.clients == 0 {
            bail!("--clients must be at least 1");
        }
        if !(self.budget_s.is_finite() && self.budget_s >= 1e-3) {
            bail!(
                "the frame budget must be at least 1 ms, not {} s",
                self.budget_s
            );
        }
        if self.max_frames == Some(0) {
            bail!("--max-frames must be at least 1");
        }
        if self.cache_bytes == 0 {
            bail!("the cache budget must be more than 0 bytes");
        }
        if self.policies.is_empty() && !self.baselines {
            bail!("nothing to run: no policies and no baselines");
        }
        Ok(())
    }
}

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
    /// LODs skipped per frame after each client's first [`WARMUP_S`] seconds (`None` when no
    /// frame is that late), mean.
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
    /// Segment bytes fetched.
    pub bytes_fetched: u64,
    /// Segments fetched.
    pub segments_fetched: u64,
    /// Fetched bytes never drawn (released, left at the end, or fetched twice).
    pub bytes_wasted: u64,
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
}

/// Runs every policy and baseline, writes the outputs into `cfg.out`, and returns the summary.
/// `progress(done, total)` counts client frames. Blocking: builds its own tokio runtime.
pub fn run(cfg: &LoadtestConfig, progress: &mut dyn FnMut(u64, u64)) -> Result<LoadtestSummary> {
    cfg.check()?;
    std::fs::create_dir_all(&cfg.out).with_context(|| format!("creating {}", cfg.out.display()))?;
    let t0 = Instant::now();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name(cpu::THREAD_NAME)
        .build()
        .context("starting the load tester's runtime")?;
    let mut summary = rt.block_on(run_all(cfg, progress))?;
    drop(rt);
    summary.wall_s = t0.elapsed().as_secs_f64();
    write_outputs(cfg, &mut summary)?;
    Ok(summary)
}

async fn run_all(
    cfg: &LoadtestConfig,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<LoadtestSummary> {
    let remote = Remote::new(&cfg.server, cfg.token.clone())?;
    let runs = cfg.runs();
    let plan = Plan {
        dt: cfg.budget_s,
        clients: cfg.clients,
        frames: cfg.frames(),
        lookahead: if cfg.baselines {
            ORACLE_LOOKAHEAD_FRAMES
        } else {
            0
        },
        size_threshold_px: cfg.size_threshold_px(),
    };
    let world = Arc::new(world::load(&remote, &cfg.path, plan).await?);
    let probe = cpu::Probe::new(&cfg.server, cfg.token.clone());
    let total = runs.len() as u64 * cfg.clients as u64 * plan.frames;
    let mut results = Vec::with_capacity(runs.len());
    for (i, (name, mode)) in runs.into_iter().enumerate() {
        let base = i as u64 * cfg.clients as u64 * plan.frames;
        let before = probe.sample().await;
        let t = Instant::now();
        let clients = run_clients(cfg, &world, &remote, mode, &mut |d| {
            progress(base + d, total)
        })
        .await?;
        let wall_s = t.elapsed().as_secs_f64();
        let usage = probe.usage(before, probe.sample().await);
        results.push(aggregate(name, mode, cfg, clients, wall_s, usage));
    }
    compare_with_demand(&mut results);
    progress(total, total);
    Ok(LoadtestSummary {
        machine: Machine {
            hostname: cpu::hostname(),
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        },
        server: cfg.server.clone(),
        model: world.header.name.clone(),
        database_id: world.database_id.clone(),
        path: cfg.path.kind.clone(),
        path_hash: format!("{:016x}", cfg.path.hash()),
        path_frames: world.path_frames(),
        frames_per_client: plan.frames,
        link: cfg.link,
        link_spec: cfg.link.to_string(),
        clients: cfg.clients,
        cache_bytes: cfg.cache_bytes,
        budget_s: cfg.budget_s,
        oracle_lookahead_frames: plan.lookahead,
        size_threshold_px: plan.size_threshold_px,
        server_cpu_source: probe.source().to_string(),
        plot_text: false,
        plots: Vec::new(),
        wall_s: 0.0,
        policies: results,
        visible_mb_client0: visible_mb(&world, plan.frames),
    })
}

/// The "0 frames" curve along client 0's frames (client 0 starts at path frame 0).
fn visible_mb(world: &World, frames: u64) -> Vec<f64> {
    if world.truth.is_empty() {
        return Vec::new();
    }
    (0..frames as usize)
        .map(|f| {
            world.truth[f % world.path_frames()]
                .as_ref()
                .map_or(0.0, |t| t.visible_bytes as f64 / 1e6)
        })
        .collect()
}

/// Plays one policy: every client from an empty cache, all at once, until each has played its
/// frames.
async fn run_clients(
    cfg: &LoadtestConfig,
    world: &Arc<World>,
    remote: &Remote,
    mode: Mode,
    progress: &mut dyn FnMut(u64),
) -> Result<Vec<ClientResult>> {
    let done = Arc::new(AtomicU64::new(0));
    let offsets = world::offsets(cfg.clients, world.path_frames());
    let mut handles = Vec::with_capacity(cfg.clients);
    for offset in offsets {
        let setup = sim::Setup {
            world: world.clone(),
            // A connection pool of its own per client, as separate machines would have.
            remote: Remote::new(remote.base(), cfg.token.clone())?,
            pipe: Arc::new(link::Pipe::new(cfg.link)),
            mode,
            offset,
            frames: cfg.frames(),
            cache_bytes: cfg.cache_bytes,
            done: done.clone(),
        };
        handles.push(tokio::spawn(sim::client(setup)));
    }
    let mut all = Box::pin(futures_util::future::join_all(handles));
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    let joined = loop {
        tokio::select! {
            j = &mut all => break j,
            _ = tick.tick() => progress(done.load(Ordering::Relaxed)),
        }
    };
    progress(done.load(Ordering::Relaxed));
    joined
        .into_iter()
        .map(|r| r.context("a simulated client panicked"))
        .collect()
}

/// One policy's figures from its clients' results.
fn aggregate(
    name: String,
    mode: Mode,
    cfg: &LoadtestConfig,
    clients: Vec<ClientResult>,
    wall_s: f64,
    usage: cpu::Usage,
) -> PolicyResult {
    let rows: Vec<&FrameStat> = clients.iter().flat_map(|c| &c.rows).collect();
    let col =
        |f: &dyn Fn(&FrameStat) -> f64| Series::of(&rows.iter().map(|r| f(r)).collect::<Vec<_>>());
    let answers: Vec<_> = clients.iter().flat_map(|c| &c.answers).collect();
    let acol = |f: &dyn Fn(&sim::AnswerStat) -> f64| {
        Series::of(&answers.iter().map(|a| f(a)).collect::<Vec<_>>())
    };
    let latencies: Vec<f64> = clients
        .iter()
        .flat_map(|c| c.latencies.iter().copied())
        .collect();
    let lat = Series::of(&latencies);
    let sum = |f: &dyn Fn(&ClientResult) -> u64| clients.iter().map(f).sum::<u64>();
    let wanted: u64 = rows.iter().map(|r| r.wanted as u64).sum();
    let hits: u64 = rows.iter().map(|r| r.hits as u64).sum();
    let (lods, objects, deficit) = (
        col(&|r| r.lods_skipped as f64),
        col(&|r| r.objects_skipped as f64),
        col(&|r| r.lod_deficit as f64),
    );
    let lookahead = col(&|r| r.lookahead_bytes as f64 / 1e6);
    let (range, look, answer_ms) = (
        acol(&|a| a.range_cells as f64),
        acol(&|a| a.lookahead_objects as f64),
        acol(&|a| a.micros as f64 / 1e3),
    );
    let wall = wall_s.max(1e-9);
    let warmup = (WARMUP_S / cfg.budget_s).ceil() as usize;
    let warm: Vec<&FrameStat> = clients
        .iter()
        .flat_map(|c| c.rows.iter().skip(warmup))
        .collect();
    let warm_mean = |f: &dyn Fn(&FrameStat) -> u32| {
        (!warm.is_empty())
            .then(|| warm.iter().map(|r| f(r) as f64).sum::<f64>() / warm.len() as f64)
    };
    let complete: Vec<(u64, u64)> = clients.iter().filter_map(|c| c.first_complete).collect();
    let mean_of = |f: &dyn Fn(&(u64, u64)) -> u64| {
        (!complete.is_empty())
            .then(|| complete.iter().map(|c| f(c) as f64).sum::<f64>() / complete.len() as f64)
    };
    PolicyResult {
        complete_clients: complete.len() as u64,
        first_complete_frame_mean: mean_of(&|c| c.0),
        first_complete_bytes_mean: mean_of(&|c| c.1),
        kind: match mode {
            Mode::Prefetch(_) => "prefetch",
            Mode::Demand => "demand",
            Mode::Oracle { .. } => "oracle",
        }
        .into(),
        policy: match mode {
            Mode::Prefetch(p) => Some(p),
            _ => None,
        },
        name,
        frames: rows.len() as u64,
        lods_skipped_mean: lods.mean,
        lods_skipped_max: lods.max,
        objects_skipped_mean: objects.mean,
        objects_skipped_max: objects.max,
        lod_deficit_mean: deficit.mean,
        lod_deficit_max: deficit.max,
        lods_skipped_warm_mean: warm_mean(&|r| r.lods_skipped),
        objects_skipped_warm_mean: warm_mean(&|r| r.objects_skipped),
        lod_deficit_warm_mean: warm_mean(&|r| r.lod_deficit),
        visible_objects_mean: col(&|r| r.visible_objects as f64).mean,
        fallback_frames: rows.iter().filter(|r| r.fallback).count() as u64,
        outside_frames: rows.iter().filter(|r| r.outside).count() as u64,
        bytes_fetched: sum(&|c| c.bytes_fetched),
        segments_fetched: sum(&|c| c.segments_fetched),
        bytes_wasted: sum(&|c| c.bytes_wasted),
        cache_hit_rate: if wanted == 0 {
            1.0
        } else {
            hits as f64 / wanted as f64
        },
        latency_p50_s: lat.p50,
        latency_p95_s: lat.p95,
        latency_p99_s: lat.p99,
        latency_mean_s: lat.mean,
        prefetch_requests: answers.len() as u64,
        prefetch_rps: answers.len() as f64 / wall,
        segment_rps: sum(&|c| c.segments_fetched) as f64 / wall,
        lookahead_mb_mean: lookahead.mean,
        lookahead_mb_max: lookahead.max,
        range_cells_mean: range.mean,
        range_cells_max: range.max,
        lookahead_objects_mean: look.mean,
        lookahead_objects_max: look.max,
        answer_ms_mean: answer_ms.mean,
        answer_ms_max: answer_ms.max,
        server_cpu_s: usage.server_s,
        server_cpu_cores: usage.server_s.map(|s| s / wall),
        server_handler_s: usage.handler_s,
        cache_budget_bytes: cfg.cache_bytes,
        cache_peak_bytes: clients.iter().map(|c| c.cache_peak).max().unwrap_or(0),
        evictions: sum(&|c| c.evictions),
        io_failures: sum(&|c| c.failures),
        wall_s,
        frame_period_s: wall_s / cfg.frames().max(1) as f64,
        lods_skipped_vs_demand: None,
        lod_deficit_vs_demand: None,
        lods_skipped_warm_vs_demand: None,
        per_client: clients.iter().map(client_figures).collect(),
        client0: clients.first().map(|c| c.rows.clone()).unwrap_or_default(),
    }
}

fn client_figures(c: &ClientResult) -> ClientFigures {
    let mean = |f: &dyn Fn(&FrameStat) -> u32| {
        c.rows.iter().map(|r| f(r) as f64).sum::<f64>() / c.rows.len().max(1) as f64
    };
    ClientFigures {
        start_frame: c.rows.first().map_or(0, |r| r.path_frame),
        lods_skipped_mean: mean(&|r| r.lods_skipped),
        objects_skipped_mean: mean(&|r| r.objects_skipped),
        lod_deficit_mean: mean(&|r| r.lod_deficit),
        fallback_frames: c.rows.iter().filter(|r| r.fallback).count() as u64,
        bytes_fetched: c.bytes_fetched,
        io_failures: c.failures,
    }
}

/// Fills in every run's ratio to demand fetch (how many times fewer LODs it skipped).
fn compare_with_demand(results: &mut [PolicyResult]) {
    let Some(d) = results.iter().find(|r| r.kind == "demand") else {
        return;
    };
    let (lods, deficit, warm) = (
        d.lods_skipped_mean,
        d.lod_deficit_mean,
        d.lods_skipped_warm_mean,
    );
    let ratio = |base: f64, x: f64| (x > 0.0).then(|| base / x);
    for r in results.iter_mut() {
        r.lods_skipped_vs_demand = ratio(lods, r.lods_skipped_mean);
        r.lod_deficit_vs_demand = ratio(deficit, r.lod_deficit_mean);
        r.lods_skipped_warm_vs_demand = warm
            .zip(r.lods_skipped_warm_mean)
            .and_then(|(base, x)| ratio(base, x));
    }
}

/// `summary.json`, `report.md`, `frames.csv` and the plots.
fn write_outputs(cfg: &LoadtestConfig, summary: &mut LoadtestSummary) -> Result<()> {
    let plots = plot::write_all(&cfg.out, summary)?;
    summary.plot_text = plots.text;
    summary.plots = plots.files;
    let csv = cfg.out.join("frames.csv");
    std::fs::write(&csv, report::frames_csv(summary))
        .with_context(|| format!("writing {}", csv.display()))?;
    let md = cfg.out.join("report.md");
    std::fs::write(&md, report::markdown(summary))
        .with_context(|| format!("writing {}", md.display()))?;
    let json = cfg.out.join("summary.json");
    std::fs::write(&json, serde_json::to_vec_pretty(summary)?)
        .with_context(|| format!("writing {}", json.display()))?;
    Ok(())
}
