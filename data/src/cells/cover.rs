//! Occluders from walls and slabs of any triangulation: the part of a thin, axis-aligned
//! object that its triangles cover on both of its faces.
//!
//! [`super::occluders::faces`] finds occluders only where a face is written as whole
//! rectangles (pairs of triangles filling one); walls exported from BIM tools are triangulated
//! around their openings by a CSG kernel, and gable walls have sloped tops, so that finds
//! nothing in them. Here an object thin along one world axis (at most [`MAX_THICKNESS`]) is
//! cut by a grid whose lines are its own vertex coordinates (so rectangular walls, doors and
//! windows come out exactly) plus at most [`EXTRA_LINES`] even lines (so sloped edges come
//! out as a staircase inside them); a grid cell is solid when its corners and centre are
//! covered by the triangles lying in both of the object's two faces. The solid cells, merged
//! into rectangles, become solid boxes, and their outline becomes occluder faces. Everything
//! is conservative: a cell counts only when covered on both faces, so a hole is never closed.

use crate::geometry::{Aabb, Mesh};
use glam::{Mat4, Vec2, Vec3};

/// Thickest object (metres along its thin axis) taken as a wall or slab.
pub const MAX_THICKNESS: f32 = 1.0;
/// Smallest extent (metres) of a wall or slab along its two long axes.
pub const MIN_SPAN: f32 = 0.5;
/// Even grid lines added along each long axis, besides the vertex coordinates.
pub const EXTRA_LINES: usize = 16;
/// How far (metres) a triangle may lie from a face's plane and still be on it.
const PLANE_TOLERANCE: f32 = 2e-3;
/// Slack (in barycentric terms) for points on a triangle's edge.
const EDGE_SLACK: f32 = 1e-5;

/// The solid boxes and occluder faces (flat boxes) of a thin wall or slab, in world space;
/// `None` when the object is not thin along a world axis.
pub fn covered(mesh: &Mesh, m: &Mat4) -> Option<(Vec<Aabb>, Vec<Aabb>)> {
    let pts: Vec<Vec3> = mesh
        .vertices
        .iter()
        .map(|v| m.transform_point3(Vec3::from(v.position)))
        .collect();
    let mut b = Aabb::EMPTY;
    pts.iter().for_each(|p| b.include(*p));
    let s = b.size();
    let t = (0..3).min_by(|&x, &y| s[x].total_cmp(&s[y]))?;
    let (u, v) = ((t + 1) % 3, (t + 2) % 3);
    if !(s[t] > 0.0 && s[t] <= MAX_THICKNESS && s[u] >= MIN_SPAN && s[v] >= MIN_SPAN) {
        return None;
    }
    let (lo, hi) = (b.min[t], b.max[t]);
    let mut on = [Vec::new(), Vec::new()];
    for tri in mesh.indices.chunks_exact(3) {
        let p = [tri[0], tri[1], tri[2]].map(|i| pts[i as usize]);
        for (k, plane) in [lo, hi].into_iter().enumerate() {
            if p.iter().all(|q| (q[t] - plane).abs() <= PLANE_TOLERANCE) {
                on[k].push(p.map(|q| Vec2::new(q[u], q[v])));
            }
        }
    }
    if on.iter().any(Vec::is_empty) {
        return None;
    }
    let lines = |axis: usize, pick: fn(Vec2) -> f32| {
        let mut l: Vec<f32> = on.iter().flatten().flatten().map(|q| pick(*q)).collect();
        let (a, z) = (b.min[axis], b.max[axis]);
        l.extend((0..=EXTRA_LINES).map(|i| a + (z - a) * i as f32 / EXTRA_LINES as f32));
        l.sort_by(f32::total_cmp);
        l.dedup_by(|x, y| (*x - *y).abs() < 1e-4);
        l
    };
    let grid = Grid {
        u: lines(u, |q| q.x),
        v: lines(v, |q| q.y),
    };
    let solid: Vec<bool> = {
        let a = grid.cover(&on[0]);
        let c = grid.cover(&on[1]);
        a.iter().zip(&c).map(|(x, y)| *x && *y).collect()
    };
    let to_box = |u0: f32, u1: f32, v0: f32, v1: f32, t0: f32, t1: f32| {
        let mut min = [0.0; 3];
        let mut max = [0.0; 3];
        (min[u], max[u], min[v], max[v], min[t], max[t]) = (u0, u1, v0, v1, t0, t1);
        Aabb { min, max }
    };
    let mut solids = Vec::new();
    let mut faces = Vec::new();
    for (i0, i1, j0, j1) in grid.rectangles(&solid) {
        let (u0, u1, v0, v1) = (grid.u[i0], grid.u[i1], grid.v[j0], grid.v[j1]);
        solids.push(to_box(u0, u1, v0, v1, lo, hi));
        faces.push(to_box(u0, u1, v0, v1, lo, lo));
        faces.push(to_box(u0, u1, v0, v1, hi, hi));
    }
    for (along_u, at, a, z) in grid.outline(&solid) {
        faces.push(if along_u {
            to_box(at, at, a, z, lo, hi)
        } else {
            to_box(a, z, at, at, lo, hi)
        });
    }
    Some((solids, faces))
}

/// A rectilinear grid over the object's two long axes.
struct Grid {
    u: Vec<f32>,
    v: Vec<f32>,
}

impl Grid {
    fn cells(&self) -> (usize, usize) {
        (self.u.len() - 1, self.v.len() - 1)
    }

    /// Which cells (row-major by `v`) have their four corners and centre covered.
    fn cover(&self, tris: &[[Vec2; 3]]) -> Vec<bool> {
        let (nu, nv) = self.cells();
        // Points: corners at (2i, 2j), centres at (2i+1, 2j+1), on a doubled lattice.
        let mu: Vec<f32> = (0..2 * nu + 1)
            .map(|k| {
                if k % 2 == 0 {
                    self.u[k / 2]
                } else {
                    (self.u[k / 2] + self.u[k / 2 + 1]) * 0.5
                }
            })
            .collect();
        let mv: Vec<f32> = (0..2 * nv + 1)
            .map(|k| {
                if k % 2 == 0 {
                    self.v[k / 2]
                } else {
                    (self.v[k / 2] + self.v[k / 2 + 1]) * 0.5
                }
            })
            .collect();
        let mut inside = vec![false; mu.len() * mv.len()];
        for t in tris {
            let (lo, hi) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
            let (a0, a1) = (
                mu.partition_point(|&x| x < lo.x - 1e-4),
                mu.partition_point(|&x| x <= hi.x + 1e-4),
            );
            let (b0, b1) = (
                mv.partition_point(|&y| y < lo.y - 1e-4),
                mv.partition_point(|&y| y <= hi.y + 1e-4),
            );
            for (j, &y) in mv.iter().enumerate().take(b1).skip(b0) {
                for (i, &x) in mu.iter().enumerate().take(a1).skip(a0) {
                    let k = j * mu.len() + i;
                    if !inside[k] && in_triangle(Vec2::new(x, y), t) {
                        inside[k] = true;
                    }
                }
            }
        }
        let at = |i: usize, j: usize| inside[j * mu.len() + i];
        let mut out = vec![false; nu * nv];
        for j in 0..nv {
            for i in 0..nu {
                let (x, y) = (2 * i, 2 * j);
                out[j * nu + i] = at(x, y)
                    && at(x + 2, y)
                    && at(x, y + 2)
                    && at(x + 2, y + 2)
                    && at(x + 1, y + 1);
            }
        }
        out
    }

    /// Solid cells merged into rectangles `(i0, i1, j0, j1)` of grid line indices: runs along
    /// `u`, stacked along `v` while the run repeats.
    fn rectangles(&self, solid: &[bool]) -> Vec<(usize, usize, usize, usize)> {
        let (nu, nv) = self.cells();
        let mut out = Vec::new();
        let mut open: Vec<(usize, usize, usize)> = Vec::new(); // (i0, i1, j0)
        for j in 0..=nv {
            let mut runs = Vec::new();
            if j < nv {
                let mut i = 0;
                while i < nu {
                    if solid[j * nu + i] {
                        let s = i;
                        while i < nu && solid[j * nu + i] {
                            i += 1;
                        }
                        runs.push((s, i));
                    } else {
                        i += 1;
                    }
                }
            }
            let mut next = Vec::new();
            for (i0, i1, j0) in open.drain(..) {
                if let Some(p) = runs.iter().position(|&r| r == (i0, i1)) {
                    runs.remove(p);
                    next.push((i0, i1, j0));
                } else {
                    out.push((i0, i1, j0, j));
                }
            }
            next.extend(runs.into_iter().map(|(i0, i1)| (i0, i1, j)));
            open = next;
        }
        out
    }

    /// The boundary between solid and open cells as segments `(along_u, at, from, to)`: at
    /// `u = at` spanning `v` from..to when `along_u`, else at `v = at` spanning `u`; collinear
    /// neighbours merged.
    fn outline(&self, solid: &[bool]) -> Vec<(bool, f32, f32, f32)> {
        let (nu, nv) = self.cells();
        let cell = |i: isize, j: isize| {
            i >= 0
                && j >= 0
                && (i as usize) < nu
                && (j as usize) < nv
                && solid[j as usize * nu + i as usize]
        };
        let mut out: Vec<(bool, f32, f32, f32)> = Vec::new();
        // Edges at u-lines (faces normal to u), walked along v.
        for i in 0..=nu {
            let mut run: Option<usize> = None;
            for j in 0..=nv {
                let edge =
                    j < nv && cell(i as isize - 1, j as isize) != cell(i as isize, j as isize);
                match (edge, run) {
                    (true, None) => run = Some(j),
                    (false, Some(s)) => {
                        out.push((true, self.u[i], self.v[s], self.v[j]));
                        run = None;
                    }
                    _ => {}
                }
            }
        }
        for j in 0..=nv {
            let mut run: Option<usize> = None;
            for i in 0..=nu {
                let edge =
                    i < nu && cell(i as isize, j as isize - 1) != cell(i as isize, j as isize);
                match (edge, run) {
                    (true, None) => run = Some(i),
                    (false, Some(s)) => {
                        out.push((false, self.v[j], self.u[s], self.u[i]));
                        run = None;
                    }
                    _ => {}
                }
            }
        }
        out
    }
}

/// Whether `p` lies in triangle `t` (its edges included).
fn in_triangle(p: Vec2, t: &[Vec2; 3]) -> bool {
    let d = (t[1] - t[0]).perp_dot(t[2] - t[0]);
    if d.abs() < 1e-12 {
        return false;
    }
    let a = (t[1] - p).perp_dot(t[2] - p) / d;
    let b = (t[2] - p).perp_dot(t[0] - p) / d;
    let c = 1.0 - a - b;
    a >= -EDGE_SLACK && b >= -EDGE_SLACK && c >= -EDGE_SLACK
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Vertex;

    /// A wall 4 m long (x), 3 m high (y), 0.2 m thick (z) with a door 1 m wide and 2 m high
    /// at x 1.5..2.5, each face triangulated as a fan around the door the way CSG kernels
    /// write it (no triangle pair fills a rectangle).
    fn wall_with_door() -> Mesh {
        let outline = [
            [0.0, 0.0],
            [1.5, 0.0],
            [1.5, 2.0],
            [2.5, 2.0],
            [2.5, 0.0],
            [4.0, 0.0],
            [4.0, 3.0],
            [0.0, 3.0],
        ];
        let mut vertices = Vec::new();
        let mut indices = Vec::new();
        for z in [0.0f32, 0.2] {
            let base = vertices.len() as u32;
            for [x, y] in outline {
                vertices.push(Vertex::new([x, y, z], [0.0, 0.0, 1.0], [1.0; 4]));
            }
            // A fan from the top-left corner (7) covers the non-convex outline exactly.
            for k in [
                (7, 0, 1),
                (7, 1, 2),
                (7, 2, 3),
                (7, 3, 6),
                (3, 4, 5),
                (3, 5, 6),
            ] {
                indices.extend([base + k.0, base + k.1, base + k.2]);
            }
        }
        Mesh { vertices, indices }
    }

    #[test]
    fn a_fanned_wall_with_a_door_is_solid_except_the_door() {
        let (solids, faces) = covered(&wall_with_door(), &Mat4::IDENTITY).unwrap();
        let area: f32 = solids.iter().map(|b| b.size().x * b.size().y).sum();
        assert!((area - (12.0 - 2.0)).abs() < 1e-3, "solid area {area}");
        assert!(solids.iter().all(|b| b.min[2] == 0.0 && b.max[2] == 0.2));
        // Nothing solid or occluding inside the door.
        let door = Vec3::new(2.0, 1.0, 0.1);
        assert!(
            !solids
                .iter()
                .any(|b| (0..3).all(|k| b.min[k] < door[k] && door[k] < b.max[k]))
        );
        // The jambs are faces: x = 1.5 and x = 2.5 from the floor to 2 m.
        for x in [1.5, 2.5] {
            assert!(
                faces
                    .iter()
                    .any(|f| f.min[0] == x && f.max[0] == x && f.min[1] == 0.0 && f.max[1] == 2.0),
                "{faces:?}"
            );
        }
    }

    #[test]
    fn a_hole_in_one_face_only_is_not_closed_and_thick_objects_are_refused() {
        let mut m = wall_with_door();
        // Drop the back face's triangles left of the door: that part is open on one side.
        m.indices.drain(18..24);
        let (solids, _) = covered(&m, &Mat4::IDENTITY).unwrap();
        let area: f32 = solids.iter().map(|b| b.size().x * b.size().y).sum();
        assert!(area < 10.0 - 1.0, "solid area {area}");
        let thick = Mat4::from_scale(Vec3::new(1.0, 1.0, 10.0));
        assert!(covered(&wall_with_door(), &thick).is_none());
    }
}
