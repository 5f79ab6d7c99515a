//! The rendering cost model of detail elision (Funkhouser 1993 §4.2.3, "Cost Heuristic").
//!
//! Funkhouser models the graphics pipeline as two concurrent stages, *per primitive* and *per
//! pixel*, so an object tuple takes as long as its slower stage:
//!
//! ```text
//! Cost(O, L) = max(C0 + C1·Poly(O, L) + C2·Vert(O, L),  C3·Pix(O))        [seconds]
//! ```
//!
//! `C0` is our addition: the fixed host-side overhead of one draw call, which matters on today's
//! APIs when thousands of small objects are drawn. The coefficients are found "experimentally by
//! rendering sample objects with a wide variety of sizes and LODs" (§4.2.3, Fig. 4.15):
//! [`CostModel::fit_geometry`], [`CostModel::fit_draws`] and [`CostModel::fit_fill`] solve small
//! non-negative least-squares problems over timed samples (the client times them at start-up).
//! Funkhouser hoped "to extend our system to learn appropriate cost coefficients during real-time
//! walkthroughs"; [`OnlineCost`] does that with a smoothed correction factor refitted from
//! measured frame times.
//!
//! Everything here is pure arithmetic: no GPU, no clock.

/// Smallest correction factor [`OnlineCost`] will apply.
pub const MIN_FACTOR: f64 = 0.25;
/// Largest correction factor [`OnlineCost`] will apply.
pub const MAX_FACTOR: f64 = 4.0;

/// Coefficients of Funkhouser's cost model (§4.2.3), all in seconds per unit.
///
/// `Cost = max(c0 + c1·triangles + c2·vertices, c3·pixels)`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CostModel {
    /// Seconds of fixed overhead per draw call (state setup, command encoding).
    pub c0: f64,
    /// Seconds per triangle in the per-primitive stage (Funkhouser's `C1`, per polygon).
    pub c1: f64,
    /// Seconds per vertex in the per-primitive stage (Funkhouser's `C2`).
    pub c2: f64,
    /// Seconds per covered pixel in the per-pixel stage (Funkhouser's `C3`).
    pub c3: f64,
}

impl Default for CostModel {
    /// Speeds of a software rasteriser (llvmpipe on a few cores): about 8 M triangles/s for
    /// indexed meshes with half as many vertices as triangles, 50 M vertices/s, 400 M pixels/s,
    /// 5 µs per draw.
    fn default() -> Self {
        CostModel {
            c0: 5.0e-6,
            c1: 1.15e-7,
            c2: 2.0e-8,
            c3: 2.5e-9,
        }
    }
}

/// One timed calibration sample: `draws` draw calls of `triangles` and `vertices` in total,
/// drawn small enough on screen that pixel fill is negligible, which took `seconds`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrawSample {
    /// Number of draw calls in the sample.
    pub draws: u64,
    /// Triangles drawn, all draws together.
    pub triangles: u64,
    /// Vertices processed, all draws together.
    pub vertices: u64,
    /// Measured time of the sample, in seconds.
    pub seconds: f64,
}

/// The result of a calibration fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// The model with the fitted coefficients (the others copied from the prior model).
    pub model: CostModel,
    /// The fitted fixed cost of one sample (per-frame overhead such as clear and submit); it is
    /// not part of the per-object cost, so it is reported here and not stored in the model.
    pub overhead_s: f64,
    /// Root-mean-square residual of the fit, in seconds (0 when nothing was fitted).
    pub rms_error_s: f64,
    /// Whether the samples determined the coefficients; when false, `model` is the prior.
    pub fitted: bool,
}

impl CostModel {
    /// Estimated seconds to draw an object of `tris` triangles and `verts` vertices covering
    /// `pixels` pixels: `max(c0 + c1·tris + c2·verts, c3·pixels)` (§4.2.3). A draw of zero
    /// triangles draws nothing and costs 0.
    pub fn cost(&self, tris: u64, verts: u64, pixels: f64) -> f64 {
        if tris == 0 {
            return 0.0;
        }
        let pixels = if pixels.is_finite() {
            pixels.max(0.0)
        } else {
            0.0
        };
        let geometry = self.c0 + self.c1 * tris as f64 + self.c2 * verts as f64;
        geometry.max(self.c3 * pixels)
    }

    /// Triangles per second this model predicts for geometry-bound meshes with half as many
    /// vertices as triangles, ignoring the per-draw overhead.
    pub fn triangles_per_second(&self) -> f64 {
        let per_tri = self.c1 + 0.5 * self.c2;
        if per_tri > 0.0 {
            1.0 / per_tri
        } else {
            f64::INFINITY
        }
    }

    /// Fits `seconds ≈ overhead + c1·triangles + c2·vertices` to `(triangles, vertices,
    /// seconds)` samples by non-negative least squares, keeping `c0` and `c3` from `self`.
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
    /// squares, keeping `c3` from `self`. `c0` is only fitted when the samples vary the number of
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
    /// (few large polygons) by non-negative least squares, keeping `c0..c2` from `self`.
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

    /// Start-up calibration: [`CostModel::default`] refined by [`CostModel::fit_geometry`] and
    /// [`CostModel::fit_fill`]; any part the samples cannot determine keeps its default. A
    /// successful geometry fit sets `c0 = 0`, since its slopes already include the per-draw
    /// overhead of the repeated sample draws.
    pub fn calibrate(geometry: &[(u64, u64, f64)], fill: &[(f64, f64)]) -> CostModel {
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
        model.fit_fill(fill).model
    }

    /// Every coefficient multiplied by `factor` (used by [`OnlineCost::apply`]).
    pub fn scaled(&self, factor: f64) -> CostModel {
        CostModel {
            c0: self.c0 * factor,
            c1: self.c1 * factor,
            c2: self.c2 * factor,
            c3: self.c3 * factor,
        }
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

/// Online refit of the cost model from measured frame times (the "learning" Funkhouser proposes
/// at the end of §4.2.3's cost heuristic).
///
/// It keeps one multiplicative correction factor `f`, applied to every prediction. After each
/// frame, [`OnlineCost::observe`] moves `log f` toward `log(measured / base prediction)` by an
/// exponential moving average with weight `alpha`; the per-frame ratio and `f` are both clamped
/// to `[MIN_FACTOR, MAX_FACTOR]`, so a hiccup (a page fault, a compositor stall) cannot derail
/// the frame budget.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnlineCost {
    factor: f64,
    alpha: f64,
}

impl Default for OnlineCost {
    /// Factor 1 and smoothing weight 0.1 (about ten frames of memory).
    fn default() -> Self {
        OnlineCost::new(0.1)
    }
}

impl OnlineCost {
    /// A correction of 1 that learns with exponential-moving-average weight `alpha` (clamped to
    /// `0..=1`; 0 never learns, 1 trusts only the last frame).
    pub fn new(alpha: f64) -> Self {
        let alpha = if alpha.is_finite() {
            alpha.clamp(0.0, 1.0)
        } else {
            0.1
        };
        OnlineCost { factor: 1.0, alpha }
    }

    /// The current correction factor (measured / base-model predicted), in
    /// `[MIN_FACTOR, MAX_FACTOR]`.
    pub fn factor(&self) -> f64 {
        self.factor
    }

    /// A base-model prediction corrected by the current factor.
    pub fn correct(&self, base_s: f64) -> f64 {
        base_s * self.factor
    }

    /// The base model with the correction folded into its coefficients: hand this to the
    /// elider so that its predictions are corrected ones.
    pub fn apply(&self, base: &CostModel) -> CostModel {
        base.scaled(self.factor)
    }

    /// Learns from one frame. `planned_s` is the prediction made with the *corrected* model
    /// (`apply`/`correct`, e.g. the elider's `Frame::predicted_s`), `measured_s` the frame's
    /// measured render time. Non-finite or non-positive values are ignored.
    pub fn observe(&mut self, planned_s: f64, measured_s: f64) {
        let valid = |x: f64| x.is_finite() && x > 0.0;
        if !valid(planned_s) || !valid(measured_s) {
            return;
        }
        let ratio = (measured_s / planned_s).clamp(MIN_FACTOR, MAX_FACTOR);
        let updated = self.factor * ratio.powf(self.alpha);
        self.factor = updated.clamp(MIN_FACTOR, MAX_FACTOR);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Tiny deterministic xorshift64* generator for test data.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }

        /// Uniform in `[lo, hi)`.
        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn close(got: f64, want: f64, rel: f64) -> bool {
        (got - want).abs() <= rel * want.abs()
    }

    const TRUTH: CostModel = CostModel {
        c0: 1.0e-5,
        c1: 2.0e-7,
        c2: 5.0e-8,
        c3: 4.0e-9,
    };

    fn geometry_samples(rng: &mut Rng, overhead: f64, noise: f64) -> Vec<(u64, u64, f64)> {
        (0..40)
            .map(|_| {
                let t = rng.range(1e3, 1e6) as u64;
                let v = (t as f64 * rng.range(0.3, 3.0)) as u64;
                let s = overhead + TRUTH.c1 * t as f64 + TRUTH.c2 * v as f64;
                (t, v, s * rng.range(1.0 - noise, 1.0 + noise))
            })
            .collect()
    }

    #[test]
    fn cost_is_max_of_geometry_and_fill() {
        let m = TRUTH;
        let geometry = m.c0 + m.c1 * 1000.0 + m.c2 * 500.0;
        assert_eq!(m.cost(1000, 500, 10.0), geometry);
        let fill = m.c3 * 1.0e7;
        assert!(fill > geometry);
        assert_eq!(m.cost(1000, 500, 1.0e7), fill);
    }

    #[test]
    fn zero_triangles_cost_nothing_and_bad_pixels_are_ignored() {
        let m = CostModel::default();
        assert_eq!(m.cost(0, 0, 1.0e9), 0.0);
        assert_eq!(m.cost(10, 5, f64::NAN), m.cost(10, 5, 0.0));
        assert_eq!(m.cost(10, 5, -100.0), m.cost(10, 5, 0.0));
    }

    #[test]
    fn default_is_about_eight_million_triangles_per_second() {
        let tps = CostModel::default().triangles_per_second();
        assert!((7.0e6..9.0e6).contains(&tps), "{tps}");
        let one_second = CostModel::default().cost(8_000_000, 4_000_000, 0.0);
        assert!((0.9..1.1).contains(&one_second), "{one_second}");
    }

    #[test]
    fn fit_geometry_recovers_known_coefficients() {
        let samples = geometry_samples(&mut Rng(7), 2.0e-3, 0.0);
        let fit = CostModel::default().fit_geometry(&samples);
        assert!(fit.fitted);
        assert!(close(fit.model.c1, TRUTH.c1, 0.05), "{:?}", fit.model);
        assert!(close(fit.model.c2, TRUTH.c2, 0.05), "{:?}", fit.model);
        assert!(close(fit.overhead_s, 2.0e-3, 0.05), "{}", fit.overhead_s);
        assert_eq!(fit.model.c0, CostModel::default().c0);
        assert_eq!(fit.model.c3, CostModel::default().c3);
        assert!(fit.rms_error_s < 1e-9);
    }

    #[test]
    fn fit_geometry_with_noise_stays_close() {
        let samples = geometry_samples(&mut Rng(11), 1.0e-3, 0.05);
        let fit = CostModel::default().fit_geometry(&samples);
        assert!(close(fit.model.c1, TRUTH.c1, 0.15), "{:?}", fit.model);
        assert!(close(fit.model.c2, TRUTH.c2, 0.25), "{:?}", fit.model);
        let predicted = fit.overhead_s + fit.model.cost(500_000, 250_000, 0.0) - fit.model.c0;
        let truth = 1.0e-3 + TRUTH.c1 * 500_000.0 + TRUTH.c2 * 250_000.0;
        assert!(close(predicted, truth, 0.05), "{predicted} vs {truth}");
    }

    #[test]
    fn fit_draws_recovers_per_draw_overhead() {
        let mut rng = Rng(3);
        let samples: Vec<DrawSample> = (0..50)
            .map(|_| {
                let draws = rng.range(1.0, 2000.0) as u64;
                let triangles = rng.range(1e3, 1e6) as u64;
                let vertices = (triangles as f64 * rng.range(0.3, 3.0)) as u64;
                let seconds = 5.0e-4
                    + TRUTH.c0 * draws as f64
                    + TRUTH.c1 * triangles as f64
                    + TRUTH.c2 * vertices as f64;
                DrawSample {
                    draws,
                    triangles,
                    vertices,
                    seconds,
                }
            })
            .collect();
        let fit = CostModel::default().fit_draws(&samples);
        for (got, want) in [
            (fit.model.c0, TRUTH.c0),
            (fit.model.c1, TRUTH.c1),
            (fit.model.c2, TRUTH.c2),
            (fit.overhead_s, 5.0e-4),
        ] {
            assert!(close(got, want, 0.05), "{got} vs {want}");
        }
    }

    #[test]
    fn fit_fill_recovers_per_pixel_coefficient() {
        let mut rng = Rng(5);
        let samples: Vec<(f64, f64)> = (0..20)
            .map(|_| {
                let px = rng.range(1e4, 1e7);
                (px, 1.0e-3 + TRUTH.c3 * px)
            })
            .collect();
        let fit = CostModel::default().fit_fill(&samples);
        assert!(fit.fitted);
        assert!(close(fit.model.c3, TRUTH.c3, 0.05), "{:?}", fit.model);
        assert!(close(fit.overhead_s, 1.0e-3, 0.05));
        assert_eq!(fit.model.c1, CostModel::default().c1);
    }

    #[test]
    fn collinear_vertices_give_a_finite_accurate_fit() {
        // Every sample is one mesh drawn n times: vertices = 3·triangles exactly.
        let samples: Vec<(u64, u64, f64)> = (1..=8)
            .map(|n| {
                let t = 10_000 * n;
                (
                    t,
                    3 * t,
                    1.0e-3 + TRUTH.c1 * t as f64 + TRUTH.c2 * 3.0 * t as f64,
                )
            })
            .collect();
        let fit = CostModel::default().fit_geometry(&samples);
        let m = fit.model;
        assert!(fit.fitted && m.c1 >= 0.0 && m.c2 >= 0.0, "{m:?}");
        let per_tri = m.c1 + 3.0 * m.c2;
        assert!(close(per_tri, TRUTH.c1 + 3.0 * TRUTH.c2, 0.01), "{m:?}");
    }

    #[test]
    fn negative_slopes_are_clamped_to_zero() {
        // Time falls with vertices: the unconstrained fit would make c2 negative.
        let samples: Vec<(u64, u64, f64)> = (0..10)
            .map(|i| {
                let t = 1000 + 1000 * i;
                let v = 20_000 - 1500 * i;
                (t, v, 1.0e-6 * t as f64)
            })
            .collect();
        let m = CostModel::default().fit_geometry(&samples).model;
        assert_eq!(m.c2, 0.0, "{m:?}");
        assert!(m.c1 > 0.0);
    }

    #[test]
    fn degenerate_input_keeps_a_finite_prior() {
        let prior = CostModel::default();
        let cases: [&[(u64, u64, f64)]; 4] = [
            &[],
            &[(0, 0, 0.0), (0, 0, 0.0)],
            &[(100, 50, 0.0)],
            &[(5, 5, f64::NAN), (7, 7, f64::INFINITY), (9, 9, -1.0)],
        ];
        for samples in cases {
            let fit = prior.fit_geometry(samples);
            assert!(!fit.fitted);
            assert_eq!(fit.model, prior);
        }
        assert_eq!(prior.fit_fill(&[]).model, prior);
        assert_eq!(prior.fit_fill(&[(0.0, 0.0)]).model, prior);
        assert_eq!(prior.fit_draws(&[]).model, prior);
        let constant = prior.fit_geometry(&[(10, 5, 1.0e-3), (1000, 500, 1.0e-3)]);
        assert!(!constant.fitted, "no slope: keep the prior");
        let m = CostModel::calibrate(&[], &[]);
        assert!([m.c0, m.c1, m.c2, m.c3].iter().all(|c| c.is_finite()));
    }

    #[test]
    fn calibrate_combines_geometry_and_fill() {
        let geometry = geometry_samples(&mut Rng(13), 0.0, 0.0);
        let fill = [(1.0e5, TRUTH.c3 * 1.0e5), (1.0e6, TRUTH.c3 * 1.0e6)];
        let m = CostModel::calibrate(&geometry, &fill);
        assert!(
            close(m.c1, TRUTH.c1, 0.05) && close(m.c3, TRUTH.c3, 0.05),
            "{m:?}"
        );
        assert_eq!(m.c0, 0.0, "per-draw overhead is inside the fitted slopes");
        assert_eq!(CostModel::calibrate(&[], &[]), CostModel::default());
    }

    #[test]
    fn online_factor_converges_to_measured_over_predicted() {
        let base = 0.020;
        let measured = 0.050;
        let mut online = OnlineCost::default();
        for _ in 0..200 {
            let planned = online.correct(base);
            online.observe(planned, measured);
        }
        assert!(
            close(online.factor(), measured / base, 0.01),
            "{}",
            online.factor()
        );
        let corrected = online.apply(&TRUTH);
        assert!(close(corrected.c1, TRUTH.c1 * 2.5, 0.01));
    }

    #[test]
    fn online_factor_is_clamped_and_ignores_garbage() {
        let mut online = OnlineCost::new(1.0);
        online.observe(0.01, 10.0);
        assert_eq!(online.factor(), MAX_FACTOR);
        online.observe(1.0, 0.0);
        online.observe(f64::NAN, 0.01);
        online.observe(0.01, f64::INFINITY);
        assert_eq!(online.factor(), MAX_FACTOR);
        for _ in 0..10 {
            online.observe(1.0, 1e-6);
        }
        assert_eq!(online.factor(), MIN_FACTOR);
    }

    #[test]
    fn online_factor_smooths_a_single_spike() {
        let mut online = OnlineCost::default();
        online.observe(0.02, 0.2); // one 10× hiccup
        assert!(online.factor() < 1.2, "{}", online.factor());
    }
}
