//! End to end on the tiny building: a real server on 127.0.0.1:0 and the real headless client
//! walking a tour through it (wgpu on llvmpipe).

use portico_client::elision::Algorithm;
use portico_client::walk::{WalkConfig, walk};
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::import::import_file;
use portico_data::path::{PathKind, generate};
use portico_protocol::Policy;
use portico_server::{AppState, Config};
use std::path::PathBuf;

/// Builds the tiny building and serves it on a background runtime; returns the base URL.
fn serve_tiny(dir: &std::path::Path) -> (String, std::sync::Arc<AppState>) {
    let params = portico_generator::Params {
        preset: portico_generator::Preset::Tiny,
        seed: 2,
        floors: Some(1),
    };
    let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
    let glb = dir.join("tiny.glb");
    std::fs::write(&glb, &b.glb).unwrap();
    let db = dir.join("tiny.portico");
    build(
        import_file(&glb).unwrap(),
        &db,
        &BuildOptions::default(),
        &Quiet,
    )
    .unwrap();
    let state = AppState::open(&db, Config::default()).unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let s = state.clone();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Runtime::new().unwrap();
        rt.block_on(async move {
            let l = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            tx.send(format!("http://{}", l.local_addr().unwrap()))
                .unwrap();
            portico_server::serve(s, l, std::future::pending())
                .await
                .unwrap();
        });
    });
    (rx.recv().unwrap(), state)
}

fn config(server: String, out: PathBuf, cache_bytes: u64) -> WalkConfig {
    let db = portico_data::Database::open(&out.parent().unwrap().join("tiny.portico")).unwrap();
    let graph = db.cell_graph().unwrap().unwrap();
    let path = generate(&graph, PathKind::Tour, 2, 1, 1.5, 1.5).unwrap();
    WalkConfig {
        server,
        token: None,
        path,
        budget_s: 0.02,
        cache_bytes,
        size: (96, 72),
        elision: Algorithm::Optimize,
        policy: Policy::default(),
        out: Some(out),
        png_every: 25,
        max_frames: Some(60),
        pace: true,
        fovy: 1.0,
        max_speed: 2.0,
        max_turn: 2.0,
    }
}

#[test]
fn a_walk_streams_the_building_and_draws_it_within_the_cache_budget() {
    let dir = tempfile::tempdir().unwrap();
    let (server, state) = serve_tiny(dir.path());
    let out = dir.path().join("walk");
    let s = walk(&config(server, out.clone(), 64 << 20), &mut |_, _| {}).unwrap();
    assert_eq!(s.frames, 60);
    assert!(s.segments_read > 0 && s.bytes_read > 0);
    assert!(s.drawn_triangles.max > 0.0, "something was drawn");
    assert!(s.cache_peak_bytes <= s.cache_budget);
    assert_eq!(s.io_failures, 0);
    assert!(state.metrics.requests("prefetch") > 0);
    // Nothing was read that the server did not send (fetches in flight at the end may be lost).
    assert!(
        s.bytes_read
            <= state
                .metrics
                .bytes_sent
                .load(std::sync::atomic::Ordering::Relaxed)
    );
    // The outputs are there.
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    assert_eq!(csv.lines().count(), 61);
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(json["frames"], 60);
    assert!(out.join("frames/frame_00025.png").exists());
}

#[test]
fn a_tiny_cache_never_overflows_and_keeps_drawing() {
    let dir = tempfile::tempdir().unwrap();
    let (server, _) = serve_tiny(dir.path());
    let out = dir.path().join("walk");
    let budget = 48 << 10;
    let s = walk(&config(server, out, budget), &mut |_, _| {}).unwrap();
    assert_eq!(s.cache_budget, budget);
    assert!(
        s.cache_peak_bytes <= budget,
        "{} > {budget}",
        s.cache_peak_bytes
    );
    assert!(s.evictions > 0, "a 48 KiB cache must release segments");
    assert!(s.drawn_triangles.max > 0.0);
}
