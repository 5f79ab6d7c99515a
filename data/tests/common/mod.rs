//! What the data tests share: the tiny generated building written as GLB.

use std::path::{Path, PathBuf};

/// Every instance's world box (its finest mesh's, placed).
#[allow(dead_code)] // not every test crate needs it
pub fn object_boxes(m: &portico_data::model::Model) -> Vec<portico_data::geometry::Aabb> {
    m.instances
        .iter()
        .map(|i| {
            m.defs[i.def as usize].lods[0]
                .bounds()
                .transformed(&i.transform)
        })
        .collect()
}

/// Generates the tiny building (`seed`, `floors` storeys) and writes it as `dir/tiny.glb`.
#[allow(dead_code)] // not every test crate builds one
pub fn tiny_glb(dir: &Path, seed: u64, floors: u32) -> PathBuf {
    let params = portico_generator::Params {
        preset: portico_generator::Preset::Tiny,
        seed,
        floors: Some(floors),
    };
    let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
    let glb = dir.join("tiny.glb");
    std::fs::write(&glb, &b.glb).unwrap();
    glb
}

/// The tiny building (seed 5, two storeys) built with `opts` into a temporary directory and
/// opened for prefetch answers, its clusters painted by `painter` if given.
#[allow(dead_code)] // not every test crate builds one
pub fn tiny_prefetcher(
    opts: &portico_data::build::BuildOptions,
    painter: Option<&mut dyn portico_data::hierarchy::ImpostorPainter>,
) -> portico_data::prefetch::Prefetcher {
    prefetcher_for(5, 2, false, opts, painter)
}

/// The tiny building (`seed`, `floors` storeys; with the generator's textured materials when
/// `textured`) built with `opts` into a temporary directory and opened for prefetch answers.
#[allow(dead_code)] // not every test crate builds one
pub fn prefetcher_for(
    seed: u64,
    floors: u32,
    textured: bool,
    opts: &portico_data::build::BuildOptions,
    painter: Option<&mut dyn portico_data::hierarchy::ImpostorPainter>,
) -> portico_data::prefetch::Prefetcher {
    let dir = tempfile::tempdir().unwrap();
    let glb = tiny_glb(dir.path(), seed, floors);
    if textured {
        let bytes = std::fs::read(&glb).unwrap();
        std::fs::write(&glb, portico_generator::with_textures(&bytes).unwrap()).unwrap();
    }
    let out = dir.path().join("tiny.portico");
    let model = portico_data::import::import_file(&glb).unwrap();
    portico_data::build::build_with(model, &out, opts, &portico_data::build::Quiet, painter)
        .unwrap();
    // The map stays valid after the directory is removed (the inode lives on).
    let db = std::sync::Arc::new(portico_data::Database::open(&out).unwrap());
    portico_data::prefetch::Prefetcher::new(db).unwrap()
}

/// An observer at `eye` looking along `dir` with the tests' field of view and speeds.
#[allow(dead_code)] // not every test crate asks
pub fn observer(eye: glam::Vec3, dir: [f32; 3]) -> portico_protocol::Observer {
    portico_protocol::Observer {
        eye: eye.into(),
        dir,
        up: [0.0, 1.0, 0.0],
        velocity: [0.0; 3],
        half_fov_x: 0.6,
        half_fov_y: 0.45,
        max_speed: 1.5,
        max_turn: 1.0,
        turn: [0.0; 3],
    }
}

/// A painter that paints nothing real: every cluster gets an "atlas" of a few bytes (the
/// prefetcher never decodes it) and grey faces, so the database has textured boxes.
#[allow(dead_code)] // not every test crate paints
pub struct FakePainter;

impl portico_data::hierarchy::ImpostorPainter for FakePainter {
    fn paint(
        &mut self,
        _: &[portico_data::hierarchy::PaintItem<'_>],
        _: &portico_data::geometry::Aabb,
        _: u32,
    ) -> Result<(Vec<u8>, [[f32; 4]; 6]), String> {
        Ok((b"\x89PNG fake atlas".to_vec(), [[0.5, 0.5, 0.5, 1.0]; 6]))
    }
}
