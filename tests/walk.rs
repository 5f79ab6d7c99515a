//! End to end on the tiny building: a real server on 127.0.0.1:0 and the real headless client
//! walking a tour through it (wgpu on llvmpipe).

use portico_client::elision::Algorithm;
use portico_data::path::{PathKind, generate};
use portico_native::walk::{WalkConfig, walk};
use portico_protocol::Policy;
use portico_server::AppState;
use std::path::PathBuf;
use std::sync::atomic::Ordering::Relaxed;

mod common;

/// The tiny building served in this process: base URL and server state.
fn serve_tiny(dir: &std::path::Path) -> (String, std::sync::Arc<AppState>) {
    let (url, state, _) = common::serve_tiny(dir);
    (url, state)
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
        transport: portico_native::stream::Transport::Push,
        paged: true,
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
    assert!(s.gpu_held_peak_bytes > 0 && s.gpu_held_peak_bytes <= s.cache_budget);
    assert_eq!(s.io_failures, 0);
    // Pushed (the default transport), over one session, never falling back to pull.
    let m = &state.metrics;
    assert_eq!(
        m.sessions_total.load(std::sync::atomic::Ordering::Relaxed),
        1
    );
    assert!(m.stream_updates.load(std::sync::atomic::Ordering::Relaxed) >= 50);
    assert_eq!(m.requests("prefetch"), 0);
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
    // What the GPU really held, counted by the renderer where meshes and boxes are made and
    // dropped — the cache, the IO stage's arrivals and the stand-in boxes together — stays in
    // the budget too (it reached 148 KB of these 48 KiB while the IO stage read without a
    // window: eight batches in flight and their uploads waiting outside the cache).
    assert!(s.gpu_held_peak_bytes > 0);
    assert!(
        s.gpu_held_peak_bytes <= budget,
        "{} bytes held on the GPU, budget {budget}",
        s.gpu_held_peak_bytes
    );
}

/// A path that stands still for ten seconds where a spin would start, looking as it would.
fn standing(db: &portico_data::Database) -> portico_data::path::CameraPath {
    let graph = db.cell_graph().unwrap().unwrap();
    let spin = generate(&graph, PathKind::Spin, 1, 1, 1.5, 1.5).unwrap();
    let k = spin.keyframes[0];
    portico_data::path::CameraPath {
        kind: "standing".into(),
        keyframes: vec![k, portico_data::path::Keyframe { t: 10.0, ..k }],
    }
}

/// Every instance at its finest LOD, from the database itself: the full-detail picture.
fn full_detail(
    db: &portico_data::Database,
    path: &portico_data::path::CameraPath,
    size: (u32, u32),
    fovy: f32,
) -> image::RgbaImage {
    use portico_render::{Camera, Draw, Renderer};
    let mut r = Renderer::new(size.0, size.1).unwrap();
    let h = db.header();
    let meshes: Vec<_> = h
        .instances
        .iter()
        .map(|i| r.upload(&db.geometry(&h.lods_of(i)[0]).unwrap()).unwrap())
        .collect();
    let draws: Vec<Draw> = h
        .instances
        .iter()
        .zip(&meshes)
        .map(|(i, mesh)| Draw::new(mesh, glam::Mat4::from_cols_array(&i.transform), [1.0; 4]))
        .collect();
    let (eye, dir) = path.sample(0.0);
    let camera = Camera {
        eye,
        target: eye + dir,
        up: glam::Vec3::Y,
        fovy,
        near: 0.05,
        far: h.bounds.size().length().max(10.0) * 1.5,
    };
    // Drawn as the walk draws the frames it saves: as a picture.
    r.picture_with_boxes(&camera, &draws, &[]).unwrap()
}

/// Whichever way the client learns the model — the core manifest and a page with each stab
/// list, pushed or pulled, or the whole manifest first — what it draws once everything has
/// arrived is the full-detail picture; the paged start reads fewer bytes before its first frame.
#[test]
fn once_everything_has_arrived_a_frame_matches_the_full_detail_render() {
    use portico_native::stream::Transport;
    let dir = tempfile::tempdir().unwrap();
    let (server, _) = serve_tiny(dir.path());
    let db = portico_data::Database::open(&dir.path().join("tiny.portico")).unwrap();
    let mut startup = Vec::new();
    for (transport, paged) in [
        (Transport::Push, true),
        (Transport::Pull, true),
        (Transport::Push, false),
    ] {
        let out = dir.path().join(format!("walk-{transport}-{paged}"));
        let mut cfg = config(server.clone(), out.clone(), 64 << 20);
        cfg.path = standing(&db);
        cfg.elision = Algorithm::None; // the finest LOD of everything visible
        cfg.policy.size_threshold_px = 0.0; // and no cap on what the server sends
        cfg.max_frames = Some(50);
        cfg.png_every = 49;
        cfg.transport = transport;
        cfg.paged = paged;
        let s = walk(&cfg, &mut |_, _| {}).unwrap();
        let what = format!("{transport}, paged {paged}");
        assert_eq!(s.io_failures, 0, "{what}");
        assert_eq!(s.manifest, if paged { "paged" } else { "whole" }, "{what}");
        startup.push(s.startup_bytes);
        let walked = image::open(out.join("frames/frame_00049.png"))
            .unwrap()
            .to_rgba8();
        let reference = full_detail(&db, &cfg.path, cfg.size, cfg.fovy);
        let sky = *reference.get_pixel(0, 0);
        let drawn = reference.pixels().filter(|p| **p != sky).count();
        assert!(
            drawn * 10 > reference.len() / 4,
            "the reference view shows the building ({drawn} px)"
        );
        let share = differing(&walked, &reference);
        assert!(
            share <= 0.01,
            "{what}: {:.1} % of pixels differ from the full-detail render",
            share * 100.0
        );
    }
    assert!(
        startup[0] * 2 < startup[2],
        "bytes before the first frame, paged and whole: {startup:?}"
    );
}

/// The share of pixels that differ by more than 8 in some channel.
fn differing(a: &image::RgbaImage, b: &image::RgbaImage) -> f64 {
    let n = a
        .pixels()
        .zip(b.pixels())
        .filter(|(a, b)| a.0.iter().zip(b.0).any(|(x, y)| x.abs_diff(y) > 8))
        .count();
    n as f64 / a.len() as f64 * 4.0
}

#[test]
fn a_compressed_database_looks_the_same_and_the_client_decodes_it() {
    let dir = tempfile::tempdir().unwrap();
    let plain_opts = portico_data::build::BuildOptions {
        compress: false,
        ..Default::default()
    };
    let plain = common::build_tiny_with(dir.path(), &plain_opts);
    let packed_dir = dir.path().join("packed");
    std::fs::create_dir(&packed_dir).unwrap();
    // Compressed: the default.
    let packed = common::build_tiny(&packed_dir);
    let (a, b) = (
        portico_data::Database::open(&plain).unwrap(),
        portico_data::Database::open(&packed).unwrap(),
    );
    let geometry = |db: &portico_data::Database| portico_data::stats::stats(db).geometry_bytes;
    assert!(
        geometry(&b) * 2 < geometry(&a),
        "compressed segments are smaller"
    );
    // Every instance at its finest LOD, from each file: no visible change.
    let path = standing(&a);
    let size = (160, 120);
    let (ra, rb) = (
        full_detail(&a, &path, size, 1.0),
        full_detail(&b, &path, size, 1.0),
    );
    let psnr = portico_lab::bench::fidelity::psnr(&ra, &rb).unwrap_or(f64::INFINITY);
    eprintln!("compressed vs plain, finest LODs: PSNR {psnr:.1} dB");
    assert!(
        psnr >= 50.0,
        "PSNR {psnr:.1} dB against the uncompressed render"
    );
    // The real client streams it, decodes it on its IO thread and draws the same picture.
    let (server, _) = common::serve_db(&packed);
    let out = packed_dir.join("walk");
    let mut cfg = config(server, out.clone(), 64 << 20);
    cfg.path = path;
    cfg.elision = Algorithm::None;
    cfg.policy.size_threshold_px = 0.0;
    cfg.max_frames = Some(50);
    cfg.png_every = 49;
    let s = walk(&cfg, &mut |_, _| {}).unwrap();
    assert_eq!(s.io_failures, 0);
    assert!(s.gpu_held_peak_bytes <= s.cache_budget);
    let walked = image::open(out.join("frames/frame_00049.png"))
        .unwrap()
        .to_rgba8();
    let reference = full_detail(&b, &cfg.path, cfg.size, cfg.fovy);
    let share = differing(&walked, &reference);
    assert!(share <= 0.01, "{:.1} % of pixels differ", share * 100.0);
    // A tiny cache holds what the segments decode to, not what they weighed on the wire: the
    // GPU never holds more than the budget.
    let budget = 48 << 10;
    let mut cfg = config(cfg.server, packed_dir.join("walk-tiny"), budget);
    cfg.max_frames = Some(60);
    let s = walk(&cfg, &mut |_, _| {}).unwrap();
    assert_eq!(s.io_failures, 0);
    assert!(s.evictions > 0 && s.drawn_triangles.max > 0.0);
    assert!(
        s.gpu_held_peak_bytes <= budget,
        "{} bytes held on the GPU, budget {budget}",
        s.gpu_held_peak_bytes
    );
}

/// A TCP proxy that holds every chunk from the server for `delay` before passing it on: a slow
/// server (or a long, thin link). Returns its base URL.
fn slow_proxy(upstream: &str, delay: std::time::Duration) -> String {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let upstream = upstream.trim_start_matches("http://").to_string();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Runtime::new().unwrap();
        rt.block_on(async move {
            let l = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            tx.send(format!("http://{}", l.local_addr().unwrap()))
                .unwrap();
            loop {
                let Ok((client, _)) = l.accept().await else {
                    return;
                };
                let up = upstream.clone();
                tokio::spawn(async move {
                    let Ok(server) = tokio::net::TcpStream::connect(&up).await else {
                        return;
                    };
                    let (mut cr, mut cw) = client.into_split();
                    let (mut sr, mut sw) = server.into_split();
                    tokio::spawn(async move {
                        let _ = tokio::io::copy(&mut cr, &mut sw).await;
                    });
                    let mut buf = vec![0u8; 64 << 10];
                    while let Ok(n) = sr.read(&mut buf).await {
                        if n == 0 {
                            break;
                        }
                        tokio::time::sleep(delay).await;
                        if cw.write_all(&buf[..n]).await.is_err() {
                            break;
                        }
                    }
                });
            }
        });
    });
    rx.recv().unwrap()
}

#[test]
fn a_slow_server_makes_the_client_skip_what_is_missing_never_wait() {
    let dir = tempfile::tempdir().unwrap();
    let (server, _) = serve_tiny(dir.path());
    let delay = std::time::Duration::from_millis(400);
    let slow = slow_proxy(&server, delay);
    let out = dir.path().join("walk");
    let mut cfg = config(slow, out, 64 << 20);
    cfg.max_frames = Some(120);
    // Pull: each read's latency is from its request (a pushed segment's is counted from the
    // latest observer sent before it came, which says nothing of the proxy's delay).
    cfg.transport = portico_native::stream::Transport::Pull;
    let s = walk(&cfg, &mut |_, _| {}).unwrap();
    assert_eq!(s.frames, 120);
    assert!(s.segments_read > 0, "{s:?}");
    // What had not arrived was skipped ...
    assert!(s.objects_skipped.max > 0.0, "{:?}", s.objects_skipped);
    assert!(
        s.fetch_latency_s.min >= delay.as_secs_f64() * 0.9,
        "{:?}",
        s.fetch_latency_s
    );
    // ... and no frame waited for it: frame times are those of the same walk straight to the
    // server (which draws more, sooner), within a frame budget — not the 400 ms of a wait.
    assert!(s.drawn_triangles.max > 0.0, "what arrived was drawn");
    let mut direct = config(server, dir.path().join("direct"), 64 << 20);
    direct.max_frames = Some(120);
    let direct = walk(&direct, &mut |_, _| {}).unwrap();
    let bound = 2.0 * direct.frame_s.p99 + cfg.budget_s;
    assert!(
        s.frame_s.p99 <= bound,
        "frame p99 {:.1} ms through the slow proxy, {:.1} ms straight to the server",
        s.frame_s.p99 * 1e3,
        direct.frame_s.p99 * 1e3
    );
    assert!(
        s.frame_s.max < delay.as_secs_f64(),
        "a frame took {} s",
        s.frame_s.max
    );
}

#[test]
fn a_server_restart_mid_walk_is_survived() {
    let dir = tempfile::tempdir().unwrap();
    let (_, state) = serve_tiny(dir.path());
    // A second server on a port of our own, which we stop and start again.
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap();
    drop(l);
    let start = |state: std::sync::Arc<AppState>| {
        let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let (up_tx, up_rx) = std::sync::mpsc::channel();
        let t = std::thread::spawn(move || {
            let rt = tokio::runtime::Runtime::new().unwrap();
            rt.block_on(async move {
                let l = tokio::net::TcpListener::bind(addr).await.unwrap();
                up_tx.send(()).unwrap();
                portico_server::serve(state, l, async move {
                    let _ = stop_rx.await;
                })
                .await
                .unwrap();
            });
        });
        up_rx.recv().unwrap();
        (stop_tx, t)
    };
    let mut running = Some(start(state.clone()));
    let out = dir.path().join("walk");
    let mut cfg = config(format!("http://{addr}"), out, 64 << 20);
    cfg.max_frames = Some(150);
    let (mut read_after, mut sessions_after) = (0u64, 0u64);
    let s = walk(&cfg, &mut |done, _| {
        if done == 20
            && let Some((stop, t)) = running.take()
        {
            let _ = stop.send(());
            t.join().unwrap();
        }
        if done == 40 {
            running = Some(start(state.clone()));
            read_after = state.metrics.requests("prefetch");
            sessions_after = state.metrics.sessions_total.load(Relaxed);
        }
    })
    .unwrap();
    assert_eq!(s.frames, 150, "the walk went on through the outage");
    assert!(s.io_failures > 0, "the outage was noticed");
    assert!(
        state.metrics.requests("prefetch") > read_after,
        "the client read over pull while the stream was down"
    );
    // Fault 8 of the second hardening round: the client used to finish every walk over pull.
    assert!(
        state.metrics.sessions_total.load(Relaxed) > sessions_after,
        "the client opened its stream again on the restarted server"
    );
    assert!(!s.database_changed);
}

/// Fault 2 of the second hardening round: a stream opened after a rebuild and reload pushed
/// the new file's segments to a client holding the old manifest (checksum rejections, objects
/// skipped for the rest of the walk). Now the stream names its database: the reload ends the
/// session, the reopened one is closed as stale, no segment of the new file reaches the client,
/// and the walk goes on with what it holds.
#[test]
fn a_rebuild_and_reload_mid_walk_sends_no_segment_of_the_new_file() {
    let dir = tempfile::tempdir().unwrap();
    let (old, _) = {
        let db = common::build_tiny(dir.path());
        (
            portico_server::AppState::open(&db, Default::default()).unwrap(),
            db,
        )
    };
    let other = tempfile::tempdir().unwrap();
    let opts = portico_data::build::BuildOptions {
        no_hierarchy: true,
        ..Default::default()
    };
    let new = portico_server::AppState::open(
        &common::build_tiny_with(other.path(), &opts),
        Default::default(),
    )
    .unwrap();
    assert_ne!(old.database_id, new.database_id);
    let (url, control) = common::serve_controlled(old.clone());
    let mut cfg = config(url, dir.path().join("walk"), 64 << 20);
    cfg.max_frames = Some(120);
    let next = new.clone();
    let s = walk(&cfg, &mut |done, _| {
        if done == 20 {
            let (swapped, _) = tokio::sync::oneshot::channel();
            let _ = control.send(portico_server::Control::Reload(next.clone(), swapped));
        }
    })
    .unwrap();
    assert_eq!(s.frames, 120, "the walk went on");
    assert!(
        s.database_changed,
        "the client learnt that the database changed"
    );
    assert_eq!(
        new.metrics.segments_sent.load(Relaxed),
        0,
        "no segment of the new file reached the client"
    );
    assert!(old.metrics.segments_sent.load(Relaxed) > 0);
}
