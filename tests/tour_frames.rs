//! The demo's tour looks where a walking person looks, ahead along the way, so the frames the
//! demo saves for its contact sheet show rooms, not a wall or a door filling the view: none of
//! them is more than 90 % one colour.
//!
//! The demo's building (the `small` preset, seed 1) is built without impostors, its tour made
//! as `portico demo` makes it, and the frames the demo saves drawn at full detail (the walk
//! draws what has arrived; this is about where the view points). `PORTICO_TOUR_FRAMES=DIR`
//! keeps the frames and their contact sheet there.

use glam::{Mat4, Vec3};
use image::RgbaImage;
use portico_client::view::{Camera, NEAR, far_plane};
use portico_data::Database;
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::import::import_file;
use portico_data::path::{CameraPath, PathKind, generate_around};
use portico_render::{Draw, Renderer, sheet};

/// The largest share of the image's pixels that are one colour (each channel cut to 32 levels:
/// a flat-shaded wall, the sky).
fn one_colour_share(img: &RgbaImage) -> f64 {
    let mut bins = std::collections::HashMap::<[u8; 3], u32>::new();
    for p in img.pixels() {
        *bins.entry([p[0] >> 3, p[1] >> 3, p[2] >> 3]).or_default() += 1;
    }
    let top = bins.values().copied().max().unwrap_or(0);
    top as f64 / (img.width() * img.height()).max(1) as f64
}

#[test]
fn one_colour_share_tells_a_wall_from_a_room() {
    let wall = RgbaImage::from_pixel(10, 10, image::Rgba([120, 120, 120, 255]));
    assert_eq!(one_colour_share(&wall), 1.0);
    let mut room = wall.clone();
    for (x, _, p) in room.enumerate_pixels_mut() {
        *p = image::Rgba([(x * 25) as u8, 90, 200, 255]);
    }
    assert!(one_colour_share(&room) <= 0.1 + 1e-9);
}

/// The times of the frames `portico demo` saves for its contact sheet: it walks at most 600
/// frames of 50 ms and saves every (frames / 36)th, all but the first (drawn before anything
/// has arrived).
fn saved_frame_times(path: &CameraPath) -> Vec<f32> {
    let budget_s = portico_client::defaults::FRAME_BUDGET_MS / 1e3;
    let frames = ((path.duration() as f64 / budget_s).ceil() as u64 + 1).min(600);
    let every = (frames / 36).max(1);
    (1..frames)
        .filter(|i| i % every == 0)
        .map(|i| (i as f64 * budget_s) as f32)
        .collect()
}

#[test]
fn the_demo_tour_saves_no_frame_of_one_colour() {
    let dir = tempfile::tempdir().unwrap();
    let params = portico_generator::Params {
        preset: portico_generator::Preset::Small,
        seed: 1,
        floors: None,
    };
    let glb = dir.path().join("building.glb");
    let b = portico_generator::generate(&params, &mut |_| {}).unwrap();
    std::fs::write(&glb, &b.glb).unwrap();
    let db_path = dir.path().join("building.portico");
    let opts = BuildOptions {
        no_hierarchy: true,
        ..BuildOptions::default()
    };
    build(import_file(&glb).unwrap(), &db_path, &opts, &Quiet).unwrap();
    let db = Database::open(&db_path).unwrap();
    let graph = db.cell_graph().unwrap().expect("cells");
    // As `portico demo` makes its tour (src/cmd/demo.rs).
    let objects: Vec<_> = db.header().instances.iter().map(|i| i.bounds).collect();
    let path = generate_around(
        &graph,
        &objects,
        PathKind::Tour,
        4,
        1,
        portico_data::person::WALK_SPEED,
        portico_data::person::TURN_DEGREES.to_radians(),
    )
    .unwrap();

    let mut r = Renderer::new(160, 120).expect("a renderer (llvmpipe in CI)");
    let h = db.header();
    let meshes: Vec<_> = (0u32..)
        .zip(&h.instances)
        .filter_map(|(i, inst)| {
            let lod = h.lods_of(inst).first()?;
            let mesh = r.upload(&db.geometry(lod).unwrap()).unwrap();
            let colour = portico_client::frame::material_of(h, i, 0, &|_| false).1;
            Some((mesh, Mat4::from_cols_array(&inst.transform), colour))
        })
        .collect();
    let draws: Vec<Draw> = meshes
        .iter()
        .map(|(m, t, c)| Draw::new(m, *t, *c))
        .collect();
    let keep = std::env::var_os("PORTICO_TOUR_FRAMES").map(std::path::PathBuf::from);
    let mut frames = Vec::new();
    let mut walls = Vec::new();
    for t in saved_frame_times(&path) {
        let (eye, dir) = path.sample(t);
        let camera = Camera {
            eye,
            target: eye + dir,
            up: Vec3::Y,
            fovy: portico_client::defaults::fov_y(),
            near: NEAR,
            far: far_plane(&h.bounds),
        };
        let img = r.picture_with_boxes(&camera, &draws, &[]).unwrap();
        let share = one_colour_share(&img);
        if share > 0.9 {
            walls.push(format!("t = {t:.2} s: {:.0} % one colour", share * 100.0));
        }
        if let Some(d) = &keep {
            std::fs::create_dir_all(d).unwrap();
            img.save(d.join(format!("t{:06.2}.png", t))).unwrap();
            eprintln!(
                "t {t:6.2}: {:3.0} % one colour, eye {eye:.2}, dir {dir:.2}, cell {:?}",
                share * 100.0,
                graph.locate(eye)
            );
        }
        frames.push(img);
    }
    assert!(frames.len() >= 12, "{} frames saved", frames.len());
    if let Some(d) = &keep {
        sheet::contact_sheet(&frames, 8, 160)
            .unwrap()
            .save(d.join("all.png"))
            .unwrap();
        let images = sheet::distinct(frames.clone(), 12, 2.0);
        sheet::contact_sheet(&images, 4, 160)
            .unwrap()
            .save(d.join("contact_sheet.png"))
            .unwrap();
    }
    assert!(
        walls.is_empty(),
        "{} of {} saved frames look at a wall: {walls:#?}",
        walls.len(),
        frames.len()
    );
}
