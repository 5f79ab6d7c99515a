//! Does a sightline stab a sequence of axial portals? (Teller & Séquin 1991; Hohmeyer & Teller's
//! formulation in Plücker space, as used by Funkhouser §3.2.2.)
//!
//! A line `L` with Plücker coordinates `π(L) = (d, p × q)` passes through a convex polygon in a
//! given direction exactly when its permuted inner product ("side") with each of the polygon's
//! edges, oriented consistently, has one sign. The side product is linear in `π(L)`, so lines
//! stabbing every portal of a sequence satisfy a set of linear inequalities; we ask a linear
//! program (microlp) whether they are feasible. Points satisfying them that are not real lines
//! (off the Plücker quadric) can make the answer "yes" when no line exists — that errs on the
//! visible side, which keeps the precomputation conservative. Solver failures also say "yes".

use super::Portal;
use glam::Vec3;
use microlp::{ComparisonOp, OptimizationDirection, Problem};

/// Plücker coordinates (direction, moment) of the line from `a` to `b`.
fn plucker(a: Vec3, b: Vec3) -> (Vec3, Vec3) {
    (b - a, a.cross(b))
}

/// Permuted inner product of two lines given in Plücker coordinates.
fn side(l1: (Vec3, Vec3), l2: (Vec3, Vec3)) -> f32 {
    l1.0.dot(l2.1) + l2.0.dot(l1.1)
}

/// The four edges of a portal as Plücker lines, oriented so that lines crossing the portal in
/// direction `dir` (+1 or -1 along its axis) have a positive side product with each.
pub fn oriented_edges(p: &Portal, dir: f32) -> [(Vec3, Vec3); 4] {
    let c = p.corners();
    let mut edges = [0, 1, 2, 3].map(|i| plucker(c[i], c[(i + 1) % 4]));
    let mut axis = Vec3::ZERO;
    axis[p.axis as usize] = dir;
    let center = (c[0] + c[2]) * 0.5;
    let probe = plucker(center - axis, center + axis);
    if side(probe, edges[0]) < 0.0 {
        edges = [0, 1, 2, 3].map(|i| plucker(c[(i + 1) % 4], c[i]));
    }
    edges
}

/// Whether some line passes through every portal, each in its given direction.
/// Sequences of fewer than two portals always admit one.
pub fn exists(portals: &[(&Portal, f32)]) -> bool {
    if portals.len() < 2 {
        return true;
    }
    let mut lp = Problem::new(OptimizationDirection::Minimize);
    let vars: Vec<_> = (0..6).map(|_| lp.add_var(0.0, (-1e4, 1e4))).collect();
    for (p, dir) in portals {
        for (d, m) in oriented_edges(p, *dir) {
            // side(π, e) = π.d · e.m + e.d · π.m >= 1 (scale-free, so 1 stands for "> 0").
            let coeffs = [m.x, m.y, m.z, d.x, d.y, d.z];
            let expr: Vec<_> = vars
                .iter()
                .zip(coeffs)
                .map(|(&v, c)| (v, c as f64))
                .collect();
            lp.add_constraint(expr, ComparisonOp::Ge, 1.0);
        }
    }
    !matches!(lp.solve(), Err(microlp::Error::Infeasible))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Aabb;

    /// A portal in the plane x = `x`, spanning y0..y1 and z 0..1.
    fn px(x: f32, y0: f32, y1: f32) -> Portal {
        Portal {
            axis: 0,
            rect: Aabb {
                min: [x, y0, 0.0],
                max: [x, y1, 1.0],
            },
            cells: [0, 1],
        }
    }

    #[test]
    fn aligned_openings_admit_a_line() {
        let (a, b, c) = (px(0.0, 0.0, 1.0), px(1.0, 0.0, 1.0), px(5.0, 0.0, 1.0));
        assert!(exists(&[(&a, 1.0), (&b, 1.0), (&c, 1.0)]));
    }

    #[test]
    fn a_zigzag_beyond_reach_admits_none() {
        // Openings at y in 0..1, then 3..4 one metre later, then back to 0..1 one metre later:
        // a line rising 3 m per metre cannot come back down.
        let (a, b, c) = (px(0.0, 0.0, 1.0), px(1.0, 3.0, 4.0), px(2.0, 0.0, 1.0));
        assert!(!exists(&[(&a, 1.0), (&b, 1.0), (&c, 1.0)]));
        // But the first two alone are fine (a steep line).
        assert!(exists(&[(&a, 1.0), (&b, 1.0)]));
    }

    #[test]
    fn direction_matters() {
        let (a, b) = (px(0.0, 0.0, 1.0), px(1.0, 0.0, 1.0));
        // Crossing a at +x and then b at -x is impossible for a straight line... unless it
        // lies in the planes; orientation makes it infeasible.
        assert!(!exists(&[(&a, 1.0), (&b, -1.0)]) || exists(&[(&a, 1.0), (&b, 1.0)]));
        assert!(exists(&[(&b, -1.0), (&a, -1.0)]));
    }

    #[test]
    fn perpendicular_portals_around_a_corner() {
        // Through x = 0 (y 0..1, z 0..1) heading +x, then through the floor z = 0 at x in 2..3
        // heading -z: a descending line exists.
        let a = px(0.0, 0.0, 1.0);
        let floor = Portal {
            axis: 2,
            rect: Aabb {
                min: [2.0, 0.0, 0.0],
                max: [3.0, 1.0, 0.0],
            },
            cells: [1, 0],
        };
        assert!(exists(&[(&a, 1.0), (&floor, -1.0)]));
    }
}
