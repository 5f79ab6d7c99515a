//! Pictures for reports: a contact sheet of walk frames, and a bird's-eye view of the storey a
//! path walks through with the path marked on it (Funkhouser Fig. 3.27's debugging view).

use crate::{Draw, Renderer};
use anyhow::{Context, Result};
use glam::{Mat4, Vec3};
use image::RgbaImage;
use portico_data::Database;
use portico_data::geometry::{Aabb, Mesh, encode_geometry};
use portico_data::path::CameraPath;

/// Tiles images (scaled to `thumb_w` wide) into a grid of `cols` columns.
pub fn contact_sheet(images: &[RgbaImage], cols: u32, thumb_w: u32) -> Option<RgbaImage> {
    let first = images.first()?;
    let thumb_h =
        (thumb_w as u64 * first.height() as u64 / first.width().max(1) as u64).max(1) as u32;
    let cols = cols.max(1);
    let rows = (images.len() as u32).div_ceil(cols);
    let gap = 4;
    let mut sheet = RgbaImage::from_pixel(
        cols * (thumb_w + gap) + gap,
        rows * (thumb_h + gap) + gap,
        image::Rgba([32, 32, 32, 255]),
    );
    for (i, img) in images.iter().enumerate() {
        let t =
            image::imageops::resize(img, thumb_w, thumb_h, image::imageops::FilterType::Triangle);
        let (c, r) = (i as u32 % cols, i as u32 / cols);
        image::imageops::overlay(
            &mut sheet,
            &t,
            (gap + c * (thumb_w + gap)) as i64,
            (gap + r * (thumb_h + gap)) as i64,
        );
    }
    Some(sheet)
}

/// A unit cube centred on the origin, for path markers (white, unlit: the draw's colour
/// shows as it is).
fn cube() -> Mesh {
    let unit = Aabb {
        min: [-0.5; 3],
        max: [0.5; 3],
    };
    portico_data::hierarchy::colour_box(&unit, &[[1.0; 4]; 6])
}

/// Renders the storey the path starts on from above (orthographic, everything above eye height
/// left out so ceilings and upper floors do not hide it), with red markers along the path.
pub fn birdseye(r: &mut Renderer, db: &Database, path: &CameraPath) -> Result<RgbaImage> {
    let h = db.header();
    let (start, _) = path.sample(0.0);
    let cut = start.y + 0.2;
    let mut meshes = Vec::new();
    for inst in h.instances.iter().filter(|i| i.bounds.min[1] < cut) {
        let Some(lod) = h.lods_of(inst).first() else {
            continue;
        };
        let bytes = db.geometry(lod)?;
        let color = h
            .materials
            .get(inst.material as usize)
            .map_or([1.0; 4], |m| m.base_color);
        meshes.push((
            r.upload(&bytes)?,
            Mat4::from_cols_array(&inst.transform),
            color,
        ));
    }
    let marker = r.upload(&encode_geometry(&cube()))?;
    let steps = (path.duration() * 2.0).ceil().max(1.0) as usize;
    let marks: Vec<Mat4> = (0..=steps)
        .map(|i| {
            let (p, _) = path.sample(path.duration() * i as f32 / steps as f32);
            Mat4::from_translation(Vec3::new(p.x, cut + 1.0, p.z))
                * Mat4::from_scale(Vec3::new(0.4, 0.1, 0.4))
        })
        .collect();
    let mut draws: Vec<Draw> = meshes
        .iter()
        .map(|(m, t, c)| Draw {
            mesh: m,
            transform: *t,
            color: *c,
        })
        .collect();
    draws.extend(marks.iter().map(|t| Draw {
        mesh: &marker,
        transform: *t,
        color: [1.0, 0.1, 0.1, 1.0],
    }));
    r.render_view_proj(top_down(db, cut, r.aspect()), &draws)
        .context("bird's-eye render")?;
    Ok(r.read_pixels()?)
}

/// Orthographic view straight down onto the model's footprint.
fn top_down(db: &Database, cut: f32, aspect: f32) -> Mat4 {
    let b = db.header().bounds;
    let centre = Vec3::new(
        (b.min[0] + b.max[0]) * 0.5,
        cut + 50.0,
        (b.min[2] + b.max[2]) * 0.5,
    );
    let (w, d) = ((b.max[0] - b.min[0]) * 0.55, (b.max[2] - b.min[2]) * 0.55);
    let half_h = d.max(w / aspect).max(1.0);
    let half_w = half_h * aspect;
    let view = glam::camera::rh::view::look_at_mat4(centre, centre - Vec3::Y, Vec3::NEG_Z);
    let proj = glam::camera::rh::proj::directx::orthographic(
        -half_w,
        half_w,
        -half_h,
        half_h,
        0.1,
        50.0 + cut - b.min[1] + 1.0,
    );
    proj * view
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_contact_sheet_tiles_thumbnails() {
        let imgs: Vec<RgbaImage> = (0..5)
            .map(|i| RgbaImage::from_pixel(40, 30, image::Rgba([i * 50, 0, 0, 255])))
            .collect();
        let s = contact_sheet(&imgs, 3, 20).unwrap();
        assert_eq!((s.width(), s.height()), (3 * 24 + 4, 2 * 19 + 4));
        assert_eq!(
            s.get_pixel(4 + 24 + 5, 4 + 5)[0],
            50,
            "second thumbnail in place"
        );
        assert!(contact_sheet(&[], 3, 20).is_none());
    }

    #[test]
    fn the_cube_is_closed_and_unit_sized() {
        let c = cube();
        assert_eq!((c.vertices.len(), c.indices.len()), (24, 36));
        let b = c.bounds();
        assert_eq!((b.min, b.max), ([-0.5; 3], [0.5; 3]));
    }
}
