//! `portico loadtest --server URL --clients N (--path FILE | --path-kind tour) [--policy SPEC |
//! --sweep [reduced|full|depth|gran|cull]] [--link rtt=20ms,rate=100mbit] [--cache-mb 64]
//! [--budget-ms 50] [--max-frames F] -o DIR`: simulated clients against a real server, to
//! measure prefetch policies against demand fetch and an oracle (Funkhouser 1993 §5.3);
//! with `--stress 1,16,64`, the server's prefetch latency at those numbers of clients instead.

use crate::cmd::values;
use crate::progress::Bars;
use anyhow::{Context, Result};
use portico_client::policy::{parse_policy, policy_spec};
use portico_lab::loadtest::stress::{StressConfig, level, reachable};
use portico_lab::loadtest::stress_plot;
use portico_lab::loadtest::stress_stream::{self, StreamStressConfig};
use portico_lab::loadtest::{Link, LoadtestConfig, LoadtestSummary, grid, run as run_loadtest};
use portico_protocol::Policy;
use std::path::PathBuf;

/// Frames per client of a sweep's runs unless `--max-frames` says otherwise (20 s at 50 ms:
/// the 15 runs of the reduced sweep take about five minutes).
const SWEEP_FRAMES: u64 = 400;

/// Arguments of `portico loadtest`.
#[derive(clap::Args)]
pub struct Args {
    /// Server base URL.
    #[arg(long, default_value = "http://127.0.0.1:7878")]
    server: String,
    /// Bearer token (also read from PORTICO_TOKEN).
    #[arg(long, env = "PORTICO_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Simulated clients.
    #[arg(long, default_value_t = 8)]
    clients: usize,
    #[command(flatten)]
    route: crate::cmd::path::PathArgs,
    #[arg(long, default_value = "", help = values::POLICY_HELP)]
    policy: String,
    /// Funkhouser's policy grid instead of one policy (`--sweep` alone: reduced). Keys of
    /// --policy that the grid does not vary (read, size) still apply.
    #[arg(long, num_args = 0..=1, default_missing_value = "reduced", value_name = "GRID",
          value_parser = values::sweep())]
    sweep: Option<String>,
    /// Each client's emulated link: rtt=DURATION (e.g. 20ms, 0.05s), rate=RATE (e.g. 100mbit,
    /// 10mbit, 1gbit, 500kbit).
    #[arg(long, default_value = "rtt=20ms,rate=100mbit")]
    link: String,
    /// Cache budget per client, MiB (2^20 bytes); several (e.g. 4,16,64,256) run the whole
    /// load test at each and compare them (`DIR/cache-<N>mb/`, `DIR/cache_sweep.md` and `.png`).
    #[arg(long, value_delimiter = ',', default_value = "64", value_name = "MB",
          value_parser = clap::value_parser!(u64).range(1..=1 << 20))]
    cache_mb: Vec<u64>,
    /// Frame budget (and frame time) in milliseconds.
    #[arg(long, default_value_t = portico_client::defaults::FRAME_BUDGET_MS)]
    budget_ms: f64,
    /// Frames per client (default: one pass over the path; with --sweep, 400).
    #[arg(long)]
    max_frames: Option<u64>,
    /// Leave out the demand-fetch and oracle baselines.
    #[arg(long)]
    no_baselines: bool,
    /// The transports each policy runs over, in the same session: `pull` (/v1/prefetch and
    /// /v1/batch), `push` (/v1/stream; runs named `<policy>+push`), or both.
    #[arg(long, value_delimiter = ',', default_value = "pull,push")]
    transport: Vec<portico_lab::loadtest::Transport>,
    /// Output directory for summary.json, report.md, frames.csv and the plots.
    #[arg(short = 'o', long, visible_alias = "output", value_name = "DIR")]
    out: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
    /// Instead of the policy runs: the server's prefetch latency at these numbers of
    /// concurrent clients (e.g. 1,16,64), each client posting one request per frame along the
    /// path; writes DIR/stress.json.
    #[arg(long, value_delimiter = ',', value_name = "CLIENTS")]
    stress: Vec<usize>,
    /// Seconds per stress level.
    #[arg(long, default_value_t = 10.0)]
    stress_seconds: f64,
    /// Stress clients post back to back instead of once per frame (the server's throughput).
    #[arg(long)]
    closed_loop: bool,
    /// Stress the push transport instead: each client holds a /v1/stream session and sends its
    /// observer every frame, pushed to at --link's rate; the server's CPU per update, update
    /// latency and memory per session come from its /metrics. Writes DIR/stress.json and
    /// DIR/scaling.png.
    #[arg(long, requires = "stress")]
    stream: bool,
    /// With --stream: a directory of an earlier stream stress run (its stress.json) to draw in
    /// the same scaling plot, e.g. the same levels against `portico serve --exact-answers`.
    #[arg(long, requires = "stream", value_name = "DIR")]
    baseline: Option<PathBuf>,
}

/// The policies to run: one from `--policy`, or the `--sweep` grid on top of it.
fn policies(a: &Args) -> Result<Vec<(String, Policy)>> {
    let base = parse_policy(&a.policy, Policy::default())
        .map_err(anyhow::Error::msg)
        .context("--policy")?;
    match &a.sweep {
        Some(name) => Ok(grid(name, base).context("--sweep")?),
        None => Ok(vec![(policy_spec(&base), base)]),
    }
}

/// Runs the load test with a progress bar and prints the summary.
pub fn run(a: Args) -> Result<()> {
    let link = Link::parse(&a.link).context("--link")?;
    let policies = policies(&a)?;
    if !(1.0..=10_000.0).contains(&a.budget_ms) {
        anyhow::bail!("--budget-ms must be 1..=10000, not {}", a.budget_ms);
    }
    if a.cache_mb.len() > 1 && !a.stress.is_empty() {
        anyhow::bail!(
            "--cache-mb with several budgets is a sweep of the policy runs, not of --stress"
        );
    }
    let path = crate::cmd::walk::load_path(&a.server, a.token.clone(), &a.route)?;
    if a.stream {
        // An unlimited link: the server's own cap on each session's rate.
        let rate = if link.rate_bytes_per_s.is_finite() {
            link.rate_bytes_per_s as u64
        } else {
            u64::MAX
        };
        return stress_stream(&a, path, policies[0].1, rate);
    }
    if !a.stress.is_empty() {
        return stress(&a, path, policies[0].1);
    }
    let cfg = LoadtestConfig {
        server: a.server,
        token: a.token,
        clients: a.clients,
        path,
        policies,
        transports: a.transport.clone(),
        baselines: !a.no_baselines,
        link,
        cache_bytes: a.cache_mb[0] << 20,
        budget_s: a.budget_ms / 1e3,
        max_frames: a.max_frames.or(a.sweep.as_ref().map(|_| SWEEP_FRAMES)),
        out: a.out,
    };
    if a.cache_mb.len() > 1 {
        return cache_sweep(&cfg, &a.cache_mb, a.json);
    }
    let bars = Bars::new();
    let (mut started, mut shown) = (false, 0u64);
    let summary = run_loadtest(&cfg, &mut |done, total| {
        if !started {
            bars.start("loadtest", total);
            started = true;
        }
        if done > shown {
            bars.inc(done - shown);
            shown = done;
        }
    })?;
    bars.finish();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print_summary(&summary, &cfg.out);
    }
    Ok(())
}

/// `--cache-mb A,B,…`: the load test at each budget, each run's table, then the sweep's table,
/// verdict and files.
fn cache_sweep(cfg: &LoadtestConfig, sizes: &[u64], json: bool) -> Result<()> {
    let bars = Bars::new();
    let mut current = None;
    let mut shown = 0u64;
    let (rows, summaries) =
        portico_lab::loadtest::cache_sweep::sweep(cfg, sizes, &mut |run, done, total| {
            if current != Some(run) {
                bars.start(&format!("loadtest, {} MiB cache", sizes[run]), total);
                (current, shown) = (Some(run), 0);
            }
            if done > shown {
                bars.inc(done - shown);
                shown = done;
            }
        })?;
    bars.finish();
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    for s in &summaries {
        print_summary(s, &cfg.out.join(format!("cache-{}mb", s.cache_bytes >> 20)));
    }
    println!("cache sweep (p / d / o: best prefetch / demand fetch / oracle):");
    for line in portico_lab::loadtest::cache_sweep::markdown(&rows).lines() {
        println!("  {line}");
    }
    println!("  {}", portico_lab::verdict::cache_sweep(&rows));
    println!(
        "  wrote {} and {}",
        cfg.out.join("cache_sweep.md").display(),
        cfg.out.join("cache_sweep.png").display()
    );
    Ok(())
}

/// `--stress`: prefetch latency per level of concurrency, a table and DIR/stress.json.
fn stress(a: &Args, path: portico_data::path::CameraPath, policy: Policy) -> Result<()> {
    let cfg = StressConfig {
        server: a.server.clone(),
        token: a.token.clone(),
        path,
        policy,
        frame_s: a.budget_ms / 1e3,
        paced: !a.closed_loop,
        duration: std::time::Duration::from_secs_f64(a.stress_seconds.clamp(0.1, 3600.0)),
    };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    rt.block_on(reachable(&a.server))?;
    println!(
        "prefetch stress against {} ({}, {} s per level)",
        a.server,
        if cfg.paced {
            format!("one request per {} ms frame per client", a.budget_ms)
        } else {
            "closed loop".into()
        },
        a.stress_seconds
    );
    println!(
        "  {:>7} {:>9} {:>8} {:>7} {:>9} {:>9} {:>9} {:>14} {:>11} {:>11} {:>6}",
        "clients",
        "requests",
        "req/s",
        "errors",
        "p50 ms",
        "p99 ms",
        "max ms",
        "server mean ms",
        "CPU/ans µs",
        "lists made",
        "items"
    );
    let mut levels = Vec::new();
    for &n in &a.stress {
        let l = rt.block_on(level(&cfg, n.max(1)))?;
        let or_dash = |v: Option<String>| v.unwrap_or_else(|| "-".into());
        println!(
            "  {:>7} {:>9} {:>8.0} {:>7} {:>9.3} {:>9.3} {:>9.3} {:>14.3} {:>11} {:>11} {:>6.0}",
            l.clients,
            l.requests,
            l.rps,
            l.errors,
            l.latency_s.p50 * 1e3,
            l.latency_s.p99 * 1e3,
            l.latency_s.max * 1e3,
            l.server_compute_s.mean * 1e3,
            or_dash(l.cpu_per_answer_s.map(|s| format!("{:.1}", s * 1e6))),
            or_dash(l.lists_computed.map(|n| n.to_string())),
            l.items.mean
        );
        levels.push(l);
    }
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let json = serde_json::json!({
        "server": a.server,
        "paced": cfg.paced,
        "frame_ms": a.budget_ms,
        "seconds_per_level": a.stress_seconds,
        "policy": policy_spec(&policy),
        "cores": std::thread::available_parallelism().map_or(1, |n| n.get()),
        "levels": levels,
    });
    let out = a.out.join("stress.json");
    std::fs::write(&out, serde_json::to_vec_pretty(&json)?)
        .with_context(|| format!("writing {}", out.display()))?;
    println!("  wrote {}", out.display());
    Ok(())
}

/// `ratio` (demand's over prefetch's) as "N.Nx fewer" or, below 1, "N.Nx more".
fn times(ratio: f64, fewer: &str, more: &str) -> String {
    if ratio >= 1.0 {
        format!("{ratio:.1}x {fewer}")
    } else {
        format!("{:.1}x {more}", 1.0 / ratio.max(1e-9))
    }
}

/// A short human summary: one line per run and the prefetch-vs-demand ratio.
pub fn print_summary(s: &LoadtestSummary, out: &std::path::Path) {
    println!(
        "loadtest: {} clients x {} frames on {} ({}), {}, cache {:.0} MiB",
        s.clients,
        s.frames_per_client,
        s.model,
        s.path,
        s.link_spec,
        s.cache_bytes as f64 / (1u64 << 20) as f64
    );
    println!(
        "  {:<44} {:>11} {:>9} {:>8} {:>9} {:>9} {:>14}",
        "run", "LODs skip", "objs skip", "hit", "MB/client", "MB waste", "lat p50/p99 ms"
    );
    for p in &s.policies {
        println!(
            "  {:<44} {:>5.2}/{:<5.0} {:>9.2} {:>8.3} {:>9.1} {:>9.1} {:>6.0}/{:<7.0}",
            p.name,
            p.lods_skipped_mean,
            p.lods_skipped_max,
            p.objects_skipped_mean,
            p.cache_hit_rate,
            p.bytes_fetched_per_client as f64 / 1e6,
            p.bytes_wasted_per_client as f64 / 1e6,
            p.latency_p50_s * 1e3,
            p.latency_p99_s * 1e3
        );
    }
    if let (Some(best), Some(demand)) = (s.best_prefetch(), s.get("demand")) {
        let fewer = best
            .lods_skipped_vs_demand
            .map_or("none skipped".into(), |r| times(r, "fewer", "more"));
        let deficit = best
            .lod_deficit_vs_demand
            .map_or("no LOD deficit".into(), |r| {
                format!("LOD deficit {}", times(r, "smaller", "larger"))
            });
        println!(
            "  best prefetch `{}`: LODs skipped per frame {:.3} against demand fetch's {:.3} ({fewer}; {deficit})",
            best.name, best.lods_skipped_mean, demand.lods_skipped_mean
        );
    }
    for v in portico_lab::verdict::loadtest(s) {
        println!("  {v}");
    }
    println!("  report: {}", out.join("report.md").display());
    let files: Vec<String> = s
        .policies
        .iter()
        .map(|p| portico_lab::loadtest::drawn_file(&p.name))
        .collect();
    println!(
        "  client 0's drawn frames: {}/{{{}}} (score them: portico bench --replay FILE)",
        out.join("drawn").display(),
        files.join(",")
    );
}

/// `--stress N,… --stream`: the push transport per level of concurrency, measured from the
/// server's own /metrics; a table, DIR/stress.json and DIR/scaling.png.
fn stress_stream(
    a: &Args,
    path: portico_data::path::CameraPath,
    policy: Policy,
    rate: u64,
) -> Result<()> {
    let cfg = StreamStressConfig {
        server: a.server.clone(),
        token: a.token.clone(),
        path,
        policy,
        frame_s: a.budget_ms / 1e3,
        rate_bytes_per_s: rate,
        duration: std::time::Duration::from_secs_f64(a.stress_seconds.clamp(0.1, 3600.0)),
    };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    // Everything that can be refused is refused before the first level runs.
    let baseline = match &a.baseline {
        Some(dir) => Some(stress_stream::read_run(dir).context("--baseline")?),
        None => None,
    };
    rt.block_on(reachable(&a.server))?;
    let pace = if rate == u64::MAX {
        "the server's cap".to_string()
    } else if rate < 125_000 {
        format!("{:.0} kbit/s", rate as f64 * 8e-3)
    } else {
        format!("{:.2} MB/s", rate as f64 / 1e6)
    };
    println!(
        "stream stress against {}: one observer per {} ms per session, pushes at {pace} per \
         session, {} s measured per level (server figures from its /metrics)",
        a.server, a.budget_ms, a.stress_seconds
    );
    println!(
        "  {:>7} {:>7} {:>9} {:>12} {:>7} {:>11} {:>11} {:>11} {:>16} {:>9} {:>8}",
        "clients",
        "refused",
        "updates/s",
        "CPU/upd µs",
        "cores",
        "upd p50 ms",
        "upd p99 ms",
        "ping p99 ms",
        "lists taken/made",
        "KB/sess",
        "MB/s out"
    );
    let mut levels: Vec<stress_stream::StreamLevel> = Vec::new();
    for &n in &a.stress {
        let l = rt.block_on(stress_stream::level(&cfg, n.max(1)))?;
        let memory = stress_stream::memory_per_session(&[levels.clone(), vec![l.clone()]].concat());
        println!(
            "  {:>7} {:>7} {:>9.0} {:>12.1} {:>7.2} {:>11.3} {:>11.3} {:>11.2} {:>16} {:>9.1} {:>8.2}",
            l.clients,
            l.refused,
            l.updates_per_s,
            l.cpu_per_update_ms * 1e3,
            l.server_cores,
            l.update_p50_s * 1e3,
            l.update_p99_s * 1e3,
            l.ping_s.p99 * 1e3,
            format!("{}/{}", l.lists_taken, l.lists_computed),
            memory.last().copied().unwrap_or(0.0) / 1e3,
            l.pushed_bytes as f64 / 1e6 / a.stress_seconds.max(1e-9)
        );
        levels.push(l);
    }
    println!(
        "  upd p50/p99: upper bounds of the server's histogram buckets (arrival to need list in \
         place); ping: round trip after an update, at the clients; lists taken/made: need lists \
         the sessions changed to / of those, computed (the rest came from the shared cache; \
         exact answers are never cached); KB/sess: resident memory growth per added session \
         (at the first levels it also holds the map's pages and shared lists as they fill)"
    );
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let json = serde_json::json!({
        "server": a.server,
        "transport": "stream",
        "frame_ms": a.budget_ms,
        "rate_bytes_per_s": rate,
        "seconds_per_level": a.stress_seconds,
        "policy": policy_spec(&policy),
        "cores": std::thread::available_parallelism().map_or(1, |n| n.get()),
        "levels": levels,
        "memory_per_session_bytes": stress_stream::memory_per_session(&levels),
    });
    let out = a.out.join("stress.json");
    std::fs::write(&out, serde_json::to_vec_pretty(&json)?)
        .with_context(|| format!("writing {}", out.display()))?;
    let plot = a.out.join("scaling.png");
    let mut runs = vec![(stress_plot::run_name(&levels), &levels[..])];
    if let Some(b) = &baseline {
        runs.push((stress_plot::run_name(b), &b[..]));
        if runs[0].0 == runs[1].0 {
            runs = vec![("this run", &levels[..]), ("baseline", &b[..])];
        }
    }
    stress_plot::scaling(&plot, &runs)?;
    println!("  wrote {} and {}", out.display(), plot.display());
    Ok(())
}
