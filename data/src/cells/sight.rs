//! What a ray really sees: the first triangle it hits among the objects' own triangles (their
//! finest LOD, in world space). `portico verify` checks the stored visibility against this
//! rather than against the occluder boxes the precompute itself used, so occluders extracted
//! wrongly (a wall that is not there, a door taken for a wall) show as false negatives.

use crate::geometry::Aabb;
use crate::geometry::slab;
use glam::{Mat4, Vec3};

/// Every object's triangles and world bounds: its own world-space triangles, or a shape shared
/// with other objects and the transform that places it (a ray is taken into the shape's
/// coordinates, where its parameter `t` is the same: the map is affine).
#[derive(Debug, Clone, Default)]
pub struct Triangles {
    bounds: Vec<Aabb>,
    /// Per object: index into `shapes`, and the world-to-shape transform when not the identity.
    placed: Vec<(u32, Option<Mat4>)>,
    shapes: Vec<Vec<[Vec3; 3]>>,
}

impl Triangles {
    /// Objects given by their bounds and world-space triangles (index = object id).
    pub fn new(bounds: Vec<Aabb>, triangles: Vec<Vec<[Vec3; 3]>>) -> Triangles {
        assert_eq!(
            bounds.len(),
            triangles.len(),
            "one triangle list per object"
        );
        Triangles {
            placed: (0..bounds.len() as u32).map(|i| (i, None)).collect(),
            bounds,
            shapes: triangles,
        }
    }

    /// Objects placed as instances of shared shapes: `placed[o]` is object `o`'s index into
    /// `shapes` and its object-to-world transform; `bounds[o]` its world box. Objects whose
    /// transform cannot be inverted (or is not finite) get no triangles.
    pub fn instanced(
        bounds: Vec<Aabb>,
        shapes: Vec<Vec<[Vec3; 3]>>,
        placed: Vec<(u32, Mat4)>,
    ) -> Triangles {
        assert_eq!(bounds.len(), placed.len(), "one placement per object");
        let empty = shapes.len() as u32;
        let mut shapes = shapes;
        shapes.push(Vec::new());
        let placed = placed
            .into_iter()
            .map(|(s, m)| {
                let inv = m.inverse();
                if (s as usize) < shapes.len() && m.determinant() != 0.0 && inv.is_finite() {
                    (s, (m != Mat4::IDENTITY).then_some(inv))
                } else {
                    (empty, None)
                }
            })
            .collect();
        Triangles {
            bounds,
            placed,
            shapes,
        }
    }

    /// Every instance of a database at its finest LOD, transformed to world space.
    ///
    /// # Errors
    /// A geometry segment that cannot be read or parsed.
    pub fn of_database(db: &crate::Database) -> crate::Result<Triangles> {
        let header = db.header();
        let mut bounds = Vec::with_capacity(header.instances.len());
        let mut triangles = Vec::with_capacity(header.instances.len());
        for inst in &header.instances {
            bounds.push(inst.bounds);
            let Some(finest) = header.lods_of(inst).first() else {
                triangles.push(Vec::new());
                continue;
            };
            let bytes = db.geometry(finest)?;
            let mesh = crate::geometry::GeometryView::parse(&bytes)
                .map_err(|e| crate::DataError::corrupt(db.path(), e))?
                .to_mesh();
            let m = glam::Mat4::from_cols_array(&inst.transform);
            let p: Vec<Vec3> = mesh
                .vertices
                .iter()
                .map(|v| m.transform_point3(Vec3::from(v.position)))
                .collect();
            triangles.push(
                mesh.indices
                    .chunks_exact(3)
                    .map(|t| [p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]])
                    .collect(),
            );
        }
        Ok(Triangles::new(bounds, triangles))
    }

    /// Every object's world box (index = object).
    pub fn bounds(&self) -> &[Aabb] {
        &self.bounds
    }

    /// The object whose triangle `origin + t·dir` hits first for `0 < t ≤ max_t`, if any.
    pub fn first_hit(&self, origin: Vec3, dir: Vec3, max_t: f32) -> Option<u32> {
        let all: Vec<u32> = (0..self.bounds.len() as u32).collect();
        self.nearest(&all, origin, dir, max_t).map(|(_, o)| o)
    }

    /// Among `candidates`, the object whose triangle `origin + t·dir` hits first for
    /// `0 < t ≤ max_t`, with that `t`.
    pub fn nearest(
        &self,
        candidates: &[u32],
        origin: Vec3,
        dir: Vec3,
        max_t: f32,
    ) -> Option<(f32, u32)> {
        let mut near: Vec<(f32, u32)> = candidates
            .iter()
            .filter_map(|&o| {
                let (t0, t1) = slab(origin, dir, self.bounds.get(o as usize)?)?;
                (t1 >= 0.0 && t0 <= max_t).then_some((t0.max(0.0), o))
            })
            .collect();
        near.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let mut best: Option<(f32, u32)> = None;
        for (enter, o) in near {
            if best.is_some_and(|(t, _)| t < enter) {
                break; // every later box starts beyond the nearest hit
            }
            let (shape, to_shape) = self.placed[o as usize];
            let (so, sd) = match to_shape {
                Some(m) => (m.transform_point3(origin), m.transform_vector3(dir)),
                None => (origin, dir),
            };
            for tri in &self.shapes[shape as usize] {
                if let Some(t) = hit(so, sd, tri)
                    && t <= max_t
                    && best.is_none_or(|(b, _)| t < b)
                {
                    best = Some((t, o));
                }
            }
        }
        best
    }
}

/// Möller–Trumbore ray–triangle intersection (both sides): the ray parameter of the hit.
fn hit(o: Vec3, d: Vec3, [a, b, c]: &[Vec3; 3]) -> Option<f32> {
    let (e1, e2) = (*b - *a, *c - *a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - *a;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t > 1e-5).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(z: f32) -> Vec<[Vec3; 3]> {
        let (a, b, c, d) = (
            Vec3::new(-1.0, -1.0, z),
            Vec3::new(1.0, -1.0, z),
            Vec3::new(1.0, 1.0, z),
            Vec3::new(-1.0, 1.0, z),
        );
        vec![[a, b, c], [a, c, d]]
    }

    fn bounds(z: f32) -> Aabb {
        Aabb {
            min: [-1.0, -1.0, z],
            max: [1.0, 1.0, z],
        }
    }

    #[test]
    fn the_nearest_triangle_wins_and_boxes_alone_do_not_count() {
        // Object 0 at z = 5, object 1 at z = 2 (nearer), object 2 a box with no triangles.
        let s = Triangles::new(
            vec![bounds(5.0), bounds(2.0), bounds(1.0)],
            vec![square(5.0), square(2.0), Vec::new()],
        );
        let (o, d) = (Vec3::ZERO, Vec3::Z);
        assert_eq!(s.first_hit(o, d, 100.0), Some(1));
        assert_eq!(s.first_hit(o, d, 1.5), None, "beyond max_t");
        assert_eq!(s.first_hit(o, -d, 100.0), None, "behind the origin");
        assert_eq!(
            s.first_hit(Vec3::new(3.0, 0.0, 0.0), d, 100.0),
            None,
            "beside"
        );
        assert_eq!(s.first_hit(Vec3::new(0.0, 0.0, 3.0), d, 100.0), Some(0));
    }
}
