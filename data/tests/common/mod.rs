//! What the data tests share: the tiny generated building written as GLB.

use std::path::{Path, PathBuf};

/// Generates the tiny building (`seed`, `floors` storeys) and writes it as `dir/tiny.glb`.
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
