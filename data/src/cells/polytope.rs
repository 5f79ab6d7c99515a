//! Planes, halfspaces and convex polygons/polyhedra: the small amount of computational geometry
//! the visibility algorithms need (clipping a region to halfspaces, its bounding box).

use crate::geometry::Aabb;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Tolerance for "on the plane", in metres.
pub const EPS: f32 = 1e-4;

/// The halfspace `normal · x <= d` (its boundary is the plane `normal · x = d`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Plane {
    /// Outward normal (need not be unit length).
    pub normal: [f32; 3],
    /// Offset.
    pub d: f32,
}

impl Plane {
    /// The halfspace bounded by the plane through `p` with outward normal `n`.
    pub fn through(p: Vec3, n: Vec3) -> Plane {
        Plane {
            normal: n.into(),
            d: n.dot(p),
        }
    }

    /// Signed distance-like value: `<= 0` inside the halfspace.
    pub fn eval(&self, p: Vec3) -> f32 {
        Vec3::from(self.normal).dot(p) - self.d
    }

    /// Whether any point of the closed box lies in the closed halfspace (within [`EPS`]).
    pub fn touches_box(&self, b: &Aabb) -> bool {
        self.touches_box_within(b, EPS)
    }

    /// [`Plane::touches_box`] with the tolerance given (metres, for a unit normal).
    pub fn touches_box_within(&self, b: &Aabb, tolerance: f32) -> bool {
        let n = Vec3::from(self.normal);
        // The box corner that minimises n · x.
        let corner = Vec3::new(
            if n.x >= 0.0 { b.min[0] } else { b.max[0] },
            if n.y >= 0.0 { b.min[1] } else { b.max[1] },
            if n.z >= 0.0 { b.min[2] } else { b.max[2] },
        );
        self.eval(corner) <= tolerance * n.length().max(1.0)
    }
}

/// Clips a convex polygon to the halfspace (Sutherland–Hodgman, one plane).
pub fn clip_polygon(poly: &[Vec3], plane: &Plane) -> Vec<Vec3> {
    let mut out = Vec::with_capacity(poly.len() + 1);
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        let (da, db) = (plane.eval(a), plane.eval(b));
        if da <= 0.0 {
            out.push(a);
        }
        if (da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0) {
            out.push(a + (b - a) * (da / (da - db)));
        }
    }
    out
}

/// The six faces of a box as counter-clockwise polygons.
pub fn box_faces(b: &Aabb) -> Vec<Vec<Vec3>> {
    let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
    let mut faces = Vec::with_capacity(6);
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [lo[axis], hi[axis]] {
            let corner = |a: f32, c: f32| {
                let mut p = Vec3::ZERO;
                p[axis] = side;
                p[u] = a;
                p[v] = c;
                p
            };
            faces.push(vec![
                corner(lo[u], lo[v]),
                corner(hi[u], lo[v]),
                corner(hi[u], hi[v]),
                corner(lo[u], hi[v]),
            ]);
        }
    }
    faces
}

/// Bounding box of `{x in b : x satisfies every plane}`, or `None` if that set is empty.
///
/// The box is kept as a convex polyhedron (a list of face polygons): each plane clips every
/// face, and the points where it cuts them, ordered around their centroid, become the new cap
/// face, so later planes clip the caps too and no vertex of the result is lost.
pub fn clipped_box_bounds(b: &Aabb, planes: &[Plane]) -> Option<Aabb> {
    let mut faces = box_faces(b);
    for p in planes {
        let mut cut = Vec::new();
        for f in &mut faces {
            let clipped = clip_polygon(f, p);
            cut.extend(clipped.iter().copied().filter(|q| p.eval(*q).abs() <= EPS));
            *f = clipped;
        }
        faces.retain(|f| f.len() >= 3);
        if faces.is_empty() {
            return None;
        }
        // Each cut point is shared by two faces; keep one of each.
        let mut unique: Vec<Vec3> = Vec::with_capacity(cut.len() / 2);
        for q in cut {
            if !unique.iter().any(|u| u.distance_squared(q) <= EPS * EPS) {
                unique.push(q);
            }
        }
        let cut = unique;
        if cut.len() >= 3 {
            faces.push(order_around_centroid(cut, Vec3::from(p.normal)));
        }
    }
    let mut out = Aabb::EMPTY;
    for q in faces.iter().flatten() {
        out.include(*q);
    }
    (!out.is_empty()).then_some(out)
}

/// Orders coplanar points by angle around their centroid (a convex cap polygon).
fn order_around_centroid(points: Vec<Vec3>, normal: Vec3) -> Vec<Vec3> {
    let c = points.iter().copied().sum::<Vec3>() / points.len() as f32;
    let n = normal.normalize_or_zero();
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    let mut keyed: Vec<(f32, Vec3)> = points
        .into_iter()
        .map(|q| ((q - c).dot(v).atan2((q - c).dot(u)), q))
        .collect();
    keyed.sort_by(|a, b| a.0.total_cmp(&b.0));
    keyed.into_iter().map(|(_, q)| q).collect()
}

/// The edges of a convex polygon of `n` corners in order.
pub fn ring(n: usize) -> Vec<(usize, usize)> {
    (0..n).map(|i| (i, (i + 1) % n)).collect()
}

/// Planes through an edge of one convex set and a corner of the other with the two on opposite
/// sides, as halfspaces containing `b`'s side: every line through a point of `a` and then a
/// point of `b` goes on inside each of them (the anti-penumbra's bounding planes, Teller 1992).
/// `a` and `b` are corner lists with their edges as index pairs.
pub fn separating_planes_of(
    a: &[Vec3],
    a_edges: &[(usize, usize)],
    b: &[Vec3],
    b_edges: &[(usize, usize)],
) -> Vec<Plane> {
    let mut out = Vec::new();
    for (from, edges, to) in [(a, a_edges, b), (b, b_edges, a)] {
        for &(i, j) in edges {
            for &w in to {
                let Some((n, d)) = plane_through(from[i], from[j], w) else {
                    continue;
                };
                let Some(sa) = side(a, n, d) else { continue };
                let Some(sb) = side(b, n, d) else { continue };
                keep_separating(&mut out, n, d, sa, sb, 0.0);
            }
        }
    }
    out
}

/// [`separating_planes_of`] for a box `a` and a convex polygon `b`: the same planes, computed
/// about the box's centre (so the tolerance is not lost to large coordinates), with the box's
/// side of each plane from its half extents (two dot products, not eight).
pub fn box_separating_planes(a: &Aabb, b: &[Vec3]) -> Vec<Plane> {
    let (lo, hi) = (Vec3::from(a.min), Vec3::from(a.max));
    let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
    let corners = box_corners(&Aabb {
        min: (-h).into(),
        max: h.into(),
    });
    let poly: Vec<Vec3> = b.iter().map(|&p| p - c).collect();
    let edges = ring(poly.len());
    let box_side = |n: Vec3, d: f32| {
        let r = n.abs().dot(h);
        let (lo, hi) = (-d - r, -d + r);
        (!(lo < -SIDE_T && hi > SIDE_T)).then_some((lo, hi))
    };
    let mut out = Vec::new();
    let mut each = |e0: Vec3, e1: Vec3, w: Vec3| {
        let Some((n, d)) = plane_through(e0, e1, w) else {
            return;
        };
        let Some(sa) = box_side(n, d) else { return };
        let Some(sb) = side(&poly, n, d) else { return };
        keep_separating(&mut out, n, d, sa, sb, n.dot(c));
    };
    for &(i, j) in &BOX_EDGES {
        for &w in &poly {
            each(corners[i], corners[j], w);
        }
    }
    for &(i, j) in &edges {
        for &w in &corners {
            each(poly[i], poly[j], w);
        }
    }
    out
}

/// The eight corners of a box, corner `i` taking `max` on axis `k` where bit `k` of `i` is set.
pub fn box_corners(b: &Aabb) -> [Vec3; 8] {
    std::array::from_fn(|i| {
        let pick = |k: usize| if i >> k & 1 == 1 { b.max[k] } else { b.min[k] };
        Vec3::new(pick(0), pick(1), pick(2))
    })
}

/// The twelve edges of a box's corners as [`box_corners`] orders them.
pub const BOX_EDGES: [(usize, usize); 12] = [
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7),
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
];

/// Signed distances this close to a plane count as on it (metres).
const SIDE_T: f32 = 1e-5;

/// The plane through the edge `e0`–`e1` and the corner `w` (unit normal `n`, `n · x = d`), if
/// the three are not collinear.
fn plane_through(e0: Vec3, e1: Vec3, w: Vec3) -> Option<(Vec3, f32)> {
    let n = (e1 - e0).cross(w - e0);
    if n.length_squared() < 1e-10 {
        return None;
    }
    let n = n.normalize();
    Some((n, n.dot(e0)))
}

/// The range of a set's signed distances from `n · x = d`; `None` as soon as it has points on
/// both sides (the common case: the plane separates nothing).
fn side(pts: &[Vec3], n: Vec3, d: f32) -> Option<(f32, f32)> {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for p in pts {
        let s = n.dot(*p) - d;
        lo = lo.min(s);
        hi = hi.max(s);
        if lo < -SIDE_T && hi > SIDE_T {
            return None;
        }
    }
    Some((lo, hi))
}

/// Keeps the plane `n · x = d` (shifted by `shift` to where the corners came from) if it has
/// `a` (distances `sa`) on one side and `b` (`sb`) on the other, as the halfspace holding `b`;
/// the same plane through several edges and corners is kept once.
fn keep_separating(
    out: &mut Vec<Plane>,
    n: Vec3,
    d: f32,
    (alo, ahi): (f32, f32),
    (blo, bhi): (f32, f32),
    shift: f32,
) {
    const T: f32 = SIDE_T;
    // a on the negative side, b on the positive: keep n · x >= d, i.e. (-n) · x <= -d.
    let plane = if ahi <= T && blo >= -T && (alo < -T || bhi > T) {
        Plane {
            normal: (-n).into(),
            d: -(d + shift),
        }
    } else if alo >= -T && bhi <= T && (ahi > T || blo < -T) {
        Plane {
            normal: n.into(),
            d: d + shift,
        }
    } else {
        return;
    };
    let same = |q: &Plane| {
        (0..3).all(|k| (q.normal[k] - plane.normal[k]).abs() < 1e-6) && (q.d - plane.d).abs() < 1e-5
    };
    if !out.iter().any(same) {
        out.push(plane);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_separating_planes_are_the_general_ones_and_keep_their_tolerance_far_out() {
        // Near the origin the box's own test keeps the planes the corner-by-corner one does.
        // Hundreds of metres out (where f32 keeps about 30 µm, coarser than the tolerance) the
        // corner-by-corner test loses planes that touch the box along an edge; the box's own,
        // computed about its centre, keeps them: it keeps the planes the other keeps, and every
        // plane it keeps separates the box from the portal.
        let mut seed = 0x2545_f491_u64;
        let mut rnd = |lo: f32, hi: f32| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            lo + (hi - lo) * ((seed >> 40) as f32 / (1u64 << 24) as f32)
        };
        let close = |p: &Plane, q: &Plane| {
            (0..3).all(|k| (p.normal[k] - q.normal[k]).abs() < 1e-4) && (p.d - q.d).abs() < 2e-2
        };
        let (mut planes, mut near_differ, mut lost, mut far_extra) = (0, 0, 0, 0);
        for case in 0..2000 {
            let far = if case % 2 == 0 { 3.0 } else { 300.0 };
            let o = Vec3::new(rnd(-far, far), rnd(-far, far) * 0.1, rnd(-far, far));
            let lo = o + Vec3::new(rnd(0.0, 2.0), rnd(0.0, 2.0), rnd(0.0, 2.0));
            let hi = lo + Vec3::new(rnd(0.01, 3.0), rnd(0.01, 3.0), rnd(0.01, 3.0));
            let eyes = Aabb {
                min: lo.into(),
                max: hi.into(),
            };
            // A door-sized portal on an axis plane beyond the box (a triangle now and then,
            // as a clipped portal may be).
            let axis = case % 3;
            let at = |u: f32, v: f32| {
                let mut p = Vec3::ZERO;
                p[axis] = hi[axis] + 0.5 + (case % 7) as f32;
                p[(axis + 1) % 3] = o[(axis + 1) % 3] + u;
                p[(axis + 2) % 3] = o[(axis + 2) % 3] + v;
                p
            };
            let (u0, v0) = (rnd(-4.0, 4.0), rnd(-4.0, 4.0));
            let (du, dv) = (rnd(0.5, 2.0), rnd(0.5, 2.5));
            let mut poly = vec![
                at(u0, v0),
                at(u0 + du, v0),
                at(u0 + du, v0 + dv),
                at(u0, v0 + dv),
            ];
            if case % 5 == 0 {
                poly.pop();
            }
            let corners = box_corners(&eyes);
            let general = separating_planes_of(&corners, &BOX_EDGES, &poly, &ring(poly.len()));
            let fast = box_separating_planes(&eyes, &poly);
            planes += general.len();
            let missing = general
                .iter()
                .filter(|g| !fast.iter().any(|f| close(g, f)))
                .count();
            let extra = fast
                .iter()
                .filter(|f| !general.iter().any(|g| close(g, f)))
                .count();
            lost += missing;
            if far < 10.0 {
                near_differ += missing + extra;
            } else {
                far_extra += extra;
            }
            for p in &fast {
                assert!(
                    poly.iter().all(|&q| p.eval(q) <= 1e-3),
                    "case {case}: {p:?}"
                );
                assert!(
                    corners.iter().all(|&q| p.eval(q) >= -1e-3),
                    "case {case}: {p:?}"
                );
            }
        }
        assert!(planes > 10_000, "{planes}");
        assert_eq!(near_differ, 0);
        // (rounding far out decides a rare plane either way; fewer planes only keep more)
        assert!(lost * 1000 <= planes, "{lost} of {planes} planes lost");
        assert!(
            far_extra > 100,
            "{far_extra}: the far cases do not test the tolerance"
        );
    }

    fn unit() -> Aabb {
        Aabb {
            min: [0.0; 3],
            max: [1.0; 3],
        }
    }

    #[test]
    fn clipping_a_box_by_a_diagonal_plane() {
        // x + y <= 1 keeps the lower-left prism.
        let p = Plane::through(Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0));
        let b = clipped_box_bounds(&unit(), &[p]).expect("non-empty");
        assert_eq!(b.max, [1.0, 1.0, 1.0]);
        // x <= 0.25 and y <= 0.5
        let px = Plane::through(Vec3::new(0.25, 0.0, 0.0), Vec3::X);
        let py = Plane::through(Vec3::new(0.0, 0.5, 0.0), Vec3::Y);
        let b = clipped_box_bounds(&unit(), &[px, py]).unwrap();
        assert!((b.max[0] - 0.25).abs() < 1e-6 && (b.max[1] - 0.5).abs() < 1e-6);
        assert_eq!(b.max[2], 1.0);
    }

    #[test]
    fn a_corner_cut_by_three_planes_keeps_its_interior_vertex() {
        // x + y + z >= 2.5 (as -x - y - z <= -2.5) keeps a small corner tetrahedron; then
        // x <= 0.9 and y <= 0.9 and z <= 0.9 cut it to a tiny region whose max is 0.9, min 0.7.
        let planes = [
            Plane::through(Vec3::splat(2.5 / 3.0), -Vec3::ONE),
            Plane::through(Vec3::splat(0.9), Vec3::X),
            Plane::through(Vec3::splat(0.9), Vec3::Y),
            Plane::through(Vec3::splat(0.9), Vec3::Z),
        ];
        let b = clipped_box_bounds(&unit(), &planes).unwrap();
        for i in 0..3 {
            assert!((b.max[i] - 0.9).abs() < 1e-4, "{b:?}");
            assert!((b.min[i] - 0.7).abs() < 1e-4, "{b:?}");
        }
    }

    #[test]
    fn empty_when_the_plane_excludes_the_box() {
        let p = Plane::through(Vec3::new(-1.0, 0.0, 0.0), Vec3::X); // x <= -1
        assert!(clipped_box_bounds(&unit(), &[p]).is_none());
        assert!(!p.touches_box(&unit()));
    }

    #[test]
    fn touches_box_is_closed() {
        let p = Plane::through(Vec3::ZERO, Vec3::X); // x <= 0 touches the x = 0 face
        assert!(p.touches_box(&unit()));
    }
}
