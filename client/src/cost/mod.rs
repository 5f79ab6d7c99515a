//! The rendering cost model of detail elision (Funkhouser 1993 §4.2.3, "Cost Heuristic").
//!
//! Funkhouser models the graphics pipeline as two concurrent stages, *per primitive* and *per
//! pixel*, so an object tuple takes as long as its slower stage:
//!
//! ```text
//! Cost(O, L) = max(C0 + C1·Poly(O, L) + C2·Vert(O, L),  (C3 + C4·Tex(O, L))·Pix(O))  [seconds]
//! ```
//!
//! `C0` and `C4` are our additions. `C0` is the fixed host-side overhead of one draw call, which
//! matters on today's APIs when thousands of small objects are drawn. `C4` is what texturing
//! adds to each pixel (`Tex` is 1 when the LOD draws with a texture, else 0): sampling and
//! filtering a mip chain doubles the per-pixel time of a software rasteriser, and Funkhouser's
//! pixels were flat- or Gouraud-shaded. The coefficients are found "experimentally by
//! rendering sample objects with a wide variety of sizes and LODs" (§4.2.3, Fig. 4.15):
//! [`CostModel::fit_geometry`], [`CostModel::fit_draws`], [`CostModel::fit_fill`] and
//! [`CostModel::fit_textured_fill`] solve small
//! non-negative least-squares problems over timed samples (the client times them at start-up).
//! Funkhouser hoped "to extend our system to learn appropriate cost coefficients during real-time
//! walkthroughs"; [`OnlineCost`] does that with a smoothed correction factor refitted from
//! measured frame times.
//!
//! Everything here is pure arithmetic: no GPU, no clock.
//!
//! This file holds the model and its online correction; `fit` holds the calibration fits and
//! their least-squares solver.

mod fit;
#[cfg(test)]
mod tests;

/// Smallest correction factor [`OnlineCost`] will apply.
pub const MIN_FACTOR: f64 = 0.25;
/// Largest correction factor [`OnlineCost`] will apply.
pub const MAX_FACTOR: f64 = 4.0;

/// Coefficients of Funkhouser's cost model (§4.2.3), all in seconds per unit.
///
/// `Cost = max(c0 + c1·triangles + c2·vertices, (c3 + c4·textured)·pixels)`.
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
    /// Seconds a texture adds to each covered pixel (sampling and filtering its mip chain);
    /// models calibrated before textures existed read it as 0.
    #[serde(default)]
    pub c4: f64,
}

impl Default for CostModel {
    /// Speeds of a software rasteriser (llvmpipe on a few cores): about 8 M triangles/s for
    /// indexed meshes with half as many vertices as triangles, 50 M vertices/s, 400 M pixels/s,
    /// 5 µs per draw; a texture doubles the per-pixel time.
    fn default() -> Self {
        CostModel {
            c0: 5.0e-6,
            c1: 1.15e-7,
            c2: 2.0e-8,
            c3: 2.5e-9,
            c4: 2.5e-9,
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
    /// `pixels` pixels, untextured: `max(c0 + c1·tris + c2·verts, c3·pixels)` (§4.2.3). A draw
    /// of zero triangles draws nothing and costs 0.
    pub fn cost(&self, tris: u64, verts: u64, pixels: f64) -> f64 {
        self.cost_of(tris, verts, pixels, false)
    }

    /// [`CostModel::cost`] of a draw that samples a texture when `textured`:
    /// `max(c0 + c1·tris + c2·verts, (c3 + c4)·pixels)`.
    pub fn cost_of(&self, tris: u64, verts: u64, pixels: f64, textured: bool) -> f64 {
        if tris == 0 {
            return 0.0;
        }
        let pixels = if pixels.is_finite() {
            pixels.max(0.0)
        } else {
            0.0
        };
        let geometry = self.c0 + self.c1 * tris as f64 + self.c2 * verts as f64;
        let per_pixel = if textured { self.c3 + self.c4 } else { self.c3 };
        geometry.max(per_pixel * pixels)
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

    /// Every coefficient multiplied by `factor` (used by [`OnlineCost::apply`]).
    pub fn scaled(&self, factor: f64) -> CostModel {
        CostModel {
            c0: self.c0 * factor,
            c1: self.c1 * factor,
            c2: self.c2 * factor,
            c3: self.c3 * factor,
            c4: self.c4 * factor,
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
