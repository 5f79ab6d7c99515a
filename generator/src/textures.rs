//! Textured materials for a generated building (`portico generate --textured`): procedural
//! brick, wood, carpet and tile images written as PNGs into the GLB, every surface given box-
//! mapped texture coordinates (the axis its face is most nearly perpendicular to, in metres over
//! the material's repeat size), so `soda` and `mega` can be measured with and without textures.
//!
//! Walls are brick, floors carpet (offices, classrooms, conference rooms, the library), tiles
//! (labs, corridors, stairwells) or wood (auditoriums), wooden furniture (desks, chairs,
//! shelves, tables, doors, stairs) wood; ceilings, lights, screens and plants stay plain.
//! The vertex colours stay and tint the textures.

use crate::GenerateError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{Value, json};
use std::borrow::Cow;
use std::io::Cursor;

/// A material the generator paints: name, image side (texels), repeat size (metres).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Surface {
    Brick,
    Wood,
    Carpet,
    Tiles,
}

impl Surface {
    const ALL: [Surface; 4] = [
        Surface::Brick,
        Surface::Wood,
        Surface::Carpet,
        Surface::Tiles,
    ];

    fn name(self) -> &'static str {
        match self {
            Surface::Brick => "brick",
            Surface::Wood => "wood",
            Surface::Carpet => "carpet",
            Surface::Tiles => "tiles",
        }
    }

    /// Texels on a side.
    fn size(self) -> u32 {
        match self {
            Surface::Carpet => 256,
            _ => 512,
        }
    }

    /// Metres one repeat of the image covers.
    fn repeat_m(self) -> f32 {
        match self {
            Surface::Brick => 1.0,
            Surface::Wood => 1.5,
            Surface::Carpet => 2.0,
            Surface::Tiles => 1.2,
        }
    }

    /// The surface a node's tags ask for, if any.
    fn of(extras: &Value) -> Option<Surface> {
        match extras["kind"].as_str()? {
            "wall" => Some(Surface::Brick),
            // Wooden furniture; lights, screens, plants and the like keep their colours.
            "furniture" => match extras["type"].as_str()? {
                "desk" | "chair" | "bookshelf" | "table" | "student_desk" | "round_table"
                | "lab_bench" | "stool" | "auditorium_seat" | "lectern" | "coat_rack" | "door"
                | "stairs" | "library_shelf" | "filing_cabinet" => Some(Surface::Wood),
                _ => None,
            },
            "floor" => Some(match extras["room"].as_str() {
                Some("lab" | "corridor" | "stairwell") => Surface::Tiles,
                Some("auditorium") => Surface::Wood,
                _ => Surface::Carpet,
            }),
            _ => None,
        }
    }

    /// The image, sRGB RGBA8, deterministic.
    fn image(self) -> image::RgbaImage {
        let n = self.size();
        let mut rng = ChaCha8Rng::seed_from_u64(self as u64 + 17);
        let noise: Vec<f32> = (0..n * n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let tone = |x: u32, y: u32| noise[((y % n) * n + x % n) as usize];
        let mut img = image::RgbaImage::new(n, n);
        // Per-brick, per-plank and per-tile colour variation.
        let vary: Vec<f32> = (0..256).map(|_| rng.random_range(-1.0..1.0)).collect();
        for y in 0..n {
            for x in 0..n {
                let c: [f32; 3] = match self {
                    Surface::Brick => {
                        let (bw, bh) = (n / 8, n / 16);
                        let row = y / bh;
                        let xs = x + if row % 2 == 1 { bw / 2 } else { 0 };
                        let mortar = y % bh < 3 || xs % bw < 3;
                        if mortar {
                            [0.72, 0.70, 0.66]
                        } else {
                            let v = vary[((row * 9 + xs / bw) % 256) as usize] * 0.08;
                            let t = tone(x, y) * 0.05;
                            [0.55 + v + t, 0.25 + v * 0.5 + t, 0.18 + t]
                        }
                    }
                    Surface::Wood => {
                        let plank = y / (n / 8);
                        let v = vary[(plank % 256) as usize] * 0.06;
                        let grain = ((x as f32 * 0.05 + tone(x / 8, y) * 0.6 + plank as f32).sin()
                            * 0.5
                            + 0.5)
                            * 0.10;
                        let seam = if y % (n / 8) < 2 { -0.15 } else { 0.0 };
                        [
                            0.52 + v + grain + seam,
                            0.36 + v + grain * 0.7 + seam,
                            0.20 + seam,
                        ]
                    }
                    Surface::Carpet => {
                        let t = tone(x, y) * 0.06 + tone(x / 4, y / 4) * 0.04;
                        [0.30 + t, 0.34 + t, 0.45 + t]
                    }
                    Surface::Tiles => {
                        let s = n / 4;
                        let grout = x % s < 3 || y % s < 3;
                        if grout {
                            [0.55, 0.55, 0.53]
                        } else {
                            let v = vary[((y / s) * 4 + x / s) as usize % 256] * 0.03;
                            let t = tone(x, y) * 0.02;
                            [0.86 + v + t, 0.86 + v + t, 0.84 + v + t]
                        }
                    }
                };
                let b = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
                img.put_pixel(x, y, image::Rgba([b(c[0]), b(c[1]), b(c[2]), 255]));
            }
        }
        img
    }
}

/// The same GLB with textured materials (see the module docs).
pub fn with_textures(glb: &[u8]) -> Result<Vec<u8>, GenerateError> {
    let parsed = gltf::binary::Glb::from_slice(glb)?;
    let mut root: Value = serde_json::from_slice(&parsed.json)?;
    let mut bin: Vec<u8> = parsed.bin.map(Cow::into_owned).unwrap_or_default();
    // Which surface each mesh is: from the node that draws it, and its MSFT_lod levels.
    let mesh_count = root["meshes"].as_array().map_or(0, Vec::len);
    let mut surface: Vec<Option<Surface>> = vec![None; mesh_count];
    for node in root["nodes"].as_array().into_iter().flatten() {
        let Some(s) = Surface::of(&node["extras"]) else {
            continue;
        };
        let lods = node["extensions"]["MSFT_lod"]["ids"].as_array();
        let lod_meshes = lods
            .into_iter()
            .flatten()
            .filter_map(|id| root["nodes"][id.as_u64()? as usize]["mesh"].as_u64());
        for m in node["mesh"].as_u64().into_iter().chain(lod_meshes) {
            if let Some(slot) = surface.get_mut(m as usize) {
                slot.get_or_insert(s);
            }
        }
    }
    // The images, their textures and materials (glTF material index = first new one + k).
    let first_material = root["materials"].as_array().map_or(0, Vec::len);
    for (k, s) in Surface::ALL.iter().enumerate() {
        let mut png = Vec::new();
        s.image()
            .write_to(&mut Cursor::new(&mut png), image::ImageFormat::Png)
            .map_err(|e| GenerateError::Texture(e.to_string()))?;
        let view = push_view(&mut root, &mut bin, &png);
        push(
            &mut root,
            "images",
            json!({"bufferView": view, "mimeType": "image/png", "name": s.name()}),
        );
        let image = root["images"].as_array().map_or(0, Vec::len) - 1;
        push(
            &mut root,
            "samplers",
            json!({"wrapS": 10497, "wrapT": 10497, "minFilter": 9987, "magFilter": 9729}),
        );
        let sampler = root["samplers"].as_array().map_or(0, Vec::len) - 1;
        push(
            &mut root,
            "textures",
            json!({"source": image, "sampler": sampler}),
        );
        let texture = root["textures"].as_array().map_or(0, Vec::len) - 1;
        push(
            &mut root,
            "materials",
            json!({
                "name": s.name(),
                "pbrMetallicRoughness": {
                    "baseColorTexture": {"index": texture},
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.9
                },
                "doubleSided": true
            }),
        );
        debug_assert_eq!(
            root["materials"].as_array().map_or(0, Vec::len),
            first_material + k + 1
        );
    }
    // Coordinates for every primitive of a textured mesh.
    for (m, s) in surface.iter().enumerate() {
        let Some(s) = *s else { continue };
        let prims = root["meshes"][m]["primitives"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        for (p, prim) in prims.iter().enumerate() {
            let (Some(pos), Some(nor)) = (
                prim["attributes"]["POSITION"].as_u64(),
                prim["attributes"]["NORMAL"].as_u64(),
            ) else {
                continue;
            };
            let positions = read_vec3(&root, &bin, pos as usize)?;
            let normals = read_vec3(&root, &bin, nor as usize)?;
            let uvs: Vec<u8> = positions
                .iter()
                .zip(&normals)
                .flat_map(|(p, n)| box_uv(*p, *n, s.repeat_m()))
                .flat_map(f32::to_le_bytes)
                .collect();
            let view = push_view(&mut root, &mut bin, &uvs);
            push(
                &mut root,
                "accessors",
                json!({"bufferView": view, "componentType": 5126, "count": positions.len(), "type": "VEC2"}),
            );
            let accessor = root["accessors"].as_array().map_or(0, Vec::len) - 1;
            let k = Surface::ALL.iter().position(|x| *x == s).unwrap_or(0);
            let prim = &mut root["meshes"][m]["primitives"][p];
            prim["attributes"]["TEXCOORD_0"] = json!(accessor);
            prim["material"] = json!(first_material + k);
        }
    }
    root["buffers"][0]["byteLength"] = json!(bin.len());
    let out = gltf::binary::Glb {
        header: parsed.header,
        json: Cow::Owned(serde_json::to_vec(&root)?),
        bin: Some(Cow::Owned(bin)),
    };
    Ok(out.to_vec()?)
}

/// Box mapping: the two axes across the face's dominant normal axis, in repeats.
fn box_uv(p: [f32; 3], n: [f32; 3], repeat: f32) -> [f32; 2] {
    let a = n.map(f32::abs);
    let (u, v) = if a[0] >= a[1] && a[0] >= a[2] {
        (p[2], -p[1])
    } else if a[1] >= a[2] {
        (p[0], p[2])
    } else {
        (p[0], -p[1])
    };
    [u / repeat, v / repeat]
}

/// Appends a JSON value to one of the root's arrays (creating it).
fn push(root: &mut Value, key: &str, v: Value) {
    match root[key].as_array_mut() {
        Some(a) => a.push(v),
        None => root[key] = json!([v]),
    }
}

/// Appends bytes to the binary chunk (4-byte aligned) as a new buffer view; returns its index.
fn push_view(root: &mut Value, bin: &mut Vec<u8>, bytes: &[u8]) -> usize {
    bin.resize(bin.len().next_multiple_of(4), 0);
    let offset = bin.len();
    bin.extend_from_slice(bytes);
    push(
        root,
        "bufferViews",
        json!({"buffer": 0, "byteOffset": offset, "byteLength": bytes.len()}),
    );
    root["bufferViews"].as_array().map_or(0, Vec::len) - 1
}

/// A float VEC3 accessor's values (the generator interleaves its vertex attributes).
fn read_vec3(root: &Value, bin: &[u8], accessor: usize) -> Result<Vec<[f32; 3]>, GenerateError> {
    let a = &root["accessors"][accessor];
    let view = &root["bufferViews"][a["bufferView"].as_u64().unwrap_or(u64::MAX) as usize];
    let start = view["byteOffset"].as_u64().unwrap_or(0) + a["byteOffset"].as_u64().unwrap_or(0);
    let stride = view["byteStride"].as_u64().unwrap_or(12).max(12);
    let count = a["count"].as_u64().unwrap_or(0);
    let bad = || GenerateError::Texture(format!("accessor {accessor} is not a float VEC3"));
    if a["componentType"] != 5126 || a["type"] != "VEC3" {
        return Err(bad());
    }
    (0..count)
        .map(|i| {
            let at = (start + i * stride) as usize;
            let c = bin.get(at..at + 12).ok_or_else(bad)?;
            Ok(std::array::from_fn(|k| {
                f32::from_le_bytes([c[k * 4], c[k * 4 + 1], c[k * 4 + 2], c[k * 4 + 3]])
            }))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_mapping_follows_the_face() {
        // A wall facing +x maps z and height; a floor maps x and z.
        assert_eq!(box_uv([1.0, 2.0, 3.0], [1.0, 0.0, 0.0], 1.0), [3.0, -2.0]);
        assert_eq!(box_uv([1.0, 2.0, 3.0], [0.0, -1.0, 0.0], 2.0), [0.5, 1.5]);
    }

    #[test]
    fn images_are_deterministic_and_not_flat() {
        for s in Surface::ALL {
            let a = s.image();
            assert_eq!(a, s.image(), "{}", s.name());
            let first = a.get_pixel(5, 5);
            assert!(a.pixels().any(|p| p != first), "{}", s.name());
        }
    }
}
