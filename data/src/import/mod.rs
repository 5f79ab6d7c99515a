//! Importers: Wavefront OBJ+MTL (`tobj`), glTF 2.0 / GLB (`gltf`) and IFC (IFClite), chosen by
//! file extension.
//!
//! Both produce a [`Model`]: definitions shared by instances, vertex colours with the material's
//! base colour already multiplied in, node tags (`extras`) carried through, coordinates relative
//! to a local origin kept in double precision, and the warnings of what was worked around.
//! Neither can panic on a file: bad input is one error line naming the file and the element
//! (mesh, primitive, accessor, node, or OBJ line).

pub mod files;
pub mod frame;
pub mod gltf;
pub mod ifc;
pub mod image;
pub mod obj;

use crate::error::{DataError, Result};
use crate::geometry::{Mesh, Vertex};
use crate::model::Model;
use frame::FrameOptions;
use glam::Vec3;
use std::path::Path;

/// Imports one model file; the format is taken from the extension (`.obj`, `.gltf`, `.glb`,
/// `.ifc`). Its unit and up axis are the format's, or found from the geometry (OBJ).
pub fn import_file(path: &Path) -> Result<Model> {
    import_file_with(path, &FrameOptions::default())
}

/// [`import_file`] with the unit and up axis the user gave (`portico build --units --up`):
/// the model is converted from them to metres, Y up.
pub fn import_file_with(path: &Path, options: &FrameOptions) -> Result<Model> {
    if !path.exists() {
        return Err(DataError::import(path, "no such file"));
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let mut model = match ext.as_str() {
        "obj" => obj::import(path, options)?,
        "gltf" | "glb" => gltf::import(path, options)?,
        "ifc" => ifc::import(path, options)?,
        other => {
            return Err(DataError::import(
                path,
                format!("unsupported model format '.{other}' (expected .obj, .gltf, .glb or .ifc)"),
            ));
        }
    };
    if model.instances.is_empty() {
        return Err(DataError::import(path, "contains no triangle meshes"));
    }
    model.sources.push(path.display().to_string());
    Ok(model)
}

/// Imports model bytes without touching the file system (no external buffers or material
/// libraries): `ext` is `obj`, `gltf` or `glb`. For fuzzing and tests.
pub fn import_bytes(bytes: &[u8], ext: &str) -> std::result::Result<Model, String> {
    let options = FrameOptions::default();
    let mut model = match ext {
        "obj" => obj::import_slice(bytes, None, &options),
        "gltf" | "glb" => gltf::import_slice(bytes, None, &options),
        "ifc" => ifc::import_slice(bytes, &options),
        other => Err(format!("unsupported model format '.{other}'")),
    }?;
    if model.instances.is_empty() {
        return Err("contains no triangle meshes".into());
    }
    // The frame the importer pushed describes these bytes: they are the model's one source.
    model.sources.push(format!("({ext} bytes)"));
    Ok(model)
}

/// Builds a mesh from float streams, validating indices and filling in missing normals with
/// area-weighted vertex normals. A vertex whose given normal is not a finite, non-zero vector
/// (exporters write `nan nan nan` for degenerate faces) gets the computed one.
pub fn mesh_from_streams(
    positions: &[[f32; 3]],
    normals: Option<&[[f32; 3]]>,
    colors: &[[f32; 4]],
    indices: Vec<u32>,
) -> std::result::Result<Mesh, String> {
    if !indices.len().is_multiple_of(3) {
        return Err(format!(
            "{} indices is not a whole number of triangles",
            indices.len()
        ));
    }
    if let Some(bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
        return Err(format!(
            "index {bad} out of range for {} vertices",
            positions.len()
        ));
    }
    if positions.iter().flatten().any(|x| !x.is_finite()) {
        return Err("a vertex position is not a finite number".into());
    }
    let computed;
    let normals = match normals {
        Some(n) if n.len() == positions.len() && n.iter().all(usable_normal) => n,
        Some(n) if n.len() == positions.len() => {
            let mut fixed = vertex_normals(positions, &indices);
            for (f, given) in fixed.iter_mut().zip(n) {
                if usable_normal(given) {
                    *f = *given;
                }
            }
            computed = fixed;
            &computed
        }
        _ => {
            computed = vertex_normals(positions, &indices);
            &computed
        }
    };
    let vertices = positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let c = colors.get(i).copied().unwrap_or([1.0; 4]);
            Vertex::new(*p, normals[i], c)
        })
        .collect();
    Ok(Mesh {
        vertices,
        indices,
        uvs: Vec::new(),
    })
}

/// Whether a given normal can be used: finite and not (nearly) zero.
fn usable_normal(n: &[f32; 3]) -> bool {
    n.iter().all(|x| x.is_finite()) && Vec3::from(*n).length_squared() > 1e-12
}

/// Area-weighted vertex normals for meshes that come without any.
fn vertex_normals(positions: &[[f32; 3]], indices: &[u32]) -> Vec<[f32; 3]> {
    let mut acc = vec![Vec3::ZERO; positions.len()];
    for t in indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| Vec3::from(positions[i as usize]));
        let n = (b - a).cross(c - a);
        for &i in t {
            acc[i as usize] += n;
        }
    }
    acc.into_iter()
        .map(|n| n.try_normalize().unwrap_or(Vec3::Y).into())
        .collect()
}

/// Concatenates meshes into one (the primitives of one glTF mesh that share a texture become
/// one object LOD). Texture coordinates are kept when every part has them.
pub fn concat(meshes: Vec<Mesh>) -> Mesh {
    let textured = meshes.iter().all(Mesh::has_uvs);
    let mut out = Mesh::default();
    for m in meshes {
        let base = out.vertices.len() as u32;
        out.vertices.extend(m.vertices);
        out.indices.extend(m.indices.into_iter().map(|i| i + base));
        if textured {
            out.uvs.extend(m.uvs);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_normals_are_computed_facing_out_of_the_winding() {
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];
        let m = mesh_from_streams(&p, None, &[], vec![0, 1, 2]).expect("mesh");
        let n = m.vertices[0].normal_f32();
        assert!((n - Vec3::Y).length() < 0.02, "{n}");
    }

    #[test]
    fn nan_and_zero_normals_are_replaced_by_computed_ones() {
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];
        let n = [[f32::NAN; 3], [0.0; 3], [1.0, 0.0, 0.0]];
        let m = mesh_from_streams(&p, Some(&n), &[], vec![0, 1, 2]).expect("mesh");
        for (i, want) in [Vec3::Y, Vec3::Y, Vec3::X].into_iter().enumerate() {
            let got = m.vertices[i].normal_f32();
            assert!((got - want).length() < 0.02, "vertex {i}: {got}");
        }
    }

    #[test]
    fn bad_indices_are_errors_not_panics() {
        let p = [[0.0; 3]; 3];
        assert!(mesh_from_streams(&p, None, &[], vec![0, 1, 3]).is_err());
        assert!(mesh_from_streams(&p, None, &[], vec![0, 1]).is_err());
    }
}
