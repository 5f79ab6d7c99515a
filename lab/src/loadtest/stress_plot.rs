//! The stream stress test's scaling plot (plotters, PNG): against the number of clients (log
//! scale), the server's CPU per observer update on the left, and the update latency inside the
//! server and the ping round trip at the clients (p99) on the right.

use super::stress_stream::StreamLevel;
use crate::style::{PALETTE, fonts_available};
use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Plot size in pixels.
const SIZE: (u32, u32) = (1200, 520);

type Points = Vec<(f64, f64)>;

/// Writes the plot to `path`; whether it has text (see [`crate::style`]).
pub fn scaling(path: &Path, levels: &[StreamLevel]) -> Result<bool> {
    let text = fonts_available();
    let err = |e: &dyn std::fmt::Display| anyhow!("plotting {}: {e}", path.display());
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (left, right) = root.split_horizontally(SIZE.0 / 2);
    let at = |f: &dyn Fn(&StreamLevel) -> f64| -> Points {
        levels
            .iter()
            .map(|l| (l.clients.max(1) as f64, f(l)))
            .collect()
    };
    panel(
        &left,
        "Server CPU per observer update",
        "µs",
        &[("server CPU / update", at(&|l| l.cpu_per_update_ms * 1e3))],
        text,
    )
    .map_err(|e| err(&e))?;
    panel(
        &right,
        "Update latency, p99",
        "ms",
        &[
            (
                "in the server (histogram bound)",
                at(&|l| l.update_p99_s * 1e3),
            ),
            (
                "ping after the update, at the client",
                at(&|l| l.ping_s.p99 * 1e3),
            ),
        ],
        text,
    )
    .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(text)
}

fn panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    title: &str,
    y_desc: &str,
    series: &[(&str, Points)],
    text: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    let xs = series.iter().flat_map(|s| s.1.iter().map(|p| p.0));
    let x_max = xs.fold(2.0f64, f64::max) * 1.5;
    let y_max = series
        .iter()
        .flat_map(|s| s.1.iter().map(|p| p.1))
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    let y_max = if y_max > 0.0 { y_max * 1.15 } else { 1.0 };
    let mut builder = ChartBuilder::on(area);
    builder.margin(16);
    if text {
        builder
            .caption(title, ("sans-serif", 20))
            .x_label_area_size(44)
            .y_label_area_size(64);
    }
    let mut chart =
        builder.build_cartesian_2d((0.8f64..x_max).log_scale(), -0.03 * y_max..y_max)?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc("Clients (one session each)").y_desc(y_desc);
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw()?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let color = PALETTE[(i + 1) % PALETTE.len()].to_rgba();
        let pts: Points = pts.iter().copied().filter(|p| p.1.is_finite()).collect();
        let drawn = chart.draw_series(LineSeries::new(pts.clone(), color.stroke_width(3)))?;
        if text {
            drawn.label(*name).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
            });
        }
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 5, color.filled())))?;
    }
    if text {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()?;
    }
    Ok(())
}
