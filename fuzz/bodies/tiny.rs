//! The tiny generated building, built once per fuzzing process (into the system's temporary
//! directory): the database the `prefetch` and `http` targets answer from.

use std::path::PathBuf;
use std::sync::OnceLock;

/// The path of the built database.
pub fn tiny_db() -> &'static PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("portico-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let params = portico_generator::Params {
            preset: portico_generator::Preset::Tiny,
            seed: 1,
            floors: Some(1),
        };
        let b = portico_generator::generate(&params, &mut |_| {}).unwrap();
        let glb = dir.join("tiny.glb");
        std::fs::write(&glb, &b.glb).unwrap();
        let out = dir.join("tiny.portico");
        let model = portico_data::import::import_file(&glb).unwrap();
        portico_data::build::build(
            model,
            &out,
            &Default::default(),
            &portico_data::build::Quiet,
        )
        .unwrap();
        out
    })
}
