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
//! into rectangles, become solid boxes, and their outline becomes occluder faces. A cell an
//! edge of a face's outline passes through is open (a slanted or small opening may miss every
//! sample point), and an object whose sides do not close its outline (a table with a shelf, a
//! double skin open at its ends) is not solid and gives nothing. Very fine objects (more than
//! [`MAX_GRID_CELLS`] cells or [`MAX_TRIANGLES`] triangles) give nothing either: fewer
//! occluders only cost culling, never a wrong answer.

use crate::geometry::{Aabb, Mesh};
use glam::{Mat4, Vec2, Vec3};
use grid::Grid;
#[cfg(test)]
use grid::crosses_open;

mod grid;

/// Thickest object (metres along its thin axis) taken as a wall or slab.
pub const MAX_THICKNESS: f32 = 1.0;
/// Smallest extent (metres) of a wall or slab along its two long axes.
pub const MIN_SPAN: f32 = 0.5;
/// Even grid lines added along each long axis, besides the vertex coordinates.
pub const EXTRA_LINES: usize = 16;
/// Most grid cells (along both long axes together) worked through for one object; a finer
/// object is not used as an occluder (fewer occluders only cost culling).
pub const MAX_GRID_CELLS: usize = 1 << 20;
/// Most triangles in one object taken as a wall or slab.
pub const MAX_TRIANGLES: usize = 200_000;
/// How far (metres) a triangle may lie from a face's plane and still be on it.
const PLANE_TOLERANCE: f32 = 2e-3;
/// Slack (in barycentric terms) for points on a triangle's edge.
const EDGE_SLACK: f32 = 1e-5;

/// The solid boxes and occluder faces (flat boxes) of a thin wall or slab, in world space;
/// `None` when the object is not thin along a world axis, has no triangles in one of its two
/// faces, is open at its sides, or is finer than the budget.
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
    if on.iter().any(Vec::is_empty) || mesh.indices.len() / 3 > MAX_TRIANGLES {
        return None;
    }
    // Closed all round: the sides (triangles facing sideways; mitred ends are slanted) must
    // add up to the outline of a face times the thickness, or the space between the faces is
    // not solid (a table with a shelf under it, a double skin open at its ends).
    let edges = [boundary(&on[0]), boundary(&on[1])];
    let outline: f32 = edges[0].iter().map(|(a, b)| a.distance(*b)).sum();
    let sides: f32 = mesh
        .indices
        .chunks_exact(3)
        .map(|tri| {
            let p = [tri[0], tri[1], tri[2]].map(|i| pts[i as usize]);
            // Facing sideways (mitred ends up to about 48°), not like the faces.
            let n = (p[1] - p[0]).cross(p[2] - p[0]);
            if n[t].abs() <= 0.75 * n.length() {
                0.5 * n.length()
            } else {
                0.0
            }
        })
        .sum();
    if sides < 0.9 * outline * (hi - lo) {
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
    let (nu, nv) = grid.cells();
    if nu * nv > MAX_GRID_CELLS {
        return None;
    }
    let solid: Vec<bool> = {
        let mut a = grid.cover(&on[0]);
        let mut c = grid.cover(&on[1]);
        // A cell an edge of a face's outline passes through is partly open, whatever its
        // sample points say (a slanted or small opening can miss all five).
        grid.cut(&mut a, &edges[0]);
        grid.cut(&mut c, &edges[1]);
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

/// The edges of a face's outline, openings included: every edge (endpoints matched to 0.1 mm)
/// not covered on both of its sides. An edge that triangles touch from one side only is on the
/// outline however many touch it: a face written twice (a two-sided export's reversed copy),
/// folded or overlapping triangles, and a T-junction's long edge all stay outline edges, so the
/// cells they cross are opened (conservative), never closed.
fn boundary(tris: &[[Vec2; 3]]) -> Vec<(Vec2, Vec2)> {
    let key = |p: Vec2| ((p.x * 1e4).round() as i64, (p.y * 1e4).round() as i64);
    /// An edge by its endpoints on a 0.1 mm grid, the lower first.
    type EdgeKey = ((i64, i64), (i64, i64));
    // Per edge: triangles on its left and on its right (seen from the lower endpoint), and the
    // edge itself.
    let mut sides: std::collections::HashMap<EdgeKey, (u32, u32, Vec2, Vec2)> =
        std::collections::HashMap::new();
    for t in tris {
        for (a, b, c) in [(t[0], t[1], t[2]), (t[1], t[2], t[0]), (t[2], t[0], t[1])] {
            let (ka, kb) = (key(a), key(b));
            if ka == kb {
                continue;
            }
            let (k, from, to) = if ka < kb {
                ((ka, kb), a, b)
            } else {
                ((kb, ka), b, a)
            };
            let e = sides.entry(k).or_insert((0, 0, from, to));
            let side = (to - from).perp_dot(c - from);
            // A degenerate triangle (its third vertex on the edge) covers neither side.
            if side > 1e-12 {
                e.0 += 1;
            } else if side < -1e-12 {
                e.1 += 1;
            }
        }
    }
    let mut out: Vec<(Vec2, Vec2)> = sides
        .into_values()
        .filter(|(left, right, _, _)| (*left == 0) != (*right == 0))
        .map(|(_, _, a, b)| (a, b))
        .collect();
    out.sort_by(|x, y| {
        [x.0.x, x.0.y, x.1.x, x.1.y]
            .iter()
            .zip([y.0.x, y.0.y, y.1.x, y.1.y].iter())
            .map(|(p, q)| p.total_cmp(q))
            .find(|o| o.is_ne())
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    out
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
        // The sides: a quad along each edge of the outline, from one face to the other.
        for i in 0..8u32 {
            let j = (i + 1) % 8;
            indices.extend([i, j, 8 + j, i, 8 + j, 8 + i]);
        }
        Mesh {
            vertices,
            indices,
            uvs: Vec::new(),
        }
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
    fn a_table_with_a_shelf_is_not_solid_between_its_boards() {
        // A 2 m × 2 m top at 0.75 m and a shelf at 0.1 m, open all round: both "faces" are
        // covered, the sides are not.
        let board = |y0: f32, y1: f32| {
            crate::lod::box_mesh(
                &Aabb {
                    min: [0.0, y0, 0.0],
                    max: [2.0, y1, 2.0],
                },
                [1.0; 4],
            )
        };
        let table = crate::import::concat(vec![board(0.1, 0.12), board(0.73, 0.75)]);
        assert!(covered(&table, &Mat4::IDENTITY).is_none());
        // A closed slab of the same size is solid.
        let slab = board(0.1, 0.75);
        let (solids, _) = covered(&slab, &Mat4::IDENTITY).unwrap();
        assert_eq!(solids.len(), 1);
    }

    /// Convex outlines (in x, y) extruded from z = 0 to 0.2, each a closed prism.
    fn prisms(outlines: &[&[[f32; 2]]]) -> Mesh {
        let mut vertices = Vec::new();
        let mut indices = Vec::new();
        for o in outlines {
            let n = o.len() as u32;
            let base = vertices.len() as u32;
            for z in [0.0f32, 0.2] {
                for [x, y] in o.iter() {
                    vertices.push(Vertex::new([*x, *y, z], [0.0, 0.0, 1.0], [1.0; 4]));
                }
            }
            for i in 1..n - 1 {
                indices.extend([base, base + i, base + i + 1]);
                indices.extend([base + n, base + n + i, base + n + i + 1]);
            }
            for i in 0..n {
                let j = (i + 1) % n;
                indices.extend([
                    base + i,
                    base + j,
                    base + n + j,
                    base + i,
                    base + n + j,
                    base + n + i,
                ]);
            }
        }
        Mesh {
            vertices,
            indices,
            uvs: Vec::new(),
        }
    }

    #[test]
    fn a_small_triangular_vent_stays_open() {
        // A 10 m × 3 m wall with a vent (4.4, 2.07), (4.65, 2.24), (4.9, 2.07), written as
        // convex pieces around it. Every sample point of the grid cells inside the vent lies on
        // its outline (which counts as covered): only the outline's crossing opens them.
        let wall = prisms(&[
            &[[0.0, 0.0], [4.4, 0.0], [4.4, 3.0], [0.0, 3.0]],
            &[[4.9, 0.0], [10.0, 0.0], [10.0, 3.0], [4.9, 3.0]],
            &[[4.4, 0.0], [4.9, 0.0], [4.9, 2.07], [4.4, 2.07]],
            &[[4.4, 2.07], [4.65, 2.24], [4.65, 3.0], [4.4, 3.0]],
            &[[4.65, 2.24], [4.9, 2.07], [4.9, 3.0], [4.65, 3.0]],
        ]);
        let (solids, _) = covered(&wall, &Mat4::IDENTITY).unwrap();
        assert!(!solids.is_empty());
        for p in [[4.65, 2.15], [4.5, 2.1], [4.8, 2.1], [4.65, 2.22]] {
            let p = Vec3::new(p[0], p[1], 0.1);
            let blocked = solids
                .iter()
                .any(|b| (0..3).all(|a| b.min[a] < p[a] && p[a] < b.max[a]));
            assert!(!blocked, "the vent is closed at {p}");
        }
    }

    #[test]
    fn a_vent_stays_open_when_every_face_is_written_twice() {
        // SketchUp-style two-sided export: each triangle again, reversed. Every edge then has
        // two triangles, but all on one side of it: still the outline.
        let mut wall = prisms(&[
            &[[0.0, 0.0], [4.4, 0.0], [4.4, 3.0], [0.0, 3.0]],
            &[[4.9, 0.0], [10.0, 0.0], [10.0, 3.0], [4.9, 3.0]],
            &[[4.4, 0.0], [4.9, 0.0], [4.9, 2.07], [4.4, 2.07]],
            &[[4.4, 2.07], [4.65, 2.24], [4.65, 3.0], [4.4, 3.0]],
            &[[4.65, 2.24], [4.9, 2.07], [4.9, 3.0], [4.65, 3.0]],
        ]);
        let twice: Vec<u32> = wall
            .indices
            .chunks_exact(3)
            .flat_map(|t| [t[0], t[2], t[1]])
            .collect();
        wall.indices.extend(twice);
        let (solids, _) = covered(&wall, &Mat4::IDENTITY).unwrap();
        let p = Vec3::new(4.65, 2.15, 0.1);
        assert!(
            !solids
                .iter()
                .any(|b| (0..3).all(|a| b.min[a] < p[a] && p[a] < b.max[a])),
            "the vent is closed"
        );
        let area: f32 = solids.iter().map(|b| b.size().x * b.size().y).sum();
        assert!(area > 25.0 && area < 30.0, "solid area {area}");
    }

    #[test]
    fn a_segment_crosses_a_cell_only_through_its_interior() {
        let (lo, hi) = (Vec2::ZERO, Vec2::ONE);
        assert!(crosses_open(
            Vec2::new(-1.0, 0.2),
            Vec2::new(2.0, 0.9),
            lo,
            hi
        ));
        // Along an edge, or touching a corner: not through the interior.
        assert!(!crosses_open(
            Vec2::new(0.0, -1.0),
            Vec2::new(0.0, 2.0),
            lo,
            hi
        ));
        assert!(!crosses_open(
            Vec2::new(-1.0, 1.0),
            Vec2::new(1.0, 3.0),
            lo,
            hi
        ));
        assert!(!crosses_open(
            Vec2::new(2.0, 2.0),
            Vec2::new(3.0, 0.5),
            lo,
            hi
        ));
    }

    #[test]
    fn a_hole_in_one_face_only_is_not_closed_and_thick_objects_are_refused() {
        let mut m = wall_with_door();
        // Drop the back face's triangles left of the door: that part is open on one side.
        m.indices.drain(18..24);
        let area: f32 = covered(&m, &Mat4::IDENTITY).map_or(0.0, |(solids, _)| {
            solids.iter().map(|b| b.size().x * b.size().y).sum()
        });
        assert!(area < 10.0 - 1.0, "solid area {area}");
        let thick = Mat4::from_scale(Vec3::new(1.0, 1.0, 10.0));
        assert!(covered(&wall_with_door(), &thick).is_none());
    }
}
