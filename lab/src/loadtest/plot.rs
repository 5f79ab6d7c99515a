//! The load test's plots (plotters, PNG): LODs skipped per frame with one line per policy
//! (Funkhouser Fig. 5.12–5.13) and the lookahead set in MB per frame (Fig. 5.11, with the
//! "0 frames" curve: what is visible from the actual viewpoint), both along client 0's frames.
//!
//! Text needs the font of [`crate::style`]; without it the plots have no text.

use super::LoadtestSummary;
use crate::style::{PALETTE, fonts_available as fonts};
use anyhow::{Result, anyhow};
use plotters::prelude::*;
use std::path::Path;

/// Most prefetch policies drawn in one plot (the best by mean LODs skipped).
pub const MAX_LINES: usize = 6;
/// Plot size in pixels.
const SIZE: (u32, u32) = (1000, 560);

/// What [`write_all`] wrote.
#[derive(Debug, Clone, Default)]
pub struct Plots {
    /// Whether the plots have text.
    pub text: bool,
    /// File names (relative to the output directory).
    pub files: Vec<String>,
}

/// One named line.
pub type Line = (String, Vec<f64>);

/// Writes `lods_skipped.png` and `lookahead_mb.png` into `out`.
pub fn write_all(out: &Path, s: &LoadtestSummary) -> Result<Plots> {
    let text = fonts();
    let chosen = chosen(s);
    let skipped: Vec<Line> = chosen
        .iter()
        .map(|p| {
            let ys = p.client0.iter().map(|r| r.lods_skipped as f64).collect();
            (p.name.clone(), ys)
        })
        .collect();
    let mut look: Vec<Line> = chosen
        .iter()
        .filter(|p| p.kind == "prefetch")
        .map(|p| {
            let ys = p
                .client0
                .iter()
                .map(|r| r.lookahead_bytes as f64 / 1e6)
                .collect();
            (p.name.clone(), ys)
        })
        .collect();
    if !s.visible_mb_client0.is_empty() {
        look.push((
            "visible from the eye now (no lookahead)".into(),
            s.visible_mb_client0.clone(),
        ));
    }
    let title = |what: &str| format!("{what}, client 0 of {} ({})", s.clients, s.link_spec);
    lines(
        &out.join("lods_skipped.png"),
        &title("LODs skipped per frame"),
        "LODs skipped",
        &skipped,
        text,
    )?;
    lines(
        &out.join("lookahead_mb.png"),
        &title("Lookahead set size"),
        "MB",
        &look,
        text,
    )?;
    Ok(Plots {
        text,
        files: vec!["lods_skipped.png".into(), "lookahead_mb.png".into()],
    })
}

/// The baselines and at most [`MAX_LINES`] prefetch policies (fewest LODs skipped first).
fn chosen(s: &LoadtestSummary) -> Vec<&super::PolicyResult> {
    let mut prefetch: Vec<_> = s.policies.iter().filter(|p| p.kind == "prefetch").collect();
    prefetch.sort_by(|a, b| a.lods_skipped_mean.total_cmp(&b.lods_skipped_mean));
    prefetch.truncate(MAX_LINES);
    prefetch
        .into_iter()
        .chain(s.policies.iter().filter(|p| p.kind != "prefetch"))
        .collect()
}

/// Most points drawn per line: longer series are reduced to the maximum of each run of frames
/// (a spike of skipped LODs must stay visible).
const PEAK_BUCKETS: usize = 1000;

/// `(frame, value)` points, at most `buckets` of them: each the largest value of its run of
/// frames, placed at the run's first frame.
fn peaks(ys: &[f64], buckets: usize) -> Vec<(f64, f64)> {
    let per = ys.len().div_ceil(buckets.max(1)).max(1);
    ys.chunks(per)
        .enumerate()
        .map(|(i, c)| ((i * per) as f64, c.iter().copied().fold(f64::MIN, f64::max)))
        .collect()
}

/// A line chart of per-frame values; without `text`, no caption, labels or legend.
pub fn lines(path: &Path, title: &str, y_desc: &str, series: &[Line], text: bool) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("plotting {}: {e}", path.display());
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let frames = series.iter().map(|s| s.1.len()).max().unwrap_or(0).max(2);
    let top = series
        .iter()
        .flat_map(|s| s.1.iter().copied())
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    let top = if top > 0.0 { top * 1.1 } else { 1.0 };
    // Start a little below zero, so lines at zero are not hidden by the axis.
    let bottom = -0.04 * top;
    let mut builder = ChartBuilder::on(&root);
    builder.margin(16);
    if text {
        builder
            .caption(title, ("sans-serif", 22))
            .x_label_area_size(44)
            .y_label_area_size(64);
    }
    let mut chart = builder
        .build_cartesian_2d(0f64..(frames - 1) as f64, bottom..top)
        .map_err(|e| err(&e))?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc("Frames").y_desc(y_desc);
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(|e| err(&e))?;
    // Earlier lines are drawn wider, so where lines coincide (at zero, typically) every
    // colour still shows as a stripe; the legend gives each line's mean and maximum.
    let n = series.len();
    for (i, (name, ys)) in series.iter().enumerate() {
        let color = PALETTE[(i + 1) % PALETTE.len()].to_rgba();
        let width = 1 + 2 * (n - 1 - i) as u32;
        let drawn = chart
            .draw_series(LineSeries::new(
                peaks(ys, PEAK_BUCKETS),
                color.stroke_width(width),
            ))
            .map_err(|e| err(&e))?;
        if text {
            let s = portico_client::stats::Series::of(ys);
            let label = format!("{name}: mean {:.2}, max {:.2}", s.mean, s.max);
            drawn.label(label).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(width))
            });
        }
    }
    if text && !series.is_empty() {
        crate::style::legend(&mut chart, SeriesLabelPosition::UpperRight).map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_series_keep_their_peaks() {
        let mut ys = vec![0.0; 5000];
        ys[2501] = 9.0;
        let p = peaks(&ys, 1000);
        assert_eq!(p.len(), 1000);
        assert_eq!(p[500], (2500.0, 9.0));
        assert_eq!(peaks(&[1.0, 2.0], 1000), vec![(0.0, 1.0), (1.0, 2.0)]);
    }

    #[test]
    fn plots_decode_with_and_without_text() {
        let dir = tempfile::tempdir().unwrap();
        let series = vec![
            ("a".to_string(), vec![0.0, 2.0, 1.0, 5.0]),
            ("b".to_string(), vec![1.0, 1.0]),
        ];
        // Without text first: no font is needed (and none may be registered yet).
        let bare = dir.path().join("bare.png");
        lines(&bare, "t", "y", &series, false).unwrap();
        let img = image::open(&bare).unwrap();
        assert_eq!((img.width(), img.height()), SIZE);
        if fonts() {
            let p = dir.path().join("text.png");
            lines(&p, "title", "y", &series, true).unwrap();
            assert!(image::open(&p).is_ok());
        } else {
            assert!(
                std::env::var_os("CI").is_none(),
                "no font for the plots' text: install fonts-dejavu-core"
            );
        }
        // Empty and flat series still draw.
        lines(&dir.path().join("empty.png"), "t", "y", &[], false).unwrap();
    }
}
