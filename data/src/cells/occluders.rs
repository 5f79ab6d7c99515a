//! The occluders the subdivision splits along: axis-aligned rectangles (flat boxes).
//!
//! An occluder instance (tagged `occluder` by its source, like the generator's walls, floors
//! and ceilings) is usually a union of boxes — a wall with a door is three — whose surfaces are
//! axis-aligned quads. Every pair of triangles of its finest mesh that lies in one axis-aligned
//! plane and exactly fills its common bounding rectangle is such a face; the faces become
//! occluders in world space, provided the instance transform keeps them axis-aligned (scales,
//! rotations by multiples of 90°, shifts). Anything else is not used as an occluder: fewer
//! occluders only means less culling, never a wrong answer.
//!
//! Untagged models (any imported file) get automatic occluders: faces of any instance with both
//! extents at least [`AUTO_MIN_EXTENT`] — slabs and walls.

use crate::geometry::{Aabb, Mesh};
use glam::{Mat4, Vec3};
use std::collections::HashMap;

/// Automatic occluders must be at least this large in two dimensions (metres).
pub const AUTO_MIN_EXTENT: f32 = 2.0;
/// Coordinates are snapped to this grid (metres) so that faces of neighbouring boxes coincide.
pub const SNAP: f32 = 1e-3;

/// The axis-aligned rectangular faces of a mesh (pairs of triangles filling a rectangle), as
/// flat boxes in the mesh's coordinates.
pub fn faces(mesh: &Mesh) -> Vec<Aabb> {
    // (axis, rectangle) → summed triangle area.
    let mut rects: HashMap<(usize, [i64; 6]), f32> = HashMap::new();
    for t in mesh.indices.chunks_exact(3) {
        let p = [t[0], t[1], t[2]].map(|i| Vec3::from(mesh.vertices[i as usize].position));
        let Some(axis) = (0..3)
            .find(|&a| (p[0][a] - p[1][a]).abs() <= SNAP && (p[0][a] - p[2][a]).abs() <= SNAP)
        else {
            continue;
        };
        let mut b = Aabb::EMPTY;
        p.iter().for_each(|q| b.include(*q));
        let key: [i64; 6] = std::array::from_fn(|k| {
            let x = if k < 3 { b.min[k] } else { b.max[k - 3] };
            (x / SNAP).round() as i64
        });
        let area = (p[1] - p[0]).cross(p[2] - p[0]).length() * 0.5;
        *rects.entry((axis, key)).or_default() += area;
    }
    let mut out: Vec<Aabb> = rects
        .into_iter()
        .filter_map(|((axis, k), area)| {
            let b = Aabb {
                min: [0, 1, 2].map(|i| k[i] as f32 * SNAP),
                max: [3, 4, 5].map(|i| k[i] as f32 * SNAP),
            };
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let full = (b.max[u] - b.min[u]) * (b.max[v] - b.min[v]);
            (full > 0.0 && (area - full).abs() <= full * 0.01).then_some(b)
        })
        .collect();
    out.sort_by(|a, b| {
        a.min
            .partial_cmp(&b.min)
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    out
}

/// The world box of a local box, if `m` keeps boxes axis-aligned (scale, 90° turns, shift).
pub fn transform_box(b: &Aabb, m: &Mat4) -> Option<Aabb> {
    let cols = [
        m.x_axis.truncate(),
        m.y_axis.truncate(),
        m.z_axis.truncate(),
    ];
    let axis_aligned = cols
        .iter()
        .all(|c| (0..3).filter(|&i| c[i].abs() > 1e-5).count() == 1);
    if !axis_aligned {
        return None;
    }
    let w = b.transformed(m);
    Some(Aabb {
        min: w.min.map(snap),
        max: w.max.map(snap),
    })
}

fn snap(x: f32) -> f32 {
    (x / SNAP).round() * SNAP
}

/// World occluder faces for a set of instances, given as (finest mesh, transform, tagged).
/// When nothing is tagged, large faces of every instance are used.
pub fn occluder_boxes<'a>(
    instances: impl Iterator<Item = (&'a Mesh, Mat4, bool)> + Clone,
) -> Vec<Aabb> {
    let any_tagged = instances.clone().any(|(_, _, tagged)| tagged);
    let mut out = Vec::new();
    let mut cache: HashMap<*const Mesh, Vec<Aabb>> = HashMap::new();
    for (mesh, m, tagged) in instances {
        if any_tagged && !tagged {
            continue;
        }
        let pieces = cache
            .entry(mesh as *const Mesh)
            .or_insert_with(|| faces(mesh));
        for p in pieces.iter() {
            let Some(w) = transform_box(p, &m) else {
                continue;
            };
            let s = w.size();
            let mut e = [s.x, s.y, s.z];
            e.sort_by(f32::total_cmp);
            if any_tagged || e[1] >= AUTO_MIN_EXTENT {
                out.push(w);
            }
        }
    }
    out.sort_by(|a, b| {
        a.min
            .partial_cmp(&b.min)
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lod::box_mesh;

    fn bx(min: [f32; 3], max: [f32; 3]) -> Aabb {
        Aabb { min, max }
    }

    #[test]
    fn a_wall_with_a_door_gives_the_faces_of_its_three_boxes() {
        let parts = [
            bx([0.0, 0.0, 0.0], [1.0, 3.0, 0.2]),
            bx([2.0, 0.0, 0.0], [4.0, 3.0, 0.2]),
            bx([1.0, 2.1, 0.0], [2.0, 3.0, 0.2]),
        ];
        let mesh = crate::import::concat(parts.iter().map(|p| box_mesh(p, [1.0; 4])).collect());
        let found = faces(&mesh);
        assert_eq!(found.len(), 18, "{found:?}");
        assert!(found.iter().all(|f| f.size().min_element() == 0.0));
        // The door opening (x 1..2, y < 2.1) is not covered by any face in the wall's planes.
        assert!(!found.iter().any(|f| f.min[2] == 0.0
            && f.max[2] == 0.0
            && f.min[0] < 1.5
            && f.max[0] > 1.5
            && f.min[1] < 1.0));
    }

    #[test]
    fn a_dented_box_loses_its_bent_faces_and_45_degrees_is_refused() {
        let b = bx([0.0; 3], [1.0; 3]);
        let mut m = box_mesh(&b, [1.0; 4]);
        m.vertices[0].position[0] += 0.3; // dent one corner of the x = 0 face
        assert_eq!(faces(&m).len(), 5);
        let r = Mat4::from_rotation_y(std::f32::consts::FRAC_PI_4);
        assert!(transform_box(&b, &r).is_none());
        let r = Mat4::from_rotation_y(std::f32::consts::FRAC_PI_2);
        let w = transform_box(&b, &r).unwrap();
        assert_eq!(w.min, [0.0, 0.0, -1.0]);
    }
}
