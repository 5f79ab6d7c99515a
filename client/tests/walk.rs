//! Walk mode in a generated building: from the foot of each flight of stairs a walker climbs to
//! the floor above, its eye always at eye height over the floor or the treads it stands on;
//! from the head it comes down again; walking off the upper floor into the stair's hole lowers
//! it; and its wall is a wall.

use glam::Vec3;
use portico_client::walk::{EYE_HEIGHT, Walker};
use portico_data::Database;
use portico_data::cells::CellGraph;
use portico_data::geometry::Aabb;

/// Walks `seconds` at 1.5 m/s along `heading` from `eye`, 30 frames a second; the last eye.
/// Every frame on its feet, the eye is at eye height above the floor under it.
fn walk(
    w: &mut Walker,
    g: &CellGraph,
    objects: &[Aabb],
    eye: Vec3,
    heading: Vec3,
    seconds: f32,
) -> Vec3 {
    let dt = 1.0 / 30.0;
    let mut eye = eye;
    for _ in 0..(seconds / dt) as usize {
        w.gather(g, objects, objects.len(), eye);
        eye = w.step(g, eye, heading.normalize() * 1.5 * dt, dt);
        if !w.falling()
            && let Some(ground) = w.ground(g, eye - Vec3::Y * EYE_HEIGHT)
        {
            assert!(
                (eye.y - EYE_HEIGHT - ground).abs() < 1e-3,
                "eye {eye} over {ground}"
            );
        }
    }
    eye
}

#[test]
fn a_walker_climbs_the_generated_stairs_and_falls_through_their_hole() {
    let dir = tempfile::tempdir().unwrap();
    let params = portico_generator::Params {
        preset: portico_generator::Preset::Tiny,
        seed: 3,
        floors: Some(2),
    };
    let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
    let glb = dir.path().join("tiny.glb");
    std::fs::write(&glb, &b.glb).unwrap();
    let out = dir.path().join("tiny.portico");
    let model = portico_data::import::import_file(&glb).unwrap();
    let opts = portico_data::build::BuildOptions::default();
    portico_data::build::build_with(model, &out, &opts, &portico_data::build::Quiet, None).unwrap();
    let db = Database::open(&out).unwrap();
    let graph = db.cell_graph().unwrap().expect("cells");
    let instances = &db.header().instances;
    let objects: Vec<Aabb> = instances
        .iter()
        .filter(|i| !i.occluder)
        .map(|i| i.bounds)
        .collect();
    let flights: Vec<Aabb> = instances
        .iter()
        .filter(|i| i.tag("kind") == Some("stairs") || i.name.contains("stairs"))
        .map(|i| i.bounds)
        .collect();
    assert!(!flights.is_empty(), "no stairs in the generated building");
    let mut holes = 0;
    for f in &flights {
        // The flight runs along z (the generator's); which end is its foot, the walk tells.
        assert!(f.max[2] - f.min[2] > f.max[0] - f.min[0], "{f:?}");
        let x = (f.min[0] + f.max[0]) / 2.0;
        let lower = f.min[1] + EYE_HEIGHT;
        let ends = [(f.min[2] - 0.6, Vec3::Z), (f.max[2] + 0.6, -Vec3::Z)];
        let climbed: Vec<(Vec3, Vec3)> = ends
            .iter()
            .map(|&(z, heading)| {
                let mut w = Walker::new();
                let top = walk(
                    &mut w,
                    &graph,
                    &objects,
                    Vec3::new(x, lower, z),
                    heading,
                    5.0,
                );
                (top, heading)
            })
            .filter(|(top, _)| top.y > lower + 3.0)
            .collect();
        assert_eq!(
            climbed.len(),
            1,
            "the flight {f:?} is climbed from one end: {climbed:?}"
        );
        let (top, heading) = climbed[0];
        let upper = top.y;
        assert!(
            upper > f.max[1] - 1.5 && upper < f.max[1] + EYE_HEIGHT,
            "{top} on {f:?}"
        );
        // Down again, back to the floor it started from.
        let mut w = Walker::new();
        let down = walk(&mut w, &graph, &objects, top, -heading, 5.0);
        assert!(
            (down.y - lower).abs() < 1e-3,
            "came down to {down}, not {lower}"
        );
        // From the upper floor beside the flight's middle, sideways into its hole: the body
        // falls onto the treads (or the floor below), lower than it was.
        let mid = (f.min[2] + f.max[2]) / 2.0 + heading.z * 1.0;
        for side in [f.min[0] - 0.6, f.max[0] + 0.6] {
            let mut w = Walker::new();
            let from = Vec3::new(side, upper, mid);
            let toward = Vec3::new(x - side, 0.0, 0.0);
            let here = walk(&mut w, &graph, &objects, from, toward, 0.2);
            if (here.y - upper).abs() > 1e-3 || (here - from).length() < 0.25 {
                continue; // no floor beside the hole on this side, or a wall between
            }
            let after = walk(&mut w, &graph, &objects, here, toward, 2.0);
            assert!(
                after.y < upper - 1.0,
                "not lowered into the hole: {from} -> {after}"
            );
            holes += 1;
        }
    }
    assert!(holes > 0, "no hole was walked into");
}
