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

/// Mean absolute difference of two images per colour channel (0–255); `f64::INFINITY` when
/// their sizes differ.
pub fn mean_difference(a: &RgbaImage, b: &RgbaImage) -> f64 {
    if a.dimensions() != b.dimensions() {
        return f64::INFINITY;
    }
    let sum: u64 = a
        .pixels()
        .zip(b.pixels())
        .map(|(p, q)| (0..3).map(|k| p[k].abs_diff(q[k]) as u64).sum::<u64>())
        .sum();
    sum as f64 / (3 * a.width() as u64 * a.height() as u64).max(1) as f64
}

/// At most `want` of `images` for a contact sheet, in order: an image that differs from the
/// last one kept by less than `min_difference` ([`mean_difference`]) is dropped (a walk that
/// stands still or turns slowly repeats itself), then `want` are taken evenly from the rest.
pub fn distinct(images: Vec<RgbaImage>, want: usize, min_difference: f64) -> Vec<RgbaImage> {
    let mut kept: Vec<RgbaImage> = Vec::new();
    for img in images {
        if kept
            .last()
            .is_none_or(|last| mean_difference(last, &img) >= min_difference)
        {
            kept.push(img);
        }
    }
    if kept.len() <= want {
        return kept;
    }
    let n = kept.len();
    let picks: Vec<usize> = (0..want).map(|i| i * (n - 1) / (want - 1).max(1)).collect();
    kept.into_iter()
        .enumerate()
        .filter(|(i, _)| picks.contains(i))
        .map(|(_, img)| img)
        .collect()
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

/// Colours of the bird's-eye view's markers (linear RGBA): the path every half second, its
/// start and its end.
pub const PATH_COLOUR: [f32; 4] = [1.0, 0.1, 0.1, 1.0];
/// See [`PATH_COLOUR`].
pub const START_COLOUR: [f32; 4] = [0.1, 0.8, 0.1, 1.0];
/// See [`PATH_COLOUR`].
pub const END_COLOUR: [f32; 4] = [0.1, 0.3, 1.0, 1.0];

/// A bird's-eye view and its scale.
#[derive(Debug)]
pub struct Birdseye {
    /// The picture (the renderer's size).
    pub image: RgbaImage,
    /// Metres of the model per pixel of the picture (the view is orthographic).
    pub metres_per_pixel: f32,
}

/// Renders the storey the path starts on from above (orthographic, everything above eye height
/// left out so ceilings and upper floors do not hide it), with markers along the path
/// ([`PATH_COLOUR`]) and at its start and end.
pub fn birdseye(r: &mut Renderer, db: &Database, path: &CameraPath) -> Result<Birdseye> {
    let h = db.header();
    let (start, _) = path.sample(0.0);
    let cut = start.y + 0.2;
    let mut meshes = Vec::new();
    for (i, inst) in (0u32..)
        .zip(&h.instances)
        .filter(|(_, i)| i.bounds.min[1] < cut)
    {
        let Some(lod) = h.lods_of(inst).first() else {
            continue;
        };
        let bytes = db.geometry(lod)?;
        // Finest LODs without their textures: a textured object in its texture's average.
        let color = portico_client::frame::material_of(h, i, 0, &|_| false).1;
        meshes.push((
            r.upload(&bytes)?,
            Mat4::from_cols_array(&inst.transform),
            color,
        ));
    }
    let marker = r.upload(&encode_geometry(&cube()))?;
    let steps = (path.duration() * 2.0).ceil().max(1.0) as usize;
    let mark = |t: f32, size: f32, lift: f32| {
        let (p, _) = path.sample(t);
        Mat4::from_translation(Vec3::new(p.x, cut + 1.0 + lift, p.z))
            * Mat4::from_scale(Vec3::new(size, 0.1, size))
    };
    let mut marks: Vec<(Mat4, [f32; 4])> = (0..=steps)
        .map(|i| {
            let t = path.duration() * i as f32 / steps as f32;
            (mark(t, 0.4, 0.0), PATH_COLOUR)
        })
        .collect();
    marks.push((mark(0.0, 1.2, 0.2), START_COLOUR));
    marks.push((mark(path.duration(), 1.2, 0.2), END_COLOUR));
    let mut draws: Vec<Draw> = meshes
        .iter()
        .map(|(m, t, c)| Draw::new(m, *t, *c))
        .collect();
    draws.extend(marks.iter().map(|(t, c)| Draw::new(&marker, *t, *c)));
    let (view_proj, half_w) = top_down(db, cut, r.aspect());
    let image = r
        .picture_view_proj(view_proj, &draws, &[])
        .context("bird's-eye render")?;
    let metres_per_pixel = 2.0 * half_w / image.width().max(1) as f32;
    Ok(Birdseye {
        image,
        metres_per_pixel,
    })
}

/// Orthographic view straight down onto the model's footprint, and its half width in metres.
fn top_down(db: &Database, cut: f32, aspect: f32) -> (Mat4, f32) {
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
    (proj * view, half_w)
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
    fn repeated_frames_are_left_off_the_sheet() {
        let grey = |v: u8| RgbaImage::from_pixel(8, 8, image::Rgba([v, v, v, 255]));
        let frames = vec![grey(10), grey(10), grey(11), grey(60), grey(60), grey(120)];
        let kept = distinct(frames, 12, 2.0);
        let values: Vec<u8> = kept.iter().map(|i| i.get_pixel(0, 0)[0]).collect();
        assert_eq!(values, vec![10, 60, 120]);
        // Evenly taken when more remain than wanted: first and last always.
        let many: Vec<RgbaImage> = (0..10).map(|i| grey(i * 20)).collect();
        let values: Vec<u8> = distinct(many, 4, 2.0)
            .iter()
            .map(|i| i.get_pixel(0, 0)[0])
            .collect();
        assert_eq!(values, vec![0, 60, 120, 180]);
        assert_eq!(mean_difference(&grey(0), &grey(30)), 30.0);
    }

    #[test]
    fn the_cube_is_closed_and_unit_sized() {
        let c = cube();
        assert_eq!((c.vertices.len(), c.indices.len()), (24, 36));
        let b = c.bounds();
        assert_eq!((b.min, b.max), ([-0.5; 3], [0.5; 3]));
    }
}
