//! `portico loadtest --cache-mb 4,16,64,256`: the whole load test (the policies and both
//! baselines, fresh clients each) once per cache budget, each run into `DIR/cache-<N>mb/`, then
//! one table (`DIR/cache_sweep.md`, `DIR/cache_sweep.json`), one plot
//! (`DIR/cache_sweep.png`) and one verdict across the budgets.
//!
//! The question is Funkhouser's (§5.3, Tables 5.5–5.7 vary the cache): reading ahead pays only
//! while what it reads fits in the cache beside what the current view needs. A lookahead larger
//! than that evicts what the next frames draw, and prefetch then skips more than plain demand
//! fetch (thrash). The sweep shows at which budget that starts.

use super::{LoadtestConfig, LoadtestSummary, PolicyResult, run};
use crate::style::{PALETTE, fonts_available};
use anyhow::{Context, Result, anyhow, bail};
use plotters::prelude::*;
use serde::Serialize;
use std::path::Path;

/// How many more objects per frame than demand fetch prefetch may skip and still count as "no
/// worse" (the means of separate runs differ by about this much with nothing changed).
pub const NO_WORSE_SLACK: f64 = 0.01;

/// One run's headline figures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figures {
    /// The run's name (the policy spec, `demand` or `oracle`).
    pub name: String,
    /// Objects skipped per frame (wanted, nothing resident), mean over every frame.
    pub objects_skipped_mean: f64,
    /// LODs skipped per frame, mean over every frame.
    pub lods_skipped_mean: f64,
    /// Segment bytes fetched per client, MB (10^6 bytes).
    pub mb_per_client: f64,
    /// Share of the fetched bytes never drawn (0..1).
    pub wasted_share: f64,
}

impl Figures {
    fn of(p: &PolicyResult) -> Self {
        Figures {
            name: p.name.clone(),
            objects_skipped_mean: p.objects_skipped_mean,
            lods_skipped_mean: p.lods_skipped_mean,
            mb_per_client: p.bytes_fetched_per_client as f64 / 1e6,
            wasted_share: p.bytes_wasted as f64 / p.bytes_fetched.max(1) as f64,
        }
    }
}

/// One cache budget: the best prefetch policy (fewest LODs skipped) and the two baselines.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    /// The cache budget per client, MiB.
    pub cache_mb: u64,
    /// The best prefetch policy's figures (`None` when no policy ran).
    pub prefetch: Option<Figures>,
    /// Demand fetch's (`None` without baselines).
    pub demand: Option<Figures>,
    /// The oracle's (`None` without baselines).
    pub oracle: Option<Figures>,
}

/// The three runs of a row, in the order of [`Row::runs`].
pub const RUNS: [&str; 3] = ["prefetch", "demand fetch", "oracle"];

impl Row {
    /// Prefetch's, demand fetch's and the oracle's figures (named by [`RUNS`]).
    pub fn runs(&self) -> [Option<&Figures>; 3] {
        [
            self.prefetch.as_ref(),
            self.demand.as_ref(),
            self.oracle.as_ref(),
        ]
    }

    /// The row of one load test's summary.
    pub fn of(s: &LoadtestSummary) -> Self {
        Row {
            cache_mb: s.cache_bytes >> 20,
            prefetch: s.best_prefetch().map(Figures::of),
            demand: s.get("demand").map(Figures::of),
            oracle: s.get("oracle").map(Figures::of),
        }
    }

    /// Whether prefetch skipped no more objects per frame than demand fetch (within
    /// [`NO_WORSE_SLACK`]); `None` without both.
    pub fn no_worse_than_demand(&self) -> Option<bool> {
        let (p, d) = (self.prefetch.as_ref()?, self.demand.as_ref()?);
        Some(p.objects_skipped_mean <= d.objects_skipped_mean + NO_WORSE_SLACK)
    }
}

/// Runs the load test at each budget of `sizes_mb` (MiB, at least two, each > 0) with the
/// rest of `cfg` (no budget twice), writes each run's outputs into `cfg.out/cache-<N>mb/` and the sweep's into
/// `cfg.out`, and returns the rows with the runs' summaries. `progress(run, done, total)`
/// reports each run's client frames.
///
/// # Errors
/// A bad size list, or what [`run`] refuses or fails at (naming the budget).
pub fn sweep(
    cfg: &LoadtestConfig,
    sizes_mb: &[u64],
    progress: &mut dyn FnMut(usize, u64, u64),
) -> Result<(Vec<Row>, Vec<LoadtestSummary>)> {
    if sizes_mb.len() < 2 || sizes_mb.contains(&0) {
        bail!("--cache-mb: a sweep needs at least two budgets, each at least 1 MiB");
    }
    if let Some(d) = sizes_mb
        .iter()
        .find(|&&a| sizes_mb.iter().filter(|&&b| b == a).count() > 1)
    {
        bail!("--cache-mb: {d} MiB is given twice");
    }
    let mut summaries = Vec::with_capacity(sizes_mb.len());
    for (i, &mb) in sizes_mb.iter().enumerate() {
        let one = LoadtestConfig {
            cache_bytes: mb << 20,
            out: cfg.out.join(format!("cache-{mb}mb")),
            ..cfg.clone()
        };
        let s = run(&one, &mut |d, t| progress(i, d, t))
            .with_context(|| format!("the load test with a {mb} MiB cache"))?;
        summaries.push(s);
    }
    let rows: Vec<Row> = summaries.iter().map(Row::of).collect();
    write(&cfg.out, &rows)?;
    Ok((rows, summaries))
}

/// `cache_sweep.md`, `cache_sweep.json` and `cache_sweep.png` in `out`.
fn write(out: &Path, rows: &[Row]) -> Result<()> {
    let md = out.join("cache_sweep.md");
    let mut text = markdown(rows);
    text.push('\n');
    text.push_str(&crate::verdict::table(&[crate::verdict::cache_sweep(rows)]));
    std::fs::write(&md, text).with_context(|| format!("writing {}", md.display()))?;
    let json = out.join("cache_sweep.json");
    std::fs::write(&json, serde_json::to_vec_pretty(rows)?)
        .with_context(|| format!("writing {}", json.display()))?;
    plot(&out.join("cache_sweep.png"), rows, fonts_available())
}

/// The sweep as a Markdown table: per budget, objects and LODs skipped per frame, MB per client
/// and the share never drawn, for prefetch / demand / oracle.
pub fn markdown(rows: &[Row]) -> String {
    let mut s = String::from(
        "| cache MiB | objects skipped p / d / o | LODs skipped p / d / o | MB per client p / d / o | never drawn p / d / o |\n|---|---|---|---|---|\n",
    );
    let three = |r: &Row, f: &dyn Fn(&Figures) -> String| {
        r.runs().map(|x| x.map_or("–".into(), f)).join(" / ")
    };
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            r.cache_mb,
            three(r, &|f| format!("{:.2}", f.objects_skipped_mean)),
            three(r, &|f| format!("{:.3}", f.lods_skipped_mean)),
            three(r, &|f| format!("{:.1}", f.mb_per_client)),
            three(r, &|f| format!("{:.0} %", f.wasted_share * 100.0)),
        ));
    }
    s
}

/// Objects skipped per frame against the cache budget (log₂ axis), one line per run kind.
fn plot(path: &Path, rows: &[Row], text: bool) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("plotting {}: {e}", path.display());
    let root = BitMapBackend::new(path, (900, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let x = |r: &Row| (r.cache_mb.max(1) as f64).log2();
    let (lo, hi) = rows
        .iter()
        .map(x)
        .fold((f64::MAX, f64::MIN), |(a, b), v| (a.min(v), b.max(v)));
    let top = rows
        .iter()
        .flat_map(|r| r.runs().into_iter().flatten())
        .map(|f| f.objects_skipped_mean)
        .fold(0.0f64, f64::max);
    let top = if top > 0.0 { top * 1.4 } else { 1.0 };
    let mut builder = ChartBuilder::on(&root);
    builder.margin(16);
    if text {
        builder
            .caption(
                "Objects skipped per frame by cache budget",
                ("sans-serif", 22),
            )
            .x_label_area_size(44)
            .y_label_area_size(64);
    }
    let mut chart = builder
        .build_cartesian_2d((lo - 0.25)..(hi + 0.25), (-0.03 * top)..top)
        .map_err(|e| err(&e))?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc("cache MiB")
            .y_desc("objects skipped")
            .x_label_formatter(&|v| format!("{:.0}", v.exp2()));
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(|e| err(&e))?;
    for (i, name) in RUNS.iter().enumerate() {
        let color = PALETTE[(i + 1) % PALETTE.len()].to_rgba();
        let points: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| r.runs()[i].map(|v| (x(r), v.objects_skipped_mean)))
            .collect();
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 5, color.filled())))
            .map_err(|e| err(&e))?;
        let drawn = chart
            .draw_series(LineSeries::new(points, color.stroke_width(3)))
            .map_err(|e| err(&e))?;
        if text {
            drawn.label(name.to_string()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
            });
        }
    }
    if text {
        crate::style::legend(&mut chart, SeriesLabelPosition::UpperRight).map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(name: &str, objects: f64) -> Figures {
        Figures {
            name: name.into(),
            objects_skipped_mean: objects,
            lods_skipped_mean: objects / 10.0,
            mb_per_client: 2.0,
            wasted_share: 0.5,
        }
    }

    fn row(mb: u64, p: f64, d: f64) -> Row {
        Row {
            cache_mb: mb,
            prefetch: Some(f("p", p)),
            demand: Some(f("demand", d)),
            oracle: Some(f("oracle", d / 2.0)),
        }
    }

    #[test]
    fn prefetch_is_judged_against_demand_at_every_budget() {
        let fine = [row(4, 0.40, 0.41), row(64, 0.10, 0.30)];
        assert_eq!(fine[0].no_worse_than_demand(), Some(true));
        let v = crate::verdict::cache_sweep(&fine);
        assert!(v.met, "{v}");
        // Thrash at the smallest budget: not met, and the verdict names the budget.
        let thrash = [row(4, 1.41, 0.40), row(64, 0.10, 0.30)];
        assert_eq!(thrash[0].no_worse_than_demand(), Some(false));
        let v = crate::verdict::cache_sweep(&thrash);
        assert!(!v.met && v.value.contains("4 MiB"), "{v}");
        // Without baselines there is nothing to judge.
        let lone = [Row {
            demand: None,
            ..row(4, 1.0, 1.0)
        }];
        assert_eq!(lone[0].no_worse_than_demand(), None);
        assert!(!crate::verdict::cache_sweep(&lone).met);
    }

    #[test]
    fn the_table_and_plot_show_every_budget() {
        let rows = [row(4, 1.41, 0.40), row(16, 0.5, 0.4), row(256, 0.1, 0.3)];
        let md = markdown(&rows);
        assert_eq!(md.lines().count(), 2 + rows.len());
        assert!(md.contains("| 4 | 1.41 / 0.40 / 0.20 |"), "{md}");
        let dir = tempfile::tempdir().unwrap();
        for text in [false, fonts_available()] {
            let png = dir.path().join("s.png");
            plot(&png, &rows, text).unwrap();
            let img = image::open(&png).unwrap();
            assert_eq!((img.width(), img.height()), (900, 520));
        }
    }
}
