//! Textures end to end: the tiny building with the generator's textured materials, served by a
//! real server and walked by the real client (wgpu on llvmpipe), against the same building
//! without textures on the same tour; streamed textured frames replayed and scored by the
//! benchmark.

use portico_client::cost::CostModel;
use portico_client::elision::Algorithm;
use portico_client::frame::{Decider, Resident, Scene};
use portico_client::view;
use portico_data::cells::StabList;
use portico_data::path::{PathKind, generate};
use portico_lab::bench::BenchConfig;
use portico_lab::drawn::{DrawnFrame, DrawnLog};
use portico_native::walk::{WalkConfig, WalkSummary, walk};
use portico_protocol::Policy;
use std::path::Path;
use std::sync::Arc;

mod common;

/// Builds the tiny building (seed 2, one storey), textured or not, into `dir`.
fn build_tiny(dir: &Path, textured: bool) -> std::path::PathBuf {
    if textured {
        common::build_tiny_textured(dir)
    } else {
        common::build_tiny(dir)
    }
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
        transport: portico_native::stream::Transport::Push,
        paged: true,
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
    // The same tour reads the textures too (their coarse levels at least: coded, a few KB each).
    assert!(
        t.bytes_read > p.bytes_read + 10_000,
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

/// What a client with everything resident draws on each of the bench's frames, as a load test
/// records it; `strip` draws every textured object in its average colour instead.
fn drawn_everything(cfg: &BenchConfig, strip: bool) -> DrawnLog {
    struct All(Vec<Option<Arc<StabList>>>);
    impl Resident for All {
        fn has(&self, _: u32) -> bool {
            true
        }
        fn stab(&self, cell: u32) -> Option<Arc<StabList>> {
            self.0.get(cell as usize).cloned().flatten()
        }
    }
    let db = portico_data::Database::open(&cfg.db).unwrap();
    let header = db.header().clone();
    let graph = db.cell_graph().unwrap().unwrap();
    let all = All((0..graph.cells.len() as u32)
        .map(|c| {
            let live = graph.cells[c as usize].live;
            live.then(|| Arc::new(db.stab_list(c).unwrap()))
        })
        .collect());
    let bounds: Vec<_> = header.instances.iter().map(|i| i.bounds).collect();
    let scene = Scene {
        header: &header,
        graph: Some(&graph),
        bounds: &bounds,
    };
    let mut decider = Decider::new(Algorithm::None, cfg.budget_s, None);
    let far = view::far_plane(&header.bounds);
    let frames = (0..cfg.frame_count())
        .map(|f| {
            let (eye, dir) = cfg.path.sample((f as f64 * cfg.dt_s) as f32);
            let v = view::Viewpoint::new(eye, dir, cfg.fovy, cfg.size, far);
            let d = decider.decide(&scene, &v, &all, &CostModel::default(), None);
            let mut frame = DrawnFrame::of(&d, f as usize);
            if strip {
                for o in &mut frame.objects {
                    let inst = &header.instances[o.instance as usize];
                    if let (Some(_), Some(t)) = (o.texture.take(), header.texture_of(inst)) {
                        o.tint = t.average;
                    }
                }
            }
            frame
        })
        .collect();
    let p = db.prologue();
    DrawnLog {
        // A policy's name has commas: the reports must keep it one field.
        run: if strip {
            "average,colours"
        } else {
            "everything"
        }
        .into(),
        database_id: format!("{:016x}{:016x}", p.header_checksum, p.index_checksum),
        path_hash: format!("{:016x}", cfg.path.hash()),
        dt_s: cfg.dt_s,
        size: cfg.size,
        fovy_deg: cfg.fovy.to_degrees(),
        frames,
    }
}

#[test]
fn streamed_frames_are_scored_by_drawing_them_again_beside_the_full_detail_ones() {
    let dir = tempfile::tempdir().unwrap();
    let db = build_tiny(dir.path(), true);
    let graph = portico_data::Database::open(&db)
        .unwrap()
        .cell_graph()
        .unwrap()
        .unwrap();
    let path = generate(&graph, PathKind::Tour, 2, 1, 1.5, 1.5).unwrap();
    let mut cfg = BenchConfig::new(db, path, 0.05, dir.path().join("bench"));
    cfg.size = (96, 72);
    cfg.max_frames = Some(8);
    cfg.dt_s = 0.25;
    cfg.algorithms = Vec::new();
    let everything = dir.path().join("everything.json");
    drawn_everything(&cfg, false).write(&everything).unwrap();
    let average = dir.path().join("average.json");
    drawn_everything(&cfg, true).write(&average).unwrap();
    cfg.replays = vec![everything.clone(), average];
    let s = portico_lab::bench::run(&cfg, &mut |_, _| {}).unwrap();

    let names: Vec<&str> = s.runs.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(
        names,
        ["regular", "streamed everything", "streamed average,colours"]
    );
    // What a client with everything drew is the full-detail frame, texel for texel ...
    assert_eq!(s.runs[1].psnr_mean, None, "{:?}", s.runs[1]);
    assert_eq!(s.runs[1].identical_frames, 8);
    // ... and the same objects in their textures' average colours are not.
    let psnr = s.runs[2].psnr_mean.expect("average colours differ");
    assert!(psnr.is_finite() && psnr < 40.0, "{psnr}");
    let csv = std::fs::read_to_string(cfg.out.join("frames.csv")).unwrap();
    let rows = csv
        .lines()
        .filter(|l| l.starts_with("\"streamed average,colours\",") && l.split(',').count() == 17)
        .count();
    assert_eq!(rows, 8, "{csv}");

    // A log from another database, or at another frame step, is refused naming the file.
    let mut log = drawn_everything(&cfg, false);
    log.database_id = "0".repeat(32);
    let other = dir.path().join("other.json");
    log.write(&other).unwrap();
    cfg.replays = vec![other.clone()];
    let e = portico_lab::bench::run(&cfg, &mut |_, _| {}).unwrap_err();
    assert!(format!("{e:#}").contains("other.json"), "{e:#}");
    // An object the model does not have is named with its frame.
    let mut log = drawn_everything(&cfg, false);
    log.frames[3].objects[1].lod = 99;
    log.write(&other).unwrap();
    let e = portico_lab::bench::run(&cfg, &mut |_, _| {}).unwrap_err();
    let e = format!("{e:#}");
    assert!(
        e.contains("other.json: frame 3, object 1") && e.contains("not LOD 99"),
        "{e}"
    );
    // Another path, frame step or image size: refused, naming the file and the option.
    cfg.replays = vec![everything.clone()];
    for (change, says) in [(0, "--path"), (1, "--frame-step-ms"), (2, "--size")] {
        let mut c = cfg.clone();
        match change {
            0 => c.path.keyframes[0].eye[0] += 0.5,
            1 => c.dt_s = 0.2,
            _ => c.size = (64, 48),
        }
        let e = format!(
            "{:#}",
            portico_lab::bench::run(&c, &mut |_, _| {}).unwrap_err()
        );
        assert!(e.contains("everything.json") && e.contains(says), "{e}");
    }
}
