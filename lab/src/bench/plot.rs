//! PNG plots of a benchmark (plotters, bitmap backend): frame time per frame with the budget as
//! a horizontal line (Funkhouser Fig. 4.22, one line per run instead of one panel each), and Es
//! and Et per frame (the per-frame curves RRB's missing figures showed, §8.2).
//!
//! Text needs the font of [`crate::style`]; without it the plots have no text.

use super::FrameRecord;
use crate::style::PALETTE;
pub use crate::style::fonts_available;
use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Plot size in pixels.
const SIZE: (u32, u32) = (960, 540);

/// One named line of a chart.
struct Line {
    name: String,
    points: Vec<(f64, f64)>,
}

/// What one chart shows.
struct Chart<'a> {
    title: &'a str,
    y_desc: &'a str,
    lines: Vec<Line>,
    /// A horizontal reference line (the budget) and its label.
    level: Option<(f64, &'a str)>,
}

/// Frame time (ms) per frame for every run, with the budget line (Funkhouser Fig. 4.22).
pub fn frame_times(
    path: &Path,
    runs: &[(String, &[FrameRecord])],
    budget_s: f64,
    text: bool,
) -> Result<()> {
    let chart = Chart {
        title: "Frame time per frame (Funkhouser Fig. 4.22)",
        y_desc: "frame time (ms)",
        lines: lines(runs, |r| Some(r.frame_s * 1e3)),
        level: Some((budget_s * 1e3, "budget")),
    };
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    draw_chart(&root, &chart, text)?;
    root.present().map_err(plot_error)
}

/// Es (top) and Et (bottom) per frame for every run (RRB §5.3).
pub fn fidelity(path: &Path, runs: &[(String, &[FrameRecord])], text: bool) -> Result<()> {
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    let panels = root.split_evenly((2, 1));
    let es = Chart {
        title: "Spatial error Es per frame (RRB eq. 5.6)",
        y_desc: "Es (intensity 0-255)",
        lines: lines(runs, |r| Some(r.es)),
        level: None,
    };
    let et = Chart {
        title: "Temporal error Et per frame (RRB eq. 5.8, per frame)",
        y_desc: "Et (intensity 0-255)",
        lines: lines(runs, |r| r.et),
        level: None,
    };
    draw_chart(&panels[0], &es, text)?;
    draw_chart(&panels[1], &et, text)?;
    root.present().map_err(plot_error)
}

/// One line per run of `value(frame)` against the frame index.
fn lines(
    runs: &[(String, &[FrameRecord])],
    value: impl Fn(&FrameRecord) -> Option<f64>,
) -> Vec<Line> {
    runs.iter()
        .map(|(name, rows)| Line {
            name: name.clone(),
            points: rows
                .iter()
                .filter_map(|r| {
                    value(r)
                        .filter(|v| v.is_finite())
                        .map(|v| (r.frame as f64, v))
                })
                .collect(),
        })
        .collect()
}

/// Draws a line chart into `area`.
fn draw_chart(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    c: &Chart<'_>,
    text: bool,
) -> Result<()> {
    let x_max = c
        .lines
        .iter()
        .flat_map(|l| &l.points)
        .map(|p| p.0)
        .fold(1.0, f64::max);
    let y_data = c
        .lines
        .iter()
        .flat_map(|l| &l.points)
        .map(|p| p.1)
        .fold(0.0, f64::max);
    let y_max = (y_data.max(c.level.map_or(0.0, |l| l.0)) * 1.1).max(1e-3);
    let mut builder = ChartBuilder::on(area);
    builder.margin(12);
    if text {
        builder
            .caption(c.title, ("sans-serif", 18))
            .x_label_area_size(32)
            .y_label_area_size(56);
    }
    let mut chart = builder
        .build_cartesian_2d(0f64..x_max, 0f64..y_max)
        .map_err(plot_error)?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc("frame")
            .y_desc(c.y_desc)
            .x_label_formatter(&|x| format!("{x:.0}"));
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw().map_err(plot_error)?;
    for (i, line) in c.lines.iter().enumerate() {
        let colour = PALETTE[i % PALETTE.len()];
        let drawn = chart
            .draw_series(LineSeries::new(
                line.points.iter().copied(),
                colour.stroke_width(1),
            ))
            .map_err(plot_error)?;
        if text {
            drawn.label(line.name.as_str()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
            });
        }
    }
    if let Some((level, name)) = c.level {
        let style = RGBColor(90, 90, 90).stroke_width(2);
        let drawn = chart
            .draw_series(DashedLineSeries::new(
                [(0.0, level), (x_max, level)],
                8,
                5,
                style,
            ))
            .map_err(plot_error)?;
        if text {
            drawn
                .label(name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], style));
        }
    }
    if text {
        crate::style::legend(&mut chart, SeriesLabelPosition::UpperRight).map_err(plot_error)?;
    }
    Ok(())
}

fn plot_error(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("drawing a plot: {e}")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(scale: f64) -> Vec<FrameRecord> {
        (0..20)
            .map(|i| FrameRecord {
                frame: i,
                frame_s: scale * (1.0 + (i as f64 * 0.3).sin().abs()),
                es: scale * 100.0 * i as f64,
                et: (i > 0).then_some(scale * 50.0),
                ..FrameRecord::default()
            })
            .collect()
    }

    #[test]
    fn plots_are_written_with_and_without_text() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (rows(0.01), rows(0.02));
        let runs = vec![
            ("regular".to_owned(), a.as_slice()),
            ("optimize".to_owned(), b.as_slice()),
        ];
        // Without text first: in a process where no test has registered the font yet, this
        // proves the no-font path draws no text at all.
        for text in [false, true] {
            let text = text && fonts_available();
            let ft = dir.path().join(format!("ft_{text}.png"));
            let fid = dir.path().join(format!("fid_{text}.png"));
            frame_times(&ft, &runs, 0.02, text).unwrap();
            fidelity(&fid, &runs, text).unwrap();
            for p in [ft, fid] {
                let img = image::open(&p).unwrap();
                assert_eq!((img.width(), img.height()), SIZE);
            }
        }
        assert!(
            fonts_available() || std::env::var_os("CI").is_none(),
            "no font for the plots' text: install fonts-dejavu-core"
        );
    }
}
