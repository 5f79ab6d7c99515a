//! `portico loadtest --stress 1,64,256,1000 --stream`: the push transport under a crowd. Each
//! client holds one `/v1/stream` session, sends its observer every frame along the path (client
//! `i` starting `i/N` of the way along and `i/N` of a frame later) and a WebSocket ping after
//! it, and takes whatever is pushed.
//!
//! The server is measured apart from this process, from its own `/metrics` read before and
//! after each level's measuring window: CPU seconds (`process_cpu_seconds_total`) per observer
//! update, the update latency histogram (arrival to need list in place), need lists computed,
//! and resident memory per session. The ping's round trip, measured here, adds what the figures
//! inside the server cannot see: time an update waits in socket buffers and for a worker.

use super::world::{PathFrame, path_frames};
use anyhow::{Context, Result};
use futures_util::{SinkExt, StreamExt};
use portico_client::stats::Series;
use portico_data::path::CameraPath;
use portico_protocol::{PROTOCOL_VERSION, Policy, StreamClient};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};
use tokio_tungstenite::tungstenite::Message;

/// A ping follows every this many updates (the pongs are a sample; pinging every update would
/// double what each update costs the server).
const PING_EVERY: usize = 4;

/// One stream stress run's settings.
#[derive(Debug, Clone)]
pub struct StreamStressConfig {
    /// Server base URL (`http://…`).
    pub server: String,
    /// Bearer token, if any (sent as `?token=`).
    pub token: Option<String>,
    /// The path the clients walk.
    pub path: CameraPath,
    /// The policy every session says hello with.
    pub policy: Policy,
    /// Seconds between one client's observer updates.
    pub frame_s: f64,
    /// Each session's push rate (bytes per second).
    pub rate_bytes_per_s: u64,
    /// The measuring window of each level (after every session is open and a second of
    /// warm-up).
    pub duration: Duration,
}

/// What one level measured.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StreamLevel {
    /// Sessions asked for.
    pub clients: usize,
    /// Whether the server shares need lists by place (`None`: it did not say); a policy may
    /// still have each session compute its own (`own_lists`).
    #[serde(default)]
    pub shared_answers: Option<bool>,
    /// Sessions the server accepted.
    pub connected: usize,
    /// Sessions refused (503 past capacity) or failed.
    pub refused: usize,
    /// Observer updates the server received in the window.
    pub updates: u64,
    /// Updates per second, all sessions together.
    pub updates_per_s: f64,
    /// Server CPU seconds in the window (its own `process_cpu_seconds_total`).
    pub server_cpu_s: f64,
    /// Server CPU per update, milliseconds.
    pub cpu_per_update_ms: f64,
    /// Server CPU as a share of one core.
    pub server_cores: f64,
    /// Update latency inside the server (arrival to need list in place), p50 and p99 upper
    /// bounds from its histogram, seconds.
    pub update_p50_s: f64,
    /// See `update_p50_s`.
    pub update_p99_s: f64,
    /// Ping round trips after each update, at the clients (s).
    pub ping_s: Series,
    /// Need lists the server computed in the window (shared-cache misses, and `own_lists`).
    pub lists_computed: u64,
    /// Of those, the lists sessions computed for their own observer, shared with nobody: all
    /// of them under the predicted lookahead, an eye outside the live cells under the range
    /// lookahead (0 from a server before this counter).
    #[serde(default)]
    pub own_lists: u64,
    /// Need lists the sessions changed to in the window (a change of place: from the shared
    /// cache or computed; with exact answers, one per update served).
    pub lists_taken: u64,
    /// Server resident memory with this level's sessions open (bytes).
    pub rss_open: f64,
    /// Server resident memory before they opened (bytes).
    pub rss_idle: f64,
    /// Bytes pushed to all sessions in the window.
    pub pushed_bytes: u64,
}

/// The figures of a `/metrics` page this harness reads.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ServerSample {
    /// `process_cpu_seconds_total`.
    pub cpu_s: f64,
    /// `process_resident_memory_bytes`.
    pub rss: f64,
    /// `portico_stream_updates_total`.
    pub updates: f64,
    /// `portico_shared_misses_total`.
    pub misses: f64,
    /// `portico_stream_own_lists_total` (0 from a server before it).
    pub own_lists: f64,
    /// `portico_prefetch_answers_total`.
    pub answers: f64,
    /// `portico_shared_answers`: whether the server shares need lists (`None`: not said).
    pub shared: Option<bool>,
    /// `portico_stream_update_seconds_bucket`: (upper bound, cumulative count).
    pub buckets: Vec<(f64, f64)>,
}

impl ServerSample {
    /// Parses the Prometheus text of `/metrics`; `None` when the CPU line is missing (a server
    /// from before these metrics, or not on Linux).
    pub fn parse(text: &str) -> Option<ServerSample> {
        let mut s = ServerSample::default();
        let mut cpu = None;
        for line in text.lines() {
            let Some((name, value)) = line.rsplit_once(' ') else {
                continue;
            };
            let Ok(v) = value.parse::<f64>() else {
                continue;
            };
            match name {
                "process_cpu_seconds_total" => cpu = Some(v),
                "process_resident_memory_bytes" => s.rss = v,
                "portico_stream_updates_total" => s.updates = v,
                "portico_shared_misses_total" => s.misses = v,
                "portico_stream_own_lists_total" => s.own_lists = v,
                "portico_prefetch_answers_total" => s.answers = v,
                "portico_shared_answers" => s.shared = Some(v > 0.0),
                _ => {
                    if let Some(le) = name
                        .strip_prefix("portico_stream_update_seconds_bucket{le=\"")
                        .and_then(|r| r.strip_suffix("\"}"))
                    {
                        let le = if le == "+Inf" {
                            f64::INFINITY
                        } else {
                            le.parse().ok()?
                        };
                        s.buckets.push((le, v));
                    }
                }
            }
        }
        s.cpu_s = cpu?;
        Some(s)
    }

    /// The upper bound of the bucket holding quantile `q` of the updates between `self` and
    /// `later` (0 when there were none).
    pub fn quantile_to(&self, later: &ServerSample, q: f64) -> f64 {
        let delta: Vec<(f64, f64)> = later
            .buckets
            .iter()
            .map(|&(le, n)| {
                let before = self.buckets.iter().find(|b| b.0 == le).map_or(0.0, |b| b.1);
                (le, n - before)
            })
            .collect();
        let total = delta.last().map_or(0.0, |d| d.1);
        if total <= 0.0 {
            return 0.0;
        }
        delta
            .iter()
            .find(|d| d.1 >= q * total)
            .map_or(f64::INFINITY, |d| d.0)
    }
}

async fn sample(http: &reqwest::Client, cfg: &StreamStressConfig) -> Result<ServerSample> {
    sample_server(http, &cfg.server, cfg.token.as_deref()).await
}

/// The server's `/metrics` figures this harness reads (errors: unreachable, or a server too old
/// to report its CPU time).
pub async fn sample_server(
    http: &reqwest::Client,
    server: &str,
    token: Option<&str>,
) -> Result<ServerSample> {
    let url = format!("{}/metrics", server.trim_end_matches('/'));
    let mut req = http.get(&url);
    if let Some(t) = token {
        req = req.bearer_auth(t);
    }
    let text = req.send().await?.error_for_status()?.text().await?;
    ServerSample::parse(&text).with_context(|| {
        format!("{url} has no process_cpu_seconds_total: the server is too old to be measured")
    })
}

/// What the clients count together.
#[derive(Default)]
struct Shared {
    pushed: AtomicU64,
    measuring: std::sync::atomic::AtomicBool,
    pings: std::sync::Mutex<Vec<f64>>,
}

/// Runs one level: `clients` sessions, a second of warm-up, then `cfg.duration` measured.
pub async fn level(cfg: &StreamStressConfig, clients: usize) -> Result<StreamLevel> {
    let frames = Arc::new(path_frames(&cfg.path, cfg.frame_s, 1e4));
    anyhow::ensure!(!frames.is_empty(), "the path has no frames");
    let http = reqwest::Client::new();
    let idle = sample(&http, cfg).await?;
    let shared = Arc::new(Shared::default());
    let stop = Arc::new(tokio::sync::Notify::new());
    let mut url = format!("{}/v1/stream", cfg.server.replacen("http", "ws", 1));
    if let Some(t) = &cfg.token {
        url = format!("{url}?token={t}");
    }
    let mut tasks = tokio::task::JoinSet::new();
    let (opened_tx, mut opened_rx) = tokio::sync::mpsc::channel(clients.max(1));
    for i in 0..clients {
        let (frames, cfg, url) = (frames.clone(), cfg.clone(), url.clone());
        let (shared, stop, opened) = (shared.clone(), stop.clone(), opened_tx.clone());
        let offset = i * frames.len() / clients.max(1);
        let phase = Duration::from_secs_f64(cfg.frame_s * i as f64 / clients.max(1) as f64);
        tasks.spawn(async move {
            one_client(&url, &frames, offset, phase, &cfg, &shared, &stop, opened).await
        });
    }
    drop(opened_tx);
    let mut connected = 0;
    while let Some(ok) = opened_rx.recv().await {
        connected += usize::from(ok);
    }
    tokio::time::sleep(Duration::from_secs(1)).await;
    let before = sample(&http, cfg).await?;
    let pushed0 = shared.pushed.load(Relaxed);
    shared.measuring.store(true, Relaxed);
    let t0 = Instant::now();
    tokio::time::sleep(cfg.duration).await;
    let after = sample(&http, cfg).await?;
    let wall = t0.elapsed().as_secs_f64();
    shared.measuring.store(false, Relaxed);
    let pushed = shared.pushed.load(Relaxed) - pushed0;
    stop.notify_waiters();
    while tasks.join_next().await.is_some() {}
    let updates = (after.updates - before.updates).max(0.0);
    let cpu = (after.cpu_s - before.cpu_s).max(0.0);
    let pings = std::mem::take(&mut *shared.pings.lock().unwrap_or_else(|e| e.into_inner()));
    let own = (after.own_lists - before.own_lists).max(0.0);
    Ok(StreamLevel {
        clients,
        shared_answers: after.shared,
        connected,
        refused: clients - connected,
        updates: updates as u64,
        updates_per_s: updates / wall.max(1e-9),
        server_cpu_s: cpu,
        cpu_per_update_ms: if updates > 0.0 {
            cpu / updates * 1e3
        } else {
            0.0
        },
        server_cores: cpu / wall.max(1e-9),
        update_p50_s: before.quantile_to(&after, 0.5),
        update_p99_s: before.quantile_to(&after, 0.99),
        ping_s: Series::of(&pings),
        lists_computed: ((after.misses - before.misses).max(0.0) + own) as u64,
        own_lists: own as u64,
        lists_taken: (after.answers - before.answers).max(0.0) as u64,
        rss_open: after.rss,
        rss_idle: idle.rss,
        pushed_bytes: pushed,
    })
}

/// One session: hello, then an observer and a ping every frame until `stop`; counts pushed
/// bytes and, while measuring, ping round trips. Says on `opened` whether it connected.
#[allow(clippy::too_many_arguments)]
async fn one_client(
    url: &str,
    frames: &[PathFrame],
    offset: usize,
    phase: Duration,
    cfg: &StreamStressConfig,
    shared: &Shared,
    stop: &tokio::sync::Notify,
    opened: tokio::sync::mpsc::Sender<bool>,
) {
    tokio::time::sleep(phase).await;
    // Small frames go out at once (Nagle's delay would add 40 ms to every ping).
    let connected = tokio_tungstenite::connect_async_with_config(url, None, true).await;
    let Ok((ws, _)) = connected else {
        let _ = opened.send(false).await;
        return;
    };
    let _ = opened.send(true).await;
    drop(opened);
    let (mut tx, mut rx) = ws.split();
    let hello = StreamClient::Hello {
        version: PROTOCOL_VERSION,
        policy: cfg.policy,
        rate_bytes_per_s: cfg.rate_bytes_per_s,
        rtt_ms: 0,
    };
    let encode = |m: &StreamClient| {
        Message::Binary(portico_protocol::to_bincode(m).unwrap_or_default().into())
    };
    if tx.send(encode(&hello)).await.is_err() {
        return;
    }
    let epoch = Instant::now();
    let stopped = stop.notified();
    tokio::pin!(stopped);
    let mut tick = tokio::time::interval(Duration::from_secs_f64(cfg.frame_s.max(1e-3)));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut f = offset;
    loop {
        tokio::select! {
            _ = &mut stopped => break,
            _ = tick.tick() => {
                let obs = StreamClient::Observer(frames[f % frames.len()].observer);
                f += 1;
                if tx.feed(encode(&obs)).await.is_err() {
                    break;
                }
                if f.is_multiple_of(PING_EVERY) {
                    let sent_at = epoch.elapsed().as_nanos() as u64;
                    let ping = Message::Ping(sent_at.to_le_bytes().to_vec().into());
                    if tx.feed(ping).await.is_err() {
                        break;
                    }
                }
                if tx.flush().await.is_err() {
                    break;
                }
            }
            msg = rx.next() => match msg {
                Some(Ok(Message::Binary(b))) => {
                    shared.pushed.fetch_add(b.len() as u64, Relaxed);
                }
                Some(Ok(Message::Pong(p))) if p.len() == 8 && shared.measuring.load(Relaxed) => {
                    let sent = u64::from_le_bytes(p[..8].try_into().unwrap_or_default());
                    let rtt = epoch.elapsed().as_nanos() as u64 - sent.min(u64::MAX / 2);
                    shared.pings.lock().unwrap_or_else(|e| e.into_inner()).push(rtt as f64 * 1e-9);
                }
                Some(Ok(_)) => {}
                _ => break,
            },
        }
    }
    let _ = tx.send(Message::Close(None)).await;
}

/// Server memory per session at each level: the growth of resident memory from the previous
/// level's sessions (or, for the first, from the idle server) over the sessions added. The
/// allocator keeps what earlier levels freed, so growth between levels is what more sessions
/// cost; bytes.
pub fn memory_per_session(levels: &[StreamLevel]) -> Vec<f64> {
    let mut out = Vec::new();
    for (i, l) in levels.iter().enumerate() {
        let (base, n0) = match i.checked_sub(1).map(|j| &levels[j]) {
            Some(p) => (p.rss_open, p.connected),
            None => (l.rss_idle, 0),
        };
        let added = l.connected.saturating_sub(n0);
        out.push(if added > 0 {
            (l.rss_open - base).max(0.0) / added as f64
        } else {
            0.0
        });
    }
    out
}

/// The levels of an earlier `--stress … --stream` run, from `dir/stress.json`.
pub fn read_run(dir: &std::path::Path) -> Result<Vec<StreamLevel>> {
    let path = dir.join("stress.json");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let run: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{} is not JSON", path.display()))?;
    anyhow::ensure!(
        run["transport"] == "stream",
        "{} is not a stream stress run (its transport is not \"stream\")",
        path.display()
    );
    serde_json::from_value(run["levels"].clone())
        .with_context(|| format!("{}: its levels do not read", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    const PAGE: &str = "# HELP x\nprocess_cpu_seconds_total 12.5\nprocess_resident_memory_bytes 1000\n\
portico_stream_updates_total 40\nportico_shared_misses_total 3\nportico_stream_own_lists_total 7\n\
portico_stream_update_seconds_bucket{le=\"0.0001\"} 30\n\
portico_stream_update_seconds_bucket{le=\"0.01\"} 39\n\
portico_stream_update_seconds_bucket{le=\"+Inf\"} 40\n";

    #[test]
    fn a_metrics_page_parses_and_quantiles_come_from_the_bucket_deltas() {
        let a = ServerSample::parse(PAGE).unwrap();
        assert_eq!(a.cpu_s, 12.5);
        assert_eq!(a.updates, 40.0);
        assert_eq!(a.misses, 3.0);
        assert_eq!(a.own_lists, 7.0);
        assert_eq!(a.buckets.len(), 3);
        let mut b = a.clone();
        // 100 more updates: 50 fast, 49 under 10 ms, 1 slower.
        b.buckets = vec![(0.0001, 80.0), (0.01, 138.0), (f64::INFINITY, 140.0)];
        assert_eq!(a.quantile_to(&b, 0.5), 0.0001);
        assert_eq!(a.quantile_to(&b, 0.99), 0.01);
        assert_eq!(a.quantile_to(&b, 1.0), f64::INFINITY);
        assert_eq!(a.quantile_to(&a, 0.99), 0.0);
        assert!(ServerSample::parse("portico_sessions 3\n").is_none());
    }

    #[test]
    fn memory_per_session_is_growth_over_the_sessions_added() {
        let level = |connected: usize, idle: f64, open: f64| StreamLevel {
            clients: connected,
            shared_answers: Some(true),
            connected,
            refused: 0,
            updates: 0,
            updates_per_s: 0.0,
            server_cpu_s: 0.0,
            cpu_per_update_ms: 0.0,
            server_cores: 0.0,
            update_p50_s: 0.0,
            update_p99_s: 0.0,
            ping_s: Series::of(&[]),
            lists_computed: 0,
            own_lists: 0,
            lists_taken: 0,
            rss_open: open,
            rss_idle: idle,
            pushed_bytes: 0,
        };
        let levels = [
            level(10, 1000.0, 3000.0),
            level(110, 2500.0, 13000.0),
            level(0, 0.0, 0.0),
        ];
        assert_eq!(memory_per_session(&levels), vec![200.0, 100.0, 0.0]);
    }
}
