//! `portico export-3dtiles`: the tiny building as 3D Tiles, read back with the `gltf` crate.

use portico_data::Database;
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::import::import_file;
use serde_json::Value;

#[test]
fn the_tileset_holds_every_instance_at_its_finest_lod_in_its_leaves_and_coarser_above() {
    let dir = tempfile::tempdir().unwrap();
    let params = portico_generator::Params {
        preset: portico_generator::Preset::Tiny,
        seed: 2,
        floors: Some(1),
    };
    let b = portico_generator::generate(&params, &mut |_| {}).unwrap();
    let glb = dir.path().join("tiny.glb");
    std::fs::write(&glb, &b.glb).unwrap();
    let db_path = dir.path().join("tiny.portico");
    build(
        import_file(&glb).unwrap(),
        &db_path,
        &BuildOptions::default(),
        &Quiet,
    )
    .unwrap();
    let db = Database::open(&db_path).unwrap();
    let header = db.header();
    let finest: u64 = header
        .instances
        .iter()
        .filter_map(|i| header.lods_of(i).first())
        .map(|l| u64::from(l.triangles))
        .sum();
    let out = dir.path().join("tiles");
    let mut heard = 0;
    let w = portico_data::tileset::write(&db, &out, finest / 6, &mut |_, _| heard += 1).unwrap();
    assert_eq!(heard, w.tiles);
    assert!(
        w.tiles >= 7,
        "{} tiles for {finest} triangles in leaves of {}",
        w.tiles,
        finest / 6
    );
    assert_eq!(w.triangles, finest);

    let tileset: Value =
        serde_json::from_slice(&std::fs::read(out.join("tileset.json")).unwrap()).unwrap();
    assert_eq!(tileset["asset"]["version"], "1.1");
    // The root's box is the model's, turned Z up.
    let b = &header.bounds;
    let root_box = tileset["root"]["boundingVolume"]["box"]
        .as_array()
        .unwrap()
        .clone();
    let c = b.center();
    for (got, want) in root_box[..3].iter().zip([c.x, -c.z, c.y]) {
        assert!(
            (got.as_f64().unwrap() - f64::from(want)).abs() < 1e-3,
            "{root_box:?}"
        );
    }
    // Every tile's content reads back as glTF with normals and colours; every instance is in
    // one tile (the triangles add up to the finest LODs'); the root holds the largest objects
    // and a child's error is below its parent's.
    fn walk(t: &Value, dir: &std::path::Path, parent_error: f64, per_tile: &mut Vec<u64>) -> u64 {
        let error = t["geometricError"].as_f64().unwrap();
        assert!(error <= parent_error, "{error} under {parent_error}");
        assert_eq!(t["refine"], "ADD");
        let Some(uri) = t["content"]["uri"].as_str() else {
            // No content: nothing large in it, and children to hold the rest.
            assert!(
                t["children"].as_array().is_some_and(|c| !c.is_empty()),
                "{t}"
            );
            per_tile.push(0);
            return t["children"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| walk(c, dir, error, per_tile))
                .sum();
        };
        let (doc, buffers, _) = gltf::import(dir.join(uri)).unwrap();
        // glTF 2.0: a scene has at least one node.
        assert!(
            doc.scenes().all(|s| s.nodes().count() > 0),
            "{uri}: an empty scene"
        );
        let triangles: u64 = doc
            .meshes()
            .flat_map(|m| m.primitives().collect::<Vec<_>>())
            .map(|p| {
                let r = p.reader(|b| Some(&buffers[b.index()]));
                assert!(r.read_colors(0).is_some() && r.read_normals().is_some());
                r.read_indices().unwrap().into_u32().count() as u64 / 3
            })
            .sum();
        per_tile.push(triangles);
        let children = t["children"].as_array().map_or(&[][..], |c| c.as_slice());
        assert_eq!(
            children.is_empty(),
            error == 0.0,
            "only leaves have no error"
        );
        triangles
            + children
                .iter()
                .map(|c| walk(c, dir, error, per_tile))
                .sum::<u64>()
    }
    let root_error = tileset["geometricError"].as_f64().unwrap();
    let mut per_tile = Vec::new();
    let all = walk(&tileset["root"], &out, root_error, &mut per_tile);
    assert_eq!(all, finest);
    assert!(per_tile[0] > 0, "the root holds the walls and slabs");
}
