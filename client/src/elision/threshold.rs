//! The per-object rules of detail elision: the static pixels-per-polygon rule (Funkhouser 1993
//! §4.2.1), the feedback rule that rescales its threshold every frame (§4.2.2), and the
//! residency fallback both share with `None` and `Coarsest` (§5.2.4).

use super::{Candidate, Choice, Elider, LodOption, finite_or_zero};

/// The finest LOD whose average polygon covers at least `px_per_tri` pixels
/// (`pixels / triangles ≥ px_per_tri`), else the coarsest; `None` if there are no LODs (§4.2.1).
pub fn static_lod(lods: &[LodOption], pixels: f32, px_per_tri: f64) -> Option<usize> {
    let pixels = finite_or_zero(pixels);
    let fits = |l: &LodOption| l.triangles == 0 || pixels / f64::from(l.triangles) >= px_per_tri;
    lods.iter()
        .position(fits)
        .or_else(|| lods.len().checked_sub(1))
}

impl Elider {
    /// Feedback rule (§4.2.2): scales the threshold by `last / budget`, both clamped.
    pub(super) fn update_threshold(&mut self, last_frame_s: Option<f64>) {
        let Some(last) = last_frame_s.filter(|t| t.is_finite() && *t >= 0.0) else {
            return;
        };
        let p = &self.params;
        let step = p.feedback_max_step.max(1.0);
        let ratio = if self.budget_s > 0.0 {
            last / self.budget_s
        } else {
            step
        };
        let t = self.threshold_px * ratio.clamp(1.0 / step, step);
        self.threshold_px = t.clamp(p.feedback_min_px_per_tri, p.feedback_max_px_per_tri);
    }
}

/// Applies residency to a desired LOD (§5.2.4): the finest resident LOD not finer than
/// `desired`; `lods_skipped = chosen − desired`; no such LOD skips the object.
pub fn resident_fallback(lods: &[LodOption], desired: Option<usize>) -> Choice {
    let Some(d) = desired else {
        return Choice::default();
    };
    match (d..lods.len()).find(|&j| lods[j].resident) {
        Some(j) => Choice {
            lod: Some(j),
            desired: Some(d),
            lods_skipped: (j - d) as u32,
            object_skipped: false,
        },
        None => Choice {
            lod: None,
            desired: Some(d),
            lods_skipped: 0,
            object_skipped: true,
        },
    }
}

/// Choices for a per-object rule followed by the residency fallback.
pub(super) fn by_rule(
    cands: &[Candidate],
    rule: impl Fn(&Candidate) -> Option<usize>,
) -> Vec<Choice> {
    cands
        .iter()
        .map(|c| resident_fallback(&c.lods, rule(c)))
        .collect()
}
