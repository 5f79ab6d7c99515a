//! `portico loadtest --stress`: the server's prefetch answer under many concurrent clients
//! (target: p99 ≤ 2 ms at 64 clients on 2 cores; Funkhouser's lookahead took 3 ms mean).
//!
//! Each client walks the path (client `i` starting `i/N` of the way along and `i/N` of a frame
//! later, as independent clients are out of phase) and posts one `/v1/prefetch` per frame, as
//! the real client does, holding everything earlier answers listed
//! (as if every read had arrived), so the answers stay the size of a walking client's. With
//! `paced` off, each client posts again as soon as its answer is in (a closed loop: the
//! server's throughput). Latency is measured at the client, request written to answer decoded,
//! over loopback HTTP/1.1 with keep-alive; the server's own compute time comes with each answer,
//! and its CPU per answer and the need lists it computed from its `/metrics` around the level.

use super::stress_stream::sample_server;
use super::world::path_frames;
use anyhow::{Context, Result};
use portico_client::stats::Series;
use portico_data::path::CameraPath;
use portico_native::net::Remote;
use portico_protocol::{PROTOCOL_VERSION, Policy, PrefetchRequest};
use serde::Serialize;
use std::collections::HashSet;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// One stress level's settings.
#[derive(Debug, Clone)]
pub struct StressConfig {
    /// Server base URL.
    pub server: String,
    /// Bearer token, if any.
    pub token: Option<String>,
    /// The path the clients walk.
    pub path: CameraPath,
    /// The policy every request carries.
    pub policy: Policy,
    /// Frame time (s): the pace of each client's requests.
    pub frame_s: f64,
    /// One request per frame (true) or back to back (false).
    pub paced: bool,
    /// How long each level runs.
    pub duration: Duration,
}

/// What one level of concurrency measured.
#[derive(Debug, Clone, Serialize)]
pub struct StressLevel {
    /// Concurrent clients.
    pub clients: usize,
    /// Requests answered.
    pub requests: u64,
    /// Requests that failed.
    pub errors: u64,
    /// Answers per second, all clients together.
    pub rps: f64,
    /// Round-trip latency at the client (s).
    pub latency_s: Series,
    /// The server's compute time per answer (s), as it reports it.
    pub server_compute_s: Series,
    /// Items per answer.
    pub items: Series,
    /// Server CPU per answer (s), from its own `process_cpu_seconds_total` over the level
    /// (`None`: the server does not report it).
    pub cpu_per_answer_s: Option<f64>,
    /// Need lists the server computed over the level (shared-cache misses; `None`: not
    /// reported). With `portico serve --exact-answers` every answer is computed and none is
    /// counted here.
    pub lists_computed: Option<u64>,
}

/// Fails with a one-line error unless a server answers `GET /healthz` at `server`, so a stress
/// run against nothing stops before it starts instead of reporting a table of errors.
pub async fn reachable(server: &str) -> Result<()> {
    let url = format!("{}/healthz", server.trim_end_matches('/'));
    let answer = reqwest::Client::new()
        .get(&url)
        .timeout(Duration::from_secs(5))
        .send()
        .await;
    match answer {
        Ok(r) if r.status().is_success() => Ok(()),
        Ok(r) => anyhow::bail!("{url} answered {}: is it a Portico server?", r.status()),
        Err(e) => anyhow::bail!(
            "no server answers at {url} ({}); start one with `portico serve FILE.portico`",
            e.without_url()
        ),
    }
}

/// Runs one level: `clients` concurrent clients for `cfg.duration`.
pub async fn level(cfg: &StressConfig, clients: usize) -> Result<StressLevel> {
    let frames = Arc::new(path_frames(&cfg.path, cfg.frame_s, 1e4));
    anyhow::ensure!(!frames.is_empty(), "the path has no frames");
    let http = reqwest::Client::new();
    let metrics = || sample_server(&http, &cfg.server, cfg.token.as_deref());
    let before = metrics().await.ok();
    let start = Instant::now();
    let mut tasks = tokio::task::JoinSet::new();
    for i in 0..clients {
        // Each client has its own connection, as separate machines would.
        let remote = Remote::new(&cfg.server, cfg.token.clone())?;
        let (frames, cfg) = (frames.clone(), cfg.clone());
        let offset = i * frames.len() / clients.max(1);
        // Independent clients draw their frames out of phase: spread the first requests over
        // one frame time (all in phase, 64 requests would land in the same millisecond).
        let phase = Duration::from_secs_f64(cfg.frame_s * i as f64 / clients.max(1) as f64);
        tasks.spawn(async move {
            if cfg.paced {
                tokio::time::sleep(phase).await;
            }
            one_client(&remote, &frames, offset, &cfg).await
        });
    }
    let (mut lat, mut compute, mut items, mut errors) = (vec![], vec![], vec![], 0u64);
    while let Some(done) = tasks.join_next().await {
        let c = done.context("stress client task")?;
        lat.extend(c.latency);
        compute.extend(c.compute);
        items.extend(c.items);
        errors += c.errors;
    }
    let wall = start.elapsed().as_secs_f64();
    let after = metrics().await.ok();
    let (cpu_per_answer_s, lists_computed) = match (before, after) {
        (Some(b), Some(a)) if a.answers > b.answers => (
            Some((a.cpu_s - b.cpu_s) / (a.answers - b.answers)),
            Some((a.misses - b.misses).max(0.0) as u64),
        ),
        _ => (None, None),
    };
    Ok(StressLevel {
        cpu_per_answer_s,
        lists_computed,
        clients,
        requests: lat.len() as u64,
        errors,
        rps: lat.len() as f64 / wall.max(1e-9),
        latency_s: Series::of(&lat),
        server_compute_s: Series::of(&compute),
        items: Series::of(&items),
    })
}

#[derive(Default)]
struct ClientFigures {
    latency: Vec<f64>,
    compute: Vec<f64>,
    items: Vec<f64>,
    errors: u64,
}

async fn one_client(
    remote: &Remote,
    frames: &[super::world::PathFrame],
    offset: usize,
    cfg: &StressConfig,
) -> ClientFigures {
    let mut out = ClientFigures::default();
    let mut held: HashSet<u32> = HashSet::new();
    let mut tick = tokio::time::interval(Duration::from_secs_f64(cfg.frame_s.max(1e-3)));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let end = Instant::now() + cfg.duration;
    let mut f = offset;
    while Instant::now() < end {
        if cfg.paced {
            tick.tick().await;
        }
        let req = PrefetchRequest {
            version: PROTOCOL_VERSION,
            observer: frames[f % frames.len()].observer,
            policy: cfg.policy,
            held: portico_protocol::encode_held(held.iter().copied()),
        };
        let t0 = Instant::now();
        match remote.prefetch(&req).await {
            Ok(resp) => {
                out.latency.push(t0.elapsed().as_secs_f64());
                out.compute.push(f64::from(resp.micros) * 1e-6);
                out.items.push(resp.items.len() as f64);
                held.extend(resp.items.iter().map(|i| i.segment));
                for e in &resp.evict {
                    held.remove(e);
                }
            }
            Err(_) => {
                out.errors += 1;
                // A refused or failing server is not hammered in a tight loop.
                tokio::time::sleep(Duration::from_secs_f64(cfg.frame_s.max(1e-3))).await;
            }
        }
        f += 1;
    }
    out
}
