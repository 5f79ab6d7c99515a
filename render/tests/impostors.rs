//! Hierarchical impostors end to end on the tiny building: `build_with` the client's painter,
//! then check the hierarchy's invariants and that a textured box seen from a capture direction
//! looks like the objects it stands in for.

use glam::Mat4;
use portico_data::Database;
use portico_data::build::{BuildOptions, Quiet, build_with};
use portico_data::hierarchy::ImpostorPainter;
use portico_data::import::import_file;
use portico_render::impostor::{Painter, face_view};
use portico_render::{Draw, Renderer};
use std::path::Path;

fn build_tiny(dir: &Path) -> Database {
    build_tiny_as(dir, false)
}

/// The tiny building (seed 4, one storey), with the generator's textured materials or not,
/// built with the client's painter.
fn build_tiny_as(dir: &Path, textured: bool) -> Database {
    let params = portico_generator::Params {
        preset: portico_generator::Preset::Tiny,
        seed: 4,
        floors: Some(1),
    };
    let mut b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
    if textured {
        b.glb = portico_generator::with_textures(&b.glb).unwrap();
    }
    let glb = dir.join("tiny.glb");
    std::fs::write(&glb, &b.glb).unwrap();
    let db = dir.join("tiny.portico");
    let mut painter = Painter::new().expect("a renderer (llvmpipe in CI)");
    build_with(
        import_file(&glb).unwrap(),
        &db,
        &BuildOptions::default(),
        &Quiet,
        Some(&mut painter as &mut dyn ImpostorPainter),
    )
    .unwrap();
    Database::open(&db).unwrap()
}

#[test]
fn every_object_is_under_one_cluster_and_big_clusters_have_textured_boxes() {
    let dir = tempfile::tempdir().unwrap();
    let db = build_tiny(dir.path());
    let h = db.header().hierarchy.as_ref().expect("hierarchy");
    let bounds: Vec<_> = db.header().instances.iter().map(|i| i.bounds).collect();
    h.check(&bounds).unwrap();
    // Exactly the clusters big enough get a textured box, with the tile their size asks for;
    // the tiny building has both kinds.
    for (i, n) in h.nodes.iter().enumerate() {
        let tile = portico_data::hierarchy::tile_for(&n.bounds);
        assert_eq!(
            n.texture != u32::MAX,
            tile > 0,
            "cluster {i}: {:?}",
            n.bounds
        );
        if tile > 0 {
            assert_eq!(n.tile, tile, "cluster {i}");
        }
    }
    let textured = h.nodes.iter().filter(|n| n.texture != u32::MAX).count();
    assert!(
        textured > 0 && textured < h.nodes.len(),
        "{textured} of {} textured",
        h.nodes.len()
    );
    let root = &h.nodes[h.root().unwrap() as usize];
    assert!(
        root.face_colors[0][3] > 0.1,
        "the building covers its side view"
    );
}

/// Sum over an atlas's covered texels of red minus blue, and their count.
fn redness(png: &[u8]) -> (f64, f64) {
    let img = image::load_from_memory(png).unwrap().to_rgba8();
    img.pixels()
        .filter(|p| p[3] > 200)
        .fold((0.0, 0.0), |(s, n), p| {
            (s + p[0] as f64 - p[2] as f64, n + 1.0)
        })
}

#[test]
fn impostors_of_textured_objects_are_painted_with_their_textures() {
    let dir = tempfile::tempdir().unwrap();
    let (p, t) = (dir.path().join("plain"), dir.path().join("textured"));
    std::fs::create_dir_all(&p).unwrap();
    std::fs::create_dir_all(&t).unwrap();
    // Mean red minus blue of every atlas's covered texels: the brick walls show.
    let red = |db: &Database| -> f64 {
        let h = db.header().hierarchy.as_ref().unwrap();
        let (s, n) = h
            .nodes
            .iter()
            .filter(|n| n.texture != u32::MAX)
            .map(|n| redness(&db.segment(n.texture).unwrap()))
            .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
        s / n
    };
    let (plain, textured) = (
        red(&build_tiny_as(&p, false)),
        red(&build_tiny_as(&t, true)),
    );
    assert!(
        // (Painting without the textures gives exactly the plain building's value.)
        textured > plain + 8.0,
        "atlas red minus blue: textured {textured:.1}, plain {plain:.1}"
    );
}

#[test]
fn a_textured_box_seen_from_a_capture_direction_matches_its_objects() {
    let dir = tempfile::tempdir().unwrap();
    let db = build_tiny(dir.path());
    let header = db.header();
    let h = header.hierarchy.as_ref().unwrap();
    // The biggest textured cluster.
    let (id, node) = h
        .nodes
        .iter()
        .enumerate()
        .filter(|(_, n)| n.texture != u32::MAX)
        .max_by_key(|(_, n)| n.instance_count)
        .unwrap();
    let size = 96;
    let mut r = Renderer::new(size, size).unwrap();
    r.set_clear(wgpu::Color::TRANSPARENT);
    let png = db.segment(node.texture).unwrap();
    let imp = r.upload_impostor(&png, &node.bounds, node.tile).unwrap();
    let meshes: Vec<_> = h
        .instances_under(id as u32)
        .into_iter()
        .map(|i| {
            let inst = &header.instances[i as usize];
            let lod = header.lods_of(inst)[0];
            let color = [1.0f32; 4];
            (r.upload(&db.geometry(&lod).unwrap()).unwrap(), inst, color)
        })
        .collect();
    for face in 0usize..6 {
        let vp = face_view(&node.bounds, face);
        let draws: Vec<Draw> = meshes
            .iter()
            .map(|(m, inst, color)| Draw::new(m, Mat4::from_cols_array(&inst.transform), *color))
            .collect();
        r.render_view_proj(vp, &draws).unwrap();
        let objects = r.read_pixels().unwrap();
        r.render_with_boxes_view_proj(vp, &[], &[&imp]).unwrap();
        let boxed = r.read_pixels().unwrap();
        let covered = |img: &image::RgbaImage| img.pixels().filter(|p| p[3] >= 128).count();
        let (a, b) = (covered(&objects), covered(&boxed));
        assert!(a > 0, "face {face}: the objects show");
        let coverage_diff = a.abs_diff(b) as f64 / a.max(b) as f64;
        assert!(coverage_diff < 0.15, "face {face}: coverage {a} vs {b}");
        // Mean colour difference over pixels both cover, per channel (0..255).
        let (mut sum, mut n) = (0u64, 0u64);
        for (p, q) in objects.pixels().zip(boxed.pixels()) {
            if p[3] >= 128 && q[3] >= 128 {
                sum += (0..3).map(|k| u64::from(p[k].abs_diff(q[k]))).sum::<u64>();
                n += 3;
            }
        }
        let mean = sum as f64 / n.max(1) as f64;
        assert!(
            mean < 24.0,
            "face {face}: mean colour difference {mean:.1} of 255"
        );
        if let Ok(out) = std::env::var("PORTICO_IMPOSTOR_PNG") {
            objects
                .save(format!("{out}/face{face}_objects.png"))
                .unwrap();
            boxed.save(format!("{out}/face{face}_box.png")).unwrap();
        }
    }
}
