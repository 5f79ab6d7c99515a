//! A display database written as OGC 3D Tiles 1.1 (`tileset.json` and one binary glTF per tile),
//! for 3DTilesRenderer, Cesium and other 3D Tiles viewers, and for measuring Portico against
//! them on the same building (`portico export-3dtiles`). The tileset is local (no root
//! transform): a globe viewer such as Cesium places it at the Earth's centre until given one.
//!
//! The tiles are a k-D tree over the instances' box centres, split at the median of the longest
//! axis until a node's instances hold at most `leaf_triangles` ([`LEAF_TRIANGLES`] by default)
//! triangles at their finest LOD (or one instance). Each instance is drawn once, at its finest
//! LOD, in the highest tile whose box it is large in (its box's diagonal at least [`KEEP`] of
//! the tile's): walls and slabs near the root, furniture deeper, small things in the leaves.
//! Children add to their parent (`ADD` refinement) once the parent's geometric error — the
//! largest diagonal of what its children hold, in metres — would show. Each tile is one glTF
//! mesh: positions, normals and vertex colours (the importers multiply the material's colour into them), the
//! instances' transforms applied. Textures are left out. Coordinates are Portico's metres, Y up,
//! as glTF content is; the bounding volumes are in 3D Tiles' Z-up frame (`(x, y, z)` becomes
//! `(x, −z, y)`), the rotation every 3D Tiles viewer applies to glTF content.

use crate::Database;
use crate::error::{DataError, Result};
use crate::geometry::{Aabb, GeometryView};
use glam::{Mat4, Vec3};
use serde_json::{Value, json};
use std::path::Path;

/// A tile keeps the instances whose box's diagonal is at least this fraction of its own.
pub const KEEP: f32 = 0.125;

/// A leaf holds at most this many triangles at its instances' finest LODs, by default.
pub const LEAF_TRIANGLES: u64 = 60_000;

/// What an export wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Written {
    /// Tiles (and binary glTF files).
    pub tiles: usize,
    /// Bytes of every file written.
    pub bytes: u64,
    /// Triangles in every tile (the finest LODs of every instance, each once).
    pub triangles: u64,
}

/// Writes `db` as a 3D Tiles tileset into `dir` (created if missing): `tileset.json` and
/// `tiles/N.glb` (for each tile that holds something), leaves of at most `leaf_triangles`. `progress` hears each tile written and
/// the count. Errors name the file.
pub fn write(
    db: &Database,
    dir: &Path,
    leaf_triangles: u64,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Written> {
    let header = db.header();
    let items: Vec<u32> = (0..header.instances.len() as u32)
        .filter(|&i| {
            let inst = &header.instances[i as usize];
            !inst.bounds.is_empty() && !header.lods_of(inst).is_empty()
        })
        .collect();
    let finest = |i: u32| {
        let inst = &header.instances[i as usize];
        header
            .lods_of(inst)
            .first()
            .map_or(0, |l| u64::from(l.triangles))
    };
    let mut nodes = Vec::new();
    split(header, items, &finest, leaf_triangles, &mut nodes);
    let tiles_dir = dir.join("tiles");
    std::fs::create_dir_all(&tiles_dir).map_err(|e| DataError::io(&tiles_dir, e))?;
    let mut written = Written::default();
    let mut json_nodes: Vec<Option<Value>> = vec![None; nodes.len()];
    // Children before parents: each node's JSON takes its children's.
    for k in (0..nodes.len()).rev() {
        let node = &nodes[k];
        let leaf = node.children.is_empty();
        // A tile with nothing of its own (no object large in it) has no content: glTF has no
        // empty scene, and a viewer would fetch it for nothing.
        let content = if node.instances.is_empty() {
            None
        } else {
            let (glb, triangles) = tile(db, &node.instances)?;
            let path = tiles_dir.join(format!("{k}.glb"));
            write_file(&path, &glb)?;
            written.bytes += glb.len() as u64;
            written.triangles += triangles;
            Some(format!("tiles/{k}.glb"))
        };
        written.tiles += 1;
        let children: Vec<Value> = node
            .children
            .iter()
            .filter_map(|&c| json_nodes[c].take())
            .collect();
        let mut t = json!({
            "boundingVolume": { "box": z_up_box(&node.bounds) },
            "geometricError": if leaf { 0.0 } else { node.below.max(1e-3) },
            "refine": "ADD",
        });
        if let Some(uri) = content {
            t["content"] = json!({ "uri": uri });
        }
        if !children.is_empty() {
            t["children"] = Value::Array(children);
        }
        json_nodes[k] = Some(t);
        progress(written.tiles, nodes.len());
    }
    let root = json_nodes.first_mut().and_then(Option::take).unwrap_or_else(|| {
        json!({ "boundingVolume": { "box": z_up_box(&header.bounds) }, "geometricError": 0.0 })
    });
    let size = header.bounds.size().length();
    let tileset = json!({
        "asset": { "version": "1.1", "generator": "portico export-3dtiles" },
        "geometricError": if size.is_finite() { size } else { 0.0 },
        "root": root,
    });
    let path = dir.join("tileset.json");
    let text = serde_json::to_vec_pretty(&tileset)
        .map_err(|e| DataError::io(&path, std::io::Error::other(e)))?;
    write_file(&path, &text)?;
    written.bytes += text.len() as u64;
    Ok(written)
}

/// One node of the tile tree.
struct Node {
    bounds: Aabb,
    /// What it draws.
    instances: Vec<u32>,
    children: Vec<usize>,
    /// The largest diagonal (metres) of what its descendants draw: its geometric error.
    below: f32,
}

/// Adds the node holding `items` and its subtree to `nodes` (pre-order); returns its index.
fn split(
    header: &crate::format::Header,
    items: Vec<u32>,
    finest: &dyn Fn(u32) -> u64,
    leaf_triangles: u64,
    nodes: &mut Vec<Node>,
) -> usize {
    let bounds_of = |i: &u32| header.instances[*i as usize].bounds;
    let bounds = items
        .iter()
        .fold(Aabb::EMPTY, |b, i| b.union(&bounds_of(i)));
    let k = nodes.len();
    nodes.push(Node {
        bounds,
        instances: Vec::new(),
        children: Vec::new(),
        below: 0.0,
    });
    let triangles: u64 = items.iter().map(|&i| finest(i)).sum();
    if triangles <= leaf_triangles || items.len() < 2 {
        nodes[k].instances = items;
        return k;
    }
    let diagonal = |b: &Aabb| b.size().length();
    let large = diagonal(&bounds) * KEEP;
    let (kept, mut rest): (Vec<u32>, Vec<u32>) = items
        .into_iter()
        .partition(|i| diagonal(&bounds_of(i)) >= large);
    nodes[k].instances = kept;
    if rest.len() < 2 {
        nodes[k].instances.extend(rest);
        return k;
    }
    let size = bounds.size();
    let axis = (0..3)
        .max_by(|&a, &b| size[a].total_cmp(&size[b]))
        .unwrap_or(0);
    let centre = |i: &u32| bounds_of(i).center()[axis];
    rest.sort_by(|a, b| centre(a).total_cmp(&centre(b)));
    let below = rest
        .iter()
        .map(|i| diagonal(&bounds_of(i)))
        .fold(0.0, f32::max);
    let high = rest.split_off(rest.len() / 2);
    let lo = split(header, rest, finest, leaf_triangles, nodes);
    let hi = split(header, high, finest, leaf_triangles, nodes);
    nodes[k].children = vec![lo, hi];
    nodes[k].below = below;
    k
}

/// `b` (Y up) as a 3D Tiles box (Z up): centre, then the three half axes.
fn z_up_box(b: &Aabb) -> Vec<f64> {
    if b.is_empty() {
        return vec![
            0.0, 0.0, 0.0, 1e-3, 0.0, 0.0, 0.0, 1e-3, 0.0, 0.0, 0.0, 1e-3,
        ];
    }
    let c = b.center();
    let h = b.size() * 0.5;
    let h = h.max(Vec3::splat(1e-3));
    [c.x, -c.z, c.y, h.x, 0.0, 0.0, 0.0, h.z, 0.0, 0.0, 0.0, h.y]
        .iter()
        .map(|&v| f64::from(v))
        .collect()
}

/// The binary glTF of `instances` at their finest LODs, and its triangles.
fn tile(db: &Database, instances: &[u32]) -> Result<(Vec<u8>, u64)> {
    let header = db.header();
    let (mut positions, mut normals, mut colors, mut indices) = (
        Vec::<[f32; 3]>::new(),
        Vec::<[f32; 3]>::new(),
        Vec::<[u8; 4]>::new(),
        Vec::<u32>::new(),
    );
    for &i in instances {
        let inst = &header.instances[i as usize];
        let lods = header.lods_of(inst);
        let Some(lod) = lods.first() else {
            continue;
        };
        let bytes = db.geometry(lod)?;
        let mesh = GeometryView::parse(&bytes)
            .map_err(|e| DataError::corrupt(db.path(), format!("instance {i}: {e}")))?
            .to_mesh();
        let m = Mat4::from_cols_array(&inst.transform);
        let n = m.inverse().transpose();
        let base = positions.len() as u32;
        for v in &mesh.vertices {
            positions.push(m.transform_point3(Vec3::from(v.position)).to_array());
            let normal = n.transform_vector3(v.normal_f32()).normalize_or(Vec3::Y);
            normals.push(normal.to_array());
            colors.push(v.color);
        }
        indices.extend(mesh.indices.iter().map(|&x| x + base));
    }
    let triangles = indices.len() as u64 / 3;
    Ok((glb(&positions, &normals, &colors, &indices), triangles))
}

/// A binary glTF 2.0 of one mesh of one primitive (a tile with nothing in it has no mesh).
fn glb(
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    colors: &[[u8; 4]],
    indices: &[u32],
) -> Vec<u8> {
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let mut push = |bytes: &[u8], target: u32| {
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        views.push(json!({ "buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len(), "target": target }));
        bin.extend_from_slice(bytes);
    };
    let (lo, hi) = positions.iter().fold(
        ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]),
        |(lo, hi), p| {
            (
                std::array::from_fn(|k| lo[k].min(p[k])),
                std::array::from_fn(|k| hi[k].max(p[k])),
            )
        },
    );
    push(bytemuck::cast_slice(positions), 34962);
    push(bytemuck::cast_slice(normals), 34962);
    push(bytemuck::cast_slice(colors), 34962);
    push(bytemuck::cast_slice(indices), 34963);
    let count = positions.len();
    let mut doc = json!({
        "asset": { "version": "2.0", "generator": "portico export-3dtiles" },
        "scene": 0,
        "scenes": [{ "nodes": [] }],
        "materials": [{
            "pbrMetallicRoughness": { "baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0 },
            "doubleSided": true
        }],
    });
    if count > 0 && !indices.is_empty() {
        doc["scenes"][0]["nodes"] = json!([0]);
        doc["nodes"] = json!([{ "mesh": 0 }]);
        doc["meshes"] = json!([{ "primitives": [{
            "attributes": { "POSITION": 0, "NORMAL": 1, "COLOR_0": 2 },
            "indices": 3,
            "material": 0,
        }]}]);
        doc["accessors"] = json!([
            { "bufferView": 0, "componentType": 5126, "count": count, "type": "VEC3", "min": lo, "max": hi },
            { "bufferView": 1, "componentType": 5126, "count": count, "type": "VEC3" },
            { "bufferView": 2, "componentType": 5121, "normalized": true, "count": count, "type": "VEC4" },
            { "bufferView": 3, "componentType": 5125, "count": indices.len(), "type": "SCALAR" },
        ]);
        doc["bufferViews"] = Value::Array(views);
        doc["buffers"] = json!([{ "byteLength": bin.len() }]);
    } else {
        bin.clear();
    }
    let mut text = serde_json::to_vec(&doc).unwrap_or_default();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + text.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(text.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
    }
    out
}

/// Writes `bytes` to `path` (whole, then renamed into place).
fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension("part");
    std::fs::write(&tmp, bytes).map_err(|e| DataError::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| DataError::io(path, e))
}
