//! Cost and benefit of one object's LODs (Funkhouser 1993 §4.2.3): `Accuracy`, the
//! LOD-independent factors `Size · Importance · Focus · Motion`, the hysteresis against last
//! frame's choice, and `Cost(O, L)` of one LOD under the cost model.

use crate::cost::CostModel;

use super::{Candidate, LodOption, Params, finite_or_zero};

/// `Accuracy = 1 − BaseError / Samples^m` with `Samples = min(triangles, pixels)` (at least 1),
/// Funkhouser §4.2.3. A LOD of no triangles draws nothing and has accuracy 0.
pub fn accuracy(params: &Params, triangles: u32, pixels: f32) -> f64 {
    if triangles == 0 {
        return 0.0;
    }
    sampled(params, f64::from(triangles).min(finite_or_zero(pixels)))
}

/// `1 − BaseError / Samples^m`, `Samples` at least 1.
fn sampled(params: &Params, samples: f64) -> f64 {
    let samples = samples.max(1.0);
    let denominator = if params.exponent == 1.0 {
        samples
    } else {
        samples.powf(params.exponent)
    };
    1.0 - params.base_error / denominator
}

/// `Texture = 1 − BaseError / Texels^m` with `Texels = min(texels, pixels)` (at least 1): the
/// texture's share of a LOD's accuracy, by the sampling argument of Funkhouser's `Accuracy`
/// (§4.2.3) applied to texels. `texels` is [`LodOption::texels`]: `None` (untextured) gives 1,
/// the average colour (0 texels) `1 − BaseError`.
pub fn texture_accuracy(params: &Params, texels: Option<f32>, pixels: f32) -> f64 {
    let Some(texels) = texels else {
        return 1.0;
    };
    sampled(params, finite_or_zero(texels).min(finite_or_zero(pixels)))
}

/// Accuracy of drawing `lod` over `pixels` pixels: [`accuracy`] of its triangles times
/// [`texture_accuracy`] of its texels.
pub fn lod_accuracy(params: &Params, lod: &LodOption, pixels: f32) -> f64 {
    accuracy(params, lod.triangles, pixels) * texture_accuracy(params, lod.texels, pixels)
}

/// The LOD-independent factors of the benefit: `Size · Importance · Focus · Motion` (§4.2.3).
pub fn object_weight(params: &Params, cand: &Candidate) -> f64 {
    let size = finite_or_zero(cand.pixels);
    let importance = finite_or_zero(cand.importance);
    let focus = weighted(params.focus_weight, cand.focus);
    let motion = weighted(params.motion_weight, cand.motion);
    size * importance * focus * motion
}

/// `1 − w·(1 − x)` with `w` and `x` clamped to `0..=1`.
fn weighted(weight: f64, x: f32) -> f64 {
    let x = if x.is_finite() {
        f64::from(x).clamp(0.0, 1.0)
    } else {
        1.0
    };
    1.0 - weight.clamp(0.0, 1.0) * (1.0 - x)
}

/// `Accuracy' = Accuracy − h·|Accuracy − Accuracy(previous)|` (no previous: no change).
pub(super) fn hysteresis(params: &Params, acc: f64, previous: Option<f64>) -> f64 {
    previous.map_or(acc, |p| acc - params.hysteresis * (acc - p).abs())
}

/// Accuracy of last frame's choice for `cand` at this frame's size: `None` when the object was
/// not a candidate last frame or its LOD index is no longer valid, 0 when it was not drawn.
pub(super) fn previous_accuracy(
    params: &Params,
    cand: &Candidate,
    prev: Option<Option<usize>>,
) -> Option<f64> {
    match prev? {
        None => Some(0.0),
        Some(l) => cand
            .lods
            .get(l)
            .map(|lod| lod_accuracy(params, lod, cand.pixels)),
    }
}

pub(super) fn lod_cost(model: &CostModel, lod: &LodOption, pixels: f32) -> f64 {
    let c = model.cost_of(
        u64::from(lod.triangles),
        u64::from(lod.vertices),
        finite_or_zero(pixels),
        lod.textured(),
    );
    if c.is_finite() {
        c.max(0.0)
    } else {
        f64::INFINITY
    }
}
