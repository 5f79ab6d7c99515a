//! The browser viewer end to end, in headless Chromium (WebGL2 through SwiftShader) driven by
//! chromedriver: the page `portico serve` serves at `/` loads the tiny building from the same
//! server (its geometry compressed), draws it, walks the standard tour by script, keeps its cache under the budget,
//! logs no errors and stays alive across a server restart; then the textured building, whose
//! texture segments the page decodes (and re-codes as BC blocks where WebGL2 offers them).
//!
//! Needs `web/build.sh` to have built `target/viewer/`, and Debian's `chromium` and
//! `chromium-driver`. Without them the test prints why and passes, unless `CI` is set (CI
//! installs and builds them), where that is a failure.

mod common;

use common::build_tiny_with;
use fantoccini::{Client, ClientBuilder};
use portico_server::{AppState, Config};
use serde_json::{Value, json};
use std::net::SocketAddr;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

const CHROMIUM: &str = "/usr/bin/chromium";
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";
/// The page's canvas size in CSS pixels (the window is a little larger).
const WIDTH: u32 = 320;
const HEIGHT: u32 = 240;

fn viewer_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("target/viewer")
}

/// Why the test cannot run here, if it cannot.
fn missing() -> Option<String> {
    if !portico_server::viewer_is_built(&viewer_dir()) {
        return Some(format!(
            "{} holds no built viewer (run `bash web/build.sh`)",
            viewer_dir().display()
        ));
    }
    [CHROMIUM, CHROMEDRIVER]
        .iter()
        .find(|p| !Path::new(p).exists())
        .map(|p| format!("{p} is not installed (apt-get install chromium chromium-driver)"))
}

/// A server on `addr` (port 0: any) that stops when the sender is dropped or fires.
fn serve(
    state: Arc<AppState>,
    addr: SocketAddr,
) -> (
    SocketAddr,
    tokio::sync::oneshot::Sender<()>,
    std::thread::JoinHandle<()>,
) {
    let (tx, rx) = std::sync::mpsc::channel();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let thread = std::thread::spawn(move || {
        let rt = tokio::runtime::Runtime::new().unwrap();
        rt.block_on(async move {
            let l = tokio::net::TcpListener::bind(addr).await.unwrap();
            tx.send(l.local_addr().unwrap()).unwrap();
            portico_server::serve(state, l, async move {
                let _ = stopped.await;
            })
            .await
            .unwrap();
        });
    });
    (rx.recv().unwrap(), stop, thread)
}

/// chromedriver on a free port in a process group of its own, killed with every Chromium it
/// started when dropped (also when the test fails before closing its session: a browser left
/// behind would keep drawing and take the CPU from every test after it).
struct Driver(Child, u16);

impl Drop for Driver {
    fn drop(&mut self) {
        // SAFETY: kill(2) on the process group this test created; no memory is involved.
        unsafe {
            libc::kill(-(self.0.id() as i32), libc::SIGKILL);
        }
        let _ = self.0.wait();
    }
}

fn chromedriver() -> Driver {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let child = Command::new(CHROMEDRIVER)
        .arg(format!("--port={port}"))
        .process_group(0)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start chromedriver");
    let driver = Driver(child, port);
    let t = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "chromedriver did not start"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    driver
}

async fn browser(port: u16) -> Client {
    let mut caps = serde_json::Map::new();
    caps.insert(
        "goog:chromeOptions".into(),
        json!({
            "binary": CHROMIUM,
            "args": [
                "--headless=new", "--no-sandbox", "--disable-dev-shm-usage",
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                format!("--window-size={},{}", WIDTH + 100, HEIGHT + 300),
                "--force-device-scale-factor=1",
            ],
        }),
    );
    let connector = hyper_util::client::legacy::connect::HttpConnector::new();
    ClientBuilder::new(connector)
        .capabilities(caps)
        .connect(&format!("http://127.0.0.1:{port}"))
        .await
        .expect("a chromium session")
}

async fn eval(c: &Client, script: &str) -> Value {
    c.execute(script, vec![]).await.expect(script)
}

async fn stats(c: &Client) -> Value {
    let s = eval(c, "return window.portico ? window.portico.stats() : null").await;
    serde_json::from_str(s.as_str().unwrap_or("null")).unwrap()
}

/// Polls the page's figures until `done` holds; fails with the page's error or its last
/// figures after `secs`.
async fn wait_for(c: &Client, secs: u64, what: &str, done: impl Fn(&Value) -> bool) -> Value {
    let t = Instant::now();
    loop {
        let failed = eval(c, "return window.porticoError || null").await;
        assert!(failed.is_null(), "the page failed: {failed}");
        let s = stats(c).await;
        if done(&s) {
            return s;
        }
        assert!(
            t.elapsed() < Duration::from_secs(secs),
            "{what}: not after {secs} s; {s}"
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// The native renderer's picture (llvmpipe) of every object at its finest LOD from the eye and
/// direction the page reports, with the page's field of view and announced speeds, at the
/// canvas's size: what the browser should show once everything there has arrived.
fn native_view(db: &Path, eye: [f32; 3], dir: [f32; 3]) -> image::RgbaImage {
    use portico_client::view::{self, Viewpoint};
    let db = portico_data::Database::open(db).unwrap();
    let header = db.header();
    let mut r = portico_render::Renderer::with_samples(WIDTH, HEIGHT, Some(1)).unwrap();
    let obs = view::observer(
        glam::Vec3::from(eye),
        glam::Vec3::from(dir),
        view::Motion::default(),
        60f32.to_radians(),
        WIDTH as f32 / HEIGHT as f32,
        2.0,
        2.0,
    );
    let vp = Viewpoint::of(&obs, (WIDTH, HEIGHT), view::far_plane(&header.bounds));
    let meshes: Vec<_> = header
        .instances
        .iter()
        .map(|inst| {
            let lod = &header.lods_of(inst)[0];
            r.upload(&db.geometry(lod).unwrap()).unwrap()
        })
        .collect();
    let draws: Vec<_> = header
        .instances
        .iter()
        .zip(&meshes)
        .map(|(inst, mesh)| {
            portico_render::Draw::new(mesh, glam::Mat4::from_cols_array(&inst.transform), [1.0; 4])
        })
        .collect();
    r.render_to_image(&vp.camera, &draws).unwrap().1
}

/// Mean absolute difference per channel (0–255) and the share of pixels off by more than 48
/// in sum over RGB.
fn difference(a: &image::RgbaImage, b: &image::RgbaImage) -> (f64, f64) {
    let (mut sum, mut off, mut n) = (0u64, 0u64, 0u64);
    for (p, q) in a.pixels().zip(b.pixels()) {
        let d: u64 = (0..3).map(|i| u64::from(p[i].abs_diff(q[i]))).sum();
        sum += d;
        off += u64::from(d > 48);
        n += 1;
    }
    (
        sum as f64 / (3 * n.max(1)) as f64,
        off as f64 / n.max(1) as f64,
    )
}

/// Share of the screenshot's canvas pixels that are not the sky colour.
fn not_sky(png: &[u8]) -> f64 {
    not_sky_image(&image::load_from_memory(png).unwrap().to_rgba8())
}

/// [`not_sky`] of a decoded picture.
fn not_sky_image(img: &image::RgbaImage) -> f64 {
    let (w, h) = (img.width().min(WIDTH), img.height().min(HEIGHT));
    // The sky (0.30, 0.50, 0.80 linear) in sRGB is about (149, 188, 231).
    let sky = [149i32, 188, 231];
    let mut other = 0u64;
    for y in 0..h {
        for x in 0..w {
            let p = img.get_pixel(x, y);
            let d: i32 = (0..3).map(|i| (i32::from(p[i]) - sky[i]).abs()).sum();
            if d > 24 {
                other += 1;
            }
        }
    }
    other as f64 / (w * h) as f64
}

#[test]
fn the_viewer_walks_the_building_in_headless_chromium() {
    if let Some(why) = missing() {
        assert!(std::env::var_os("CI").is_none(), "{why}, but CI is set");
        eprintln!("skipped: {why}");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path().to_path_buf();
    // Compressed geometry (the default): the page decodes it (meshoptimizer's codecs, in
    // Rust) on its thread.
    let db = build_tiny_with(dir.path(), &portico_data::build::BuildOptions::default());
    let compressed = {
        let d = portico_data::Database::open(&db).unwrap();
        d.segments()
            .iter()
            .filter(|e| portico_data::codec::is_compressed(&d.segment(e.id).unwrap()))
            .count()
    };
    assert!(
        compressed > 10,
        "only {compressed} segments were stored compressed"
    );
    let config = || Config {
        viewer: Some(viewer_dir()),
        ..Config::default()
    };
    let state = AppState::open(&db, config()).unwrap();
    let (addr, stop, server) = serve(state, "127.0.0.1:0".parse().unwrap());
    let driver = chromedriver();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let c = browser(driver.1).await;
        // A cache of 1 MiB (the tiny building's geometry is about 0.5 MB at every LOD).
        c.goto(&format!(
            "http://{addr}/?backend=webgl&cache_mb=1#eye=0,0,0&dir=1,0,0"
        ))
        .await
        .unwrap();
        eval(
            &c,
            &format!("document.getElementById('view').style.width='{WIDTH}px'; document.getElementById('view').style.height='{HEIGHT}px';"),
        )
        .await;
        // The tour's first view: the page loads, fetches and draws what is visible.
        wait_for(&c, 90, "the viewer started", |s| s["frames"].as_u64() > Some(0)).await;
        eval(&c, "window.portico.tour(true)").await;
        let s = wait_for(&c, 90, "a complete frame", |s| {
            s["first_complete_frame"].is_u64() && s["segments_received"].as_u64() > Some(3)
        })
        .await;
        assert_eq!(s["backend"], "Gl", "WebGL2 was asked for: {s}");
        assert_eq!(s["transport"], "stream", "segments are pushed by default: {s}");
        assert_eq!(s["manifest"], "paged", "the core manifest first, then pages: {s}");
        assert_eq!(s["answers"], 0, "nothing was pulled while the stream worked: {s}");
        let before = s["eye"].clone();
        let frames = s["frames"].as_u64().unwrap();
        // The tour walks: frames go on and the eye moves.
        let s = wait_for(&c, 60, "the tour moved", |s| {
            s["eye"] != before && s["frames"].as_u64() > Some(frames + 10)
        })
        .await;
        assert!(s["touring"].as_bool().unwrap(), "{s}");
        let png = c.screenshot().await.unwrap();
        let drawn = not_sky(&png);
        assert!(drawn > 0.05, "the frame is all sky ({drawn:.3} drawn): {s}");
        // The mini-map shows the storey's cells and the observer (its red marker).
        let map = eval(
            &c,
            "const m = document.getElementById('map'); \
             const d = m.getContext('2d').getImageData(0, 0, m.width, m.height).data; \
             let observer = 0, cells = 0; \
             for (let i = 0; i < d.length; i += 4) { \
               if (d[i] > 200 && d[i + 1] < 120 && d[i + 2] < 100) observer++; \
               else if (d[i] > 90 && d[i + 1] > 90 && d[i + 2] > 90) cells++; } \
             return [observer, cells];",
        )
        .await;
        assert!(map[0].as_u64() > Some(10) && map[1].as_u64() > Some(100), "the mini-map: {map}");
        // The address holds the viewpoint.
        let url = c.current_url().await.unwrap();
        assert!(url.fragment().is_some_and(|f| f.starts_with("eye=")), "{url}");

        // Standing still where the tour is now, once everything visible is resident at the
        // detail the elision wants, the page shows what the native renderer draws there.
        let here = stats(&c).await;
        let (eye, dir) = (here["eye"].clone(), here["dir"].clone());
        let args: Vec<String> = [&eye, &dir]
            .iter()
            .flat_map(|v| v.as_array().unwrap().iter().map(|x| x.to_string()))
            .collect();
        eval(&c, &format!("window.portico.look({})", args.join(","))).await;
        eval(&c, "for (const id of ['stats', 'help', 'map']) document.getElementById(id).style.display = 'none';").await;
        let frames = stats(&c).await["frames"].as_u64().unwrap();
        wait_for(&c, 60, "a complete frame where the tour stood", |s| {
            s["frames"].as_u64() > Some(frames + 5)
                && s["objects_skipped"] == 0
                && s["lods_skipped"] == 0
                && !s["touring"].as_bool().unwrap()
        })
        .await;
        // The view levels out after `look` (pitch decays): draw natively what the page shows now.
        let still = stats(&c).await;
        let (eye, dir) = (still["eye"].clone(), still["dir"].clone());
        let canvas = c.find(fantoccini::Locator::Id("view")).await.unwrap();
        let shot = image::load_from_memory(&canvas.screenshot().await.unwrap())
            .unwrap()
            .to_rgba8();
        assert_eq!((shot.width(), shot.height()), (WIDTH, HEIGHT));
        let f = |v: &Value| -> [f32; 3] {
            let a = v.as_array().unwrap();
            std::array::from_fn(|i| a[i].as_f64().unwrap() as f32)
        };
        let native = native_view(&db, f(&eye), f(&dir));
        let (mean, off) = difference(&shot, &native);
        eprintln!(
            "browser against native: mean difference {mean:.2} per channel, {:.2} % of pixels off, {:.2} drawn",
            off * 100.0,
            not_sky_image(&shot)
        );
        if mean >= 6.0 || off >= 0.05 {
            let keep = std::env::temp_dir();
            shot.save(keep.join("portico-browser.png")).unwrap();
            native.save(keep.join("portico-native.png")).unwrap();
        }
        assert!(
            mean < 6.0 && off < 0.05,
            "the browser's frame differs from the native one: mean {mean:.2} per channel, {:.1} % of pixels off (both saved in {})",
            off * 100.0,
            std::env::temp_dir().display()
        );

        // A viewpoint pasted into the address of the open page moves the observer there.
        eval(&c, "location.hash = '#eye=1.5,1.25,2.5&dir=0,0,1'").await;
        wait_for(&c, 30, "the pasted viewpoint", |s| {
            s["eye"] == json!([1.5, 1.25, 2.5]) && !s["touring"].as_bool().unwrap_or(true)
        })
        .await;

        // The server goes away and comes back on the same address: the page keeps drawing.
        drop(stop);
        server.join().unwrap();
        let down = stats(&c).await;
        tokio::time::sleep(Duration::from_secs(2)).await;
        let state = AppState::open(&db, config()).unwrap();
        let (_, stop, server) = serve(state, addr);
        // The stream closed with the server: the page pulls over HTTP meanwhile, then opens a
        // new stream session.
        let sessions = down["stream_sessions"].as_u64().unwrap();
        let s = wait_for(&c, 90, "frames, answers and a new stream after the restart", |s| {
            s["frames"].as_u64() > down["frames"].as_u64().map(|f| f + 20)
                && s["answers"].as_u64() > Some(0)
                && s["stream_sessions"].as_u64() > Some(sessions)
                && s["transport"] == "stream"
        })
        .await;
        assert!(s["failures"].as_u64() > Some(0), "the restart went unnoticed: {s}");
        // Everything the page holds on the GPU, in the cache or not, within the budget the
        // address gave (1 MiB: the cache's seven eighths and the IO stage's eighth).
        let held = s["gpu_held_peak_bytes"].as_u64().expect("gpu_held_peak_bytes");
        assert!(held <= 1 << 20, "GPU memory over the budget: {s}");
        assert!(held > 0, "{s}");
        assert_eq!(s["unusable_segments"], 0, "{s}");
        let errors = eval(&c, "return window.porticoErrors || []").await;
        assert_eq!(errors, json!([]), "the page logged errors");

        // Pull only, as asked: the same building arrives through prefetch answers and batches.
        c.goto(&format!("http://{addr}/?backend=webgl&transport=pull"))
            .await
            .unwrap();
        let s = wait_for(&c, 90, "a complete frame, pulled", |s| {
            s["first_complete_frame"].is_u64() && s["segments_received"].as_u64() > Some(3)
        })
        .await;
        assert_eq!(s["transport"], "pull", "{s}");
        assert_eq!(s["stream_sessions"], 0, "{s}");
        assert!(s["answers"].as_u64() > Some(0), "{s}");
        assert_eq!(s["manifest"], "paged", "pages come beside the stab lists pulled: {s}");

        // Maciel's cluster traversal, as the native walk's `--elision impostors` runs it, and
        // the whole manifest read first, as asked.
        c.goto(&format!(
            "http://{addr}/?backend=webgl&elision=impostors&manifest=whole"
        ))
        .await
        .unwrap();
        let s = wait_for(&c, 90, "a complete frame, impostors", |s| {
            s["first_complete_frame"].is_u64() && s["segments_received"].as_u64() > Some(3)
        })
        .await;
        assert_eq!(s["elision"], "impostors", "{s}");
        // Boxes stand in for the clusters whose detail had not come (or is far).
        assert!(s["frames_with_boxes"].as_u64() > Some(0), "no impostor boxes drawn: {s}");
        assert_eq!(s["manifest"], "whole", "{s}");
        assert_eq!(s["unusable_segments"], 0, "{s}");
        let errors = eval(&c, "return window.porticoErrors || []").await;
        assert_eq!(errors, json!([]), "the page logged errors");
        drop(stop);
        server.join().unwrap();

        // The textured building: the page decodes its texture segments (JPEG or PNG) and,
        // where the GPU takes BC textures, re-codes them as BC1 / BC3, on its one thread.
        let textured = common::build_tiny_textured(&tmp);
        let state = AppState::open(&textured, config()).unwrap();
        let (addr, stop, server) = serve(state, "127.0.0.1:0".parse().unwrap());
        c.goto(&format!("http://{addr}/?backend=webgl#eye=0,0,0&dir=1,0,0"))
            .await
            .unwrap();
        wait_for(&c, 90, "the textured viewer started", |s| {
            s["frames"].as_u64() > Some(0)
        })
        .await;
        eval(&c, "window.portico.tour(true)").await;
        let s = wait_for(&c, 120, "texture segments decoded", |s| {
            s["texture_segments"].as_u64() >= Some(4)
        })
        .await;
        let (ms, texels, gpu) = (
            s["texture_ms"].as_f64().unwrap(),
            s["texture_texel_bytes"].as_u64().unwrap(),
            s["texture_gpu_bytes"].as_u64().unwrap(),
        );
        eprintln!(
            "textures in Chromium ({}): {} segments, {:.2} MB of texels in {ms:.0} ms ({:.1} ms per decoded MB), {:.2} MB on the GPU ({})",
            s["backend"],
            s["texture_segments"],
            texels as f64 / 1e6,
            ms / (texels as f64 / 1e6),
            gpu as f64 / 1e6,
            s["texel_format"],
        );
        assert!(ms > 0.0 && texels > 0, "{s}");
        match s["texel_format"].as_str() {
            // BC1 for the generator's opaque textures: an eighth of the texels, plus partial
            // blocks of the smallest levels.
            Some("Block") => assert!(gpu * 7 < texels, "{s}"),
            Some("Rgba8") => assert_eq!(gpu, texels, "{s}"),
            _ => panic!("texel_format: {s}"),
        }
        assert_eq!(s["unusable_segments"], 0, "{s}");
        let errors = eval(&c, "return window.porticoErrors || []").await;
        assert_eq!(errors, json!([]), "the page logged errors");
        drop(stop);
        server.join().unwrap();

        // Walking like a person, on two storeys joined by a flight of stairs.
        walk_and_pick(&c, &tmp).await;
        c.close().await.unwrap();
    });
}

/// Holds `code` down in the page for `ms` milliseconds; the eye then.
async fn hold(c: &Client, code: &str, ms: u64) -> Value {
    eval(
        c,
        &format!("window.dispatchEvent(new KeyboardEvent('keydown', {{code: '{code}'}}))"),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(ms)).await;
    eval(
        c,
        &format!("window.dispatchEvent(new KeyboardEvent('keyup', {{code: '{code}'}}))"),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    stats(c).await["eye"].clone()
}

/// In walk mode (the page's default) the page's observer stops at a wall where the walker
/// of the client core does, and walking off the upper floor into a stair's hole lowers it; a
/// click on an object names it with its tags.
async fn walk_and_pick(c: &Client, dir: &Path) {
    use glam::Vec3;
    use portico_client::walk::Walker;
    let db = common::build_tiny_floors(dir, 2);
    let d = portico_data::Database::open(&db).unwrap();
    let graph = d.cell_graph().unwrap().expect("cells");
    let header = d.header();
    // A place on the upper floor beside the flight's hole, facing it, with a wall behind.
    let flight = header
        .instances
        .iter()
        .find(|i| i.tag("kind") == Some("stairs") || i.name.contains("stairs"))
        .expect("a flight of stairs")
        .bounds;
    let x = (flight.min[0] + flight.max[0]) / 2.0;
    let z = (flight.min[2] + flight.max[2]) / 2.0 + 0.5;
    let native = |from: Vec3, toward: Vec3, seconds: f32| {
        let mut w = Walker::new();
        let mut eye = from;
        for _ in 0..(seconds * 30.0) as usize {
            w.gather_header(&graph, header, 0, eye);
            eye = w.step(&graph, eye, toward.normalize() * 1.5 / 30.0, 1.0 / 30.0);
        }
        eye
    };
    let (start, toward) = [flight.min[0] - 0.6, flight.max[0] + 0.6]
        .into_iter()
        .filter_map(|side| {
            // On the floor under a point a little below the flight's top (the upper storey).
            let toward = Vec3::new(x - side, 0.0, 0.0).normalize();
            let above = Vec3::new(side, flight.max[1] - 0.2, z);
            let floor = Walker::new().ground(&graph, above)?;
            Some((
                Vec3::new(side, floor + portico_client::walk::EYE_HEIGHT, z),
                toward,
            ))
        })
        .find(|&(s, t)| native(s, t, 2.0).y < s.y - 1.0)
        .expect("a side of the hole with a floor");
    let wall = native(start, -toward, 3.0);
    assert!(
        (wall - start).length() < 4.0,
        "no wall behind {start}: {wall}"
    );

    let state = AppState::open(
        &db,
        Config {
            viewer: Some(viewer_dir()),
            ..Config::default()
        },
    )
    .unwrap();
    let (addr, stop, server) = serve(state, "127.0.0.1:0".parse().unwrap());
    let back = -toward;
    c.goto(&format!(
        "http://{addr}/?backend=webgl#eye={},{},{}&dir={},0,{}",
        start.x, start.y, start.z, back.x, back.z
    ))
    .await
    .unwrap();
    let s = wait_for(c, 90, "the two-storey building drawn", |s| {
        s["first_complete_frame"].is_u64() && s["gait"] == "walk"
    })
    .await;
    let eye = |v: &Value| -> Vec3 {
        let a = v.as_array().unwrap();
        Vec3::new(
            a[0].as_f64().unwrap() as f32,
            a[1].as_f64().unwrap() as f32,
            a[2].as_f64().unwrap() as f32,
        )
    };
    assert!(
        (eye(&s["eye"]) - start).length() < 0.05,
        "the walker moved the start: {s}"
    );
    // Into the wall behind for 3 s: stopped where the client core's walker stops (1.5 m/s
    // would have gone 4.5 m).
    let stopped = eye(&hold(c, "KeyW", 3000).await);
    assert!(
        (stopped - wall).length() < 0.05,
        "the page stopped at {stopped}, the walker at {wall}"
    );
    // Turned round, on over the hole: lowered onto the flight or the floor below.
    eval(
        c,
        &format!(
            "window.portico.look({},{},{},{},0,{})",
            stopped.x, stopped.y, stopped.z, toward.x, toward.z
        ),
    )
    .await;
    let lowered = eye(&hold(c, "KeyW", 4000).await);
    assert!(
        lowered.y < start.y - 1.0,
        "not lowered over the hole: {lowered} from {start}"
    );

    // A click on what is in front: its name and tags.
    let picked: Value = serde_json::from_str(
        eval(c, "return window.portico.pick(0, -0.2)")
            .await
            .as_str()
            .unwrap(),
    )
    .unwrap();
    assert!(
        picked["instance"].is_u64() && picked["triangles"].as_u64() > Some(0),
        "{picked}"
    );
    assert!(
        !picked["tags"].as_array().unwrap().is_empty() && picked["class"].is_string(),
        "{picked}"
    );
    // The panel shows it by its next refresh (four a second).
    tokio::time::sleep(Duration::from_millis(600)).await;
    let shown = eval(c, "return document.getElementById('pick').textContent").await;
    let shown = shown.as_str().unwrap_or_default();
    assert!(
        shown.contains(picked["name"].as_str().unwrap()),
        "the panel shows {shown:?} for {picked}"
    );
    let errors = eval(c, "return window.porticoErrors || []").await;
    assert_eq!(errors, json!([]), "the page logged errors");
    drop(stop);
    server.join().unwrap();
}
