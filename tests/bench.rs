//! `portico bench` end to end on the tiny building (wgpu on llvmpipe, 96x72 images, 20 frames):
//! every run replays the same frames, Regular scores zero against itself, a coarse run does not,
//! and the report, CSV and plots are written.

use portico_client::elision::Algorithm;
use portico_data::path::{PathKind, generate};
use portico_lab::bench::{BenchConfig, BenchSummary, RunKind, RunSummary, report, run};
use std::path::Path;

const FRAMES: u64 = 20;

mod common;

use common::build_tiny;

fn config(dir: &Path) -> BenchConfig {
    let db = build_tiny(dir);
    let graph = portico_data::Database::open(&db)
        .unwrap()
        .cell_graph()
        .unwrap()
        .unwrap();
    let path = generate(&graph, PathKind::Tour, 2, 1, 1.5, 1.5).unwrap();
    let mut cfg = BenchConfig::new(db, path, 0.02, dir.join("bench"));
    cfg.size = (96, 72);
    cfg.max_frames = Some(FRAMES);
    cfg.dt_s = 0.1;
    cfg.algorithms = vec![
        RunKind::Elision(Algorithm::None),
        RunKind::Elision(Algorithm::Static),
        RunKind::Elision(Algorithm::Feedback),
        RunKind::Elision(Algorithm::Optimize),
        RunKind::Coarsest,
    ];
    cfg
}

fn by_name<'a>(s: &'a BenchSummary, name: &str) -> &'a RunSummary {
    s.runs
        .iter()
        .find(|r| r.name == name)
        .unwrap_or_else(|| panic!("no run {name}"))
}

#[test]
fn bench_runs_every_algorithm_on_the_same_frames_and_reports_fidelity() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path());
    let mut calls = Vec::new();
    let s = run(&cfg, &mut |done, total| calls.push((done, total))).unwrap();

    // Every run present, Regular first, all with the same frames.
    let names: Vec<&str> = s.runs.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "regular", "none", "static", "feedback", "optimize", "coarsest"
        ]
    );
    assert!(s.runs.iter().all(|r| r.frames == FRAMES));
    assert_eq!(calls.last(), Some(&(FRAMES, FRAMES)));
    assert_eq!(calls.len() as u64, FRAMES);
    assert!(
        s.runs
            .iter()
            .all(|r| r.frame_time.mean > 0.0 && r.frame_time.max >= r.frame_time.min)
    );

    // The self-test: Regular against itself.
    let regular = by_name(&s, "regular");
    assert_eq!((regular.es_mean, regular.et_mean), (0.0, 0.0));
    assert_eq!((regular.es_rrb, regular.et_rrb), (0.0, 0.0));
    assert_eq!(regular.psnr_mean, None, "identical frames have PSNR = ∞");
    assert_eq!(regular.identical_frames, FRAMES);
    assert!(s.self_test.passed, "{:?}", s.self_test);
    assert!(regular.polygons_mean > 0.0);

    // Critical vertices were found and seen.
    assert!(s.critical.counts.critical > 0);
    assert!(s.critical.counts.critical <= s.critical.counts.vertices);
    assert!(s.critical.visible_per_frame.max > 0.0);

    // Coarse geometry is visibly different: Es > 0, finite PSNR, fewer polygons.
    let coarse = by_name(&s, "coarsest");
    assert!(coarse.es_mean > 0.0, "{coarse:?}");
    assert!(coarse.es_max >= coarse.es_mean);
    assert!(coarse.psnr_mean.is_some_and(|p| p.is_finite() && p > 0.0));
    assert!(coarse.psnr_min.is_some_and(|p| p.is_finite()));
    assert!(coarse.polygons_mean < regular.polygons_mean);
    assert!(coarse.polygons_vs_regular < 1.0);

    // Budgeted runs are flagged; Regular and Coarsest are not.
    assert!(by_name(&s, "optimize").budgeted && !regular.budgeted && !coarse.budgeted);

    check_files(&cfg.out, &s);
}

/// summary.json, report.md, frames.csv and decodable PNGs.
fn check_files(out: &Path, s: &BenchSummary) {
    for f in report::FILES {
        assert!(out.join(f).is_file(), "{f} missing");
        assert!(s.files.iter().any(|x| x == f));
    }
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join(report::SUMMARY)).unwrap()).unwrap();
    assert_eq!(json["runs"].as_array().map(Vec::len), Some(6));
    assert!(json["runs"][0]["psnr_mean"].is_null());
    assert_eq!(
        json["model"]["database_id"].as_str().map(str::len),
        Some(32)
    );
    assert!(json["machine"]["cores"].as_u64().is_some_and(|c| c >= 1));
    assert_eq!(json["path"]["hash"].as_str().map(str::len), Some(16));
    let md = std::fs::read_to_string(out.join(report::REPORT)).unwrap();
    assert!(md.contains("Self-test") && md.contains("PASS"), "{md}");
    assert!(md.contains("| optimize |") && md.contains("| coarsest |"));
    let csv = std::fs::read_to_string(out.join(report::FRAMES_CSV)).unwrap();
    assert_eq!(csv.lines().count() as u64, 1 + 6 * FRAMES);
    for png in [report::FRAME_TIME_PNG, report::FIDELITY_PNG] {
        let img = image::open(out.join(png)).unwrap_or_else(|e| panic!("{png}: {e}"));
        assert!(img.width() > 100 && img.height() > 100);
    }
}

#[test]
fn bad_configurations_fail_with_clear_errors_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = config(dir.path());
    cfg.budget_s = -1.0;
    let e = run(&cfg, &mut |_, _| {}).unwrap_err();
    assert!(format!("{e:#}").contains("budget"), "{e:#}");
    cfg.budget_s = 0.02;
    cfg.path.keyframes.clear();
    let e = run(&cfg, &mut |_, _| {}).unwrap_err();
    assert!(format!("{e:#}").contains("path"), "{e:#}");
    let mut cfg = config(dir.path());
    cfg.db = dir.path().join("missing.portico");
    let e = run(&cfg, &mut |_, _| {}).unwrap_err();
    assert!(format!("{e:#}").contains("missing.portico"), "{e:#}");
    assert!(
        "regular,bogus"
            .parse::<RunKind>()
            .is_err_and(|e| e.to_string().contains("regular,bogus"))
    );
}
