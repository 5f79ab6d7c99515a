//! `portico bench --db FILE.portico (--path FILE | --path-kind tour [--legs L --seed S])
//! --budget-ms B [--size 640x480] [--max-frames F] [--algorithms regular,none,static,feedback,optimize,impostors,coarsest]
//! [--replay LOADTEST/drawn/RUN.json ...] -o DIR`: frame rate and image fidelity of the detail elision algorithms
//! (Funkhouser Table 4.3 / Fig. 4.22, RRB §5.2-5.3). The work is `portico_lab::bench`.

use crate::cmd::values;
use crate::progress::Bars;
use anyhow::Result;
use portico_data::Database;
use portico_data::path::CameraPath;
use portico_lab::bench::{BenchConfig, BenchSummary, RunKind, report};
use std::path::PathBuf;

/// Arguments of `portico bench`.
#[derive(clap::Args)]
pub struct Args {
    /// The display database.
    #[arg(long)]
    db: PathBuf,
    #[command(flatten)]
    route: crate::cmd::path::PathArgs,
    /// Frame-time budget of the elision algorithms, milliseconds.
    #[arg(long, default_value_t = portico_client::defaults::FRAME_BUDGET_MS)]
    budget_ms: f64,
    /// Image size WxH, pixels.
    #[arg(long, default_value = values::SIZE)]
    size: String,
    /// Stop after this many frames.
    #[arg(long)]
    max_frames: Option<u64>,
    /// Runs, comma-separated (regular is always run first: it is the fidelity reference).
    #[arg(long, default_value = "regular,none,static,feedback,optimize", value_delimiter = ',',
          value_parser = values::bench_run())]
    algorithms: Vec<String>,
    /// A load test's drawn-frames log (its `drawn/<run>.json`) to draw and score as a run of
    /// its own: the PSNR of what a streamed client drew. Repeatable; the load test's
    /// --budget-ms must equal --frame-step-ms.
    #[arg(long, value_name = "FILE")]
    replay: Vec<PathBuf>,
    /// Path time between frames, milliseconds (frame i shows the path at i x this).
    #[arg(long, default_value_t = 50.0)]
    frame_step_ms: f64,
    /// Side of the area of interest around each critical vertex, 1-10 pixels (RRB §5.3.4).
    #[arg(long, default_value_t = 5)]
    patch_px: u32,
    /// Vertical field of view, degrees.
    #[arg(long, default_value_t = portico_client::defaults::FOV_Y_DEGREES)]
    fov: f32,
    /// Output directory (summary.json, report.md, frames.csv, PNG plots).
    #[arg(short = 'o', long, visible_alias = "output", value_name = "DIR")]
    out: PathBuf,
    /// Print the summary as JSON instead of the table.
    #[arg(long)]
    json: bool,
}

/// Loads the path file or generates a standard path through the database's cells.
fn load_path(a: &Args) -> Result<CameraPath> {
    a.route
        .load(|| crate::cmd::path::Scene::of_database(&Database::open(&a.db)?))
}

/// Runs the benchmark with a progress bar and prints the table.
pub fn run(a: Args) -> Result<()> {
    let path = load_path(&a)?;
    let mut cfg = BenchConfig::new(a.db.clone(), path, a.budget_ms / 1e3, a.out.clone());
    cfg.size = crate::cmd::walk::parse_size(&a.size)?;
    cfg.max_frames = a.max_frames;
    cfg.algorithms = RunKind::parse_list(&a.algorithms.join(","))?;
    cfg.dt_s = a.frame_step_ms / 1e3;
    cfg.patch_px = a.patch_px;
    cfg.replays = a.replay.clone();
    cfg.fovy = a.fov.clamp(10.0, 150.0).to_radians();
    let bars = Bars::new();
    let mut started = false;
    let summary = portico_lab::bench::run(&cfg, &mut |_, total| {
        if !started {
            bars.start("bench", total);
            started = true;
        }
        bars.inc(1);
    })?;
    bars.finish();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print_summary(&summary, &a.out);
    }
    Ok(())
}

/// The table and where the files are.
fn print_summary(s: &BenchSummary, out: &std::path::Path) {
    println!(
        "bench: {} ({}), {} frames at {}x{}, budget {:.0} ms, on {}",
        s.model.name,
        s.model.database_id,
        s.parameters.frames,
        s.parameters.size.0,
        s.parameters.size.1,
        s.parameters.budget_s * 1e3,
        s.adapter
    );
    println!("{}", report::self_test_line(s));
    println!();
    print!("{}", report::table(&s.runs));
    println!();
    println!(
        "critical vertices: {} of {} ({:.1} %), {:.0} visible per frame",
        s.critical.counts.critical,
        s.critical.counts.vertices,
        s.critical.fraction * 100.0,
        s.critical.visible_per_frame.mean
    );
    println!("wrote {} in {:.1} s", out.display(), s.wall_s);
}
