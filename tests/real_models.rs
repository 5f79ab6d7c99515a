//! Models a user brings that are not buildings: Debian's `assimp-testmodels` spider (an OBJ with
//! no walls at all: the cells are an open grid) and the two-cylinder engine (one object: the
//! cells are one box). Each builds, is served, and is walked headless along the default path,
//! which for a model without rooms is an orbit and a fly-through; the frames must show it.

use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

const ASSIMP: &str = "/usr/share/assimp/models";

fn corpus(rel: &str) -> Option<PathBuf> {
    let p = Path::new(ASSIMP).join(rel);
    if p.exists() {
        return Some(p);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{ASSIMP} missing: .ci/run installs assimp-testmodels"
    );
    eprintln!("skipping: {} not installed", p.display());
    None
}

fn portico(args: &[&str]) -> std::process::Output {
    let out = Command::new(env!("CARGO_BIN_EXE_portico"))
        .args(args)
        .output()
        .expect("run portico");
    assert!(
        out.status.success(),
        "portico {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A server on a free loopback port; killed when dropped.
struct Server(Child, String);

impl Server {
    fn start(db: &Path) -> Server {
        let mut child = Command::new(env!("CARGO_BIN_EXE_portico"))
            .args(["serve", db.to_str().unwrap(), "--listen", "127.0.0.1:0"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start the server");
        let mut lines = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
        let first = lines.next().unwrap().unwrap();
        let url = format!("http://{}", first.rsplit("http://").next().unwrap().trim());
        // Keep draining the server's log so it never blocks on a full pipe.
        std::thread::spawn(move || lines.for_each(drop));
        Server(child, url)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Builds `model` into `dir/m.portico` with `extra` build flags.
fn build_in(dir: &Path, model: &Path, extra: &[&str]) -> PathBuf {
    let db = dir.join("m.portico");
    let mut args = vec!["build", model.to_str().unwrap(), "-o", db.to_str().unwrap()];
    args.extend_from_slice(extra);
    portico(&args);
    db
}

/// Builds, serves and walks a model; returns drawn triangles per frame.
fn walk_model(model: &Path) -> Vec<u64> {
    let dir = tempfile::tempdir().unwrap();
    let db = build_in(dir.path(), model, &["--no-textures"]);
    let server = Server::start(&db);
    let out = dir.path().join("walk");
    portico(&[
        "walk",
        "--server",
        &server.1,
        "--size",
        "160x120",
        "--max-frames",
        "60",
        "--out",
        out.to_str().unwrap(),
    ]);
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = head.iter().position(|h| *h == "drawn_triangles").unwrap();
    lines
        .map(|l| l.split(',').nth(col).unwrap().parse().unwrap())
        .collect()
}

fn assert_seen(name: &str, drawn: &[u64]) {
    assert_eq!(drawn.len(), 60, "{name}: frames");
    // The first frames (50 ms each) may come before any geometry arrives: the client never
    // waits. After that, every frame shows the model.
    let empty = drawn.iter().skip(20).filter(|&&t| t == 0).count();
    assert_eq!(
        empty, 0,
        "{name}: {empty} empty frames after the first 20: {drawn:?}"
    );
}

#[test]
fn the_spider_without_walls_builds_serves_and_walks() {
    let Some(m) = corpus("OBJ/spider.obj") else {
        return;
    };
    assert_seen("spider.obj", &walk_model(&m));
}

#[test]
fn the_engine_an_object_not_a_building_builds_serves_and_walks() {
    let Some(m) = corpus("glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb") else {
        return;
    };
    assert_seen("2CylinderEngine.glb", &walk_model(&m));
}

#[test]
fn roomless_models_get_an_orbit_and_a_flythrough() {
    let Some(m) = corpus("glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let db = build_in(dir.path(), &m, &["--no-hierarchy"]);
    let path = dir.path().join("path.json");
    portico(&[
        "path",
        "--db",
        db.to_str().unwrap(),
        "-o",
        path.to_str().unwrap(),
    ]);
    let p: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(p["kind"], "orbit+flythrough");
    let keys = p["keyframes"].as_array().unwrap();
    let duration = keys.last().unwrap()["t"].as_f64().unwrap();
    assert!(duration > 12.0, "{duration} s");
}

#[test]
fn the_ifc_house_builds_with_its_rooms_as_cells_verifies_and_walks() {
    let Some(m) = corpus("IFC/AC14-FZK-Haus.ifc") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("haus.portico");
    let out = portico(&["build", m.to_str().unwrap(), "-o", db.to_str().unwrap()]);
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(!log.contains("warning"), "{log}");
    let inspect: serde_json::Value =
        serde_json::from_slice(&portico(&["inspect", db.to_str().unwrap(), "--json"]).stdout)
            .unwrap();
    let stats = &inspect["cell_stats"];
    let live = stats["live_cells"].as_u64().unwrap();
    // Seven rooms, their door and window openings, the stair's hole, the outside.
    assert!((20..=80).contains(&live), "{stats}");
    // Occlusion culling is left: a cell sees far from every object.
    let seen = stats["objects_visible"][0].as_f64().unwrap();
    // Per instance: the windows and doors of one type share a definition.
    let objects = inspect["instances"].as_u64().unwrap() as f64;
    assert!(seen < 0.95 * objects, "{seen} of {objects}: {stats}");
    let verify: serde_json::Value = serde_json::from_slice(
        &portico(&["verify", db.to_str().unwrap(), "--rays", "20000", "--json"]).stdout,
    )
    .unwrap();
    assert_eq!(verify["false_negatives"], 0, "{verify}");
    assert_seen("AC14-FZK-Haus.ifc", &walk_model(&m));
}

/// A frame from the middle of each room of the IFC house, at eye height, looking along the
/// room, shows that room: drawn with every object, it is nearly the same picture as drawn with
/// only the objects touching the room (its walls, floor, ceiling, furniture, doors, windows).
/// A frame from inside a wall, from the outside, or of the wrong storey would not be.
#[test]
fn a_frame_in_each_room_of_the_ifc_house_shows_that_room() {
    use portico_render::{Camera, Draw, Renderer};
    let Some(m) = corpus("IFC/AC14-FZK-Haus.ifc") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let db = build_in(dir.path(), &m, &["--no-hierarchy", "--no-cells"]);
    let spaces = portico_data::import::import_file(&m).unwrap().spaces;
    assert_eq!(spaces.len(), 7);
    let db = portico_data::Database::open(&db).unwrap();
    let h = db.header();
    let (w, hgt) = (160, 120);
    let mut r = Renderer::new(w, hgt).unwrap();
    r.set_clear(portico_render::wgpu::Color {
        r: 1.0,
        g: 0.0,
        b: 1.0,
        a: 1.0,
    });
    let meshes: Vec<_> = h
        .instances
        .iter()
        .map(|i| r.upload(&db.geometry(&h.lods_of(i)[0]).unwrap()).unwrap())
        .collect();
    for s in &spaces {
        let b = &s.bounds;
        let size = b.size();
        // Touching the room: within a wall's thickness of its box (windows and doors sit in
        // the middle of their walls).
        let touches = |o: &portico_data::geometry::Aabb| {
            (0..3).all(|k| o.min[k] <= b.max[k] + 0.4 && o.max[k] >= b.min[k] - 0.4)
        };
        let draws = |only_room: bool| -> Vec<Draw> {
            h.instances
                .iter()
                .zip(&meshes)
                .filter(|(i, _)| !only_room || touches(&i.bounds))
                .map(|(i, mesh)| {
                    Draw::new(mesh, glam::Mat4::from_cols_array(&i.transform), [1.0; 4])
                })
                .collect()
        };
        let mut eye = b.center();
        eye.y = b.min[1] + 1.6;
        let look = if size.x >= size.z {
            glam::Vec3::X
        } else {
            glam::Vec3::NEG_Z
        };
        let camera = Camera {
            eye,
            target: eye + look,
            up: glam::Vec3::Y,
            fovy: 1.0,
            near: 0.05,
            far: 100.0,
        };
        let all = r.render_to_image(&camera, &draws(false)).unwrap().1;
        let room = r.render_to_image(&camera, &draws(true)).unwrap().1;
        let same = all
            .pixels()
            .zip(room.pixels())
            .filter(|(a, b)| (0..3).all(|k| a[k].abs_diff(b[k]) <= 8))
            .count() as f64
            / f64::from(w * hgt);
        assert!(
            same >= 0.8,
            "{}: only {:.0} % of the frame is the room",
            s.name,
            same * 100.0
        );
        // And the room is seen, not the background (cleared to magenta): most pixels are drawn.
        let drawn = all
            .pixels()
            .filter(|p| p[0] < 250 || p[1] > 5 || p[2] < 250)
            .count() as f64
            / f64::from(w * hgt);
        assert!(drawn >= 0.5, "{}: {:.0} % drawn", s.name, drawn * 100.0);
    }
}
