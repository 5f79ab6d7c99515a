//! Textures end to end: the tiny building with the generator's textured materials, served by a
//! real server and walked by the real client (wgpu on llvmpipe), against the same building
//! without textures on the same tour.

use portico_client::elision::Algorithm;
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::import::import_file;
use portico_data::path::{PathKind, generate};
use portico_native::walk::{WalkConfig, WalkSummary, walk};
use portico_protocol::Policy;
use std::path::Path;

mod common;

/// Builds the tiny building (seed 2, one storey), textured or not, as `dir/NAME.portico`.
fn build_tiny(dir: &Path, textured: bool) -> std::path::PathBuf {
    let params = portico_generator::Params {
        preset: portico_generator::Preset::Tiny,
        seed: 2,
        floors: Some(1),
    };
    let mut glb = portico_generator::generate(&params, &mut |_| {})
        .unwrap()
        .glb;
    let name = if textured {
        glb = portico_generator::with_textures(&glb).unwrap();
        "textured"
    } else {
        "plain"
    };
    let file = dir.join(format!("{name}.glb"));
    std::fs::write(&file, &glb).unwrap();
    let db = dir.join(format!("{name}.portico"));
    build(
        import_file(&file).unwrap(),
        &db,
        &BuildOptions::default(),
        &Quiet,
    )
    .unwrap();
    db
}

/// Walks 80 frames of the building's tour with `cache_bytes`, a picture every 20 frames.
fn walk_tiny(db: &Path, out: &Path, cache_bytes: u64) -> WalkSummary {
    let (server, _) = common::serve_db(db);
    let graph = portico_data::Database::open(db)
        .unwrap()
        .cell_graph()
        .unwrap()
        .unwrap();
    let cfg = WalkConfig {
        server,
        token: None,
        path: generate(&graph, PathKind::Tour, 2, 1, 1.5, 1.5).unwrap(),
        budget_s: 0.05,
        cache_bytes,
        size: (128, 96),
        elision: Algorithm::Optimize,
        policy: Policy::default(),
        out: Some(out.to_path_buf()),
        png_every: 20,
        max_frames: Some(80),
        pace: true,
        fovy: 1.0,
        max_speed: 1.5,
        max_turn: 1.5,
    };
    walk(&cfg, &mut |_, _| {}).unwrap()
}

/// Mean absolute difference between horizontally adjacent pixels: texture detail.
fn detail(png: &Path) -> f64 {
    let img = image::open(png).unwrap().to_rgb8();
    let mut sum = 0.0;
    let mut n = 0.0;
    for y in 0..img.height() {
        for x in 1..img.width() {
            let (a, b) = (img.get_pixel(x - 1, y), img.get_pixel(x, y));
            sum += (0..3).map(|k| a[k].abs_diff(b[k]) as f64).sum::<f64>();
            n += 1.0;
        }
    }
    sum / n
}

#[test]
fn a_textured_walk_streams_and_draws_its_textures_within_the_budget() {
    let dir = tempfile::tempdir().unwrap();
    let plain = build_tiny(dir.path(), false);
    let textured = build_tiny(dir.path(), true);
    // A budget smaller than the textures' 6 MB: they must share it with the geometry.
    let budget = 4 << 20;
    let p = walk_tiny(&plain, &dir.path().join("plain"), budget);
    let t = walk_tiny(&textured, &dir.path().join("textured"), budget);
    for (name, s) in [("plain", &p), ("textured", &t)] {
        assert_eq!(s.frames, 80, "{name}");
        assert_eq!(s.io_failures, 0, "{name}");
        assert!(s.cache_peak_bytes <= s.cache_budget, "{name}");
        assert!(
            s.gpu_held_peak_bytes > 0 && s.gpu_held_peak_bytes <= s.cache_budget,
            "{name}: {} held",
            s.gpu_held_peak_bytes
        );
        assert!(s.drawn_triangles.max > 0.0, "{name}");
        assert!(
            s.objects_skipped.mean <= 0.5,
            "{name}: {}",
            s.objects_skipped.mean
        );
    }
    // The same tour reads the textures too (their coarse levels at least).
    assert!(
        t.bytes_read > p.bytes_read + 50_000,
        "textured {} bytes, plain {}",
        t.bytes_read,
        p.bytes_read
    );
    // And draws them: the frames show the bricks', planks' and tiles' detail.
    let frames = ["frame_00040.png", "frame_00060.png"];
    let d = |out: &str| -> f64 {
        frames
            .iter()
            .map(|f| detail(&dir.path().join(out).join("frames").join(f)))
            .sum()
    };
    let (dp, dt) = (d("plain"), d("textured"));
    assert!(dt > 2.0 * dp, "detail textured {dt:.2} vs plain {dp:.2}");
}
