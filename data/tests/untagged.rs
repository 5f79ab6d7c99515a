//! A building exported without Portico's tags (no `occluder`, `kind`, `room` extras, as any
//! modelling tool writes it) must get the cells its tagged export gets: the walls and slabs
//! are found from their shape (`cells::occluders::structural`).

use glam::Vec3;
use portico_data::cells::occluders::occluder_boxes;
use portico_data::cells::sight::Triangles;
use portico_data::cells::verify::verify_against_triangles;
use portico_data::cells::{Precomputed, precompute};
use portico_data::import::import_bytes;
use portico_generator::{Params, Preset, generate, without_tags};

mod common;

fn cells_of(glb: &[u8]) -> (Precomputed, usize) {
    let m = import_bytes(glb, "glb").expect("the generated building imports");
    let occ = occluder_boxes(
        m.instances
            .iter()
            .map(|i| (&m.defs[i.def as usize].lods[0], i.transform, i.occluder)),
    );
    let objects = common::object_boxes(&m);
    let p = precompute(&m.bounds(), &occ, &objects, &|_, _| {}, &|| {});
    let tagged = m.instances.iter().filter(|i| i.occluder).count();
    (p, tagged)
}

#[test]
fn an_untagged_export_gets_the_tagged_buildings_cells_and_culling() {
    let params = Params {
        preset: Preset::Small,
        seed: 3,
        floors: Some(2),
    };
    let glb = generate(&params, &mut |_| {}).unwrap().glb;
    let bare = without_tags(&glb).unwrap();
    let (tagged, n_tagged) = cells_of(&glb);
    let (untagged, n_untagged) = cells_of(&bare);
    assert!(n_tagged > 0 && n_untagged == 0, "{n_tagged} / {n_untagged}");
    let (a, b) = (&tagged.stats, &untagged.stats);
    let near = |x: f64, y: f64| (x - y).abs() <= 0.1 * x.max(y);
    assert!(
        near(a.live_cells as f64, b.live_cells as f64),
        "live cells: tagged {}, untagged {}",
        a.live_cells,
        b.live_cells
    );
    assert!(
        near(a.objects_visible.0, b.objects_visible.0),
        "objects visible per cell: tagged {:?}, untagged {:?}",
        a.objects_visible,
        b.objects_visible
    );
    assert!(!b.grid_fallback);
    // And nothing visible is culled: rays against the objects' own triangles.
    let m = import_bytes(&bare, "glb").unwrap();
    let triangles: Vec<Vec<[Vec3; 3]>> = m
        .instances
        .iter()
        .map(|i| {
            let mesh = &m.defs[i.def as usize].lods[0];
            mesh.indices
                .chunks_exact(3)
                .map(|t| {
                    t.iter()
                        .map(|&k| {
                            i.transform
                                .transform_point3(Vec3::from(mesh.vertices[k as usize].position))
                        })
                        .collect::<Vec<_>>()
                        .try_into()
                        .unwrap()
                })
                .collect()
        })
        .collect();
    let scene = Triangles::new(common::object_boxes(&m), triangles);
    let report = verify_against_triangles(&untagged.graph, &untagged.stabs, &scene, 20_000, 1);
    assert_eq!(report.false_negatives, 0, "{report:?}");
}
