//! What the client's end-to-end tests share: the tiny generated building, built into a
//! temporary directory, and served by a real server on 127.0.0.1:0 in this process.

#![allow(dead_code)] // each test file uses its own part of this

use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::import::import_file;
use portico_server::{AppState, Config};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Builds the tiny building (one storey, seed 2) into `dir`; returns the database file.
pub fn build_tiny(dir: &Path) -> PathBuf {
    build_tiny_with(dir, &BuildOptions::default())
}

/// [`build_tiny`] with build options (`dir/tiny.portico`).
pub fn build_tiny_with(dir: &Path, opts: &BuildOptions) -> PathBuf {
    let params = portico_generator::Params {
        preset: portico_generator::Preset::Tiny,
        seed: 2,
        floors: Some(1),
    };
    let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
    let glb = dir.join("tiny.glb");
    std::fs::write(&glb, &b.glb).unwrap();
    let db = dir.join("tiny.portico");
    build(import_file(&glb).unwrap(), &db, opts, &Quiet).unwrap();
    db
}

/// The tiny building on `floors` storeys (`dir/tiny-N.portico`), the generator's seed 3: from
/// two storeys up, stairwells with a flight of stairs to the next.
pub fn build_tiny_floors(dir: &Path, floors: u32) -> PathBuf {
    let params = portico_generator::Params {
        preset: portico_generator::Preset::Tiny,
        seed: 3,
        floors: Some(floors),
    };
    let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
    let glb = dir.join(format!("tiny-{floors}.glb"));
    std::fs::write(&glb, &b.glb).unwrap();
    let db = dir.join(format!("tiny-{floors}.portico"));
    build(
        import_file(&glb).unwrap(),
        &db,
        &BuildOptions::default(),
        &Quiet,
    )
    .unwrap();
    db
}

/// The tiny building with the generator's textured materials (`dir/textured.portico`), its
/// texture segments cut into parts of 4 KiB (so that every client joins parts, whatever level
/// it asks for).
pub fn build_tiny_textured(dir: &Path) -> PathBuf {
    let params = portico_generator::Params {
        preset: portico_generator::Preset::Tiny,
        seed: 2,
        floors: Some(1),
    };
    let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
    let glb = dir.join("textured.glb");
    std::fs::write(&glb, portico_generator::with_textures(&b.glb).unwrap()).unwrap();
    let db = dir.join("textured.portico");
    let opts = BuildOptions {
        part_bytes: Some(4 << 10),
        ..Default::default()
    };
    build(import_file(&glb).unwrap(), &db, &opts, &Quiet).unwrap();
    db
}

/// Builds the tiny building into `dir` and serves it on a background runtime; returns the base
/// URL, the server's state (for its metrics) and the database file.
pub fn serve_tiny(dir: &Path) -> (String, Arc<AppState>, PathBuf) {
    let db = build_tiny(dir);
    let (url, state) = serve_db(&db);
    (url, state, db)
}

/// Serves a database on a background runtime; returns the base URL and the server's state.
pub fn serve_db(db: &Path) -> (String, Arc<AppState>) {
    let state = AppState::open(db, Config::default()).unwrap();
    let s = state.clone();
    let url = in_background(move |l| async move {
        portico_server::serve(s, l, std::future::pending())
            .await
            .unwrap();
    });
    (url, state)
}

/// Serves `state` on a background runtime with the accept loop's own controls (reload, stop);
/// returns the base URL and the control sender.
pub fn serve_controlled(
    state: Arc<AppState>,
) -> (
    String,
    tokio::sync::mpsc::UnboundedSender<portico_server::Control>,
) {
    let (control, rx) = tokio::sync::mpsc::unbounded_channel();
    let url = in_background(move |l| async move {
        portico_server::serve_with_control(l, state, rx, |_, _| {})
            .await
            .unwrap();
    });
    (url, control)
}

/// Runs `serve` on a listener on a free loopback port, on a runtime of its own thread; returns
/// the base URL once it listens.
fn in_background<F: std::future::Future<Output = ()>>(
    serve: impl FnOnce(tokio::net::TcpListener) -> F + Send + 'static,
) -> String {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let rt = tokio::runtime::Runtime::new().unwrap();
        rt.block_on(async move {
            let l = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            tx.send(format!("http://{}", l.local_addr().unwrap()))
                .unwrap();
            serve(l).await;
        });
    });
    rx.recv().unwrap()
}

/// Runs the `portico` binary with `args`.
pub fn portico(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_portico"))
        .args(args)
        .output()
        .expect("run portico")
}

/// Runs a command that must succeed; returns its stdout.
pub fn ok(args: &[&str]) -> String {
    let out = portico(args);
    assert!(
        out.status.success(),
        "portico {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8")
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}
