//! Calibration of the cost model from timed samples (Funkhouser 1993 §4.2.3, Fig. 4.15: the
//! coefficients are found "experimentally by rendering sample objects"): the geometry, per-draw
//! and fill fits, the start-up calibration that combines them, and the small non-negative
//! least-squares solver they share.

use super::{CostModel, DrawSample, Fit};

impl CostModel {
    /// Fits `seconds ≈ overhead + c1·triangles + c2·vertices` to `(triangles, vertices,
    /// seconds)` samples by non-negative least squares, keeping `c0`, `c3` and `c4` from `self`.
    /// Degenerate samples (none, all zero, no slope) leave `self` unchanged (`fitted: false`).
    ///
    /// Samples that repeat one mesh `n` times fold the per-draw overhead into `c1`/`c2` (and,
    /// as vertices are then proportional to triangles, put it all in `c1`): fit from a prior with
    /// `c0 = 0` as [`CostModel::calibrate`] does, or use [`CostModel::fit_draws`].
    pub fn fit_geometry(&self, samples: &[(u64, u64, f64)]) -> Fit {
        let rows = samples
            .iter()
            .map(|&(t, v, s)| ([1.0, t as f64, v as f64], s));
        let solved = solve_nnls(rows);
        let fitted = solved.as_ref().is_some_and(|s| s.x[1] + s.x[2] > 0.0);
        match solved.filter(|_| fitted) {
            Some(s) => Fit {
                model: CostModel {
                    c1: s.x[1],
                    c2: s.x[2],
                    ..*self
                },
                overhead_s: s.x[0],
                rms_error_s: s.rms,
                fitted: true,
            },
            None => self.unfitted(),
        }
    }

    /// Fits `seconds ≈ overhead + c0·draws + c1·triangles + c2·vertices` by non-negative least
    /// squares, keeping `c3` and `c4` from `self`. `c0` is only fitted when the samples vary the number of
    /// draws independently of the geometry; otherwise the fit puts it in `c1`/`c2` and `c0` is 0.
    pub fn fit_draws(&self, samples: &[DrawSample]) -> Fit {
        let rows = samples.iter().map(|s| {
            let x = [1.0, s.draws as f64, s.triangles as f64, s.vertices as f64];
            (x, s.seconds)
        });
        let solved = solve_nnls(rows);
        let fitted = solved.as_ref().is_some_and(|s| s.x[2] + s.x[3] > 0.0);
        match solved.filter(|_| fitted) {
            Some(s) => Fit {
                model: CostModel {
                    c0: s.x[1],
                    c1: s.x[2],
                    c2: s.x[3],
                    ..*self
                },
                overhead_s: s.x[0],
                rms_error_s: s.rms,
                fitted: true,
            },
            None => self.unfitted(),
        }
    }

    /// Fits `seconds ≈ overhead + c3·pixels` to `(pixels, seconds)` samples of fill-bound draws
    /// (few large polygons) by non-negative least squares, keeping `c0..c2` and `c4` from
    /// `self` (`c4` is what a texture adds to `c3`: refit it after a new `c3`).
    pub fn fit_fill(&self, samples: &[(f64, f64)]) -> Fit {
        let rows = samples.iter().map(|&(p, s)| ([1.0, p], s));
        let solved = solve_nnls(rows);
        match solved.filter(|s| s.x[1] > 0.0) {
            Some(s) => Fit {
                model: CostModel {
                    c3: s.x[1],
                    ..*self
                },
                overhead_s: s.x[0],
                rms_error_s: s.rms,
                fitted: true,
            },
            None => self.unfitted(),
        }
    }

    /// Fits `seconds ≈ overhead + (c3 + c4)·pixels` to `(pixels, seconds)` samples of textured
    /// fill-bound draws, keeping every other coefficient: `c4` is the fitted slope less `c3`
    /// (never negative). Degenerate samples leave `self` unchanged (`fitted: false`).
    pub fn fit_textured_fill(&self, samples: &[(f64, f64)]) -> Fit {
        let fit = self.fit_fill(samples);
        Fit {
            model: CostModel {
                c4: if fit.fitted {
                    (fit.model.c3 - self.c3).max(0.0)
                } else {
                    self.c4
                },
                ..*self
            },
            ..fit
        }
    }

    /// Start-up calibration: [`CostModel::default`] refined by [`CostModel::fit_geometry`],
    /// [`CostModel::fit_fill`] and [`CostModel::fit_textured_fill`] (`textured` may be empty);
    /// any part the samples cannot determine keeps its default. A successful geometry fit sets
    /// `c0 = 0`, since its slopes already include the per-draw overhead of the repeated sample
    /// draws.
    pub fn calibrate(
        geometry: &[(u64, u64, f64)],
        fill: &[(f64, f64)],
        textured: &[(f64, f64)],
    ) -> CostModel {
        let prior = CostModel {
            c0: 0.0,
            ..CostModel::default()
        };
        let geometry = prior.fit_geometry(geometry);
        let model = if geometry.fitted {
            geometry.model
        } else {
            CostModel::default()
        };
        let model = model.fit_fill(fill).model;
        model.fit_textured_fill(textured).model
    }

    fn unfitted(&self) -> Fit {
        Fit {
            model: *self,
            overhead_s: 0.0,
            rms_error_s: 0.0,
            fitted: false,
        }
    }
}

/// A solved least-squares problem: coefficients and root-mean-square residual.
#[derive(Debug, Clone, Copy)]
struct Solved<const K: usize> {
    x: [f64; K],
    rms: f64,
}

/// The normal equations `AᵀA x = Aᵀy` of a small least-squares problem, plus `yᵀy` and the
/// number of rows, accumulated from `(row, y)` pairs.
struct Normal<const K: usize> {
    ata: [[f64; K]; K],
    aty: [f64; K],
    yty: f64,
    rows: usize,
}

impl<const K: usize> Normal<K> {
    /// Accumulates the finite rows with non-negative, finite `y`; skips the rest.
    fn accumulate(rows: impl Iterator<Item = ([f64; K], f64)>) -> Self {
        let mut n = Normal {
            ata: [[0.0; K]; K],
            aty: [0.0; K],
            yty: 0.0,
            rows: 0,
        };
        for (a, y) in rows {
            if y.is_finite() && y >= 0.0 && a.iter().all(|v| v.is_finite()) {
                n.add(&a, y);
            }
        }
        n
    }

    fn add(&mut self, a: &[f64; K], y: f64) {
        for i in 0..K {
            for j in 0..K {
                self.ata[i][j] += a[i] * a[j];
            }
            self.aty[i] += a[i] * y;
        }
        self.yty += y * y;
        self.rows += 1;
    }
}

/// Non-negative least squares for `K ≤ 4` unknowns: every subset of the unknowns is solved
/// unconstrained (on the Jacobi-scaled normal equations); the feasible (all ≥ 0) subset with the
/// least residual is the exact NNLS optimum. Earlier (larger, lower-index) subsets win ties, so
/// collinear columns resolve deterministically. `None` when there are no usable rows.
fn solve_nnls<const K: usize>(rows: impl Iterator<Item = ([f64; K], f64)>) -> Option<Solved<K>> {
    let n = Normal::accumulate(rows);
    if n.rows == 0 || n.yty <= 0.0 {
        return None;
    }
    let scale: [f64; K] = std::array::from_fn(|i| n.ata[i][i].sqrt());
    let tiny = 1e-9 * n.yty.sqrt();
    let mut best: Option<([f64; K], f64)> = None;
    for mask in subsets_largest_first(K) {
        let Some(x) = solve_subset(&n, &scale, mask, tiny) else {
            continue;
        };
        let residual = residual_sq(&n, &x);
        let better = best.is_none_or(|(_, r)| residual < r - 1e-12 * n.yty);
        if better {
            best = Some((x, residual));
        }
    }
    best.map(|(x, r)| Solved {
        x,
        rms: (r.max(0.0) / n.rows as f64).sqrt(),
    })
}

/// Bit masks of all non-empty subsets of `k` unknowns, larger subsets first, then by mask.
fn subsets_largest_first(k: usize) -> Vec<u32> {
    let mut masks: Vec<u32> = (1..(1u32 << k)).collect();
    masks.sort_by_key(|m| (std::cmp::Reverse(m.count_ones()), *m));
    masks
}

/// Solves the normal equations restricted to the unknowns in `mask` (the others are 0). `None`
/// if the restricted system is singular, uses an all-zero column, or has a negative solution.
/// Scaled solutions within `tiny` of zero are rounding noise and become exactly 0.
fn solve_subset<const K: usize>(
    n: &Normal<K>,
    scale: &[f64; K],
    mask: u32,
    tiny: f64,
) -> Option<[f64; K]> {
    let idx: Vec<usize> = (0..K).filter(|i| mask & (1 << i) != 0).collect();
    if idx
        .iter()
        .any(|&i| scale[i] <= 0.0 || !scale[i].is_finite())
    {
        return None;
    }
    let m: Vec<Vec<f64>> = idx
        .iter()
        .map(|&i| {
            idx.iter()
                .map(|&j| n.ata[i][j] / (scale[i] * scale[j]))
                .collect()
        })
        .collect();
    let b: Vec<f64> = idx.iter().map(|&i| n.aty[i] / scale[i]).collect();
    let z = gauss_solve(m, b)?;
    let mut x = [0.0; K];
    for (k, &i) in idx.iter().enumerate() {
        if z[k] < -tiny || !z[k].is_finite() {
            return None;
        }
        x[i] = if z[k] <= tiny { 0.0 } else { z[k] / scale[i] };
    }
    Some(x)
}

/// `‖Ax − y‖² = yᵀy − 2xᵀAᵀy + xᵀAᵀAx`.
fn residual_sq<const K: usize>(n: &Normal<K>, x: &[f64; K]) -> f64 {
    let mut quad = 0.0;
    let mut lin = 0.0;
    for i in 0..K {
        lin += x[i] * n.aty[i];
        for j in 0..K {
            quad += x[i] * n.ata[i][j] * x[j];
        }
    }
    n.yty - 2.0 * lin + quad
}

/// Gaussian elimination with partial pivoting on a small, well-scaled system (unit diagonal).
/// `None` when a pivot falls below `1e-10`, i.e. the columns are (nearly) collinear.
fn gauss_solve(mut m: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for col in 0..n {
        let pivot = (col..n).max_by(|&r, &s| m[r][col].abs().total_cmp(&m[s][col].abs()))?;
        if m[pivot][col].abs() < 1e-10 {
            return None;
        }
        m.swap(col, pivot);
        b.swap(col, pivot);
        let (top, rest) = m.split_at_mut(col + 1);
        let pivot_row = &top[col];
        for (r, row) in rest.iter_mut().enumerate() {
            let f = row[col] / pivot_row[col];
            for (x, p) in row[col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
            }
            b[col + 1 + r] -= f * b[col];
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let tail: f64 = (row + 1..n).map(|k| m[row][k] * x[k]).sum();
        x[row] = (b[row] - tail) / m[row][row];
    }
    Some(x)
}
