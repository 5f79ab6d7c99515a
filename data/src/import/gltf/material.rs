//! glTF materials (glTF 2.0 §3.9): the base colour factor and texture (with its sampler's wrap
//! modes and `KHR_texture_transform`), the emissive factor and texture
//! (`KHR_materials_emissive_strength`), `KHR_materials_unlit`, `doubleSided` and the alpha mode.
//!
//! Images come from `data:` URIs, files beside the model (found as Windows exporters meant
//! them: [`crate::import::files`]) or buffer views (GLB), in any format the `image` crate reads;
//! a texture whose only image is in `EXT_texture_webp` is read from there. Every image is sized
//! first and the model's textures are scaled together to one budget
//! ([`crate::import::image::fit`]). An image that is missing or does not decode (a KTX2 image
//! that is not Basis Universal, an AVIF) is named in a warning and its material keeps its colour: never a
//! failed import.

use super::buffers::{Views, data_uri};
use crate::import::files;
use crate::import::image::{MODEL_TEXELS, decode, dimensions, fit, limit_warning};
use crate::model::{Material, TextureRole};
use crate::texture::{AlphaMode, TextureImage, Wrap, average_color};
use ::gltf::json;
use json::validation::Checked;
use serde_json::Value;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// How a textured material maps a primitive's coordinates onto its image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct UvMap {
    /// Which `TEXCOORD_n` set.
    pub set: u32,
    /// `KHR_texture_transform` as a 2 × 3 matrix (rows), identity without it.
    pub transform: [[f32; 3]; 2],
    /// The image's wrap modes: a whole-number offset can be taken off the coordinates (every
    /// whole number with `REPEAT`, even ones with `MIRRORED_REPEAT`, none with `CLAMP`).
    pub wrap: [Wrap; 2],
}

impl UvMap {
    /// The coordinates of one primitive, transformed, less the whole-number offset the wrap
    /// modes allow: tiling placed in world units (coordinates near 1e5, where f32 steps by
    /// 1/128) comes near 0 and samples as finely as any other (exact: the image repeats).
    pub fn coordinates(&self, uv: &[f32]) -> Vec<[f32; 2]> {
        let t: Vec<[f64; 2]> = uv
            .chunks_exact(2)
            .map(|c| {
                let [a, b] = self.transform.map(|r| r.map(f64::from));
                let (u, v) = (c[0] as f64, c[1] as f64);
                [a[0] * u + a[1] * v + a[2], b[0] * u + b[1] * v + b[2]]
            })
            .collect();
        let mut offset = [0.0f64; 2];
        for (k, o) in offset.iter_mut().enumerate() {
            let min = t.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
            if !min.is_finite() {
                continue;
            }
            *o = match self.wrap[k] {
                Wrap::Repeat => min.floor(),
                Wrap::Mirror => (min / 2.0).floor() * 2.0,
                Wrap::Clamp => 0.0,
            };
        }
        t.iter()
            .map(|p| [(p[0] - offset[0]) as f32, (p[1] - offset[1]) as f32])
            .collect()
    }
}

/// The model's materials and textures, and per glTF material how it maps coordinates.
pub(super) struct Materials {
    /// Index 0 is a default white; glTF material `i` is at `i + 1`.
    pub materials: Vec<Material>,
    /// The decoded images the materials use.
    pub textures: Vec<TextureImage>,
    /// Per glTF material, its texture's coordinate map (`None`: untextured).
    pub uv: Vec<Option<UvMap>>,
}

/// Reads every material, decoding each image they use once, all within the model's budget.
pub(super) fn materials(
    root: &json::Root,
    raw: &Value,
    views: &Views,
    base: Option<&Path>,
    warnings: &mut Vec<String>,
) -> Materials {
    let mut out = Materials {
        materials: vec![Material::default()],
        textures: Vec::new(),
        uv: Vec::with_capacity(root.materials.len()),
    };
    // Each material's base-colour and emissive slots, resolved to (image, wrap) keys.
    type Key = (usize, [Wrap; 2]);
    let mut slots: Vec<[Option<Key>; 2]> = Vec::with_capacity(root.materials.len());
    for (i, m) in root.materials.iter().enumerate() {
        let pbr = &m.pbr_metallic_roughness;
        let base_slot = pbr.base_color_texture.as_ref().map(|t| t.index.value());
        let emissive_slot = m.emissive_texture.as_ref().map(|t| t.index.value());
        let mut keys = [None, None];
        for (k, slot) in [base_slot, emissive_slot].into_iter().enumerate() {
            let Some(t) = slot else { continue };
            match texture_source(root, raw, t) {
                Ok(key) => keys[k] = Some(key),
                Err(e) => warnings.push(format!(
                    "material {i}{}: texture {t}: {e}; drawn in its colour",
                    name_of(&m.name)
                )),
            }
        }
        slots.push(keys);
    }
    // Every image's size first, then one scale for all, then each decoded in turn.
    let mut images: BTreeMap<usize, Result<(u32, u32), String>> = BTreeMap::new();
    for &source in slots.iter().flatten().flatten().map(|(s, _)| s) {
        images.entry(source).or_insert_with(|| {
            let (name, bytes, warning) = image_bytes(root, views, base, source)?;
            warnings.extend(warning);
            let size = dimensions(&name, &bytes).map_err(|e| format!("image '{name}': {e}"))?;
            warnings.extend(limit_warning(&name, size));
            Ok(size)
        });
    }
    // One texture per (image, wrap): an image sampled two ways is stored, and counted, twice.
    let keys: std::collections::BTreeSet<(usize, [u8; 2])> = slots
        .iter()
        .flatten()
        .flatten()
        .map(|(s, w)| (*s, w.map(|w| w as u8)))
        .collect();
    let sizes: Vec<(u32, u32)> = keys
        .iter()
        .filter_map(|(s, _)| images[s].as_ref().ok())
        .copied()
        .collect();
    let (scale, budget) = fit(&sizes, MODEL_TEXELS);
    warnings.extend(budget);
    let mut decoded: HashMap<Key, Result<u32, String>> = HashMap::new();
    let mut emissive_only: HashMap<Key, Result<[f32; 4], String>> = HashMap::new();
    for (i, m) in root.materials.iter().enumerate() {
        let pbr = &m.pbr_metallic_roughness;
        let mraw = &raw["materials"][i];
        let warn = |e: &String, warnings: &mut Vec<String>| {
            warnings.push(format!(
                "material {i}{}: {e}; drawn in its colour",
                name_of(&m.name)
            ));
        };
        let mut load = |key: Key, warnings: &mut Vec<String>| -> Option<u32> {
            let r = decoded.entry(key).or_insert_with(|| {
                images[&key.0].clone()?;
                let (name, bytes, _) = image_bytes(root, views, base, key.0)?;
                let img = decode(&name, &bytes, key.1, scale)
                    .map_err(|e| format!("image '{name}': {e}"))?;
                out.textures.push(img);
                Ok(out.textures.len() as u32 - 1)
            });
            r.as_ref().inspect_err(|e| warn(e, warnings)).ok().copied()
        };
        let [base_key, emissive_key] = slots[i];
        let strength = mraw["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"]
            .as_f64()
            .filter(|s| s.is_finite() && *s >= 0.0)
            .unwrap_or(1.0) as f32;
        let mut emissive = m.emissive_factor.0.map(|c| c * strength);
        let base_texture = base_key.and_then(|k| load(k, warnings));
        let (texture, role, slot) = match (base_texture, emissive_key) {
            (Some(t), Some(e)) if Some(e) == base_key => {
                (Some(t), TextureRole::Both, "baseColorTexture")
            }
            (Some(t), Some(e)) => {
                // One texture per draw: the emissive image adds its average colour.
                let avg = emissive_only.entry(e).or_insert_with(|| {
                    images[&e.0].clone()?;
                    let (name, bytes, _) = image_bytes(root, views, base, e.0)?;
                    let img = decode(&name, &bytes, e.1, scale.min(1.0 / 16.0))
                        .map_err(|e| format!("image '{name}': {e}"))?;
                    Ok(average_color(&img.rgba))
                });
                match avg {
                    Ok(a) => {
                        emissive = [emissive[0] * a[0], emissive[1] * a[1], emissive[2] * a[2]];
                        warnings.push(format!(
                            "material {i}{}: its emissive texture is drawn as its average colour \
                             beside its base-colour texture (one texture per surface)",
                            name_of(&m.name)
                        ));
                    }
                    Err(e) => warn(e, warnings),
                }
                (Some(t), TextureRole::Base, "baseColorTexture")
            }
            (Some(t), None) => (Some(t), TextureRole::Base, "baseColorTexture"),
            (None, Some(e)) => match load(e, warnings) {
                Some(t) => (Some(t), TextureRole::Emissive, "emissiveTexture"),
                None => (None, TextureRole::Base, ""),
            },
            (None, None) => (None, TextureRole::Base, ""),
        };
        let uv = texture.map(|_| {
            let info = if slot == "emissiveTexture" {
                &mraw["emissiveTexture"]
            } else {
                &mraw["pbrMetallicRoughness"]["baseColorTexture"]
            };
            let set = info["texCoord"].as_u64().unwrap_or(0) as u32;
            let key = if role == TextureRole::Emissive {
                emissive_key
            } else {
                base_key
            };
            let wrap = key.map_or([Wrap::Repeat; 2], |k| k.1);
            uv_map(set, &info["extensions"]["KHR_texture_transform"], wrap)
        });
        let alpha = match m.alpha_mode {
            Checked::Valid(json::material::AlphaMode::Mask) => {
                AlphaMode::Mask(m.alpha_cutoff.map_or(0.5, |c| c.0))
            }
            Checked::Valid(json::material::AlphaMode::Blend) => AlphaMode::Blend,
            _ => AlphaMode::Opaque,
        };
        out.materials.push(Material {
            name: m.name.clone().unwrap_or_default(),
            base_color: pbr.base_color_factor.0,
            texture,
            texture_role: role,
            emissive,
            unlit: mraw["extensions"]["KHR_materials_unlit"].is_object(),
            double_sided: m.double_sided,
            alpha,
        });
        out.uv.push(uv);
    }
    out
}

/// `KHR_texture_transform` (offset, rotation, scale, texCoord) over the texture info's set:
/// `T · R · S` as the extension defines it.
fn uv_map(set: u32, ext: &Value, wrap: [Wrap; 2]) -> UvMap {
    let num = |v: &Value, d: f32| v.as_f64().map_or(d, |x| x as f32);
    let pair = |k: &str, d: f32| [num(&ext[k][0], d), num(&ext[k][1], d)];
    let (o, s) = (pair("offset", 0.0), pair("scale", 1.0));
    let r = num(&ext["rotation"], 0.0);
    let (sin, cos) = r.sin_cos();
    let finite = [o[0], o[1], s[0], s[1], r].iter().all(|x| x.is_finite());
    let transform = if ext.is_object() && finite {
        [
            [cos * s[0], sin * s[1], o[0]],
            [-sin * s[0], cos * s[1], o[1]],
        ]
    } else {
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    };
    let set = ext["texCoord"].as_u64().map_or(set, |s| s as u32);
    UvMap {
        set,
        transform,
        wrap,
    }
}

/// glTF texture `t`'s image index and its sampler's wrap modes: its `source`, else its
/// `EXT_texture_webp` or `KHR_texture_basisu` (KTX2) image. An image only in another
/// extension is an error naming the extension.
fn texture_source(root: &json::Root, raw: &Value, t: usize) -> Result<(usize, [Wrap; 2]), String> {
    let tex = root
        .textures
        .get(t)
        .ok_or_else(|| "does not exist".to_string())?;
    let wrap = tex
        .sampler
        .and_then(|s| root.samplers.get(s.value()))
        .map_or([Wrap::Repeat; 2], |s| [wrap(s.wrap_s), wrap(s.wrap_t)]);
    let traw = &raw["textures"][t];
    if let Some(source) = traw["source"].as_u64() {
        return Ok((source as usize, wrap));
    }
    let ext = &traw["extensions"];
    for image_ext in ["EXT_texture_webp", "KHR_texture_basisu"] {
        if let Some(source) = ext[image_ext]["source"].as_u64() {
            return Ok((source as usize, wrap));
        }
    }
    let names: Vec<&str> = ext
        .as_object()
        .map_or(Vec::new(), |o| o.keys().map(String::as_str).collect());
    Err(match names.as_slice() {
        [] => "it has no image".into(),
        _ => format!(
            "its only image is in {}, which this build does not read",
            names.join(", ")
        ),
    })
}

/// Image `source`'s name, encoded bytes, and a warning when its URI had to be read otherwise
/// to find the file ([`files::find`]). A URI names a file beside the model, never one outside
/// its directory; `%5C` and `\` are read as `/`.
fn image_bytes(
    root: &json::Root,
    views: &Views,
    base: Option<&Path>,
    source: usize,
) -> Result<(String, Vec<u8>, Option<String>), String> {
    let img = root
        .images
        .get(source)
        .ok_or_else(|| format!("image {source} does not exist"))?;
    match (&img.uri, img.buffer_view) {
        (Some(uri), _) if uri.starts_with("data:") => {
            Ok((format!("image {source}"), data_uri(uri)?, None))
        }
        (Some(uri), _) if uri.contains("://") => Err(format!("image '{uri}' is not a local file")),
        (Some(uri), _) => {
            let dir = base.ok_or_else(|| format!("external image '{uri}' without a directory"))?;
            let file = urlencoding::decode(uri)
                .map_err(|_| format!("image URI '{uri}' is not valid UTF-8"))?;
            let found = files::find(dir, &file).map_err(|e| format!("image {e}"))?;
            let bytes =
                std::fs::read(&found.path).map_err(|e| format!("{}: {e}", found.path.display()))?;
            let warning = found.warning.map(|w| format!("image URI {w}"));
            Ok((file.into_owned(), bytes, warning))
        }
        (None, Some(v)) => Ok((
            img.name
                .clone()
                .unwrap_or_else(|| format!("image {source}")),
            views.bytes(v.value())?.to_vec(),
            None,
        )),
        (None, None) => Err(format!("image {source} has neither a URI nor a view")),
    }
}

fn wrap(m: Checked<json::texture::WrappingMode>) -> Wrap {
    match m {
        Checked::Valid(json::texture::WrappingMode::ClampToEdge) => Wrap::Clamp,
        Checked::Valid(json::texture::WrappingMode::MirroredRepeat) => Wrap::Mirror,
        _ => Wrap::Repeat,
    }
}

fn name_of(name: &Option<String>) -> String {
    name.as_deref().map_or(String::new(), |n| format!(" '{n}'"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_transform_is_translation_rotation_scale() {
        let clamp = [Wrap::Clamp; 2];
        let ext = serde_json::json!({"offset": [0.5, 0.0], "scale": [2.0, 3.0], "rotation": 0.0});
        let m = uv_map(0, &ext, clamp);
        assert_eq!(m.coordinates(&[1.0, 1.0]), vec![[2.5, 3.0]]);
        // A quarter turn: (1, 0) goes to (0, -1) as the extension's matrix says.
        let ext = serde_json::json!({"rotation": std::f32::consts::FRAC_PI_2, "texCoord": 1});
        let m = uv_map(0, &ext, clamp);
        let [u, v] = m.coordinates(&[1.0, 0.0])[0];
        assert!(u.abs() < 1e-6 && (v + 1.0).abs() < 1e-6, "{u} {v}");
        assert_eq!(m.set, 1);
        assert_eq!(
            uv_map(2, &Value::Null, clamp).coordinates(&[0.3, 0.4]),
            vec![[0.3, 0.4]]
        );
    }

    #[test]
    fn whole_number_offsets_come_off_as_the_wrap_allows() {
        let far = [100_000.25f32, -7.5, 100_003.0, -6.0];
        let repeat = uv_map(0, &Value::Null, [Wrap::Repeat; 2]);
        assert_eq!(repeat.coordinates(&far), vec![[0.25, 0.5], [3.0, 2.0]]);
        let mirror = uv_map(0, &Value::Null, [Wrap::Mirror, Wrap::Clamp]);
        assert_eq!(mirror.coordinates(&far), vec![[0.25, -7.5], [3.0, -6.0]]);
        let odd = [3.5f32, 0.0];
        assert_eq!(mirror.coordinates(&odd), vec![[1.5, 0.0]]);
    }
}
