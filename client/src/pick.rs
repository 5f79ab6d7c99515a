//! The object under a pixel: the ray from the eye through the pixel (the frame's
//! view-projection inverted) against the world boxes of the instances the frame drew, the
//! nearest box it enters first. A box is an object's bounds, so a click beside a thin diagonal
//! object may still name it; only what was drawn can be named, and a box holding the eye (a
//! room-sized object one stands in) is looked past.

use glam::{Mat4, Vec3, Vec4};
use portico_data::format::Header;
use portico_data::geometry::{Aabb, slab};
use serde::Serialize;

/// What a pick names: the object's identity from its source (a BIM export's class, storey and
/// GUID are kept as tags by the importers) and what is drawn of it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Picked {
    /// Index into the header's instances.
    pub instance: u32,
    /// Name from the source.
    pub name: String,
    /// Its class: the IFC entity (`ifc_class`) or the source's `kind` tag, if either is there.
    pub class: Option<String>,
    /// The storey it stands on (`storey` tag), if known.
    pub storey: Option<String>,
    /// The IFC GlobalId (`guid` tag), if any.
    pub guid: Option<String>,
    /// Every tag from the source, sorted by key.
    pub tags: Vec<(String, String)>,
    /// The LOD drawn (0 = finest) of how many.
    pub lod: usize,
    /// How many LODs it has.
    pub lods: usize,
    /// Triangles of the LOD drawn.
    pub triangles: u32,
    /// Bytes the drawn LOD holds on the GPU.
    pub bytes: u64,
    /// Distance along the ray to its box (metres).
    pub distance: f32,
}

impl Picked {
    /// Instance `instance` of `header`, drawn at `lod` holding `bytes`, `distance` metres away.
    /// `None` if the header has no such instance.
    pub fn of(
        header: &Header,
        instance: u32,
        lod: usize,
        bytes: u64,
        distance: f32,
    ) -> Option<Picked> {
        let inst = header.instances.get(instance as usize)?;
        let lods = header.lods_of(inst);
        let tag = |k: &str| inst.tag(k).map(str::to_string);
        Some(Picked {
            instance,
            name: inst.name.clone(),
            class: tag("ifc_class").or_else(|| tag("kind")),
            storey: tag("storey"),
            guid: tag("guid"),
            tags: inst.tags.clone(),
            lod,
            lods: lods.len(),
            triangles: lods.get(lod).map_or(0, |l| l.triangles),
            bytes,
            distance,
        })
    }

    /// The lines a pick panel shows.
    pub fn lines(&self) -> String {
        let mut t = if self.name.is_empty() {
            format!("object {}", self.instance)
        } else {
            self.name.clone()
        };
        for (k, v) in [
            ("class", &self.class),
            ("storey", &self.storey),
            ("GUID", &self.guid),
        ] {
            if let Some(v) = v {
                t += &format!("\n{k}: {v}");
            }
        }
        t += &format!(
            "\nLOD {} of {} ({} triangles, {:.1} KB), {:.1} m away",
            self.lod + 1,
            self.lods,
            self.triangles,
            self.bytes as f64 / 1e3,
            self.distance
        );
        t
    }
}

/// The ray (origin on the near plane, unit direction) through the point `ndc` of the image,
/// each coordinate -1..1 (x right, y up), of a frame drawn with `view_proj` (depth 0..1, as
/// [`crate::view::Camera::view_proj`] makes it). `None` if `view_proj` cannot be inverted.
pub fn ray(view_proj: &Mat4, ndc: [f32; 2]) -> Option<(Vec3, Vec3)> {
    if view_proj.determinant().abs() < f32::MIN_POSITIVE {
        return None;
    }
    let inv = view_proj.inverse();
    let at = |z: f32| {
        let p = inv * Vec4::new(ndc[0], ndc[1], z, 1.0);
        (p.w.abs() > f32::MIN_POSITIVE).then(|| p.truncate() / p.w)
    };
    let (near, far) = (at(0.0)?, at(1.0)?);
    let dir = (far - near).try_normalize()?;
    Some((near, dir))
}

/// The object among `boxes` (an id and its world box: the instances the frame drew) whose box
/// the ray from `origin` along `dir` enters first, and how far along the ray (metres) it does.
pub fn pick<'a>(
    boxes: impl IntoIterator<Item = (u32, &'a Aabb)>,
    origin: Vec3,
    dir: Vec3,
) -> Option<(u32, f32)> {
    boxes
        .into_iter()
        .filter_map(|(i, b)| {
            let (t0, t1) = slab(origin, dir, b)?;
            (t0 >= 0.0 && t1 >= t0).then_some((i, t0))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::Camera;

    fn pick_in(boxes: &[Aabb], drawn: &[u32], o: Vec3, d: Vec3) -> Option<(u32, f32)> {
        pick(drawn.iter().map(|&i| (i, &boxes[i as usize])), o, d)
    }

    #[test]
    fn the_nearest_box_under_the_pixel_is_picked() {
        let camera = Camera {
            eye: Vec3::ZERO,
            target: Vec3::X,
            up: Vec3::Y,
            fovy: 1.0,
            near: 0.1,
            far: 100.0,
        };
        let vp = camera.view_proj(1.0);
        let (o, d) = ray(&vp, [0.0, 0.0]).unwrap();
        assert!(
            (d - Vec3::X).length() < 1e-4 && (o - Vec3::X * 0.1).length() < 1e-3,
            "{o} {d}"
        );
        let near = Aabb {
            min: [2.0, -0.5, -0.5],
            max: [2.5, 0.5, 0.5],
        };
        let far = Aabb {
            min: [5.0, -2.0, -2.0],
            max: [6.0, 2.0, 2.0],
        };
        let around = Aabb {
            min: [-10.0; 3],
            max: [10.0; 3],
        };
        let up = Aabb {
            min: [2.0, 0.52, -0.5],
            max: [2.5, 0.8, 0.5],
        };
        let h = [far, near, around, up];
        // Straight ahead: the near box, not the far one behind it nor the one holding the eye.
        assert_eq!(pick_in(&h, &[0, 1, 2, 3], o, d).map(|p| p.0), Some(1));
        // Only what was drawn.
        assert_eq!(pick_in(&h, &[0, 2, 3], o, d).map(|p| p.0), Some(0));
        // Up in the image: the box above.
        let (o, d) = ray(&vp, [0.0, 0.5]).unwrap();
        assert_eq!(pick_in(&h, &[0, 1, 2, 3], o, d).map(|p| p.0), Some(3));
        // Beside everything: nothing.
        let (o, d) = ray(&vp, [-0.99, 0.0]).unwrap();
        assert_eq!(pick_in(&h, &[1, 3], o, d), None);
    }
}
