//! `portico loadtest`: many simulated clients against a real server, to
//! measure a prefetch policy the way Funkhouser §5.2–5.3 measured his (Tables 5.1–5.10,
//! Figures 5.11–5.13), but over a network.
//!
//! Each client is a tokio task playing the real client's frame loop without a GPU
//! ([`sim`]): the same byte-budgeted [`portico_client::cache::ObjectCache`], the same frame
//! decision ([`portico_client::frame`]) with the `optimize` elider and the default cost model,
//! frames at the frame budget in real time, and the render never waits: what is not resident is
//! skipped and counted. Clients replay one path, client `i` starting `i/N` of the way along it
//! (wrapping), and talk to the server through an emulated link each ([`link`]: round-trip time
//! per request, a token bucket at the link rate): over HTTP pull (`/v1/prefetch`,
//! `/v1/batch`), or over server push (`/v1/stream`), each policy once per transport asked for,
//! in the same session.
//!
//! Policies run one after another with fresh clients (empty caches) on the same path and link.
//! Two baselines run in the same session: **demand** fetch (no lookahead: each frame fetch the
//! missing LODs the elider wanted) and an **oracle** that knows the future path (fetches what
//! an omniscient client draws in the next [`ORACLE_LOOKAHEAD_FRAMES`] frames, nearest first).
//!
//! [`run`] writes `summary.json`, `report.md` (tables in Funkhouser's layout, [`report`]),
//! `frames.csv` (client 0's frames per policy) and two PNG plots ([`plot`]).
//!
//! [`cache_sweep`] runs it all at several cache budgets. This file holds the configuration and
//! [`run`]; the summary's types are in `summary`, the
//! session that plays every run in `runner`, and the per-policy figures in `aggregate`.

pub mod cache_sweep;
pub mod cpu;
pub mod link;
pub mod plot;
pub mod report;
pub mod sim;
pub mod stress;
pub mod stress_plot;
pub mod stress_stream;
pub mod sweep;
pub mod waste;
pub mod world;

mod aggregate;
mod runner;
mod summary;

pub use link::{Link, LinkError};
pub use summary::{ClientFigures, LoadtestSummary, Machine, PolicyResult};
pub use sweep::{UnknownSweep, grid};

use anyhow::{Context, Result, bail};
use portico_data::path::CameraPath;
use portico_data::texture::TexelFormat;
pub use portico_native::stream::Transport;
use portico_protocol::Policy;
use runner::run_all;
use sim::Mode;
use std::path::PathBuf;
use std::time::Instant;

/// The file in `drawn/` that holds run `run`'s client 0 frames ([`crate::drawn::DrawnLog`]):
/// the name with everything but ASCII letters, digits and `-` made `_`, then `.json`.
pub fn drawn_file(run: &str) -> String {
    let stem: String = run
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("{stem}.json")
}

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
    /// How the policies' clients get their segments: each policy runs once per transport, in
    /// this order (pull runs keep the policy's name, push runs add `+push`); the baselines
    /// always pull (their lists are their own).
    pub transports: Vec<Transport>,
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

    /// How the clients hold textures: block-compressed when the first policy says so (`bc=1`);
    /// every run of the session, the baselines too, then holds them so.
    pub fn texels(&self) -> TexelFormat {
        match self.policies.first() {
            Some((_, p)) if p.block_textures => TexelFormat::Block,
            _ => TexelFormat::Rgba8,
        }
    }

    /// The runs in order: the policies, then the baselines.
    fn runs(&self) -> Vec<(String, Mode)> {
        let mut runs: Vec<(String, Mode)> = Vec::new();
        for (name, p) in &self.policies {
            let policy = Policy {
                // The lookahead stops at the cache's own part of the budget.
                cache_bytes: portico_client::cache::split_budget(self.cache_bytes).0,
                frame_time_s: self.budget_s as f32,
                screen: [world::SCREEN.0, world::SCREEN.1],
                block_textures: self.texels() == TexelFormat::Block,
                ..*p
            };
            for &t in &self.transports {
                let run = match t {
                    Transport::Pull => name.clone(),
                    Transport::Push => format!("{name}+push"),
                };
                runs.push((run, Mode::Prefetch(policy, t)));
            }
        }
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
        if !self.policies.is_empty() && self.transports.is_empty() {
            bail!("no transport to run the policies over (expected pull, push or both)");
        }
        if self.policies.is_empty() && !self.baselines {
            bail!("nothing to run: no policies and no baselines");
        }
        Ok(())
    }
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
