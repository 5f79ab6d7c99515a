//! `portico demo [--preset small] [--out DIR] [--serve]`: the whole system in one command.
//!
//! Generates a furnished building, builds its display database, serves it on a free loopback
//! port in this process, walks a tour through it with the real headless client, runs a short
//! load test of the prefetch policy against the same server, and writes `DIR/report.md` with
//! the frame-time and prefetch figures, a contact sheet of frames, a bird's-eye view and plots.

use crate::cmd::values;
use crate::cmd::walk::print_summary;
use crate::progress::Bars;
use anyhow::{Context, Result};
use portico_client::elision::Algorithm;
use portico_client::policy::policy_spec;
use portico_data::Database;
use portico_data::build::{BuildOptions, build_with};
use portico_data::import::import_file;
use portico_data::path::{CameraPath, PathKind, generate_around};
use portico_generator::{Params, Preset};
use portico_lab::loadtest::{
    Link, LoadtestConfig, LoadtestSummary, Transport, run as run_loadtest,
};
use portico_lab::verdict::Verdict;
use portico_native::walk::{WalkConfig, WalkSummary, walk};
use portico_protocol::Policy;
use portico_render::Renderer;
use portico_render::sheet;
use portico_server::{AppState, Config};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `portico demo`.
#[derive(clap::Args)]
pub struct Args {
    /// Building size.
    #[arg(long, default_value = "small", value_parser = values::preset())]
    preset: Preset,
    /// Random seed (building and tour).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output directory.
    #[arg(
        short = 'o',
        long,
        visible_alias = "output",
        value_name = "DIR",
        default_value = "portico-demo"
    )]
    out: PathBuf,
    /// Legs of the tour (rooms visited).
    #[arg(long, default_value_t = values::LEGS)]
    legs: usize,
    /// Frame budget, ms.
    #[arg(long, default_value_t = portico_client::defaults::FRAME_BUDGET_MS)]
    budget_ms: f64,
    /// Client cache budget, MiB (2^20 bytes).
    #[arg(long, default_value_t = portico_client::defaults::CACHE_MB)]
    cache_mb: u64,
    /// Image size WxH, pixels.
    #[arg(long, default_value = values::SIZE)]
    size: String,
    /// Stop the walk after this many frames.
    #[arg(long, default_value_t = 600)]
    max_frames: u64,
    /// Simulated clients in the load test (0 = skip it).
    #[arg(long, default_value_t = 4)]
    clients: usize,
    /// Frames each simulated client plays.
    #[arg(long, default_value_t = 300)]
    loadtest_frames: u64,
    /// Then serve the building with the browser viewer (as `portico serve`) until Ctrl-C.
    #[arg(long)]
    serve: bool,
}

/// Timings of the demo's steps.
struct Steps {
    lines: Vec<(String, f64)>,
    /// How many steps the demo announces.
    total: usize,
}

impl Steps {
    /// Runs one step between a line that says what it does and one that says how long it took.
    fn time<T>(&mut self, name: &str, what: &str, f: impl FnOnce() -> Result<T>) -> Result<T> {
        let t0 = Instant::now();
        let n = self.lines.len() + 1;
        eprintln!("[{n}/{}] {name}: {what}", self.total);
        let v = f()?;
        let s = t0.elapsed().as_secs_f64();
        eprintln!("      {name} done in {s:.1} s");
        self.lines.push((name.to_string(), s));
        Ok(v)
    }
}

/// Runs every step and writes the report.
pub fn run(a: Args) -> Result<()> {
    let t0 = Instant::now();
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let out = a.out.canonicalize()?;
    let mut steps = Steps {
        lines: Vec::new(),
        total: if a.clients > 0 { 6 } else { 5 },
    };
    let glb = out.join("building.glb");
    let db_path = out.join("building.portico");
    steps.time("generate", "a furnished building as glTF", || {
        generate_building(&a, &glb)
    })?;
    steps.time(
        "build",
        "LODs, cells and portals, visibility, impostors",
        || build_database(&glb, &db_path),
    )?;
    let state = AppState::open(&db_path, Config::default())?;
    let server = Server::start(state.clone())?;
    eprintln!("      serving it on {}", server.url);
    let path = steps.time("path", "a tour through the rooms", || {
        tour(&db_path, &a, &out)
    })?;
    let walked = steps.time(
        "walk",
        "the headless client walks the tour in real time, fetching as it goes",
        || walk_tour(&a, &server.url, &path, &out),
    )?;
    print_summary(&walked);
    let pictures = steps.time("pictures", "contact sheet and bird's-eye view", || {
        pictures(&a, &db_path, &path, &out)
    })?;
    let load = match a.clients {
        0 => None,
        n => Some(steps.time(
            "loadtest",
            &format!("{n} simulated clients: prefetch against demand fetch and an oracle"),
            || loadtest(&a, n, &server.url, &path, &out),
        )?),
    };
    server.stop();
    let mut verdicts = portico_lab::verdict::walk(&walked);
    if let Some((_, v)) = &load {
        verdicts.extend(v.iter().cloned());
    }
    let report = report(
        &a,
        &state,
        &Outcome {
            w: &walked,
            load: load.as_ref().map(|(s, _)| s.as_str()),
            verdicts: &verdicts,
            pics: &pictures,
            steps: &steps,
            total_s: t0.elapsed().as_secs_f64(),
        },
    );
    std::fs::write(out.join("report.md"), report)?;
    let met = verdicts.iter().filter(|v| v.met).count();
    eprintln!(
        "\ndemo done in {:.1} s: {met} of {} targets met.",
        t0.elapsed().as_secs_f64(),
        verdicts.len()
    );
    for v in &verdicts {
        eprintln!("  {v}");
    }
    eprintln!("Everything is in {}:", out.display());
    for f in [
        "report.md",
        "contact_sheet.png",
        "birdseye.png",
        "walk/frames.csv",
        "walk/summary.json",
        "loadtest/report.md",
    ] {
        if out.join(f).exists() {
            eprintln!("  {}", out.join(f).display());
        }
    }
    if a.serve {
        eprintln!();
        return crate::cmd::serve::run(crate::cmd::serve::Args::for_file(&db_path));
    }
    let viewer = crate::cmd::serve::viewer_dir(None).ok().flatten();
    // The binary as it was run (a newcomer ran `cargo run`: `portico` is not on the PATH yet).
    let exe = std::env::current_exe()
        .map(|e| e.display().to_string())
        .unwrap_or_else(|_| "portico".into());
    eprintln!(
        "\nWalk it in a browser: `{exe} serve {}`{}, then open http://127.0.0.1:7878/ \
         (or run the demo with --serve).",
        db_path.display(),
        if viewer.is_some() {
            ""
        } else {
            " (after `bash web/build.sh`, which builds the viewer)"
        }
    );
    Ok(())
}

fn generate_building(a: &Args, glb: &Path) -> Result<()> {
    let params = Params {
        preset: a.preset,
        seed: a.seed,
        floors: None,
    };
    let b = portico_generator::generate(&params, &mut |_| {})?;
    std::fs::write(glb, &b.glb).with_context(|| format!("writing {}", glb.display()))?;
    eprintln!("{} ({:.1} MB)", glb.display(), b.glb.len() as f64 / 1e6);
    Ok(())
}

fn build_database(glb: &Path, db: &Path) -> Result<()> {
    let bars = Bars::new();
    let mut painter = portico_render::impostor::Painter::new().ok();
    let r = build_with(
        import_file(glb)?,
        db,
        &BuildOptions::default(),
        &bars,
        painter
            .as_mut()
            .map(|p| p as &mut dyn portico_data::hierarchy::ImpostorPainter),
    )?;
    bars.finish();
    eprintln!(
        "{} ({:.1} MB)",
        db.display(),
        r.written.file_bytes as f64 / 1e6
    );
    Ok(())
}

fn tour(db: &Path, a: &Args, out: &Path) -> Result<CameraPath> {
    let db = Database::open(db)?;
    let graph = db.cell_graph()?.context("the demo building has no cells")?;
    let objects: Vec<_> = db.header().instances.iter().map(|i| i.bounds).collect();
    let p = generate_around(
        &graph,
        &objects,
        PathKind::Tour,
        a.legs,
        a.seed,
        portico_data::person::WALK_SPEED,
        portico_data::person::TURN_DEGREES.to_radians(),
    )
    .context("no live cells")?;
    std::fs::write(out.join("path.json"), serde_json::to_vec_pretty(&p)?)?;
    Ok(p)
}

fn walk_tour(a: &Args, url: &str, path: &CameraPath, out: &Path) -> Result<WalkSummary> {
    let budget_s = a.budget_ms / 1e3;
    let frames = ((path.duration() as f64 / budget_s).ceil() as u64 + 1).min(a.max_frames);
    let cfg = WalkConfig {
        server: url.to_string(),
        token: None,
        path: path.clone(),
        budget_s,
        cache_bytes: a.cache_mb << 20,
        size: crate::cmd::walk::parse_size(&a.size)?,
        elision: Algorithm::Optimize,
        policy: Policy::default(),
        out: Some(out.join("walk")),
        // More frames than the sheet shows: it keeps twelve that differ.
        png_every: (frames / 36).max(1),
        max_frames: Some(a.max_frames),
        pace: true,
        fovy: portico_client::defaults::fov_y(),
        max_speed: 2.0,
        max_turn: 2.0,
        transport: portico_native::stream::Transport::Push,
        paged: true,
    };
    let bars = Bars::new();
    bars.start("walk", frames);
    let s = walk(&cfg, &mut |_, _| bars.inc(1))?;
    bars.finish();
    Ok(s)
}

/// Paths of the pictures made.
struct Pictures {
    sheet: bool,
    birdseye: bool,
}

fn pictures(a: &Args, db: &Path, path: &CameraPath, out: &Path) -> Result<Pictures> {
    let mut frames: Vec<PathBuf> = std::fs::read_dir(out.join("walk/frames"))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        // The first frame is drawn before anything has arrived (the client never waits): sky.
        .filter(|p| !p.ends_with("frame_00000.png"))
        .collect();
    frames.sort();
    let images: Vec<image::RgbaImage> = frames
        .iter()
        .filter_map(|p| image::open(p).ok().map(|i| i.to_rgba8()))
        .collect();
    // Twelve frames that differ (standing still or turning slowly repeats a frame).
    let images = sheet::distinct(images, 12, 2.0);
    let sheet = match sheet::contact_sheet(&images, 4, 240) {
        Some(s) => s.save(out.join("contact_sheet.png")).is_ok(),
        None => false,
    };
    let (w, h) = crate::cmd::walk::parse_size(&a.size)?;
    let mut r = Renderer::new(w * 2, h * 2)?;
    let db = Database::open(db)?;
    let view = sheet::birdseye(&mut r, &db, path)?;
    let srgb = |c: [f32; 4]| c.map(|v| (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8);
    let [p, s, e] = [sheet::PATH_COLOUR, sheet::START_COLOUR, sheet::END_COLOUR].map(|c| {
        let [r, g, b, _] = srgb(c);
        [r, g, b]
    });
    let img = portico_lab::picture::scale_and_legend(
        &view.image,
        view.metres_per_pixel,
        &[(s, "start"), (p, "the path, every 0.5 s"), (e, "end")],
    )?;
    let birdseye = img.save(out.join("birdseye.png")).is_ok();
    Ok(Pictures { sheet, birdseye })
}

/// A short load test of the default prefetch policy against demand fetch and the oracle, on
/// the walked path; returns its summary as a Markdown section for the report, and its verdicts.
fn loadtest(
    a: &Args,
    clients: usize,
    url: &str,
    path: &CameraPath,
    out: &Path,
) -> Result<(String, Vec<Verdict>)> {
    let policy = Policy::default();
    let cfg = LoadtestConfig {
        server: url.to_string(),
        token: None,
        clients,
        path: path.clone(),
        policies: vec![(policy_spec(&policy), policy)],
        transports: vec![Transport::Pull, Transport::Push],
        baselines: true,
        link: Link::parse("rtt=20ms,rate=100mbit").map_err(anyhow::Error::msg)?,
        cache_bytes: a.cache_mb << 20,
        budget_s: a.budget_ms / 1e3,
        max_frames: Some(a.loadtest_frames),
        out: out.join("loadtest"),
    };
    let bars = Bars::new();
    let mut started = false;
    let mut shown = 0;
    let s = run_loadtest(&cfg, &mut |done, total| {
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
    crate::cmd::loadtest::print_summary(&s, &cfg.out);
    Ok((loadtest_section(&s), portico_lab::verdict::loadtest(&s)))
}

/// The load test's headline table: one row per run, and prefetch against demand fetch.
fn loadtest_section(s: &LoadtestSummary) -> String {
    let mut r = String::new();
    let _ = writeln!(
        r,
        "{} simulated clients x {} frames on the walked path, link {}, cache {} MiB each \
         (full report: `loadtest/report.md`).\n",
        s.clients,
        s.frames_per_client,
        s.link_spec,
        s.cache_bytes >> 20
    );
    let _ = writeln!(
        r,
        "| run | LODs skipped/frame (mean, max) | objects skipped/frame | cache hit rate | MB fetched per client | MB never drawn per client | request->resident p50 / p99 ms |\n|---|---|---|---|---|---|---|"
    );
    for p in &s.policies {
        let _ = writeln!(
            r,
            "| `{}` | {:.2}, {:.0} | {:.2} | {:.3} | {:.1} | {:.1} | {:.0} / {:.0} |",
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
        let _ = writeln!(
            r,
            "\nPrefetch `{}` skips {:.2} LODs per frame against demand fetch's {:.2}.",
            best.name, best.lods_skipped_mean, demand.lods_skipped_mean
        );
    }
    for plot in &s.plots {
        let _ = writeln!(r, "\n![{plot}](loadtest/{plot})");
    }
    r
}

/// The server, on a runtime of its own, on a free loopback port.
struct Server {
    url: String,
    stop: tokio::sync::oneshot::Sender<()>,
    thread: std::thread::JoinHandle<()>,
}

impl Server {
    fn start(state: std::sync::Arc<AppState>) -> Result<Server> {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()?;
        let listener = rt.block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))?;
        let url = format!("http://{}", listener.local_addr()?);
        let (stop, rx) = tokio::sync::oneshot::channel::<()>();
        let thread = std::thread::spawn(move || {
            let served = rt.block_on(portico_server::serve(state, listener, async move {
                let _ = rx.await;
            }));
            if let Err(e) = served {
                eprintln!("server stopped: {e}");
            }
        });
        Ok(Server { url, stop, thread })
    }

    fn stop(self) {
        let _ = self.stop.send(());
        let _ = self.thread.join();
    }
}

/// What the report tells.
struct Outcome<'a> {
    w: &'a WalkSummary,
    /// The load test's section, if it ran.
    load: Option<&'a str>,
    verdicts: &'a [Verdict],
    pics: &'a Pictures,
    steps: &'a Steps,
    total_s: f64,
}

fn report(a: &Args, state: &AppState, o: &Outcome<'_>) -> String {
    let Outcome {
        w,
        load,
        verdicts,
        pics,
        steps,
        total_s,
    } = *o;
    let ms = |x: f64| x * 1e3;
    let db = state.db();
    let mut r = String::new();
    let _ = writeln!(
        r,
        "# Portico demo: `{}` preset, seed {}\n",
        preset_name(a.preset),
        a.seed
    );
    let _ = writeln!(
        r,
        "Generated, built, served on loopback, walked with the headless wgpu client ({}), in {:.1} s.\n",
        w.adapter, total_s
    );
    let met = verdicts.iter().filter(|v| v.met).count();
    let _ = writeln!(
        r,
        "## Verdicts: {met} of {} targets met\n\n{}",
        verdicts.len(),
        portico_lab::verdict::table(verdicts)
    );
    let _ = writeln!(r, "## Steps\n\n| step | seconds |\n|---|---|");
    for (name, s) in &steps.lines {
        let _ = writeln!(r, "| {name} | {s:.2} |");
    }
    let h = db.header();
    let _ = writeln!(
        r,
        "\n## Model\n\n{} instances of {} objects, {} triangles at the finest LOD, database {:.1} MB ({} segments), id `{}`.\n",
        h.instances.len(),
        h.objects.len(),
        w.model_triangles,
        db.file_len() as f64 / 1e6,
        db.segments().len(),
        state.database_id
    );
    let _ = writeln!(
        r,
        "## Walk ({} frames, budget {:.0} ms, cache {} MiB, elision {})\n",
        w.frames,
        ms(w.budget_s),
        a.cache_mb,
        w.elision
    );
    let _ = writeln!(
        r,
        "| figure | mean | sd | p95 | p99 | max |\n|---|---|---|---|---|---|"
    );
    for (name, s, scale) in [
        ("frame time (ms)", &w.frame_s, 1e3),
        ("render time (ms)", &w.render_s, 1e3),
        ("triangles drawn", &w.drawn_triangles, 1.0),
        ("visible objects", &w.visible_objects, 1.0),
        ("LODs skipped", &w.lods_skipped, 1.0),
        ("objects skipped", &w.objects_skipped, 1.0),
        ("fetch latency (ms)", &w.fetch_latency_s, 1e3),
    ] {
        let _ = writeln!(
            r,
            "| {name} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            s.mean * scale,
            s.sd * scale,
            s.p95 * scale,
            s.p99 * scale,
            s.max * scale
        );
    }
    let _ = writeln!(
        r,
        "\nFrames over budget: {}. Drawn per frame: {:.3} % of the model's triangles. Cache peak {:.1} of {:.1} MiB; {} segments ({:.1} MB) read, {} released.\n",
        w.frames_over_budget,
        w.drawn_fraction * 100.0,
        w.cache_peak_bytes as f64 / crate::cmd::walk::MIB,
        w.cache_budget as f64 / crate::cmd::walk::MIB,
        w.segments_read,
        w.bytes_read as f64 / 1e6,
        w.evictions
    );
    let _ = writeln!(
        r,
        "Per-frame rows: `walk/frames.csv`; summary: `walk/summary.json`.\n"
    );
    if pics.sheet {
        let _ = writeln!(r, "## Frames\n\n![frames](contact_sheet.png)\n");
    }
    if pics.birdseye {
        let _ = writeln!(
            r,
            "## Bird's-eye view of the first storey walked\n\nSeen from above with everything over eye height left out; the path is marked every half second from the green start to the blue end, and the bar in the lower left gives the scale.\n\n![birdseye](birdseye.png)\n"
        );
    }
    if let Some(l) = load.filter(|l| !l.is_empty()) {
        let _ = writeln!(r, "## Load test\n\n{l}\n");
    }
    r
}

fn preset_name(p: Preset) -> &'static str {
    match p {
        Preset::Tiny => "tiny",
        Preset::Small => "small",
        Preset::Soda => "soda",
        Preset::Mega => "mega",
    }
}
