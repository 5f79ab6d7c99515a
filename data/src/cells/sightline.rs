//! Does a sightline stab a sequence of axial portals? (Teller & Séquin 1991; Hohmeyer & Teller's
//! formulation in Plücker space, as used by Funkhouser §3.2.2.)
//!
//! A line `L` with Plücker coordinates `π(L) = (d, p × q)` passes through a convex polygon in a
//! given direction exactly when its permuted inner product ("side") with each of the polygon's
//! edges, oriented consistently, is positive. The side product is linear in `π(L)`, so lines
//! stabbing every portal of a sequence satisfy `A π > 0`, one row per edge. By Gordan's theorem
//! that system has a solution unless some `y ≥ 0, y ≠ 0` has `Aᵀ y = 0`, which a phase-1
//! simplex on 7 equality rows decides ([`gordan_infeasible`]); a general LP solver spent ~100 µs
//! per test here, this one a few µs.
//!
//! Points satisfying the inequalities that are not real lines (off the Plücker quadric) can
//! make the answer "yes" when no line exists. That errs on the visible side, as do numerical
//! doubts and iteration limits, which keeps the precomputation conservative.

use super::Portal;
use glam::{DVec3, Vec3};
/// The four edges of a portal as Plücker lines `(direction, moment)` about `origin`, in f64,
/// oriented so that lines crossing the portal in direction `dir` (+1 or -1 along its axis)
/// have a positive side product with each. Corners are made relative to `origin` first: their
/// differences are exact, while products at building coordinates in f32 are not.
pub fn oriented_edges(p: &Portal, dir: f32, origin: Vec3) -> [(DVec3, DVec3); 4] {
    let c = p.corners().map(|q| (q - origin).as_dvec3());
    let mut edges = [0, 1, 2, 3].map(|i| (c[(i + 1) % 4] - c[i], c[i].cross(c[(i + 1) % 4])));
    let center = (c[0] + c[2]) * 0.5;
    let mut axis = DVec3::ZERO;
    axis[p.axis as usize] = dir as f64;
    let probe = (2.0 * axis, (center - axis).cross(center + axis));
    if side(probe, edges[0]) < 0.0 {
        // Reversing a line negates both its direction and its moment.
        edges = edges.map(|(d, m)| (-d, -m));
    }
    edges
}

/// Permuted inner product of two lines in Plücker coordinates.
fn side(a: (DVec3, DVec3), b: (DVec3, DVec3)) -> f64 {
    a.0.dot(b.1) + b.0.dot(a.1)
}

/// One inequality row per portal edge: `side(π, e) = π.d · e.m + e.d · π.m > 0`, linear in
/// `π = (π.d, π.m)`; rows normalised to unit length.
fn edge_rows(portals: &[(&Portal, f32)]) -> Vec<[f64; 6]> {
    let origin = portals[0].0.rect.center();
    portals
        .iter()
        .flat_map(|(p, dir)| oriented_edges(p, *dir, origin))
        .filter_map(|(d, m)| {
            let row = [m.x, m.y, m.z, d.x, d.y, d.z];
            let norm = row.iter().map(|x| x * x).sum::<f64>().sqrt();
            (norm > 0.0).then(|| row.map(|x| x / norm))
        })
        .collect()
}

/// Whether some line passes through every portal, each in its given direction.
/// Sequences of fewer than two portals always admit one.
pub fn exists(portals: &[(&Portal, f32)]) -> bool {
    if portals.len() < 2 {
        return true;
    }
    let rows = edge_rows(portals);
    !gordan_infeasible(&rows)
}

/// True only when some non-negative combination of the rows, with weights summing to 1, is
/// zero: then no `x` has `row · x > 0` for every row. Decided by phase 1 of the simplex method
/// (Bland's rule, so it cannot cycle) on `Σ y_i row_i = 0, Σ y_i = 1, y ≥ 0`. Any doubt
/// (iteration limit, tiny pivots) answers false.
pub fn gordan_infeasible(rows: &[[f64; 6]]) -> bool {
    const R: usize = 7;
    const TOL: f64 = 1e-9;
    let m = rows.len();
    let cols = m + R + 1; // y, artificials, rhs
    let rhs = cols - 1;
    let mut t = vec![0.0f64; R * cols];
    for (i, row) in rows.iter().enumerate() {
        for r in 0..6 {
            t[r * cols + i] = row[r];
        }
        t[6 * cols + i] = 1.0;
    }
    for r in 0..R {
        t[r * cols + m + r] = 1.0;
    }
    t[6 * cols + rhs] = 1.0;
    let mut basis: Vec<usize> = (m..m + R).collect();
    for _ in 0..50 * (m + R) {
        // Phase-1 reduced cost of column j: sum over rows whose basic variable is artificial.
        // (Artificial columns cost 1 themselves.)
        let reduced = |j: usize| -> f64 {
            let cost = if j >= m { 1.0 } else { 0.0 };
            (0..R)
                .filter(|&r| basis[r] >= m)
                .map(|r| t[r * cols + j])
                .sum::<f64>()
                - cost
        };
        let Some(enter) = (0..m + R).find(|&j| !basis.contains(&j) && reduced(j) > TOL) else {
            let objective: f64 = (0..R)
                .filter(|&r| basis[r] >= m)
                .map(|r| t[r * cols + rhs])
                .sum();
            return objective < 1e-7;
        };
        let mut leave: Option<(usize, f64)> = None;
        for r in 0..R {
            let a = t[r * cols + enter];
            if a > TOL {
                let ratio = t[r * cols + rhs] / a;
                if leave.is_none_or(|(lr, best)| {
                    ratio < best - 1e-12 || (ratio <= best + 1e-12 && basis[r] < basis[lr])
                }) {
                    leave = Some((r, ratio));
                }
            }
        }
        let Some((pr, _)) = leave else {
            return false; // unbounded phase 1 cannot happen; be conservative anyway
        };
        pivot(&mut t, cols, pr, enter);
        basis[pr] = enter;
    }
    false
}

fn pivot(t: &mut [f64], cols: usize, pr: usize, pc: usize) {
    let p = t[pr * cols + pc];
    for j in 0..cols {
        t[pr * cols + j] /= p;
    }
    for r in 0..t.len() / cols {
        if r == pr {
            continue;
        }
        let f = t[r * cols + pc];
        if f != 0.0 {
            for j in 0..cols {
                t[r * cols + j] -= f * t[pr * cols + j];
            }
        }
    }
}

/// The same question asked of a general LP solver (microlp); the tests cross-check with it.
#[cfg(test)]
fn exists_by_microlp(portals: &[(&Portal, f32)]) -> bool {
    use microlp::{ComparisonOp, OptimizationDirection, Problem};
    let mut lp = Problem::new(OptimizationDirection::Minimize);
    let vars: Vec<_> = (0..6).map(|_| lp.add_var(0.0, (-1e4, 1e4))).collect();
    for row in edge_rows(portals) {
        let expr: Vec<_> = vars.iter().zip(row).map(|(&v, c)| (v, c)).collect();
        lp.add_constraint(expr, ComparisonOp::Ge, 1e-3);
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
        // Crossing one opening at +x and the other at -x is impossible for a straight line;
        // both at +x, or both at -x, are fine. (Only directions count, not the order.)
        assert!(!exists(&[(&a, 1.0), (&b, -1.0)]));
        assert!(!exists(&[(&b, -1.0), (&a, 1.0)]));
        assert!(exists(&[(&a, 1.0), (&b, 1.0)]));
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

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 300, ..Default::default() })]

        /// The simplex never says "no line" where the general LP solver finds one.
        #[test]
        fn agrees_with_a_general_lp_solver(
            spec in proptest::collection::vec((0u8..3, -3i32..3, -2i32..3, 1i32..3, -2i32..3, 1i32..3), 2..6)
        ) {
            let portals: Vec<Portal> = spec.iter().enumerate().map(|(i, &(axis, _, u0, du, v0, dv))| {
                let a = axis as usize;
                let (u, v) = ((a + 1) % 3, (a + 2) % 3);
                let mut min = [0.0f32; 3];
                let mut max = [0.0f32; 3];
                min[a] = i as f32 * 2.0; max[a] = min[a];
                min[u] = u0 as f32; max[u] = (u0 + du) as f32;
                min[v] = v0 as f32; max[v] = (v0 + dv) as f32;
                Portal { axis, rect: Aabb { min, max }, cells: [0, 1] }
            }).collect();
            let seq: Vec<(&Portal, f32)> = portals.iter().zip(&spec).map(|(p, s)| (p, if s.1 >= 0 { 1.0 } else { -1.0 })).collect();
            let ours = exists(&seq);
            let theirs = exists_by_microlp(&seq);
            proptest::prop_assert!(ours || !theirs, "simplex says no line, microlp found one");
        }
    }

    /// The other direction: where the general solver proves no line exists, the simplex says
    /// so too (it may answer "yes" only out of numerical doubt, which keeps the precompute
    /// conservative but culls less), on 2,000 random portal sequences with many of each answer.
    #[test]
    fn finds_the_sequences_without_a_line_that_a_general_solver_finds() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (mut none, mut agreed, mut some) = (0, 0, 0);
        for _ in 0..2000 {
            let n = rng.random_range(2..5);
            let portals: Vec<Portal> = (0..n)
                .map(|i| {
                    let a = rng.random_range(0..3usize);
                    let (u, v) = ((a + 1) % 3, (a + 2) % 3);
                    let mut min = [0.0f32; 3];
                    let mut max = [0.0f32; 3];
                    min[a] = i as f32 * 2.0;
                    max[a] = min[a];
                    min[u] = rng.random_range(-3.0..3.0);
                    max[u] = min[u] + rng.random_range(0.2..2.0);
                    min[v] = rng.random_range(-3.0..3.0);
                    max[v] = min[v] + rng.random_range(0.2..2.0);
                    Portal {
                        axis: a as u8,
                        rect: Aabb { min, max },
                        cells: [0, 1],
                    }
                })
                .collect();
            let seq: Vec<(&Portal, f32)> = portals
                .iter()
                .map(|p| (p, if rng.random_bool(0.5) { 1.0 } else { -1.0 }))
                .collect();
            if exists_by_microlp(&seq) {
                some += 1;
                assert!(
                    exists(&seq),
                    "simplex says no line, microlp found one: {seq:?}"
                );
            } else {
                none += 1;
                agreed += usize::from(!exists(&seq));
            }
        }
        assert!(
            none >= 200 && some >= 200,
            "{none} without a line, {some} with one"
        );
        assert!(
            agreed * 100 >= none * 98,
            "the simplex found {agreed} of the {none} sequences without a line"
        );
    }
}

#[cfg(test)]
mod regression {
    use super::*;
    use crate::geometry::Aabb;

    fn pz(z: f32, x0: f32, x1: f32) -> Portal {
        Portal {
            axis: 2,
            rect: Aabb {
                min: [x0, 3.9500003, z],
                max: [x1, 6.05, z],
            },
            cells: [0, 1],
        }
    }

    /// Two doors across a corridor, each a thin cell with a portal on both faces (found on the
    /// `mega` preset: a real ray passes, the first simplex said no).
    #[test]
    fn doors_across_a_corridor() {
        let ps = [
            pz(9.700001, 76.9, 77.9),
            pz(9.5, 76.9, 77.9),
            pz(7.3, 77.600006, 78.600006),
            pz(7.1000004, 77.600006, 78.600006),
        ];
        let seq: Vec<(&Portal, f32)> = ps.iter().map(|p| (p, -1.0)).collect();
        assert!(exists_by_microlp(&seq), "microlp");
        assert!(exists(&seq), "simplex");
    }
}
