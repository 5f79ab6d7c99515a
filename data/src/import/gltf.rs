//! glTF 2.0 / GLB import through the `gltf` crate.
//!
//! - One glTF mesh used by several nodes becomes one definition with several instances
//!   (Funkhouser §3.1: shared object definitions).
//! - A node's `MSFT_lod` extension (`{"ids": [node, ...]}`, coarser and coarser) gives the
//!   definition's lower LODs; the generator writes its parametric LODs that way (§3.1.3).
//! - Node `extras`: `occluder: true` marks structural occluders (walls, floors, ceilings); every
//!   other scalar becomes a string tag.
//! - Vertex colour = `COLOR_0` × the primitive's base colour factor.

use super::{concat, mesh_from_streams};
use crate::error::{DataError, Result};
use crate::geometry::Mesh;
use crate::model::{Instance, Material, Model, ObjectDef};
use glam::Mat4;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// Deepest node hierarchy we follow; deeper means a malformed file.
const MAX_DEPTH: usize = 256;

/// Imports a `.gltf` (with external or embedded buffers) or `.glb` file.
pub fn import(path: &Path) -> Result<Model> {
    let err = |what: String| DataError::import(path, what);
    let gltf::Gltf { document, blob } =
        gltf::Gltf::open(path).map_err(|e| err(format!("glTF: {e}")))?;
    let buffers = gltf::import_buffers(&document, path.parent(), blob)
        .map_err(|e| err(format!("glTF buffers: {e}")))?;
    let mut importer = Importer {
        doc: &document,
        buffers: &buffers,
        model: Model::default(),
        defs: HashMap::new(),
    };
    importer.model.materials = materials(&document);
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next())
        .ok_or_else(|| err("glTF: the file has no scene".into()))?;
    let mut stack: Vec<(gltf::Node, Mat4, usize)> =
        scene.nodes().map(|n| (n, Mat4::IDENTITY, 0)).collect();
    stack.reverse();
    while let Some((node, parent, depth)) = stack.pop() {
        if depth > MAX_DEPTH {
            return Err(err(format!("glTF: node hierarchy deeper than {MAX_DEPTH}")));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if node.mesh().is_some() {
            importer.instance(&node, world).map_err(err)?;
        }
        let children: Vec<_> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|c| (c, world, depth + 1)));
    }
    Ok(importer.model)
}

/// The material table: index 0 is a default white, glTF material `i` is at `i + 1`.
fn materials(doc: &gltf::Document) -> Vec<Material> {
    let mut out = vec![Material::default()];
    out.extend(doc.materials().map(|m| Material {
        name: m.name().unwrap_or("").to_string(),
        base_color: m.pbr_metallic_roughness().base_color_factor(),
        texture: None,
    }));
    out
}

struct Importer<'a> {
    doc: &'a gltf::Document,
    buffers: &'a [gltf::buffer::Data],
    model: Model,
    /// (mesh index, LOD mesh indices) → definition index.
    defs: HashMap<(usize, Vec<usize>), u32>,
}

impl Importer<'_> {
    /// Adds an instance for a node with a mesh, creating its definition on first use.
    fn instance(&mut self, node: &gltf::Node, world: Mat4) -> Result<(), String> {
        let Some(mesh) = node.mesh() else {
            return Ok(());
        };
        let key = (mesh.index(), self.lod_meshes(node)?);
        let def = match self.defs.get(&key) {
            Some(&d) => d,
            None => {
                let d = self.definition(&mesh, &key.1)?;
                self.defs.insert(key, d);
                d
            }
        };
        let (occluder, tags) = extras(node)?;
        let material = self.model.defs[def as usize].material;
        self.model.instances.push(Instance {
            name: node
                .name()
                .map_or_else(|| format!("node{}", node.index()), str::to_string),
            def,
            transform: world,
            material,
            occluder,
            tags,
        });
        Ok(())
    }

    /// Mesh indices of the node's `MSFT_lod` levels, coarser and coarser.
    fn lod_meshes(&self, node: &gltf::Node) -> Result<Vec<usize>, String> {
        let Some(ext) = node.extension_value("MSFT_lod") else {
            return Ok(Vec::new());
        };
        let ids = ext
            .get("ids")
            .and_then(|v| v.as_array())
            .ok_or_else(|| format!("node {}: MSFT_lod without an 'ids' array", node.index()))?;
        ids.iter()
            .map(|id| {
                let n = id
                    .as_u64()
                    .and_then(|i| self.doc.nodes().nth(i as usize))
                    .ok_or_else(|| {
                        format!("node {}: MSFT_lod id {id} is not a node", node.index())
                    })?;
                n.mesh()
                    .map(|m| m.index())
                    .ok_or_else(|| format!("node {}: MSFT_lod node {id} has no mesh", node.index()))
            })
            .collect()
    }

    /// Creates a definition from a mesh and its LOD meshes.
    fn definition(&mut self, mesh: &gltf::Mesh, lods: &[usize]) -> Result<u32, String> {
        let mut levels = vec![self.mesh(mesh)?];
        for &i in lods {
            let m = self
                .doc
                .meshes()
                .nth(i)
                .ok_or_else(|| format!("LOD mesh {i} does not exist"))?;
            levels.push(self.mesh(&m)?);
        }
        let material = mesh
            .primitives()
            .next()
            .and_then(|p| p.material().index())
            .map_or(0, |i| i as u32 + 1);
        let name = mesh
            .name()
            .map_or_else(|| format!("mesh{}", mesh.index()), str::to_string);
        self.model.defs.push(ObjectDef {
            name,
            lods: levels,
            material,
        });
        Ok(self.model.defs.len() as u32 - 1)
    }

    /// All triangle primitives of a mesh, concatenated.
    fn mesh(&self, mesh: &gltf::Mesh) -> Result<Mesh, String> {
        let mut parts = Vec::new();
        for prim in mesh.primitives() {
            let at = || format!("mesh {} primitive {}", mesh.index(), prim.index());
            let Some(part) = self
                .primitive(&prim)
                .map_err(|e| format!("{}: {e}", at()))?
            else {
                continue;
            };
            parts.push(part);
        }
        Ok(concat(parts))
    }

    /// One primitive as a triangle list; `None` for points and lines.
    fn primitive(&self, prim: &gltf::Primitive) -> Result<Option<Mesh>, String> {
        use gltf::mesh::Mode;
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<[f32; 3]> = reader
            .read_positions()
            .ok_or("no POSITION attribute (or its buffer is missing)")?
            .collect();
        let normals: Option<Vec<[f32; 3]>> = reader.read_normals().map(|n| n.collect());
        let factor = prim.material().pbr_metallic_roughness().base_color_factor();
        let colors: Vec<[f32; 4]> = match reader.read_colors(0) {
            Some(c) => c
                .into_rgba_f32()
                .map(|c| [0, 1, 2, 3].map(|i| c[i] * factor[i]))
                .collect(),
            None => vec![factor; positions.len()],
        };
        let raw: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..positions.len() as u32).collect(),
        };
        let indices = match prim.mode() {
            Mode::Triangles => raw,
            Mode::TriangleStrip => strip_to_list(&raw),
            Mode::TriangleFan => fan_to_list(&raw),
            _ => return Ok(None),
        };
        mesh_from_streams(&positions, normals.as_deref(), &colors, indices).map(Some)
    }
}

/// Reads a node's `extras`: the `occluder` flag and every other scalar as a tag.
fn extras(node: &gltf::Node) -> Result<(bool, BTreeMap<String, String>), String> {
    let Some(raw) = node.extras() else {
        return Ok((false, BTreeMap::new()));
    };
    let value: serde_json::Value = serde_json::from_str(raw.get())
        .map_err(|e| format!("node {}: extras are not JSON: {e}", node.index()))?;
    let mut tags = BTreeMap::new();
    let mut occluder = false;
    if let Some(map) = value.as_object() {
        for (k, v) in map {
            match (k.as_str(), v) {
                ("occluder", serde_json::Value::Bool(b)) => occluder = *b,
                (_, serde_json::Value::String(s)) => {
                    tags.insert(k.clone(), s.clone());
                }
                (_, serde_json::Value::Number(_) | serde_json::Value::Bool(_)) => {
                    tags.insert(k.clone(), v.to_string());
                }
                _ => {}
            }
        }
    }
    Ok((occluder, tags))
}

fn strip_to_list(s: &[u32]) -> Vec<u32> {
    (2..s.len())
        .flat_map(|i| {
            if i % 2 == 0 {
                [s[i - 2], s[i - 1], s[i]]
            } else {
                [s[i - 1], s[i - 2], s[i]]
            }
        })
        .collect()
}

fn fan_to_list(s: &[u32]) -> Vec<u32> {
    (2..s.len()).flat_map(|i| [s[0], s[i - 1], s[i]]).collect()
}
