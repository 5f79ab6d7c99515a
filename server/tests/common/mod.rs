//! What the server's test binaries share: the tiny building's database, a server on a free
//! loopback port, and an observer inside a live cell.
#![allow(dead_code)]

pub mod attack;

use portico_data::Database;
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::import::import_file;
use portico_protocol::{Observer, PROTOCOL_VERSION, Policy, PrefetchRequest};
use portico_server::{AppState, Config};
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

/// The tiny building's database (plain geometry), built once per test binary.
pub fn db_path() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        let params = portico_generator::Params {
            preset: portico_generator::Preset::Tiny,
            seed: 1,
            floors: Some(1),
        };
        let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
        let dir = tempfile::tempdir().unwrap().keep();
        let glb = dir.join("tiny.glb");
        std::fs::write(&glb, &b.glb).unwrap();
        let out = dir.join("tiny.portico");
        // Plain geometry: the pacing tests need answers larger than a compressed tiny building's
        // (31 KB); the server sends either kind's bytes as they are.
        let opts = BuildOptions {
            compress: false,
            ..BuildOptions::default()
        };
        build(import_file(&glb).unwrap(), &out, &opts, &Quiet).unwrap();
        out
    })
}

/// The `small` building flattened (about 20 MB of segments: more than any socket buffers hold),
/// built once per test binary.
pub fn big_db_path() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        let params = portico_generator::Params {
            preset: portico_generator::Preset::Small,
            seed: 1,
            floors: Some(1),
        };
        let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
        let dir = tempfile::tempdir().unwrap().keep();
        let glb = dir.join("small.glb");
        std::fs::write(&glb, &b.glb).unwrap();
        let out = dir.join("small.portico");
        // Plain geometry: compressed, the segments would be a fifth as large, and fit in the
        // socket buffers the slow-reader tests must overflow.
        let opts = BuildOptions {
            flatten: true,
            no_hierarchy: true,
            compress: false,
            ..BuildOptions::default()
        };
        build(import_file(&glb).unwrap(), &out, &opts, &Quiet).unwrap();
        out
    })
}

pub struct Running {
    pub base: String,
    pub state: Arc<AppState>,
    pub stop: Option<tokio::sync::oneshot::Sender<()>>,
    pub task: tokio::task::JoinHandle<std::io::Result<()>>,
}

pub async fn start(config: Config) -> Running {
    start_on(db_path(), config).await
}

/// A server over the database at `path`.
pub async fn start_on(path: &std::path::Path, config: Config) -> Running {
    let state = AppState::open(path, config).unwrap();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let base = format!("http://{}", listener.local_addr().unwrap());
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(portico_server::serve(state.clone(), listener, async move {
        let _ = rx.await;
    }));
    Running {
        base,
        state,
        stop: Some(tx),
        task,
    }
}

pub fn observer(db: &Database) -> Observer {
    let g = db.cell_graph().unwrap().unwrap();
    let c = g.cells.iter().find(|c| c.live).unwrap();
    let mid = |k: usize| (c.bounds.min[k] + c.bounds.max[k]) * 0.5;
    Observer {
        eye: [mid(0), mid(1), mid(2)],
        dir: [1.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        velocity: [0.0; 3],
        half_fov_x: 0.6,
        half_fov_y: 0.45,
        max_speed: 1.5,
        max_turn: 1.0,
        turn: [0.0; 3],
    }
}

/// A policy that wants the whole building (every cell, every object, every byte).
pub fn wide_policy() -> Policy {
    use portico_protocol::{Granularity, LookaheadCull, RangeCull};
    Policy {
        depth_frames: 10_000,
        range_cull: RangeCull::Any,
        lookahead_cull: LookaheadCull::Any,
        granularity: Granularity::Cell,
        size_threshold_px: 0.0,
        read_bytes: 1 << 30,
        cache_bytes: 1 << 30,
        ..Policy::default()
    }
}

/// A stand-in viewer folder: the page, the glue, `module` as the wasm module, and a gzipped
/// module beside it.
pub fn viewer_folder(dir: &std::path::Path, module: &[u8]) {
    std::fs::write(
        dir.join("index.html"),
        "<!doctype html><title>Portico</title>",
    )
    .unwrap();
    std::fs::write(
        dir.join("portico_web.js"),
        "export default function init() {}",
    )
    .unwrap();
    std::fs::write(dir.join("portico_web_bg.wasm"), module).unwrap();
    std::fs::write(dir.join("portico_web_bg.wasm.gz"), b"gzipped module").unwrap();
}

pub fn request(db: &Database) -> PrefetchRequest {
    PrefetchRequest {
        version: PROTOCOL_VERSION,
        observer: observer(db),
        policy: Policy::default(),
        held: Vec::new(),
    }
}
