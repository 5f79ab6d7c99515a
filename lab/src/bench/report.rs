//! The benchmark's files: `summary.json`, `report.md` (a table in the layout of Funkhouser
//! Table 4.3 with RRB's fidelity columns added), `frames.csv` and the PNG plots.

use super::{BenchSummary, FrameRecord, RunSummary, plot};
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

/// Summary JSON file name.
pub const SUMMARY: &str = "summary.json";
/// Markdown report file name.
pub const REPORT: &str = "report.md";
/// Per-frame CSV file name.
pub const FRAMES_CSV: &str = "frames.csv";
/// Frame-time plot file name.
pub const FRAME_TIME_PNG: &str = "frame_time.png";
/// Es/Et plot file name.
pub const FIDELITY_PNG: &str = "fidelity.png";
/// Every file [`write_all`] writes.
pub const FILES: [&str; 5] = [SUMMARY, REPORT, FRAMES_CSV, FRAME_TIME_PNG, FIDELITY_PNG];

/// Writes every output file into `out`.
pub fn write_all(out: &Path, s: &BenchSummary, runs: &[(String, &[FrameRecord])]) -> Result<()> {
    write_csv(&out.join(FRAMES_CSV), runs).with_context(|| format!("writing {FRAMES_CSV}"))?;
    let text = plot::fonts_available();
    plot::frame_times(&out.join(FRAME_TIME_PNG), runs, s.parameters.budget_s, text)?;
    plot::fidelity(&out.join(FIDELITY_PNG), runs, text)?;
    std::fs::write(out.join(REPORT), markdown(s)).with_context(|| format!("writing {REPORT}"))?;
    let json = serde_json::to_vec_pretty(s)?;
    std::fs::write(out.join(SUMMARY), json).with_context(|| format!("writing {SUMMARY}"))
}

/// One row per run and frame.
pub fn write_csv(path: &Path, runs: &[(String, &[FrameRecord])]) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(
        f,
        "run,frame,t,frame_s,visibility_s,elision_s,render_s,predicted_s,visible_objects,drawn_objects,triangles,critical_visible,es,et,psnr,mse"
    )?;
    let opt = |x: Option<f64>| x.map_or(String::new(), |v| format!("{v:.4}"));
    for (name, rows) in runs {
        // A replayed load test run is named after its policy, commas and all.
        let name = format!("\"{}\"", name.replace('"', "\"\""));
        for r in *rows {
            writeln!(
                f,
                "{name},{},{:.4},{:.6},{:.6},{:.6},{:.6},{:.6},{},{},{},{},{:.4},{},{},{:.4}",
                r.frame,
                r.t,
                r.frame_s,
                r.visibility_s,
                r.elision_s,
                r.render_s,
                r.predicted_s,
                r.visible_objects,
                r.drawn_objects,
                r.triangles,
                r.critical_visible,
                r.es,
                opt(r.et),
                r.psnr.map_or("inf".to_owned(), |p| format!("{p:.3}")),
                r.mse
            )?;
        }
    }
    f.flush()
}

/// PSNR as text: `∞` for `None`.
pub fn psnr_text(p: Option<f64>) -> String {
    p.map_or("∞".to_owned(), |v| format!("{v:.2}"))
}

/// The self-test line of the report.
pub fn self_test_line(s: &BenchSummary) -> String {
    let t = &s.self_test;
    format!(
        "Self-test (RRB §5.2): regular against itself: Es = {}, Et = {}, PSNR = {} dB: {}",
        t.es,
        t.et,
        psnr_text(t.psnr),
        if t.passed { "PASS" } else { "FAIL" }
    )
}

/// The main table, Funkhouser Table 4.3's frame-time columns plus RRB's.
pub fn table(runs: &[RunSummary]) -> String {
    let mut t = String::from(
        "| algorithm | frame time mean (s) | min | max | sd | MAD | p95 | p99 | frames over budget | polygons (mean) | vs regular | Es | Et | PSNR (dB) |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in runs {
        let f = &r.frame_time;
        let _ = writeln!(
            t,
            "| {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {} / {} | {:.0} | {:.1} % | {:.3} | {:.3} | {} |",
            r.name,
            f.mean,
            f.min,
            f.max,
            f.sd,
            f.mad,
            f.p95,
            f.p99,
            r.frames_over_budget,
            r.frames,
            r.polygons_mean,
            r.polygons_vs_regular * 100.0,
            r.es_mean,
            r.et_mean,
            psnr_text(r.psnr_mean),
        );
    }
    t
}

/// The RRB-normalised fidelity numbers and per-frame extremes.
fn fidelity_table(runs: &[RunSummary]) -> String {
    let mut t = String::from(
        "| algorithm | Es | Es max | Et | Et max | Es (RRB, n_v = V) | Et (RRB eq. 5.10) | PSNR min | PSNR of mean MSE | identical frames |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in runs {
        let _ = writeln!(
            t,
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.5} | {:.5} | {} | {} | {} |",
            r.name,
            r.es_mean,
            r.es_max,
            r.et_mean,
            r.et_max,
            r.es_rrb,
            r.et_rrb,
            psnr_text(r.psnr_min),
            psnr_text(r.psnr_of_mean_mse),
            r.identical_frames,
        );
    }
    t
}

/// The whole `report.md`.
pub fn markdown(s: &BenchSummary) -> String {
    let p = &s.parameters;
    let c = &s.critical;
    let mut m = String::new();
    let _ = writeln!(m, "# portico bench: {}\n", s.model.name);
    let _ = writeln!(
        m,
        "Frame rate and image fidelity of the detail elision algorithms (Funkhouser 1993 §4.2.4, \
         Table 4.3, Fig. 4.22; RRB, Yuan 2001, §5.2-5.3). Every run replays the same \
         frame-indexed path; Es, Et and PSNR compare frame i with the Regular frame i.\n"
    );
    let _ = writeln!(m, "{}\n", self_test_line(s));
    let _ = writeln!(m, "## Frame time and fidelity\n");
    let _ = writeln!(
        m,
        "Budget {:.1} ms, {} frames per run.\n",
        p.budget_s * 1e3,
        p.frames
    );
    m.push_str(&table(&s.runs));
    let _ = writeln!(m, "\n![frame time per frame]({})\n", FRAME_TIME_PNG);
    let _ = writeln!(m, "## Fidelity detail\n");
    m.push_str(&fidelity_table(&s.runs));
    let _ = writeln!(m, "\n![Es and Et per frame]({})\n", FIDELITY_PNG);
    let _ = writeln!(m, "## How it was measured\n");
    let _ = writeln!(
        m,
        "- Frame time: visibility + detail elision + render until the GPU finished (RRB §5.2 \
         trap bracket); MAD is RRB eq. 5.2. Regular has no budget; its over-budget count uses \
         the same budget for comparison.\n\
         - Critical vertices (RRB §5.3.3): {} of {} welded vertices ({:.1} %): {} curvature \
         extrema (second eigenvalue of the angle-normalised Garland quadric normal block > {}), {} \
         boundary, {} colour-border; {:.0} visible per frame on average (max {:.0}).\n\
         - Visibility of a critical vertex: {}.\n\
         - Area of interest: {}x{} px square around the vertex's pixel in the Regular frame; {}.\n\
         - Es_i = mean over visible critical vertices of |I0 - I|; Es = mean over frames (eq. \
         5.5-5.7). Et_i = mean over vertices visible in frames i-1 and i of |e_i - e_(i-1)|, \
         e = I0 - I (eq. 5.8-5.9); Et = mean over frames 1..n-1. The RRB columns divide by every \
         critical vertex of the model (n_v = |V|) as printed.\n\
         - PSNR = 10 log10(255^2 / MSE) over R, G, B of the whole frame (eq. 5.4); ∞ when equal.",
        c.counts.critical,
        c.counts.vertices,
        c.fraction * 100.0,
        c.counts.extrema,
        p.critical.curvature_threshold,
        c.counts.boundary,
        c.counts.colour_border,
        c.visible_per_frame.mean,
        c.visible_per_frame.max,
        p.visibility_test,
        p.patch_px,
        p.patch_px,
        p.intensity,
    );
    let _ = writeln!(m, "\n## Machine, model, path, parameters\n");
    let _ = writeln!(
        m,
        "- machine: {} ({} cores, {})\n- adapter: {}{}\n- model: {} (`{}`), database id `{}`, {} \
         instances, {} triangles at the finest LOD, {:.1} MB of GPU geometry\n- path: {} \
         (hash `{}`), {} keyframes, {:.1} s; frame i at t = i x {} s\n- image {}x{}, field of \
         view {:.0}°, runs: {}\n- cost model: {:?}\n- wall time {:.1} s",
        s.machine.hostname,
        s.machine.cores,
        s.machine.os,
        s.adapter,
        if s.cpu_adapter {
            " (software rasteriser: absolute times are CPU times)"
        } else {
            ""
        },
        s.model.name,
        s.model.file,
        s.model.database_id,
        s.model.instances,
        s.model.triangles,
        s.model.gpu_bytes as f64 / 1e6,
        s.path.kind,
        s.path.hash,
        s.path.keyframes,
        s.path.duration_s,
        p.dt_s,
        p.size.0,
        p.size.1,
        p.fov_deg,
        p.runs.join(", "),
        s.cost_model,
        s.wall_s,
    );
    m
}
