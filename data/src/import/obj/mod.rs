//! Wavefront OBJ + MTL import through `tobj`: every OBJ object/group (per material) becomes one
//! definition with one instance (OBJ has no instancing).
//!
//! The text first goes through [`text`] (encodings, continuations, lenient numbers, unnamed
//! materials); `tobj` then parses it one line at a time from a reader that counts lines, so any
//! error it reports names the source line. Positions are read in double precision and moved to
//! the model's local origin ([`crate::bulk::local_origin`]): survey coordinates keep their
//! millimetres. A material library that is missing or unreadable costs only colours (warned).
//! A material's `map_Kd` image (any format the `image` crate reads, TGA included; found beside
//! the library as Windows exporters meant it: [`crate::import::files`]) is its texture, all of
//! a model's scaled to one budget, with `map_d`'s luminance as a cut-out mask; `d` below 1
//! (or `1 − Tr` without `d`) is blending; `Ke` is emitted light. An image that is missing or
//! does not decode is named in a warning and the material keeps its colour. Each object's
//! texture coordinates lose their whole-number offset (the maps repeat).

pub mod text;

use super::frame::{FrameOptions, Piece, pieces_of, settle};
use super::mesh_from_streams;
use crate::bulk::{DBox, bulk, local_origin};
use crate::error::{DataError, Result};
use crate::frame::SourceFrame;
use crate::import::files;
use crate::import::image::{MODEL_TEXELS, decode, dimensions, fit, limit_warning};
use crate::model::{Instance, Material, Model, ObjectDef};
use crate::texture::{AlphaMode, TextureImage, Wrap};
use glam::{DMat4, DVec3, Mat4};
use std::collections::{BTreeMap, HashMap};
use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};

/// Imports an OBJ file (and its MTL library when it loads; a missing MTL only loses colours),
/// in the unit and up axis `options` give or the geometry shows ([`crate::import::frame`]).
pub fn import(path: &Path, options: &FrameOptions) -> Result<Model> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    import_slice(&bytes, path.parent(), options).map_err(|e| DataError::import(path, e))
}

/// Imports OBJ bytes; material libraries are read from `base` (none when `None`). The error is
/// one line naming the source line at fault. OBJ says nothing of its unit or up axis: both
/// come from `options` or from the geometry, and the model is converted to metres, Y up.
pub fn import_slice(
    bytes: &[u8],
    base: Option<&Path>,
    options: &FrameOptions,
) -> Result<Model, String> {
    let (src, encoding) = text::decode(bytes);
    let norm = text::obj(&src)?;
    let mut warnings = Vec::new();
    if let Some(e) = encoding {
        warnings.push(format!("read as {e}"));
    }
    warnings.extend(norm.warnings.iter().cloned());
    let opts = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let mut reader = LineReader::new(norm.text.as_bytes());
    let mtl_warnings = std::cell::RefCell::new(Vec::new());
    let loaded = tobj::load_obj_buf(&mut reader, &opts, |lib| {
        let Some(dir) = base else {
            return Err(tobj::LoadError::OpenFileFailed);
        };
        let file = dir.join(lib);
        let bytes = std::fs::read(&file).map_err(|e| {
            mtl_warnings
                .borrow_mut()
                .push(format!("{}: {e}; materials are white", file.display()));
            tobj::LoadError::OpenFileFailed
        })?;
        let m = text::mtl(&text::decode(&bytes).0);
        mtl_warnings.borrow_mut().extend(
            m.warnings
                .iter()
                .map(|w| format!("{}: {w}", file.display())),
        );
        tobj::load_mtl_buf(&mut m.text.as_bytes()).inspect_err(|e| {
            mtl_warnings
                .borrow_mut()
                .push(format!("{}: {e}; materials are white", file.display()));
        })
    });
    let (models, mtl) = loaded.map_err(|e| format!("line {}: {e}", norm.line(reader.line)))?;
    warnings.extend(mtl_warnings.into_inner());
    let mtl = mtl.unwrap_or_default();
    let mut model = Model {
        materials: vec![Material::default()],
        ..Model::default()
    };
    let maps = material_textures(base, &mtl, &mut model.textures, &mut warnings);
    for (m, (texture, mask)) in mtl.iter().zip(maps) {
        // `d` is opacity; `Tr` (transparency) its complement where `d` is absent. Some
        // exporters write `Tr` as opacity: `Tr 1` alone would hide the surface, so it is read
        // as opaque, with a warning.
        let mut transparency = m
            .unknown_param
            .get("Tr")
            .and_then(|t| t.trim().parse::<f64>().ok());
        if m.dissolve.is_none() && transparency.is_some_and(|t| t >= 0.999) {
            warnings.push(format!(
                "material '{}': 'Tr 1' without 'd' would make it invisible; read as opaque \
                 (some exporters write Tr as opacity)",
                m.name
            ));
            transparency = None;
        }
        let alpha = m
            .dissolve
            .or(transparency.filter(|t| t.is_finite()).map(|t| 1.0 - t))
            .unwrap_or(1.0)
            .clamp(0.0, 1.0) as f32;
        model.materials.push(Material {
            name: m.name.clone(),
            base_color: m.diffuse.map_or([1.0, 1.0, 1.0, alpha], |d| {
                [d[0] as f32, d[1] as f32, d[2] as f32, alpha]
            }),
            texture,
            emissive: m
                .emissive
                .map_or([0.0; 3], |e| e.map(|c| c.max(0.0) as f32)),
            alpha: if mask {
                AlphaMode::Mask(0.5)
            } else if alpha < 1.0 {
                AlphaMode::Blend
            } else {
                AlphaMode::Opaque
            },
            ..Material::default()
        });
    }
    // Positions in f64: the unit and up axis first, then the bulk and its origin in metres,
    // then everything relative to it.
    let objects: Vec<&tobj::Model> = models
        .iter()
        .filter(|m| !m.mesh.indices.is_empty())
        .collect();
    let mut world: Vec<Vec<DVec3>> = objects
        .iter()
        .map(|m| {
            m.mesh
                .positions
                .chunks_exact(3)
                .map(|c| DVec3::new(c[0], c[1], c[2]))
                .collect()
        })
        .collect();
    let pieces: Vec<Piece> = objects
        .iter()
        .zip(&world)
        .flat_map(|(m, p)| pieces_of(p, &m.mesh.indices, &DMat4::IDENTITY))
        .collect();
    let (frame, frame_warnings) = settle(&pieces, &SourceFrame::metres_y_up(), true, options);
    drop(pieces);
    warnings.extend(frame_warnings);
    let to_metres = frame.to_metres_y_up();
    let turn = frame.up.to_y_up();
    if !frame.is_identity() {
        for q in world.iter_mut().flatten() {
            *q = to_metres.transform_point3(*q);
        }
    }
    model.frames.push(frame);
    let boxes: Vec<DBox> = world
        .iter()
        .map(|p| {
            let mut b = DBox::EMPTY;
            p.iter().for_each(|q| b.include(*q));
            b
        })
        .collect();
    let bulk = bulk(&boxes);
    for &s in &bulk.strays {
        warnings.push(format!(
            "object '{}' lies {:.0} m from the rest of the model: it gets a cell of its own",
            objects[s].name,
            boxes[s].distance(&bulk.bounds)
        ));
    }
    let origin = local_origin(&bulk.bounds);
    model.origin = origin.to_array();
    for (m, world) in objects.into_iter().zip(&world) {
        let mesh = &m.mesh;
        let material = mesh.material_id.map_or(0, |i| i as u32 + 1);
        let base = model
            .materials
            .get(material as usize)
            .map_or([1.0; 4], |mat| mat.base_color);
        let positions: Vec<[f32; 3]> = world
            .iter()
            .map(|p| (*p - origin).as_vec3().to_array())
            .collect();
        let normals: Vec<[f32; 3]> = mesh
            .normals
            .chunks_exact(3)
            .map(|c| {
                turn.transform_vector3(DVec3::new(c[0], c[1], c[2]))
                    .as_vec3()
                    .to_array()
            })
            .collect();
        let colors: Vec<[f32; 4]> = if mesh.vertex_color.len() == mesh.positions.len() {
            mesh.vertex_color
                .chunks_exact(3)
                .map(|c| {
                    [
                        c[0] as f32 * base[0],
                        c[1] as f32 * base[1],
                        c[2] as f32 * base[2],
                        base[3],
                    ]
                })
                .collect()
        } else {
            vec![base; positions.len()]
        };
        let normals = (!normals.is_empty()).then_some(normals.as_slice());
        let mut lod = mesh_from_streams(&positions, normals, &colors, mesh.indices.clone())
            .map_err(|e| format!("object '{}': {e}", m.name))?;
        let textured = model
            .materials
            .get(material as usize)
            .is_some_and(|m| m.texture.is_some());
        if textured && mesh.texcoords.len() == mesh.positions.len() / 3 * 2 {
            // OBJ puts v = 0 at the image's bottom; textures here start at the top (glTF).
            // The maps repeat: the whole-number offset comes off in f64 (world-unit tiling).
            let uv: Vec<[f64; 2]> = mesh
                .texcoords
                .chunks_exact(2)
                .map(|c| [c[0], 1.0 - c[1]])
                .collect();
            let floor = |k: usize| {
                let min = uv.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
                if min.is_finite() { min.floor() } else { 0.0 }
            };
            let offset = [floor(0), floor(1)];
            lod.uvs = uv
                .iter()
                .map(|p| [(p[0] - offset[0]) as f32, (p[1] - offset[1]) as f32])
                .collect();
            lod.validate()
                .map_err(|e| format!("object '{}': {e}", m.name))?;
        }
        let def = model.defs.len() as u32;
        model.defs.push(ObjectDef {
            name: m.name.clone(),
            lods: vec![lod],
            material,
        });
        model.instances.push(Instance {
            name: m.name.clone(),
            def,
            transform: Mat4::IDENTITY,
            material,
            occluder: false,
            tags: Default::default(),
        });
    }
    model.warnings = warnings;
    Ok(model)
}

/// Loads the materials' `map_Kd` images (with `map_d` as alpha) into `textures`, all scaled
/// by one factor to the model's texture budget ([`crate::import::image::fit`]): per material,
/// its texture's index and whether it is a cut-out. A map shared by several materials is
/// loaded once, unless one adds its own `map_d` mask. A map that cannot be read costs a
/// warning naming it, and its material is drawn in its colour.
fn material_textures(
    base: Option<&Path>,
    mtl: &[tobj::Material],
    textures: &mut Vec<TextureImage>,
    warnings: &mut Vec<String>,
) -> Vec<(Option<u32>, bool)> {
    // Every named map found and sized first: its file and size (texels), or why it cannot be
    // read.
    type Sized = Result<(PathBuf, (u32, u32)), String>;
    let mut files: BTreeMap<&str, Sized> = BTreeMap::new();
    for m in mtl {
        for file in [&m.diffuse_texture, &m.dissolve_texture]
            .into_iter()
            .flatten()
        {
            files.entry(file.as_str()).or_insert_with(|| {
                let dir = base.ok_or("no directory to read it from")?;
                let (path, warning) = map_path(dir, file)?;
                warnings.extend(warning.map(|w| format!("material '{}': map {w}", m.name)));
                let bytes = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
                let size =
                    dimensions(file, &bytes).map_err(|e| format!("{}: {e}", path.display()))?;
                warnings.extend(limit_warning(file, size));
                Ok((path, size))
            });
        }
    }
    let kd: Vec<(u32, u32)> = mtl
        .iter()
        .filter_map(|m| m.diffuse_texture.as_deref())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .filter_map(|f| files[f].as_ref().ok().map(|r| r.1))
        .collect();
    let (scale, budget) = fit(&kd, MODEL_TEXELS);
    warnings.extend(budget);
    let load = |file: &str, scale: f64| -> Result<TextureImage, String> {
        let (path, _) = files[file].clone()?;
        let bytes = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        decode(file, &bytes, [Wrap::Repeat; 2], scale)
            .map_err(|e| format!("{}: {e}", path.display()))
    };
    let mut shared: HashMap<&str, u32> = HashMap::new();
    let mut out = Vec::with_capacity(mtl.len());
    for m in mtl {
        let Some(file) = m.diffuse_texture.as_deref() else {
            out.push((None, false));
            continue;
        };
        if m.dissolve_texture.is_none()
            && let Some(&i) = shared.get(file)
        {
            out.push((Some(i), false));
            continue;
        }
        let mut img = match load(file, scale) {
            Ok(img) => img,
            Err(e) => {
                warnings.push(format!(
                    "material '{}': map_Kd {e}; drawn in its colour",
                    m.name
                ));
                out.push((None, false));
                continue;
            }
        };
        let mut mask = false;
        if let Some(d) = &m.dissolve_texture {
            match load(d, scale) {
                Ok(a) => {
                    let a = image::DynamicImage::from(
                        image::RgbaImage::from_raw(a.width, a.height, a.rgba).unwrap_or_default(),
                    )
                    .resize_exact(img.width, img.height, image::imageops::FilterType::Triangle)
                    .into_rgba8();
                    for (p, q) in img.rgba.chunks_exact_mut(4).zip(a.pixels()) {
                        p[3] = ((q[0] as u32 + q[1] as u32 + q[2] as u32) / 3) as u8;
                    }
                    mask = true;
                }
                Err(e) => warnings.push(format!("material '{}': map_d {e}; opaque", m.name)),
            }
        }
        textures.push(img);
        let i = textures.len() as u32 - 1;
        if !mask {
            shared.insert(file, i);
        }
        out.push((Some(i), mask));
    }
    out
}

/// A map statement's file beside the library ([`files::find`]: `\` read as `/`, any case):
/// the whole text, else its last word (after options such as `-s 1 1 1` or `-bm 0.5`), each
/// as written, else its bare file name in the library's directory; the first found, with the
/// warning saying how it was found.
fn map_path(dir: &Path, file: &str) -> Result<(PathBuf, Option<String>), String> {
    let last = file.split_whitespace().last().unwrap_or(file);
    let mut first_error = None;
    for f in [file.trim(), last] {
        let bare = f.rsplit(['/', '\\']).next().unwrap_or(f);
        for candidate in [f, bare] {
            match files::find(dir, candidate) {
                Ok(found) => {
                    // MTL names are Windows paths: only a difference in case is news.
                    let warning = match (candidate == f, found.warning) {
                        (true, w) => w.filter(|_| found.case_differs),
                        (false, _) => Some(format!(
                            "'{f}' not found as written: read as '{}' beside the library",
                            found
                                .path
                                .file_name()
                                .map_or(String::new(), |n| n.to_string_lossy().into_owned())
                        )),
                    };
                    return Ok((found.path, warning));
                }
                Err(e) => {
                    first_error.get_or_insert(e);
                }
            }
        }
    }
    Err(first_error.unwrap_or_else(|| format!("'{file}' not found")))
}

/// A reader that hands out at most one line per `fill_buf`, so that when the parser fails,
/// `line` is the 0-based index of the line it was reading.
struct LineReader<'a> {
    text: &'a [u8],
    pos: usize,
    newlines: usize,
    /// Index of the line the last `fill_buf` started in.
    line: usize,
}

impl<'a> LineReader<'a> {
    fn new(text: &'a [u8]) -> Self {
        LineReader {
            text,
            pos: 0,
            newlines: 0,
            line: 0,
        }
    }
}

impl Read for LineReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let chunk = self.fill_buf()?;
        let n = chunk.len().min(buf.len());
        buf[..n].copy_from_slice(&chunk[..n]);
        self.consume(n);
        Ok(n)
    }
}

impl BufRead for LineReader<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        if self.pos == 0 || self.text.get(self.pos - 1) == Some(&b'\n') {
            self.line = self.newlines;
        }
        let rest = &self.text[self.pos..];
        let end = rest
            .iter()
            .position(|&b| b == b'\n')
            .map_or(rest.len(), |i| i + 1);
        Ok(&rest[..end])
    }

    fn consume(&mut self, amt: usize) {
        let amt = amt.min(self.text.len() - self.pos);
        self.newlines += self.text[self.pos..self.pos + amt]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        self.pos += amt;
    }
}
