//! glTF 2.0 / GLB import.
//!
//! The `gltf` crate parses and cross-checks the JSON (every index in range); everything read from
//! the buffers goes through `accessor`, which checks each accessor before reading it, so a
//! broken file is refused with one line naming its mesh, primitive and accessor, never a panic.
//!
//! - Shared definitions: one glTF mesh used by several nodes becomes one definition with several
//!   instances (Funkhouser §3.1). A node's `MSFT_lod` extension (`{"ids": [node, ...]}`, coarser
//!   and coarser) gives the definition's lower LODs; the generator writes its LODs that way.
//! - Geometry as real exporters write it: triangle lists, strips and fans; `KHR_mesh_quantization`
//!   (dequantised) and `EXT_meshopt_compression` (decoded, `buffers`); sparse accessors; morph
//!   targets at their default weights; skinned meshes placed by their skeleton's rest pose (glTF
//!   §3.7.3: the skinned node's own transform is ignored). Draco and glTF 1.0 are refused.
//! - Coordinates in double precision: node transforms are read from the JSON as f64 and composed
//!   in f64; the model moves to a local origin ([`crate::bulk::local_origin`]) kept in
//!   [`Model::origin`]; objects far from the bulk are named in a warning.
//! - Node `extras`: `occluder: true` marks structural occluders; every other scalar is a tag.
//! - Vertex colour = `COLOR_0` × the primitive's base colour factor; the texture (any format
//!   the `image` crate reads, WebP from `EXT_texture_webp`; its sampler's wrap modes and
//!   `KHR_texture_transform` baked into the coordinates, less each primitive's whole-number
//!   offset), emissive colour, unlit, sides and alpha mode go to the material (`material`).
//!   Primitives of one mesh with different textures become separate objects: an object draws
//!   with one texture.

mod accessor;
mod buffers;
mod material;
mod place;
mod primitive;

use super::concat;
use super::frame::FrameOptions;
use crate::bulk::MAX_COORDINATE;
use crate::error::{DataError, Result};
use crate::geometry::Mesh;
use crate::model::{Model, ObjectDef};
use ::gltf::json;
use accessor::{Accessors, Semantic};
use buffers::{Buffers, Views};
use glam::{DMat4, DQuat, DVec3, DVec4};
use json::validation::Validate;
use serde_json::Value;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// Deepest node hierarchy we follow; deeper means a malformed file.
const MAX_DEPTH: usize = 256;

/// Extensions whose data this importer decodes.
const DECODED: &[&str] = &[
    "KHR_mesh_quantization",
    buffers::MESHOPT,
    "KHR_texture_transform",
    "EXT_texture_webp",
    "KHR_materials_unlit",
    "KHR_materials_emissive_strength",
];

/// Extensions a texture may hold its image in: with one of them a texture needs no `source`
/// (each texture says what it lacks, `material`).
const IMAGE_EXTENSIONS: &[&str] = &[
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "EXT_texture_avif",
    "MSFT_texture_dds",
];

/// Imports a `.gltf` (with external or embedded buffers) or `.glb` file. Errors name the file
/// and the element at fault.
pub fn import(path: &Path, options: &FrameOptions) -> Result<Model> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    import_slice(&bytes, path.parent(), options).map_err(|e| DataError::import(path, e))
}

/// Imports glTF or GLB bytes; external buffers are read from `base` (refused when `None`).
/// The error is one line naming the element at fault (without the file name). glTF is metres
/// and Y up by its specification: the frame `options` give is applied, and a model whose
/// geometry clearly says otherwise gets a warning naming the options ([`crate::import::frame::settle`]).
pub fn import_slice(
    bytes: &[u8],
    base: Option<&Path>,
    options: &FrameOptions,
) -> Result<Model, String> {
    if bytes.starts_with(b"glTF") && bytes.get(4..8) == Some(&1u32.to_le_bytes()[..]) {
        return Err(
            "binary glTF 1.0 is not supported (only glTF 2.0); convert it, e.g. with Blender"
                .into(),
        );
    }
    let (json_bytes, blob) = if bytes.starts_with(b"glTF") {
        // The `gltf` crate subtracts the 12-byte header from the declared length unchecked (a
        // panic in debug builds, a wrapped length in release): checked here first.
        let declared = bytes
            .get(8..12)
            .map(|l| u32::from_le_bytes([l[0], l[1], l[2], l[3]]));
        match declared {
            Some(n) if n >= 12 => {}
            Some(n) => {
                return Err(format!(
                    "GLB container: header declares {n} bytes, less than the 12-byte header itself"
                ));
            }
            None => return Err("GLB container: truncated inside its 12-byte header".into()),
        }
        let glb = ::gltf::Glb::from_slice(bytes).map_err(|e| format!("GLB container: {e}"))?;
        (glb.json.into_owned(), glb.bin.map(|b| b.into_owned()))
    } else {
        (bytes.to_vec(), None)
    };
    let raw: Value = serde_json::from_slice(&json_bytes).map_err(|e| format!("glTF JSON: {e}"))?;
    match raw["asset"]["version"].as_str() {
        Some(v) if v.starts_with("2.") => {}
        Some(v) => {
            return Err(format!(
                "glTF {v} is not supported (only glTF 2.0); convert it, e.g. with Blender or gltf-pipeline"
            ));
        }
        None => {
            return Err(
                "not glTF 2.0: asset.version is missing (glTF 1.0?); convert it, e.g. with Blender"
                    .into(),
            );
        }
    }
    let root: json::Root = serde_json::from_slice(&json_bytes).map_err(|e| format!("glTF: {e}"))?;
    let mut warnings = check(&root)?;
    let buffers = Buffers::load(&root, &raw, base, blob, &mut warnings)?;
    let views = Views::new(&root, &raw, buffers);
    let quantization = root
        .extensions_used
        .iter()
        .any(|e| e == "KHR_mesh_quantization");
    let mats = material::materials(&root, &raw, &views, base, &mut warnings);
    let mut imp = Importer {
        root: &root,
        raw: &raw,
        acc: Accessors::new(&root, &views, quantization),
        model: Model::default(),
        defs: HashMap::new(),
        uv: mats.uv,
        options: *options,
    };
    imp.model.materials = mats.materials;
    imp.model.textures = mats.textures;
    imp.run(&mut warnings)?;
    if !imp.acc.undeclared_quantization.is_empty() {
        warnings.push(format!(
            "accessors {:?} are quantised but KHR_mesh_quantization is not declared; read as the extension says",
            imp.acc.undeclared_quantization
        ));
    }
    imp.model.warnings.extend(warnings);
    Ok(imp.model)
}

/// The `gltf` crate's cross-checks (indices in range, enum values known) and the required
/// extensions; returns warnings for required extensions that only affect looks.
fn check(root: &json::Root) -> Result<Vec<String>, String> {
    if root
        .extensions_used
        .iter()
        .any(|e| e == "KHR_draco_mesh_compression")
    {
        return Err("meshes compressed with Draco (KHR_draco_mesh_compression) are not supported; \
             re-export without Draco, or recompress with gltfpack (EXT_meshopt_compression is supported)"
            .into());
    }
    // The `gltf` crate's cross-check indexes a primitive's POSITION accessor before checking
    // that it exists (gltf-json 1.4.1, mesh.rs): check it first, so its validation cannot panic.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let position = prim.attributes.get(&json::validation::Checked::Valid(
                json::mesh::Semantic::Positions,
            ));
            if let Some(a) = position.filter(|a| a.value() >= root.accessors.len()) {
                return Err(format!(
                    "mesh {m} primitive {p}: POSITION accessor {} does not exist",
                    a.value()
                ));
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(root, json::Path::new, &mut |path, e| {
        let path = path().to_string();
        // Required extensions are judged below, not by the crate's list; accessor min and max
        // are optional to us (bounds come from the data).
        let bounds = path.ends_with(".min") || path.ends_with(".max");
        // A texture whose image is in an extension has no `source`.
        let in_extension = path.starts_with("textures[") && path.ends_with("].source");
        if e != json::validation::Error::Unsupported
            && !((bounds || in_extension) && e == json::validation::Error::Missing)
        {
            errors.push(format!("{path}: {e}"));
        }
    });
    if let Some(first) = errors.first() {
        let more = match errors.len() {
            1 => String::new(),
            n => format!(" (and {} more)", n - 1),
        };
        return Err(format!("invalid glTF: {first}{more}"));
    }
    let mut warnings = Vec::new();
    for ext in &root.extensions_required {
        if DECODED.contains(&ext.as_str()) || IMAGE_EXTENSIONS.contains(&ext.as_str()) {
            continue;
        }
        let looks = [
            "KHR_materials_",
            "KHR_texture_",
            "EXT_texture_",
            "KHR_lights_",
        ];
        if looks.iter().any(|p| ext.starts_with(p)) {
            warnings.push(format!(
                "required extension {ext} is ignored: geometry is right, materials may look different"
            ));
            continue;
        }
        return Err(format!("required extension {ext} is not supported"));
    }
    Ok(warnings)
}

/// An instance before the model is moved to its local origin.
struct Placed {
    node: usize,
    def: u32,
    world: DMat4,
}

struct Importer<'a> {
    root: &'a json::Root,
    raw: &'a Value,
    acc: Accessors<'a>,
    model: Model,
    /// (mesh, LOD meshes, morph weights' bits) → definitions (one per texture).
    defs: HashMap<(usize, Vec<usize>, Vec<u32>), Vec<u32>>,
    /// Per glTF material, how its texture maps coordinates (`None`: untextured).
    uv: Vec<Option<material::UvMap>>,
    /// The unit and up axis the user gave.
    options: FrameOptions,
}

impl Importer<'_> {
    fn run(&mut self, warnings: &mut Vec<String>) -> Result<(), String> {
        let order = self.scene_order(warnings)?;
        let mut world: Vec<Option<DMat4>> = vec![None; self.root.nodes.len()];
        for &(n, parent) in &order {
            let base = parent.and_then(|p| world[p]).unwrap_or(DMat4::IDENTITY);
            world[n] = Some(base * self.local_transform(n)?);
        }
        let mut placed = Vec::new();
        for &(n, _) in &order {
            let node = &self.root.nodes[n];
            let (Some(mesh), Some(w)) = (node.mesh, world[n]) else {
                continue;
            };
            let at = |e: String| format!("node {n}{}: {e}", name_of(&node.name));
            let ps = match node.skin {
                Some(skin) => self
                    .skinned(n, mesh.value(), skin.value(), &world)
                    .map_err(at)?,
                None => {
                    let defs = self.definition(n, mesh.value()).map_err(at)?;
                    defs.into_iter()
                        .map(|def| Placed {
                            node: n,
                            def,
                            world: w,
                        })
                        .collect()
                }
            };
            // Points and lines are not drawn: a mesh with no triangle primitive is no object.
            let drawn: Vec<Placed> = ps
                .into_iter()
                .filter(|p| !self.model.defs[p.def as usize].lods[0].indices.is_empty())
                .collect();
            if drawn.is_empty() {
                warnings.push(format!(
                    "node {n}{}: mesh {} has no triangles (points or lines only): skipped",
                    name_of(&node.name),
                    mesh.value()
                ));
                continue;
            }
            placed.extend(drawn);
        }
        self.place(placed, warnings)
    }

    /// Reachable nodes in depth-first order with their parents. glTF requires the nodes to form
    /// a forest (§3.5.3): a node with two parents or a scene root with a parent is refused, so
    /// no file can make the walk loop or blow up.
    fn scene_order(
        &self,
        warnings: &mut Vec<String>,
    ) -> Result<Vec<(usize, Option<usize>)>, String> {
        let nodes = &self.root.nodes;
        let mut parent: Vec<Option<usize>> = vec![None; nodes.len()];
        for (i, n) in nodes.iter().enumerate() {
            for c in n.children.iter().flatten() {
                let c = c.value();
                if parent[c].replace(i).is_some() || c == i {
                    return Err(format!(
                        "node {c} has more than one parent (glTF nodes form trees)"
                    ));
                }
            }
        }
        let roots: Vec<usize> = match self
            .root
            .scene
            .or_else(|| (!self.root.scenes.is_empty()).then(|| json::Index::new(0)))
        {
            Some(s) => self.root.scenes[s.value()]
                .nodes
                .iter()
                .map(|n| n.value())
                .collect(),
            None => {
                warnings.push("the file has no scene: every root node is used".into());
                (0..nodes.len()).filter(|&i| parent[i].is_none()).collect()
            }
        };
        let mut order = Vec::new();
        let mut stack: Vec<(usize, Option<usize>, usize)> = Vec::new();
        for &r in roots.iter().rev() {
            if parent[r].is_some() {
                return Err(format!("scene root node {r} is also another node's child"));
            }
            stack.push((r, None, 0));
        }
        while let Some((n, p, depth)) = stack.pop() {
            if depth > MAX_DEPTH {
                return Err(format!("node {n}: hierarchy deeper than {MAX_DEPTH}"));
            }
            order.push((n, p));
            for c in nodes[n].children.iter().flatten().rev() {
                stack.push((c.value(), Some(n), depth + 1));
            }
        }
        Ok(order)
    }

    /// A node's local transform in double precision, read from the JSON (the `gltf` crate
    /// keeps only f32, which loses centimetres at survey coordinates).
    fn local_transform(&self, n: usize) -> Result<DMat4, String> {
        let node = &self.raw["nodes"][n];
        let name = name_of(&self.root.nodes[n].name);
        let nums = |key: &str, len: usize| -> Result<Option<Vec<f64>>, String> {
            match &node[key] {
                Value::Null => Ok(None),
                Value::Array(a) if a.len() == len => a
                    .iter()
                    .map(|v| v.as_f64().filter(|x| x.is_finite()))
                    .collect::<Option<Vec<f64>>>()
                    .map(Some)
                    .ok_or_else(|| format!("node {n}{name}: '{key}' holds a non-finite number")),
                _ => Err(format!("node {n}{name}: '{key}' is not {len} numbers")),
            }
        };
        let m = if let Some(m) = nums("matrix", 16)? {
            DMat4::from_cols_slice(&m)
        } else {
            let t = nums("translation", 3)?.map_or(DVec3::ZERO, |v| DVec3::from_slice(&v));
            let r = match nums("rotation", 4)? {
                None => DQuat::IDENTITY,
                Some(v) => DQuat::from_vec4(
                    DVec4::from_slice(&v)
                        .try_normalize()
                        .ok_or_else(|| format!("node {n}{name}: rotation is not a quaternion"))?,
                ),
            };
            let s = nums("scale", 3)?.map_or(DVec3::ONE, |v| DVec3::from_slice(&v));
            DMat4::from_scale_rotation_translation(s, r, t)
        };
        let t = m.w_axis.truncate();
        if t.abs().max_element() > MAX_COORDINATE {
            return Err(format!(
                "node {n}{name}: translation ({:.3e}, {:.3e}, {:.3e}) m is beyond ±{MAX_COORDINATE:.0e} m, not a building's coordinate",
                t.x, t.y, t.z
            ));
        }
        Ok(m)
    }

    /// The definitions for a plain mesh node (one per texture its primitives use), created on
    /// first use. A mesh split by texture keeps no `MSFT_lod` levels: they are one mesh each.
    fn definition(&mut self, n: usize, mesh: usize) -> Result<Vec<u32>, String> {
        let lods = self.lod_meshes(n)?;
        let weights = self.morph_weights(n, mesh);
        let key = (mesh, lods, weights.iter().map(|w| w.to_bits()).collect());
        if let Some(d) = self.defs.get(&key) {
            return Ok(d.clone());
        }
        let groups = self.mesh(mesh, &weights, None)?;
        let defs = if let [(material, finest)] = groups.as_slice() {
            let mut levels = vec![finest.clone()];
            for &l in &key.1 {
                let coarser = self.mesh(l, &self.morph_weights(n, l), None)?;
                levels.push(concat(coarser.into_iter().map(|(_, m)| m).collect()));
            }
            vec![self.push_def(mesh, *material, levels)]
        } else {
            groups
                .into_iter()
                .map(|(material, m)| self.push_def(mesh, material, vec![m]))
                .collect()
        };
        self.defs.insert(key, defs.clone());
        Ok(defs)
    }

    fn push_def(&mut self, mesh: usize, material: u32, lods: Vec<Mesh>) -> u32 {
        let m = &self.root.meshes[mesh];
        self.model.defs.push(ObjectDef {
            name: m.name.clone().unwrap_or_else(|| format!("mesh{mesh}")),
            lods,
            material,
        });
        self.model.defs.len() as u32 - 1
    }

    /// Morph target weights: the node's, else the mesh's defaults (glTF §3.7.2.2).
    fn morph_weights(&self, n: usize, mesh: usize) -> Vec<f32> {
        self.root.nodes[n]
            .weights
            .clone()
            .or_else(|| self.root.meshes[mesh].weights.clone())
            .unwrap_or_default()
    }

    /// Mesh indices of the node's `MSFT_lod` levels, coarser and coarser.
    fn lod_meshes(&self, n: usize) -> Result<Vec<usize>, String> {
        let ext = &self.raw["nodes"][n]["extensions"]["MSFT_lod"];
        if ext.is_null() {
            return Ok(Vec::new());
        }
        let ids = ext["ids"]
            .as_array()
            .ok_or_else(|| "MSFT_lod without an 'ids' array".to_string())?;
        ids.iter()
            .map(|id| {
                let node = id
                    .as_u64()
                    .and_then(|i| self.root.nodes.get(i as usize))
                    .ok_or_else(|| format!("MSFT_lod id {id} is not a node"))?;
                node.mesh
                    .map(|m| m.value())
                    .ok_or_else(|| format!("MSFT_lod node {id} has no mesh"))
            })
            .collect()
    }

    /// A skinned node: its mesh skinned at the skeleton's rest pose (joint matrix = joint world
    /// transform × inverse bind matrix, glTF §3.7.3), expressed relative to the first joint,
    /// which becomes the instance's transform. The node's own transform is ignored, as glTF says.
    fn skinned(
        &mut self,
        n: usize,
        mesh: usize,
        skin: usize,
        world: &[Option<DMat4>],
    ) -> Result<Vec<Placed>, String> {
        let s = &self.root.skins[skin];
        let joints: Vec<DMat4> = s
            .joints
            .iter()
            .map(|j| {
                world[j.value()].ok_or_else(|| {
                    format!("skin {skin}: joint node {} is not in the scene", j.value())
                })
            })
            .collect::<Result<_, _>>()?;
        let anchor = *joints
            .first()
            .ok_or_else(|| format!("skin {skin} has no joints"))?;
        let ibm: Vec<DMat4> = match s.inverse_bind_matrices {
            Some(a) => {
                let (m, _) = self.acc.floats(a.value(), Semantic::InverseBind)?;
                m.chunks_exact(16)
                    .map(|c| DMat4::from_cols_array(&std::array::from_fn(|k| c[k] as f64)))
                    .collect()
            }
            None => vec![DMat4::IDENTITY; joints.len()],
        };
        if ibm.len() < joints.len() {
            return Err(format!(
                "skin {skin}: {} inverse bind matrices for {} joints",
                ibm.len(),
                joints.len()
            ));
        }
        let to_anchor = anchor.inverse();
        let matrices: Vec<DMat4> = joints
            .iter()
            .zip(&ibm)
            .map(|(j, b)| to_anchor * *j * *b)
            .collect();
        let weights = self.morph_weights(n, mesh);
        let groups = self.mesh(mesh, &weights, Some(&matrices))?;
        Ok(groups
            .into_iter()
            .map(|(material, lod)| Placed {
                node: n,
                def: self.push_def(mesh, material, vec![lod]),
                world: anchor,
            })
            .collect())
    }

    /// The triangle primitives of a mesh, concatenated per texture and alpha mode (untextured
    /// ones together), each group with the material of its first primitive; `skin` holds joint
    /// matrices for a skinned mesh. Never empty.
    fn mesh(
        &mut self,
        mesh: usize,
        weights: &[f32],
        skin: Option<&[DMat4]>,
    ) -> Result<Vec<(u32, Mesh)>, String> {
        type Key = (Option<u32>, crate::texture::AlphaMode);
        let mut groups: Vec<(Key, u32, Vec<Mesh>)> = Vec::new();
        let name = name_of(&self.root.meshes[mesh].name);
        for p in 0..self.root.meshes[mesh].primitives.len() {
            let material = self.root.meshes[mesh].primitives[p]
                .material
                .map(|m| m.value());
            let uv = material.and_then(|m| self.uv.get(m).copied().flatten());
            let Some(part) =
                primitive::primitive(self.root, &mut self.acc, mesh, p, weights, skin, uv)
                    .map_err(|e| format!("mesh {mesh}{name} primitive {p}: {e}"))?
            else {
                continue;
            };
            let index = material.map_or(0, |m| m as u32 + 1);
            let m = &self.model.materials[index as usize];
            let key = (m.texture.filter(|_| part.has_uvs()), m.alpha);
            match groups.iter_mut().find(|g| g.0 == key) {
                Some(g) => g.2.push(part),
                None => groups.push((key, index, vec![part])),
            }
        }
        if groups.is_empty() {
            return Ok(vec![(0, Mesh::default())]);
        }
        Ok(groups
            .into_iter()
            .map(|(_, material, parts)| (material, concat(parts)))
            .collect())
    }
}

/// `" 'name'"` for messages, or nothing.
fn name_of(name: &Option<String>) -> String {
    name.as_deref().map_or(String::new(), |n| format!(" '{n}'"))
}

/// Reads a node's `extras`: the `occluder` flag and every other scalar as a tag.
fn extras(raw: &json::Extras) -> Result<(bool, BTreeMap<String, String>), String> {
    let Some(raw) = raw else {
        return Ok((false, BTreeMap::new()));
    };
    let value: Value =
        serde_json::from_str(raw.get()).map_err(|e| format!("extras are not JSON: {e}"))?;
    let mut tags = BTreeMap::new();
    let mut occluder = false;
    if let Some(map) = value.as_object() {
        for (k, v) in map {
            match (k.as_str(), v) {
                ("occluder", Value::Bool(b)) => occluder = *b,
                (_, Value::String(s)) => {
                    tags.insert(k.clone(), s.clone());
                }
                (_, Value::Number(_) | Value::Bool(_)) => {
                    tags.insert(k.clone(), v.to_string());
                }
                _ => {}
            }
        }
    }
    Ok((occluder, tags))
}
