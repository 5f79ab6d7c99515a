//! The grid a wall or slab is cut by ([`super::covered`]): which of its cells the triangles of a
//! face cover at every sample point, which an outline edge crosses, and the solid cells merged
//! into rectangles and outlined.

use super::EDGE_SLACK;
use glam::Vec2;

/// A rectilinear grid over the object's two long axes.
pub(super) struct Grid {
    pub(super) u: Vec<f32>,
    pub(super) v: Vec<f32>,
}

impl Grid {
    pub(super) fn cells(&self) -> (usize, usize) {
        (self.u.len() - 1, self.v.len() - 1)
    }

    /// Which cells (row-major by `v`) have their four corners and centre covered.
    pub(super) fn cover(&self, tris: &[[Vec2; 3]]) -> Vec<bool> {
        let (nu, nv) = self.cells();
        // Points: corners at (2i, 2j), centres at (2i+1, 2j+1), on a doubled lattice (each
        // line and the midpoint after it).
        let doubled = |l: &[f32]| -> Vec<f32> {
            (0..2 * l.len() - 1)
                .map(|k| {
                    if k % 2 == 0 {
                        l[k / 2]
                    } else {
                        (l[k / 2] + l[k / 2 + 1]) * 0.5
                    }
                })
                .collect()
        };
        let (mu, mv) = (doubled(&self.u), doubled(&self.v));
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

    /// Marks not covered every cell whose interior one of `edges` passes through.
    pub(super) fn cut(&self, covered: &mut [bool], edges: &[(Vec2, Vec2)]) {
        let nu = self.u.len() - 1;
        for &(a, b) in edges {
            let (lo, hi) = (a.min(b), a.max(b));
            let i0 = self.u.partition_point(|&x| x <= lo.x).saturating_sub(1);
            let i1 = self.u.partition_point(|&x| x < hi.x).min(nu);
            let j0 = self.v.partition_point(|&y| y <= lo.y).saturating_sub(1);
            let j1 = self.v.partition_point(|&y| y < hi.y).min(self.v.len() - 1);
            for j in j0..j1 {
                for i in i0..i1 {
                    let (clo, chi) = (
                        Vec2::new(self.u[i], self.v[j]),
                        Vec2::new(self.u[i + 1], self.v[j + 1]),
                    );
                    if covered[j * nu + i] && crosses_open(a, b, clo, chi) {
                        covered[j * nu + i] = false;
                    }
                }
            }
        }
    }

    /// Solid cells merged into rectangles `(i0, i1, j0, j1)` of grid line indices: runs along
    /// `u`, stacked along `v` while the run repeats.
    pub(super) fn rectangles(&self, solid: &[bool]) -> Vec<(usize, usize, usize, usize)> {
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
    pub(super) fn outline(&self, solid: &[bool]) -> Vec<(bool, f32, f32, f32)> {
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

/// Whether the segment `a`–`b` passes through the open rectangle `lo`–`hi` (Liang–Barsky).
pub(super) fn crosses_open(a: Vec2, b: Vec2, lo: Vec2, hi: Vec2) -> bool {
    let e = 1e-5;
    let (lo, hi) = (lo + Vec2::splat(e), hi - Vec2::splat(e));
    if lo.x >= hi.x || lo.y >= hi.y {
        return false;
    }
    let d = b - a;
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for (p, q) in [
        (-d.x, a.x - lo.x),
        (d.x, hi.x - a.x),
        (-d.y, a.y - lo.y),
        (d.y, hi.y - a.y),
    ] {
        if p == 0.0 {
            if q <= 0.0 {
                return false;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    t0 < t1
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
