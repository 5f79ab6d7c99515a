//! The stream stress test's scaling plot (plotters, PNG): against the number of clients (log
//! scale), the server's CPU per observer update on the left, and the update latency inside the
//! server and the ping round trip at the clients (p99, log scale) on the right; one set of lines per run
//! (this run, and a baseline run's levels when given: before and after in one picture).

use super::stress_stream::StreamLevel;
use crate::style::{PALETTE, fonts_available};
use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use std::path::Path;

/// Plot size in pixels.
const SIZE: (u32, u32) = (1200, 520);

type Points = Vec<(f64, f64)>;
/// A named line and its colour's index in [`PALETTE`].
type Line = (String, Points, usize);

/// The name of a run in the legend: what its server said about sharing, and whether the
/// sessions computed their own lists anyway (the predicted lookahead) for most of those taken.
pub fn run_name(levels: &[StreamLevel]) -> &'static str {
    let Some(l) = levels.first() else {
        return "server";
    };
    match l.shared_answers {
        Some(true) if l.own_lists * 2 > l.lists_taken => "own lists",
        Some(true) => "shared lists",
        Some(false) => "exact lists",
        None => "server",
    }
}

/// Writes the plot of `runs` (a name and its levels each) to `path`; whether it has text (see
/// [`crate::style`]).
pub fn scaling(path: &Path, runs: &[(&str, &[StreamLevel])]) -> Result<bool> {
    let text = fonts_available();
    let err = |e: &dyn std::fmt::Display| anyhow!("plotting {}: {e}", path.display());
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (left, right) = root.split_horizontally(SIZE.0 / 2);
    let at = |levels: &[StreamLevel], f: &dyn Fn(&StreamLevel) -> f64| -> Points {
        levels
            .iter()
            .map(|l| (l.clients.max(1) as f64, f(l)))
            .collect()
    };
    // A run is one colour on both panels (its ping line the next colour): shared lists green,
    // exact lists red, whichever run is the baseline, so pictures compare at a glance.
    let colour = |i: usize, name: &str| match name {
        "exact lists" => 1,
        "shared lists" => 3,
        _ => 5 + 2 * i,
    };
    let cpu: Vec<Line> = runs
        .iter()
        .enumerate()
        .map(|(i, (name, l))| {
            let ys = at(l, &|l| l.cpu_per_update_ms * 1e3);
            (name.to_string(), ys, colour(i, name))
        })
        .collect();
    let mut latency = Vec::new();
    for (i, (name, l)) in runs.iter().enumerate() {
        let c = colour(i, name);
        latency.push((
            format!("{name}: in the server (bucket bound)"),
            at(l, &|l| l.update_p99_s * 1e3),
            c,
        ));
        latency.push((
            format!("{name}: ping after the update"),
            at(l, &|l| l.ping_s.p99 * 1e3),
            c + 1,
        ));
    }
    panel(
        &left,
        "Server CPU per observer update",
        "µs",
        &cpu,
        text,
        false,
    )
    .map_err(|e| err(&e))?;
    panel(
        &right,
        "Update latency, p99",
        "ms (log scale)",
        &latency,
        text,
        true,
    )
    .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(text)
}

/// Latencies under this (ms) are drawn at it: the log axis has no zero.
const LATENCY_FLOOR_MS: f64 = 0.05;

fn panel(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    title: &str,
    y_desc: &str,
    series: &[Line],
    text: bool,
    log_y: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    if log_y {
        let floor = |pts: &Points| -> Points {
            pts.iter()
                .map(|&(x, y)| (x, y.max(LATENCY_FLOOR_MS)))
                .collect()
        };
        let series: Vec<Line> = series
            .iter()
            .map(|(n, p, c)| (n.clone(), floor(p), *c))
            .collect();
        let top = y_top(&series) * 2.0;
        return draw(
            area,
            title,
            y_desc,
            &series,
            text,
            (LATENCY_FLOOR_MS..top).log_scale(),
        );
    }
    let top = y_top(series) * 1.15;
    draw(area, title, y_desc, series, text, -0.03 * top..top)
}

/// The largest finite value of the series (1 when there is none).
fn y_top(series: &[Line]) -> f64 {
    let top = series
        .iter()
        .flat_map(|s| s.1.iter().map(|p| p.1))
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    if top > 0.0 { top } else { 1.0 }
}

fn draw<Y>(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    title: &str,
    y_desc: &str,
    series: &[Line],
    text: bool,
    y_range: Y,
) -> Result<(), Box<dyn std::error::Error>>
where
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let xs = series.iter().flat_map(|s| s.1.iter().map(|p| p.0));
    let x_max = xs.fold(2.0f64, f64::max) * 1.5;
    let mut builder = ChartBuilder::on(area);
    builder.margin(16);
    if text {
        builder
            .caption(title, ("sans-serif", 20))
            .x_label_area_size(44)
            .y_label_area_size(64);
    }
    let mut chart = builder.build_cartesian_2d((0.8f64..x_max).log_scale(), y_range)?;
    let mut mesh = chart.configure_mesh();
    if text {
        mesh.x_desc("Clients (one session each)")
            .y_desc(y_desc)
            .x_label_formatter(&|x| format!("{x:.0}"));
    } else {
        mesh.x_labels(0).y_labels(0);
    }
    mesh.draw()?;
    for (name, pts, c) in series {
        let color = PALETTE[c % PALETTE.len()].to_rgba();
        let pts: Points = pts.iter().copied().filter(|p| p.1.is_finite()).collect();
        let drawn = chart.draw_series(LineSeries::new(pts.clone(), color.stroke_width(3)))?;
        if text {
            drawn.label(name.as_str()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
            });
        }
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 5, color.filled())))?;
    }
    if text {
        crate::style::legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use portico_client::stats::Series;

    fn level(clients: usize, shared: bool, cpu_ms: f64) -> StreamLevel {
        StreamLevel {
            clients,
            shared_answers: Some(shared),
            connected: clients,
            refused: 0,
            updates: 100,
            updates_per_s: 20.0 * clients as f64,
            server_cpu_s: 1.0,
            cpu_per_update_ms: cpu_ms,
            server_cores: 0.5,
            update_p50_s: 1e-4,
            update_p99_s: if shared { 1e-4 } else { 0.5 },
            ping_s: Series::of(&[0.001, 0.002]),
            lists_computed: 1,
            own_lists: 0,
            lists_taken: 2,
            rss_open: 0.0,
            rss_idle: 0.0,
            pushed_bytes: 0,
        }
    }

    #[test]
    fn a_run_and_its_baseline_draw_in_one_picture() {
        let dir = tempfile::tempdir().unwrap();
        let after = [level(1, true, 0.1), level(1000, true, 0.03)];
        let before = [level(1, false, 1.0), level(1000, false, 0.06)];
        assert_eq!(run_name(&after), "shared lists");
        assert_eq!(run_name(&before), "exact lists");
        let mut own = level(1, true, 0.1);
        own.own_lists = own.lists_taken;
        assert_eq!(run_name(&[own]), "own lists");
        let p = dir.path().join("scaling.png");
        scaling(&p, &[("shared lists", &after), ("exact lists", &before)]).unwrap();
        let img = image::open(&p).unwrap().to_rgb8();
        assert_eq!((img.width(), img.height()), SIZE);
        // Both runs' colours are drawn (each run one colour, its ping line the next).
        for c in [PALETTE[1], PALETTE[3]] {
            assert!(
                img.pixels().any(|px| px.0 == [c.0, c.1, c.2]),
                "no line in {c:?}"
            );
        }
    }
}
