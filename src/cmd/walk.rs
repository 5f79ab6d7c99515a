//! `portico walk --server URL (--path FILE | --path-kind tour) --budget-ms 50 --cache-mb 64
//! --size 640x480 --elision optimize --out DIR`: the headless walkthrough client.

use crate::cmd::values;
use crate::progress::Bars;
use anyhow::{Context, Result, bail};
use portico_client::defaults;
use portico_client::elision::Algorithm;
use portico_client::policy::parse_policy;
use portico_data::path::CameraPath;
use portico_native::net::Remote;
use portico_native::walk::{WalkConfig, WalkSummary, walk};
use portico_protocol::Policy;
use std::path::PathBuf;

/// Arguments of `portico walk`.
#[derive(clap::Args)]
pub struct Args {
    /// Server base URL.
    #[arg(long, default_value = "http://127.0.0.1:7878")]
    server: String,
    /// Bearer token (also read from PORTICO_TOKEN).
    #[arg(long, env = "PORTICO_TOKEN", hide_env_values = true)]
    token: Option<String>,
    #[command(flatten)]
    route: crate::cmd::path::PathArgs,
    /// Frame-time budget in milliseconds.
    #[arg(long, default_value_t = defaults::FRAME_BUDGET_MS)]
    budget_ms: f64,
    /// Client cache budget, MiB (2^20 bytes).
    #[arg(long, default_value_t = defaults::CACHE_MB)]
    cache_mb: u64,
    /// Image size WxH, pixels.
    #[arg(long, default_value = values::SIZE)]
    size: String,
    /// Detail elision.
    #[arg(long, default_value = "optimize", value_parser = values::elision())]
    elision: Algorithm,
    #[arg(long, default_value = "", help = values::POLICY_HELP)]
    policy: String,
    /// How segments come: `push` (one WebSocket, /v1/stream; HTTP pull when no session opens)
    /// or `pull` (/v1/prefetch and /v1/batch each round trip).
    #[arg(long, default_value = "push")]
    transport: portico_native::stream::Transport,
    /// Read the whole manifest before the first frame (on a big model, megabytes), instead of
    /// the core manifest and then each cell's page with its stab list.
    #[arg(long)]
    whole_manifest: bool,
    /// Output directory for frames.csv, summary.json and PNGs.
    #[arg(short = 'o', long, visible_alias = "output", value_name = "DIR")]
    out: Option<PathBuf>,
    /// Save every N-th frame as PNG (0 = none).
    #[arg(long, default_value_t = 0)]
    frames_png: u64,
    /// Stop after this many frames.
    #[arg(long)]
    max_frames: Option<u64>,
    /// Run frames back to back instead of holding each to the budget.
    #[arg(long)]
    no_pace: bool,
    /// Vertical field of view, degrees.
    #[arg(long, default_value_t = defaults::FOV_Y_DEGREES)]
    fov: f32,
    /// Print the summary as JSON.
    #[arg(long)]
    json: bool,
    /// Walk interactively in a window (Funkhouser's mouse and keyboard navigation: hold the
    /// left button to walk towards the cursor, right to back away, middle to spin; Control to
    /// look up and down; arrows and keypad step; Escape quits). Starts where the path starts.
    /// Needs a build with `--features window`.
    #[arg(long)]
    window: bool,
    /// With --window: save the walk as a path JSON file here when the window closes.
    #[arg(long, requires = "window")]
    record: Option<PathBuf>,
}

/// Bytes in a MiB: cache budgets are binary (`--cache-mb 64` is 64 MiB), data volumes decimal.
pub const MIB: f64 = 1_048_576.0;

/// Parses `WxH`.
pub fn parse_size(s: &str) -> Result<(u32, u32)> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .with_context(|| format!("size {s:?} is not WxH"))?;
    let (w, h): (u32, u32) = (w.parse()?, h.parse()?);
    if !(16..=8192).contains(&w) || !(16..=8192).contains(&h) {
        bail!("size {s:?}: each side must be 16..=8192 pixels");
    }
    Ok((w, h))
}

/// The path of a walk or load test: the file, or a standard path through the server's cells.
pub fn load_path(
    server: &str,
    token: Option<String>,
    route: &crate::cmd::path::PathArgs,
) -> Result<CameraPath> {
    route.load(|| crate::cmd::path::Scene::of_server(&Remote::new(server, token)?))
}

/// Runs the walk with a progress bar and prints the summary.
pub fn run(a: Args) -> Result<()> {
    let path = load_path(&a.server, a.token.clone(), &a.route)?;
    let policy = parse_policy(&a.policy, Policy::default()).map_err(anyhow::Error::msg)?;
    let cfg = WalkConfig {
        server: a.server,
        token: a.token,
        path,
        budget_s: a.budget_ms.max(1.0) / 1e3,
        cache_bytes: a.cache_mb << 20,
        size: parse_size(&a.size)?,
        elision: a.elision,
        policy,
        out: a.out,
        png_every: a.frames_png,
        max_frames: a.max_frames,
        pace: !a.no_pace,
        fovy: a.fov.clamp(10.0, 150.0).to_radians(),
        max_speed: defaults::MAX_SPEED,
        max_turn: defaults::MAX_TURN,
        transport: a.transport,
        paged: !a.whole_manifest,
    };
    if a.window {
        let summary = interactive(&cfg, a.record)?;
        print_summary(&summary);
        return Ok(());
    }
    let bars = Bars::new();
    let mut started = false;
    let summary = walk(&cfg, &mut |done, total| {
        if !started {
            bars.start("walk", total);
            started = true;
        }
        bars.inc(1);
        let _ = done;
    })?;
    bars.finish();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print_summary(&summary);
    }
    if summary.database_changed {
        eprintln!(
            "warning: the server's database changed during the walk (rebuilt and reloaded): reading stopped; walk again to see the new one"
        );
    }
    if summary.frames > 0 && summary.visible_objects.max <= 0.0 {
        bail!(
            "the walk saw nothing in {} frames: its path ({}) never looks at the model; try --path-kind orbit",
            summary.frames,
            summary.path
        );
    }
    if summary.frames > 0 && summary.drawn_triangles.max <= 0.0 {
        eprintln!(
            "warning: nothing arrived in time to be drawn in {} frames (the client never waits); walk longer",
            summary.frames
        );
    }
    Ok(())
}

#[cfg(feature = "window")]
fn interactive(cfg: &WalkConfig, record: Option<PathBuf>) -> Result<WalkSummary> {
    portico_native::window::run(cfg, &portico_native::window::WindowOptions { record })
}

#[cfg(not(feature = "window"))]
fn interactive(_: &WalkConfig, _: Option<PathBuf>) -> Result<WalkSummary> {
    bail!(
        "this portico was built without the `window` feature; build it with \
         `cargo build --release --features window`"
    )
}

/// A short human summary.
pub fn print_summary(s: &WalkSummary) {
    print_figures(s);
    for v in portico_lab::verdict::walk(s) {
        println!("  {v}");
    }
}

fn print_figures(s: &WalkSummary) {
    let ms = |x: f64| x * 1e3;
    println!(
        "walk: {} frames of {} on {} ({})",
        s.frames, s.model, s.adapter, s.elision
    );
    println!(
        "  frame time ms: mean {:.1} sd {:.1} p95 {:.1} p99 {:.1} max {:.1} (budget {:.0}; {} over)",
        ms(s.frame_s.mean),
        ms(s.frame_s.sd),
        ms(s.frame_s.p95),
        ms(s.frame_s.p99),
        ms(s.frame_s.max),
        ms(s.budget_s),
        s.frames_over_budget
    );
    println!(
        "  drawn: {:.0} triangles mean ({:.3}% of {}), visible objects {:.1} mean",
        s.drawn_triangles.mean,
        s.drawn_fraction * 100.0,
        s.model_triangles,
        s.visible_objects.mean
    );
    println!(
        "  skipped per frame: LODs {:.2} mean / {:.0} max, objects {:.2} mean / {:.0} max",
        s.lods_skipped.mean, s.lods_skipped.max, s.objects_skipped.mean, s.objects_skipped.max
    );
    match s.first_complete {
        Some(f) => println!(
            "  first complete frame (every visible object drawn): frame {} after {:.0} KB read",
            f.frame,
            f.bytes as f64 / 1e3
        ),
        None => println!("  no frame drew every visible object"),
    }
    println!(
        "  cache: peak {:.1} of {:.1} MiB (GPU memory held, queue and stand-ins included: {:.1} MiB), {} evictions; read {} segments, {:.1} MB; fetch latency p50 {:.1} ms p99 {:.1} ms",
        s.cache_peak_bytes as f64 / MIB,
        s.cache_budget as f64 / MIB,
        s.gpu_held_peak_bytes as f64 / MIB,
        s.evictions,
        s.segments_read,
        s.bytes_read as f64 / 1e6,
        ms(s.fetch_latency_s.p50),
        ms(s.fetch_latency_s.p99)
    );
}
