//! Wavefront OBJ + MTL import through `tobj`: every OBJ object/group becomes one definition
//! with one instance at the identity transform (OBJ has no instancing).

use super::mesh_from_streams;
use crate::error::{DataError, Result};
use crate::model::{Instance, Material, Model, ObjectDef};
use glam::Mat4;
use std::path::Path;

/// Imports an OBJ file (and its MTL library when it loads; a missing MTL only loses colours).
pub fn import(path: &Path) -> Result<Model> {
    let opts = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, mtl) =
        tobj::load_obj(path, &opts).map_err(|e| DataError::import(path, format!("OBJ: {e}")))?;
    let mtl = mtl.unwrap_or_else(|e| {
        tracing::warn!(
            "{}: materials not loaded ({e}); using white",
            path.display()
        );
        Vec::new()
    });
    let mut model = Model {
        materials: vec![Material::default()],
        ..Model::default()
    };
    model.materials.extend(mtl.iter().map(|m| Material {
        name: m.name.clone(),
        base_color: m.diffuse.map_or([1.0; 4], |d| [d[0], d[1], d[2], 1.0]),
        texture: None,
    }));
    for m in models {
        let mesh = &m.mesh;
        if mesh.indices.is_empty() {
            continue;
        }
        let material = mesh.material_id.map_or(0, |i| i as u32 + 1);
        let base = model
            .materials
            .get(material as usize)
            .map_or([1.0; 4], |mat| mat.base_color);
        let positions: Vec<[f32; 3]> = mesh
            .positions
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let normals: Vec<[f32; 3]> = mesh
            .normals
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let colors: Vec<[f32; 4]> = if mesh.vertex_color.len() == mesh.positions.len() {
            mesh.vertex_color
                .chunks_exact(3)
                .map(|c| [c[0] * base[0], c[1] * base[1], c[2] * base[2], base[3]])
                .collect()
        } else {
            vec![base; positions.len()]
        };
        let normals = (!normals.is_empty()).then_some(normals.as_slice());
        let lod = mesh_from_streams(&positions, normals, &colors, mesh.indices.clone())
            .map_err(|e| DataError::import(path, format!("object '{}': {e}", m.name)))?;
        let def = model.defs.len() as u32;
        model.defs.push(ObjectDef {
            name: m.name.clone(),
            lods: vec![lod],
            material,
        });
        model.instances.push(Instance {
            name: m.name,
            def,
            transform: Mat4::IDENTITY,
            material,
            occluder: false,
            tags: Default::default(),
        });
    }
    Ok(model)
}
