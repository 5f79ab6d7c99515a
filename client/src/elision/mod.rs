//! Detail elision: which level of detail (if any) to draw for each potentially visible object
//! so that the frame fits its time budget (Funkhouser 1993 §4.2).
//!
//! Four algorithms, selectable for comparison as in Funkhouser's Table 4.3 (§4.2.4):
//!
//! * [`Algorithm::None`]: the finest LOD of every object; no budget.
//! * [`Algorithm::Static`] (§4.2.1): the finest LOD whose average polygon covers at least
//!   [`Params::static_px_per_tri`] (1024) pixels, i.e. `pixels / triangles ≥ 1024`, else the
//!   coarsest.
//! * [`Algorithm::Feedback`] (§4.2.2): the static rule with a threshold rescaled each frame by
//!   `last frame time / budget` (the ratio clamped to `[1/feedback_max_step, feedback_max_step]`,
//!   the threshold to `[feedback_min_px_per_tri, feedback_max_px_per_tri]`).
//! * [`Algorithm::Optimize`] (§4.2.3): maximise `Σ Benefit` subject to `Σ Cost ≤ budget`, at
//!   most one LOD per object (the multiple-choice knapsack problem), with Funkhouser's
//!   incremental greedy (Fig. 4.20), warm-started from the previous frame.
//!
//! ## Cost and benefit (§4.2.3)
//!
//! `Cost(O, L)` is [`CostModel::cost_of`]: `max(C0 + C1·tris + C2·verts, (C3 + C4·Tex)·pixels)`,
//! `Tex` 1 when the LOD draws with a resident texture. The benefit of drawing object `O` at LOD
//! `L` is
//!
//! ```text
//! Benefit(O, L)  = Size(O) · Importance(O) · Focus(O) · Motion(O) · Accuracy'(O, L)
//! Size           = projected pixels of the bounding box
//! Focus          = 1 − focus_weight  · (1 − focus)        (focus, motion in 0..1)
//! Motion         = 1 − motion_weight · (1 − motion)
//! Accuracy(L)    = Geometry(L) · Texture(L)
//! Geometry(L)    = 1 − BaseError / Samples(L)^m,  Samples = min(triangles, pixels), ≥ 1
//! Texture(L)     = 1 − BaseError / Texels(L)^m,   Texels = min(texels drawn, pixels), ≥ 1
//! Accuracy'(L)   = Accuracy(L) − h · |Accuracy(L) − Accuracy(previous frame's choice)|
//! ```
//!
//! with Funkhouser's `BaseError = 0.5` and `m = 1` (flat-shading exponent; Samples "never more
//! than #pixels", so a LOD with more triangles than the object covers pixels adds no benefit
//! and `Optimize` does not draw it, whatever the budget). `Texture` is our extension of the same
//! sampling argument to textures (1 for an untextured object): a texture's detail is sampled by
//! its texels as a shape's is by its triangles, texels finer than the pixels they land on add
//! nothing (the finest useful mip), and a textured object drawn in its average colour (one
//! sample) keeps half its accuracy. So `Optimize` prefers a LOD that can show a resident texture
//! to one that cannot, and a fill-bound textured object pays `C4` for it. Not drawing an object has accuracy 0,
//! so its benefit is 0, or `−h·Size·…·Accuracy(previous)` when it was drawn last frame. The last factor is Funkhouser's
//! *Hysteresis*: "reduce the Benefit by an amount proportional to the difference in level of
//! detail from the previous frame". Measuring that difference in accuracy makes every move away
//! from last frame's LOD worth `h` (10 %) less than it would otherwise be, in both directions,
//! so a small change of view does not flip a choice. [`LodOption::error`] is not used: without
//! the object's size in metres it cannot be turned into pixels.
//!
//! ## The incremental greedy (§4.2.3, Fig. 4.20)
//!
//! Each object's resident options (plus "not drawn") are reduced to the upper convex hull of
//! their (cost, benefit) points, so value (`ΔBenefit / ΔCost`) falls with every step up, as the
//! paper's "diminishing returns" condition requires. Starting from the previous frame's choices
//! (newly visible objects at their coarsest option), the loop increments the object whose next
//! step has the highest value while the frame fits (priority queue *NEXT*), then decrements
//! objects whose current step has the lowest value until it fits again (queue *CURRENT*); it
//! stops when the same step is incremented and decremented. Both queues are binary heaps with
//! lazy invalidation (a per-object version number), so a frame costs `O(n log n)` at worst and a
//! few iterations when the view is coherent. Three refinements, each cheap:
//!
//! 1. *fill*: leftover budget goes to the remaining steps in value order, skipping those that
//!    do not fit;
//! 2. *incumbent*: if last frame's choices (snapped to this frame's hulls) still fit and score at
//!    least as high, they are kept, which makes repeated frames stable;
//! 3. *best single*: if one object alone scores more than the greedy solution, it is drawn
//!    alone; with the greedy's prefix this gives the classic knapsack guarantee of at least
//!    half the optimum that Funkhouser cites.
//!
//! ## Residency (§5.2.4)
//!
//! The client never waits for data. `None`, `Static` and `Feedback` draw the finest resident LOD
//! not finer than the desired one (the smallest resident index ≥ desired): `lods_skipped =
//! chosen − desired`, and an object with no such LOD is skipped (`object_skipped`).
//! `Optimize` only ever considers resident LODs. Its `desired` LOD is the one it would pick for
//! that object at this frame's marginal value of time λ (the value of the step the loop ended
//! on) if every LOD of the object were resident; `lods_skipped = chosen − desired` and the
//! object is skipped when it is desired but not drawn, e.g. when none of its LODs is resident.
//!
//! ## Layout
//!
//! This file holds the public types and the [`Elider`] that dispatches to an algorithm;
//! `benefit` holds accuracy, benefit and hysteresis, `threshold` the static and feedback rules
//! and the residency fallback, `hull` the options and their convex hulls, and `optimize` the
//! incremental greedy.

use std::collections::HashMap;
use std::fmt;
use std::hash::{BuildHasherDefault, Hasher};
use std::str::FromStr;

use crate::cost::CostModel;

mod benefit;
mod hull;
mod optimize;
#[cfg(test)]
mod tests;
mod threshold;

pub use benefit::{accuracy, lod_accuracy, object_weight, texture_accuracy};
pub use threshold::{resident_fallback, static_lod};

use benefit::{hysteresis, lod_cost, previous_accuracy};
use hull::Context;
use optimize::Optimizer;
use threshold::by_rule;

/// A detail elision algorithm (Funkhouser §4.2.4 compares these four).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Algorithm {
    /// The finest LOD of every object, whatever it costs.
    None,
    /// The finest LOD whose average polygon covers at least 1024 pixels (§4.2.1).
    Static,
    /// The static rule with a pixels-per-polygon threshold adapted to the last frame (§4.2.2).
    Feedback,
    /// Cost/benefit optimisation within the frame budget (§4.2.3).
    #[default]
    Optimize,
    /// Maciel's cluster traversal: far clusters as boxes, the rest as objects with their finest
    /// resident LOD that fits ([`crate::cluster`]; the frame decision drives it). As an object
    /// elider on its own it is [`Algorithm::Optimize`].
    Impostors,
    /// Every object at its coarsest resident LOD: the cheapest image, a baseline for the
    /// benchmark.
    Coarsest,
}

impl Algorithm {
    /// Every algorithm, in the order of Funkhouser's Table 4.3.
    pub const ALL: [Algorithm; 4] = [
        Algorithm::None,
        Algorithm::Static,
        Algorithm::Feedback,
        Algorithm::Optimize,
    ];

    /// The lower-case name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Algorithm::None => "none",
            Algorithm::Static => "static",
            Algorithm::Feedback => "feedback",
            Algorithm::Optimize => "optimize",
            Algorithm::Impostors => "impostors",
            Algorithm::Coarsest => "coarsest",
        }
    }
}

impl fmt::Display for Algorithm {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An unknown algorithm name was given to [`Algorithm::from_str`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown detail elision algorithm `{0}` (expected none, static, feedback, optimize, impostors or coarsest)"
)]
pub struct ParseAlgorithmError(pub String);

impl FromStr for Algorithm {
    type Err = ParseAlgorithmError;

    /// Parses `none`, `static`, `feedback`, `optimize`, `impostors` or `coarsest`
    /// (case-insensitive; `optimise` too).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "none" => Ok(Algorithm::None),
            "static" => Ok(Algorithm::Static),
            "feedback" => Ok(Algorithm::Feedback),
            "optimize" | "optimise" => Ok(Algorithm::Optimize),
            "impostors" => Ok(Algorithm::Impostors),
            "coarsest" => Ok(Algorithm::Coarsest),
            _ => Err(ParseAlgorithmError(s.to_owned())),
        }
    }
}

/// One level of detail of a candidate object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LodOption {
    /// Triangles drawn at this LOD.
    pub triangles: u32,
    /// Vertices processed at this LOD.
    pub vertices: u32,
    /// Geometric error against the finest LOD, in metres (informational; see the module docs).
    pub error: f32,
    /// Whether this LOD is on the GPU now; only resident LODs can be drawn.
    pub resident: bool,
    /// The texture detail this LOD is drawn with: `None` for an untextured object; for a
    /// textured one the texels of the finest resident mip level over the whole object (the
    /// level's width × height × the times the texture repeats across it, squared: an upper
    /// bound, as the repeat count is the larger of the two axes'), 0 when this
    /// LOD draws the texture's average colour (no coordinates, or nothing resident).
    pub texels: Option<f32>,
}

impl LodOption {
    /// An untextured LOD.
    pub fn new(triangles: u32, vertices: u32, error: f32, resident: bool) -> Self {
        LodOption {
            triangles,
            vertices,
            error,
            resident,
            texels: None,
        }
    }

    /// Whether drawing this LOD samples a texture (its pixels cost `c3 + c4`).
    pub fn textured(&self) -> bool {
        self.texels.is_some_and(|t| t > 0.0)
    }
}

/// A potentially visible object offered to the elider this frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// Instance id, stable across frames (warm start and hysteresis key on it).
    pub id: u32,
    /// The object's LODs, finest first.
    pub lods: Vec<LodOption>,
    /// Projected screen area of the object's bounding box, in pixels (Funkhouser's `Size`).
    pub pixels: f32,
    /// Closeness to the view centre, 0..1 (1 = at the centre); weighted by
    /// [`Params::focus_weight`].
    pub focus: f32,
    /// Semantic importance multiplier (1 = ordinary).
    pub importance: f32,
    /// Steadiness on screen, 0..1 (1 = static relative to the eye); weighted by
    /// [`Params::motion_weight`].
    pub motion: f32,
}

impl Candidate {
    /// A candidate with neutral focus, importance and motion (all 1).
    pub fn new(id: u32, lods: Vec<LodOption>, pixels: f32) -> Self {
        Candidate {
            id,
            lods,
            pixels,
            focus: 1.0,
            importance: 1.0,
            motion: 1.0,
        }
    }
}

/// What the elider decided for one candidate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Choice {
    /// Index into the candidate's `lods` to draw, or `None` to draw nothing.
    pub lod: Option<usize>,
    /// The LOD the algorithm wanted before residency was applied (see the module docs).
    pub desired: Option<usize>,
    /// LOD levels given up because finer ones were not resident (`lod − desired`).
    pub lods_skipped: u32,
    /// The object was wanted but nothing resident could be drawn for it.
    pub object_skipped: bool,
}

/// The elider's decision for a whole frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Frame {
    /// One choice per candidate, in the candidates' order.
    pub choices: Vec<Choice>,
    /// Predicted render time of the drawn LODs, `Σ Cost`, in seconds.
    pub predicted_s: f64,
    /// `Σ Benefit` over all candidates, with hysteresis against the previous frame (an object
    /// drawn last frame and not now counts negatively).
    pub benefit: f64,
    /// Total [`Choice::lods_skipped`].
    pub lods_skipped: u32,
    /// Number of candidates with [`Choice::object_skipped`].
    pub objects_skipped: u32,
}

/// Tunable constants of the algorithms; [`Params::default`] holds Funkhouser's values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Static rule: pixels an average polygon must cover (Funkhouser: 1024).
    pub static_px_per_tri: f64,
    /// Feedback rule: smallest threshold, pixels per polygon.
    pub feedback_min_px_per_tri: f64,
    /// Feedback rule: largest threshold, pixels per polygon.
    pub feedback_max_px_per_tri: f64,
    /// Feedback rule: most the threshold may change in one frame (a factor ≥ 1).
    pub feedback_max_step: f64,
    /// `BaseError` of `Accuracy = 1 − BaseError / Samples^m` (Funkhouser: 0.5).
    pub base_error: f64,
    /// Exponent `m` of `Accuracy = 1 − BaseError / Samples^m` (flat = 1, Gouraud = 2).
    pub exponent: f64,
    /// Hysteresis `h`: `Accuracy' = Accuracy − h·|Accuracy − Accuracy(previous)|`.
    pub hysteresis: f64,
    /// `Focus = 1 − focus_weight·(1 − focus)`; 0 ignores focus, 1 uses it as is.
    pub focus_weight: f64,
    /// `Motion = 1 − motion_weight·(1 − motion)`; 0 ignores motion, 1 uses it as is.
    pub motion_weight: f64,
}

impl Default for Params {
    /// Funkhouser's 1024 px/polygon, BaseError 0.5, m = 1; hysteresis 0.1; focus and motion
    /// at half weight (so peripheral or moving objects keep half their benefit).
    fn default() -> Self {
        Params {
            static_px_per_tri: 1024.0,
            feedback_min_px_per_tri: 1.0,
            feedback_max_px_per_tri: 1_048_576.0,
            feedback_max_step: 2.0,
            base_error: 0.5,
            exponent: 1.0,
            hysteresis: 0.1,
            focus_weight: 0.5,
            motion_weight: 0.5,
        }
    }
}

/// The detail elision stage: chooses LODs frame after frame, remembering the previous frame's
/// choices for the warm start and the hysteresis.
#[derive(Debug, Clone)]
pub struct Elider {
    algorithm: Algorithm,
    budget_s: f64,
    params: Params,
    threshold_px: f64,
    previous: IdMap,
    opt: Optimizer,
}

impl Elider {
    /// An elider running `algorithm` within `budget_s` seconds per frame, with default params.
    pub fn new(algorithm: Algorithm, budget_s: f64) -> Self {
        let params = Params::default();
        Elider {
            algorithm,
            budget_s: sanitize_budget(budget_s),
            params,
            threshold_px: params.static_px_per_tri,
            previous: IdMap::default(),
            opt: Optimizer::default(),
        }
    }

    /// The same elider with other params (resets the feedback threshold to the static one).
    pub fn with_params(mut self, params: Params) -> Self {
        self.params = params;
        self.threshold_px = params.static_px_per_tri;
        self
    }

    /// The algorithm in use.
    pub fn algorithm(&self) -> Algorithm {
        self.algorithm
    }

    /// The frame budget, in seconds.
    pub fn budget_s(&self) -> f64 {
        self.budget_s
    }

    /// Changes the frame budget (negative or NaN budgets become 0).
    pub fn set_budget(&mut self, budget_s: f64) {
        self.budget_s = sanitize_budget(budget_s);
    }

    /// The params in use.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// The current pixels-per-polygon threshold of the feedback rule.
    pub fn threshold_px(&self) -> f64 {
        self.threshold_px
    }

    /// Forgets the previous frame (no warm start or hysteresis next time) and the feedback
    /// threshold, e.g. after a teleport.
    pub fn reset(&mut self) {
        self.previous.clear();
        self.threshold_px = self.params.static_px_per_tri;
    }

    /// `Benefit(O, L)` of drawing `cand` at `lod` (`None` = not drawn), with hysteresis against
    /// the last frame this elider chose (see the module docs for the formula).
    pub fn benefit(&self, cand: &Candidate, lod: Option<usize>) -> f64 {
        let prev = self.previous_accuracy(cand);
        let acc = lod
            .and_then(|l| cand.lods.get(l))
            .map_or(0.0, |l| lod_accuracy(&self.params, l, cand.pixels));
        object_weight(&self.params, cand) * hysteresis(&self.params, acc, prev)
    }

    /// Chooses this frame's LODs for `cands` under `cost`; `last_frame_s` is the measured time
    /// of the previous frame (used by `Feedback` only).
    pub fn choose(
        &mut self,
        cands: &[Candidate],
        cost: &CostModel,
        last_frame_s: Option<f64>,
    ) -> Frame {
        let choices = match self.algorithm {
            Algorithm::None => by_rule(cands, |c| (!c.lods.is_empty()).then_some(0)),
            Algorithm::Coarsest => by_rule(cands, |c| c.lods.len().checked_sub(1)),
            Algorithm::Static => {
                let t = self.params.static_px_per_tri;
                by_rule(cands, |c| static_lod(&c.lods, c.pixels, t))
            }
            Algorithm::Feedback => {
                self.update_threshold(last_frame_s);
                let t = self.threshold_px;
                by_rule(cands, |c| static_lod(&c.lods, c.pixels, t))
            }
            Algorithm::Optimize | Algorithm::Impostors => self.optimize(cands, cost),
        };
        let frame = self.summarise(cands, cost, choices);
        self.remember(cands, &frame.choices);
        frame
    }

    fn optimize(&mut self, cands: &[Candidate], cost: &CostModel) -> Vec<Choice> {
        let ctx = Context {
            params: &self.params,
            model: cost,
            previous: &self.previous,
        };
        self.opt.solve(cands, &ctx, self.budget_s)
    }

    /// Accuracy of the LOD drawn for `cand` last frame: `None` if it was not a candidate (no
    /// hysteresis), 0 if it was not drawn.
    fn previous_accuracy(&self, cand: &Candidate) -> Option<f64> {
        previous_accuracy(&self.params, cand, self.previous.get(&cand.id).copied())
    }

    /// Totals of a frame: cost, benefit and skip counts.
    fn summarise(&self, cands: &[Candidate], model: &CostModel, choices: Vec<Choice>) -> Frame {
        let mut frame = Frame::default();
        for (cand, choice) in cands.iter().zip(&choices) {
            if let Some(l) = choice.lod.and_then(|l| cand.lods.get(l)) {
                frame.predicted_s += lod_cost(model, l, cand.pixels);
            }
            frame.benefit += self.benefit(cand, choice.lod);
            frame.lods_skipped += choice.lods_skipped;
            frame.objects_skipped += u32::from(choice.object_skipped);
        }
        frame.choices = choices;
        frame
    }

    fn remember(&mut self, cands: &[Candidate], choices: &[Choice]) {
        self.previous.clear();
        self.previous.reserve(cands.len());
        for (cand, choice) in cands.iter().zip(choices) {
            self.previous.insert(cand.id, choice.lod);
        }
    }
}

/// Last frame's choices by instance id.
type IdMap = HashMap<u32, Option<usize>, BuildHasherDefault<IdHasher>>;

/// A multiplicative (Fx-style) hasher for the `u32` instance ids: several times faster than the
/// default SipHash on such short keys, and ids come from our own database, not from an attacker.
#[derive(Debug, Clone, Copy, Default)]
struct IdHasher(u64);

impl Hasher for IdHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u32(&mut self, n: u32) {
        self.write_u64(u64::from(n));
    }

    fn write_u64(&mut self, n: u64) {
        self.0 = (self.0.rotate_left(5) ^ n).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

fn sanitize_budget(budget_s: f64) -> f64 {
    if budget_s.is_nan() {
        0.0
    } else {
        budget_s.max(0.0)
    }
}

fn finite_or_zero(x: f32) -> f64 {
    if x.is_finite() {
        f64::from(x).max(0.0)
    } else {
        0.0
    }
}
