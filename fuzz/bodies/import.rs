//! Fuzzes the model importers: any bytes, read as glTF/GLB (the container is told by its magic)
//! and as OBJ, must give a model or an error, never a panic, a hang or unbounded memory. Seed the
//! corpus with the import cases (fuzz/README.md): small real glTF and OBJ files, each with a
//! fault real exporters produce.
use portico_data::import::import_bytes;

/// One input.
pub fn run(data: &[u8]) {
    let _ = import_bytes(data, "gltf");
    let _ = import_bytes(data, "obj");
}
