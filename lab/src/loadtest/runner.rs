//! The load test's session: loads the shared world once, then plays each policy and baseline
//! with fresh clients, all at once, sampling the server's CPU around each run.

use super::aggregate::{aggregate, compare_with_demand};
use super::sim::{ClientResult, Mode};
use super::world::{Plan, World};
use super::{LoadtestConfig, LoadtestSummary, Machine, ORACLE_LOOKAHEAD_FRAMES};
use super::{cpu, link, sim, world};
use crate::drawn::DrawnLog;
use anyhow::{Context, Result};
use portico_native::net::Remote;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// Frames of the unmeasured warm-up pass before the runs.
const WARMUP_FRAMES: u64 = 20;

pub(super) async fn run_all(
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
        texels: cfg.texels(),
    };
    let world = Arc::new(world::load(&remote, &cfg.path, plan).await?);
    // Last session's drawn frames would pass for this one's.
    let drawn = cfg.out.join("drawn");
    if drawn.exists() {
        std::fs::remove_dir_all(&drawn).with_context(|| format!("clearing {}", drawn.display()))?;
    }
    let probe = cpu::Probe::new(&cfg.server, cfg.token.clone());
    let total = runs.len() as u64 * cfg.clients as u64 * plan.frames;
    // The server's own cold start (the file's pages, stab lists decoded on first use) is not
    // the clients': an unmeasured pass of the first run over the clients' first frames, so
    // the first measured run does not pay for it alone (it made a first run's first complete
    // frame up to 9 frames later now and then, whatever the policy).
    if let Some(&(_, mode)) = runs.first() {
        let warm = WARMUP_FRAMES.min(plan.frames);
        run_clients(cfg, &world, &remote, mode, warm, &mut |_| {}).await?;
    }
    let mut results = Vec::with_capacity(runs.len());
    for (i, (name, mode)) in runs.into_iter().enumerate() {
        let base = i as u64 * cfg.clients as u64 * plan.frames;
        let before = probe.sample().await;
        let t = Instant::now();
        let mut clients = run_clients(cfg, &world, &remote, mode, plan.frames, &mut |d| {
            progress(base + d, total)
        })
        .await?;
        let wall_s = t.elapsed().as_secs_f64();
        let usage = probe.usage(before, probe.sample().await);
        write_drawn(cfg, &world, &name, &mut clients)?;
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

/// Writes client 0's drawn frames to `<out>/drawn/<run>.json` ([`DrawnLog`]), for the
/// benchmark to score against the full-detail frames (`portico bench --replay`).
fn write_drawn(
    cfg: &LoadtestConfig,
    world: &World,
    run: &str,
    clients: &mut [ClientResult],
) -> Result<()> {
    let Some(first) = clients.first_mut() else {
        return Ok(());
    };
    let dir = cfg.out.join("drawn");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let log = DrawnLog {
        run: run.to_owned(),
        database_id: world.database_id.clone(),
        path_hash: format!("{:016x}", cfg.path.hash()),
        dt_s: cfg.budget_s,
        size: world::SCREEN,
        fovy_deg: world::FOVY_DEG,
        frames: std::mem::take(&mut first.drawn),
    };
    log.write(&dir.join(super::drawn_file(run)))
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
    frames: u64,
    progress: &mut dyn FnMut(u64),
) -> Result<Vec<ClientResult>> {
    let done = Arc::new(AtomicU64::new(0));
    let offsets = world::offsets(cfg.clients, world.path_frames());
    let mut handles = Vec::with_capacity(cfg.clients);
    for (i, offset) in offsets.into_iter().enumerate() {
        let setup = sim::Setup {
            world: world.clone(),
            // A connection pool of its own per client, as separate machines would have.
            remote: Remote::new(remote.base(), cfg.token.clone())?,
            pipe: Arc::new(link::Pipe::new(cfg.link)),
            mode,
            offset,
            frames,
            cache_bytes: cfg.cache_bytes,
            done: done.clone(),
            // Client 0 starts at path frame 0: its frames are the benchmark's frames.
            record: i == 0 && frames == cfg.frames(),
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
