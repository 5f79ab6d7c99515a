//! glTF materials (glTF 2.0 §3.9): the base colour factor, the base-colour texture with its
//! sampler's wrap modes and `KHR_texture_transform`, and the alpha mode. Images come from
//! `data:` URIs, files beside the model or buffer views (GLB), as PNG or JPEG. An image that is
//! missing or does not decode is named in a warning and its material keeps its base colour:
//! never a failed import.

use super::buffers::{Views, data_uri};
use crate::import::image::decode;
use crate::model::Material;
use crate::texture::{AlphaMode, TextureImage, Wrap};
use ::gltf::json;
use json::validation::Checked;
use serde_json::Value;
use std::collections::HashMap;
use std::path::Path;

/// How a textured material maps a primitive's coordinates onto its image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct UvMap {
    /// Which `TEXCOORD_n` set.
    pub set: u32,
    /// `KHR_texture_transform` as a 2 × 3 matrix (rows), identity without it.
    pub transform: [[f32; 3]; 2],
}

impl UvMap {
    /// The coordinate after the transform.
    pub fn apply(&self, uv: [f32; 2]) -> [f32; 2] {
        let [a, b] = self.transform;
        [
            a[0] * uv[0] + a[1] * uv[1] + a[2],
            b[0] * uv[0] + b[1] * uv[1] + b[2],
        ]
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

/// Reads every material, decoding each texture they use once.
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
    // Decoded once per image and wrap mode, however many textures name it.
    let mut decoded: HashMap<(usize, [Wrap; 2]), Option<u32>> = HashMap::new();
    let mut texels = 0u64;
    for (i, m) in root.materials.iter().enumerate() {
        let pbr = &m.pbr_metallic_roughness;
        let alpha = match m.alpha_mode {
            Checked::Valid(json::material::AlphaMode::Mask) => {
                AlphaMode::Mask(m.alpha_cutoff.map_or(0.5, |c| c.0))
            }
            Checked::Valid(json::material::AlphaMode::Blend) => AlphaMode::Blend,
            _ => AlphaMode::Opaque,
        };
        let mut texture = None;
        let mut uv = None;
        if let Some(info) = &pbr.base_color_texture {
            let t = info.index.value();
            let warn = |e: String, warnings: &mut Vec<String>| {
                warnings.push(format!(
                    "material {i}{}: texture {t}: {e}; drawn in its base colour",
                    name_of(&m.name)
                ));
            };
            let index = match texture_source(root, raw, t) {
                Err(e) => {
                    warn(e, warnings);
                    None
                }
                Ok(key) => *decoded.entry(key).or_insert_with(|| {
                    let img = texture_image(root, views, base, key.0, key.1).and_then(|img| {
                        texels += img.width as u64 * img.height as u64;
                        if texels > MAX_MODEL_TEXELS {
                            return Err(format!(
                                "the model's textures pass {} M texels",
                                MAX_MODEL_TEXELS >> 20
                            ));
                        }
                        Ok(img)
                    });
                    match img {
                        Ok(img) => {
                            out.textures.push(img);
                            Some(out.textures.len() as u32 - 1)
                        }
                        Err(e) => {
                            warn(e, warnings);
                            None
                        }
                    }
                }),
            };
            if index.is_some() {
                let ext = &raw["materials"][i]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"]
                    ["KHR_texture_transform"];
                uv = Some(uv_map(info.tex_coord, ext));
                texture = index;
            }
        }
        out.materials.push(Material {
            name: m.name.clone().unwrap_or_default(),
            base_color: pbr.base_color_factor.0,
            texture,
            alpha,
        });
        out.uv.push(uv);
    }
    out
}

/// `KHR_texture_transform` (offset, rotation, scale, texCoord) over the texture info's set:
/// `T · R · S` as the extension defines it.
fn uv_map(set: u32, ext: &Value) -> UvMap {
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
    UvMap { set, transform }
}

/// Texels all of a model's textures may hold together (1 GiB decoded): past it, textures are
/// left out with a warning.
const MAX_MODEL_TEXELS: u64 = 256 << 20;

/// glTF texture `t`'s image index and its sampler's wrap modes.
fn texture_source(root: &json::Root, raw: &Value, t: usize) -> Result<(usize, [Wrap; 2]), String> {
    let tex = root
        .textures
        .get(t)
        .ok_or_else(|| "does not exist".to_string())?;
    let wrap = tex
        .sampler
        .and_then(|s| root.samplers.get(s.value()))
        .map_or([Wrap::Repeat; 2], |s| [wrap(s.wrap_s), wrap(s.wrap_t)]);
    // A texture whose only image is in an extension (WebP, KTX2) has no `source`.
    let source = raw["textures"][t]["source"]
        .as_u64()
        .ok_or("its image is in a format this build does not read (no PNG or JPEG source)")?
        as usize;
    Ok((source, wrap))
}

/// Decodes image `source` to be sampled with `wrap`. A URI may name a file beside the model,
/// never one outside its directory.
fn texture_image(
    root: &json::Root,
    views: &Views,
    base: Option<&Path>,
    source: usize,
    wrap: [Wrap; 2],
) -> Result<TextureImage, String> {
    let img = root
        .images
        .get(source)
        .ok_or_else(|| format!("image {source} does not exist"))?;
    let (name, bytes) = match (&img.uri, img.buffer_view) {
        (Some(uri), _) if uri.starts_with("data:") => (format!("image {source}"), data_uri(uri)?),
        (Some(uri), _) if uri.contains("://") => {
            return Err(format!("image '{uri}' is not a local file"));
        }
        (Some(uri), _) => {
            let dir = base.ok_or_else(|| format!("external image '{uri}' without a directory"))?;
            let file = urlencoding::decode(uri)
                .map_err(|_| format!("image URI '{uri}' is not valid UTF-8"))?;
            let rel = Path::new(file.as_ref());
            if rel.is_absolute()
                || rel
                    .components()
                    .any(|c| c == std::path::Component::ParentDir)
            {
                return Err(format!("image '{uri}' lies outside the model's directory"));
            }
            let path = dir.join(rel);
            let bytes = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            (file.into_owned(), bytes)
        }
        (None, Some(v)) => (
            img.name
                .clone()
                .unwrap_or_else(|| format!("image {source}")),
            views.bytes(v.value())?.to_vec(),
        ),
        (None, None) => return Err(format!("image {source} has neither a URI nor a view")),
    };
    decode(&name, &bytes, wrap).map_err(|e| format!("image '{name}': {e}"))
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
        let ext = serde_json::json!({"offset": [0.5, 0.0], "scale": [2.0, 3.0], "rotation": 0.0});
        let m = uv_map(0, &ext);
        assert_eq!(m.apply([1.0, 1.0]), [2.5, 3.0]);
        // A quarter turn: (1, 0) goes to (0, -1) as the extension's matrix says.
        let ext = serde_json::json!({"rotation": std::f32::consts::FRAC_PI_2, "texCoord": 1});
        let m = uv_map(0, &ext);
        let [u, v] = m.apply([1.0, 0.0]);
        assert!(u.abs() < 1e-6 && (v + 1.0).abs() < 1e-6, "{u} {v}");
        assert_eq!(m.set, 1);
        assert_eq!(uv_map(2, &Value::Null).apply([0.3, 0.4]), [0.3, 0.4]);
    }
}
