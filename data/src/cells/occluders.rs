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
//! Tagged walls and slabs that are not written as boxes (BIM exports triangulate walls around
//! their openings) give what their triangles cover on both faces instead ([`super::cover`]).
//!
//! Untagged objects, in untagged models and beside tagged ones alike (BIM exports write walls
//! as proxies or generic models next to tagged walls), are occluders when shaped like walls
//! and slabs ([`wall_or_slab`]); a model with no tags and none of those gets the faces of any
//! instance with both extents at least [`AUTO_MIN_EXTENT`].
//!
//! Solid volume matters too: the space inside a wall is cut into cells by the planes of other
//! walls, and those cells must be dead, not joined to each other by "portals" inside the
//! solid. Runs of 12 consecutive triangles that exactly cover a box's surface (how the
//! generator, and most box modellers, write boxes) give the solid boxes ([`solid_boxes`]).

use crate::geometry::{Aabb, Mesh};
use glam::{Mat4, Vec3};
use std::collections::HashMap;

/// Automatic occluders must be at least this large in two dimensions (metres).
pub const AUTO_MIN_EXTENT: f32 = 2.0;
/// Coordinates are snapped to this grid (metres) so that faces of neighbouring boxes coincide.
pub const SNAP: f32 = 1e-3;
/// `1 / SNAP`, exactly.
const SNAPS_PER_METRE: f64 = 1000.0;

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
        let key: [i64; 6] =
            std::array::from_fn(|k| grid(if k < 3 { b.min[k] } else { b.max[k - 3] }));
        let area = (p[1] - p[0]).cross(p[2] - p[0]).length() * 0.5;
        *rects.entry((axis, key)).or_default() += area;
    }
    let mut out: Vec<Aabb> = rects
        .into_iter()
        .filter_map(|((axis, k), area)| {
            let b = Aabb {
                min: [0, 1, 2].map(|i| ungrid(k[i])),
                max: [3, 4, 5].map(|i| ungrid(k[i])),
            };
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let full = (b.max[u] - b.min[u]) * (b.max[v] - b.min[v]);
            (full > 0.0 && (area - full).abs() <= full * 0.01).then_some(b)
        })
        .collect();
    sort_dedup(&mut out);
    out
}

/// Sorts boxes by all six coordinates (a total order, so the result does not depend on hash
/// order) and removes duplicates: the same input always gives the same database.
fn sort_dedup(boxes: &mut Vec<Aabb>) {
    let key = |b: &Aabb| [b.min[0], b.min[1], b.min[2], b.max[0], b.max[1], b.max[2]];
    boxes.sort_by(|a, b| {
        key(a)
            .iter()
            .zip(key(b).iter())
            .map(|(x, y)| x.total_cmp(y))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    boxes.dedup();
}

/// Boxes written as 12 consecutive triangles covering exactly a box's surface: solid volume.
pub fn solid_boxes(mesh: &Mesh) -> Vec<Aabb> {
    let tris: Vec<[Vec3; 3]> = mesh
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]].map(|i| Vec3::from(mesh.vertices[i as usize].position)))
        .collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i + 12 <= tris.len() {
        match as_box(&tris[i..i + 12]) {
            Some(b) => {
                out.push(b);
                i += 12;
            }
            None => i += 1,
        }
    }
    out
}

/// The bounds of a set of triangles if they are exactly that box's surface.
fn as_box(tris: &[[Vec3; 3]]) -> Option<Aabb> {
    let mut b = Aabb::EMPTY;
    for p in tris.iter().flatten() {
        b.include(*p);
    }
    let size = b.size();
    if size.min_element() <= 0.0 {
        return None;
    }
    let mut area = 0.0f64;
    for t in tris {
        let on_face = (0..3).any(|a| {
            [b.min[a], b.max[a]]
                .iter()
                .any(|&f| t.iter().all(|p| (p[a] - f).abs() <= SNAP))
        });
        if !on_face {
            return None;
        }
        area += ((t[1] - t[0]).cross(t[2] - t[0]).length() * 0.5) as f64;
    }
    let surface = 2.0 * (size.x * size.y + size.y * size.z + size.z * size.x) as f64;
    ((area - surface).abs() <= surface * 0.01).then_some(b)
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

/// The nearest point of the [`SNAP`] grid. Computed in f64 so that a grid point is the f32
/// nearest to it: a wall at 123 m snaps to exactly 123.0, as the model's bounds have it (in f32,
/// `123_000.0 * 0.001` is 123.00001, which leaves slivers of open space between walls and the
/// bounds).
fn snap(x: f32) -> f32 {
    ungrid(grid(x))
}

/// Index of the [`SNAP`] grid point nearest to `x`.
fn grid(x: f32) -> i64 {
    (x as f64 * SNAPS_PER_METRE).round() as i64
}

/// The f32 nearest to grid point `k`.
fn ungrid(k: i64) -> f32 {
    (k as f64 / SNAPS_PER_METRE) as f32
}

/// The occluders of a model in world space.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Occluders {
    /// Axis-aligned occluding faces (flat boxes): what the subdivision splits along.
    pub faces: Vec<Aabb>,
    /// Solid boxes (walls, slabs): cells inside them are dead.
    pub solids: Vec<Aabb>,
    /// Boxes of the rooms the source names (IFC spaces), split along where no occluder
    /// splits ([`super::subdivide::subdivide_around`]); they occlude nothing.
    pub rooms: Vec<Aabb>,
}

/// Thinnest untagged object taken as a wall (metres): door leaves and panels are thinner.
pub const MIN_WALL_THICKNESS: f32 = 0.08;
/// Shortest untagged wall (metres along the floor); walls are at least
/// [`AUTO_MIN_EXTENT`] high, slabs at least that in both directions.
pub const MIN_WALL_LENGTH: f32 = 0.5;

/// World occluders for a set of instances, given as (finest mesh in its source triangle order,
/// transform, tagged). Tagged instances give their boxes' faces and solids, or what their
/// triangles cover when they are not written as boxes. Every untagged instance shaped like a
/// wall or slab ([`wall_or_slab`]: thin along one axis, large along the others) gives what its
/// triangles cover ([`super::cover`]), whatever the rest of the file is tagged with: BIM tools
/// export walls as generic models or proxies beside their tagged walls. A model with no
/// tagged instance and no such object falls back to the large faces of every instance (and no
/// solids: an untagged box may be furniture, not a wall).
pub fn occluder_boxes<'a>(
    instances: impl Iterator<Item = (&'a Mesh, Mat4, bool)> + Clone,
) -> Occluders {
    let any_tagged = instances.clone().any(|(_, _, tagged)| tagged);
    let mut solids = Vec::new();
    let mut out = Vec::new();
    let mut cache: HashMap<*const Mesh, (Vec<Aabb>, Vec<Aabb>)> = HashMap::new();
    for (mesh, m, tagged) in instances.clone() {
        if !tagged {
            if wall_or_slab(mesh, &m) {
                add_covered(mesh, &m, &mut solids, &mut out);
            }
            continue;
        }
        let (pieces, boxes) = cache
            .entry(mesh as *const Mesh)
            .or_insert_with(|| (faces(mesh), solid_boxes(mesh)));
        // Not written as whole boxes (a BIM wall cut around its openings, a gable): what its
        // triangles cover on both faces.
        if boxes.is_empty() && add_covered(mesh, &m, &mut solids, &mut out) {
            continue;
        }
        solids.extend(boxes.iter().filter_map(|b| transform_box(b, &m)));
        out.extend(pieces.iter().filter_map(|p| transform_box(p, &m)));
    }
    if !any_tagged && out.is_empty() {
        for (mesh, m, _) in instances {
            let pieces = cache
                .entry(mesh as *const Mesh)
                .or_insert_with(|| (faces(mesh), Vec::new()));
            for p in pieces.0.iter() {
                let Some(w) = transform_box(p, &m) else {
                    continue;
                };
                let s = w.size();
                let mut e = [s.x, s.y, s.z];
                e.sort_by(f32::total_cmp);
                if e[1] >= AUTO_MIN_EXTENT {
                    out.push(w);
                }
            }
        }
    }
    sort_dedup(&mut out);
    sort_dedup(&mut solids);
    Occluders {
        faces: out,
        solids,
        rooms: Vec::new(),
    }
}

/// Whether an untagged object is shaped like a wall (thin horizontally, at least
/// [`AUTO_MIN_EXTENT`] high and [`MIN_WALL_LENGTH`] long) or a slab (thin vertically, at least
/// [`AUTO_MIN_EXTENT`] both ways), between [`MIN_WALL_THICKNESS`] and
/// [`super::cover::MAX_THICKNESS`] thick. Furniture, door leaves and glass panes are not, so
/// they neither split the cells nor close the doors.
pub fn wall_or_slab(mesh: &Mesh, m: &Mat4) -> bool {
    let s = mesh.bounds().transformed(m).size();
    let Some(t) = (0..3).min_by(|&a, &b| s[a].total_cmp(&s[b])) else {
        return false;
    };
    let thick = (MIN_WALL_THICKNESS..=super::cover::MAX_THICKNESS).contains(&s[t]);
    let large = if t == 1 {
        s.x >= AUTO_MIN_EXTENT && s.z >= AUTO_MIN_EXTENT
    } else {
        s.y >= AUTO_MIN_EXTENT && s[2 - t] >= MIN_WALL_LENGTH
    };
    thick && large
}

/// Adds what a wall or slab covers ([`super::cover::covered`]), snapped to the grid, to
/// `solids` and `faces`; false when it is not one.
fn add_covered(mesh: &Mesh, m: &Mat4, solids: &mut Vec<Aabb>, faces: &mut Vec<Aabb>) -> bool {
    let Some((s, f)) = super::cover::covered(mesh, m) else {
        return false;
    };
    solids.extend(s.iter().filter_map(|b| transform_box(b, &Mat4::IDENTITY)));
    faces.extend(f.iter().filter_map(|b| transform_box(b, &Mat4::IDENTITY)));
    true
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
        let mut solids = solid_boxes(&mesh);
        solids.sort_by(|a, b| a.min.partial_cmp(&b.min).unwrap());
        let mut expected = parts.to_vec();
        expected.sort_by(|a, b| a.min.partial_cmp(&b.min).unwrap());
        assert_eq!(solids, expected);
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
