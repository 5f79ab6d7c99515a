//! Painting impostors at build time (Maciel §5.2.2): each face of a cluster's box is an
//! orthographic view of the real objects beneath it, drawn with the walkthrough renderer on a
//! transparent background, so the textured box shows what the objects would show from far away
//! and lets what is behind its gaps show through; textured objects are painted with their
//! textures. `portico build` hands a [`Painter`] to
//! [`portico_data::build::build_with`].

use crate::{Draw, GpuMesh, GpuTexture, RenderError, Renderer};
use glam::{Mat4, Vec3};
use image::RgbaImage;
use portico_data::geometry::{Aabb, encode_geometry};
use portico_data::hierarchy::{FACES, ImpostorPainter, PaintItem, face_frame};
use portico_data::texture::{cut_segments, mip_chain};
use std::collections::HashMap;

/// The build-time impostor painter: a renderer, and every geometry and texture it has
/// uploaded.
pub struct Painter {
    renderer: Renderer,
    meshes: HashMap<(u32, u32), GpuMesh>,
    textures: HashMap<u32, GpuTexture>,
    tile: u32,
}

impl Painter {
    /// A painter on the default adapter (llvmpipe where there is no GPU).
    pub fn new() -> Result<Painter, RenderError> {
        let mut renderer = Renderer::new(16, 16)?;
        renderer.set_clear(wgpu::Color::TRANSPARENT);
        Ok(Painter {
            renderer,
            meshes: HashMap::new(),
            textures: HashMap::new(),
            tile: 16,
        })
    }

    /// The adapter it paints with.
    pub fn adapter_info(&self) -> String {
        self.renderer.adapter_info()
    }

    /// One face's view of `items` (a `tile` × `tile` image).
    fn face(
        &mut self,
        items: &[PaintItem<'_>],
        b: &Aabb,
        face: usize,
    ) -> Result<RgbaImage, String> {
        let draws: Vec<Draw<'_>> = items
            .iter()
            .filter_map(|it| {
                Some(Draw {
                    mesh: self.meshes.get(&it.key)?,
                    transform: it.transform,
                    color: it.color,
                    texture: it.texture.and_then(|(t, _)| self.textures.get(&t)),
                    alpha: it.alpha,
                    surface: it.surface,
                })
            })
            .collect();
        self.renderer
            .render_view_proj(face_view(b, face), &draws)
            .map_err(|e| e.to_string())?;
        self.renderer.read_pixels().map_err(|e| e.to_string())
    }
}

impl ImpostorPainter for Painter {
    fn paint(
        &mut self,
        items: &[PaintItem<'_>],
        bounds: &Aabb,
        tile: u32,
    ) -> Result<(Vec<u8>, [[f32; 4]; 6]), String> {
        if tile != self.tile {
            self.renderer
                .resize(tile, tile)
                .map_err(|e| e.to_string())?;
            self.tile = tile;
        }
        for it in items {
            if !self.meshes.contains_key(&it.key) {
                let gpu = self
                    .renderer
                    .upload(&encode_geometry(it.mesh))
                    .map_err(|e| e.to_string())?;
                self.meshes.insert(it.key, gpu);
            }
            if let Some((t, img)) = it.texture
                && !self.textures.contains_key(&t)
            {
                // The whole chain in one texture: the finest segment holds every level.
                let chain = mip_chain(img.width, img.height, &img.rgba);
                let finest = cut_segments(img.width, img.height, &chain).pop();
                let Some((_, _, _, bytes)) = finest else {
                    continue;
                };
                let gpu = self
                    .renderer
                    .upload_texture(&bytes, img.wrap)
                    .map_err(|e| e.to_string())?;
                self.textures.insert(t, gpu);
            }
        }
        let mut atlas = RgbaImage::new(tile * 3, tile * 2);
        let mut colors = [[0.0f32; 4]; 6];
        for (face, color) in colors.iter_mut().enumerate().take(FACES.len()) {
            let view = self.face(items, bounds, face)?;
            *color = average_color(&view);
            let (x, y) = ((face % 3) as u32 * tile, (face / 3) as u32 * tile);
            image::imageops::replace(&mut atlas, &view, i64::from(x), i64::from(y));
        }
        Ok((encode_png(&atlas)?, colors))
    }
}

/// The orthographic view of face `face` of `b` from outside: the face fills the image exactly,
/// oriented as [`face_frame`] says, and the whole depth of the box is inside the clip volume.
pub fn face_view(b: &Aabb, face: usize) -> Mat4 {
    let (n, right, up) = face_frame(face);
    let size = b.size().max(Vec3::splat(1e-3));
    let (hx, hy, hz) = (
        right.abs().dot(size) * 0.5,
        up.abs().dot(size) * 0.5,
        n.abs().dot(size) * 0.5,
    );
    let c = b.center();
    let eye = c + n * (hz + 1.0);
    let view = glam::camera::rh::view::look_at_mat4(eye, c, up);
    let proj = glam::camera::rh::proj::directx::orthographic(-hx, hx, -hy, hy, 0.5, 2.0 * hz + 1.5);
    proj * view
}

/// Mean linear colour of the covered pixels, alpha = the covered fraction.
pub fn average_color(img: &RgbaImage) -> [f32; 4] {
    let to_linear = |c: u8| {
        let c = f32::from(c) / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let mut sum = [0.0f32; 3];
    let mut covered = 0u32;
    for p in img.pixels().filter(|p| p[3] >= 128) {
        for k in 0..3 {
            sum[k] += to_linear(p[k]);
        }
        covered += 1;
    }
    let n = covered.max(1) as f32;
    let total = (img.width() * img.height()).max(1) as f32;
    [sum[0] / n, sum[1] / n, sum[2] / n, covered as f32 / total]
}

fn encode_png(img: &RgbaImage) -> Result<Vec<u8>, String> {
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}
