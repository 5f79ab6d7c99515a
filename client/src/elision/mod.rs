//! Detail elision: which level of detail (if any) to draw for each potentially visible object
//! so that the frame fits its time budget (Funkhouser 1993 §4.2; DESIGN §5).
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
//! `Cost(O, L)` is [`CostModel::cost`]: `max(C0 + C1·tris + C2·verts, C3·pixels)`. The benefit
//! of drawing object `O` at LOD `L` is
//!
//! ```text
//! Benefit(O, L)  = Size(O) · Importance(O) · Focus(O) · Motion(O) · Accuracy'(O, L)
//! Size           = projected pixels of the bounding box
//! Focus          = 1 − focus_weight  · (1 − focus)        (focus, motion in 0..1)
//! Motion         = 1 − motion_weight · (1 − motion)
//! Accuracy(L)    = 1 − BaseError / Samples(L)^m,  Samples = min(triangles, pixels), ≥ 1
//! Accuracy'(L)   = Accuracy(L) − h · |Accuracy(L) − Accuracy(previous frame's choice)|
//! ```
//!
//! with Funkhouser's `BaseError = 0.5` and `m = 1` (flat-shading exponent; Samples "never more
//! than #pixels", so a LOD with more triangles than the object covers pixels adds no benefit
//! and `Optimize` does not draw it, whatever the budget). Not drawing an object has accuracy 0, so its benefit is 0, or `−h·Size·…·
//! Accuracy(previous)` when it was drawn last frame. The last factor is Funkhouser's
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

use std::cmp::{Ordering, Reverse};
use std::collections::{BinaryHeap, HashMap};
use std::fmt;
use std::hash::{BuildHasherDefault, Hasher};
use std::str::FromStr;

use crate::cost::CostModel;

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

/// `Accuracy = 1 − BaseError / Samples^m` with `Samples = min(triangles, pixels)` (at least 1),
/// Funkhouser §4.2.3. A LOD of no triangles draws nothing and has accuracy 0.
pub fn accuracy(params: &Params, triangles: u32, pixels: f32) -> f64 {
    if triangles == 0 {
        return 0.0;
    }
    let samples = f64::from(triangles).min(finite_or_zero(pixels)).max(1.0);
    let denominator = if params.exponent == 1.0 {
        samples
    } else {
        samples.powf(params.exponent)
    };
    1.0 - params.base_error / denominator
}

/// The LOD-independent factors of the benefit: `Size · Importance · Focus · Motion` (§4.2.3).
pub fn object_weight(params: &Params, cand: &Candidate) -> f64 {
    let size = finite_or_zero(cand.pixels);
    let importance = finite_or_zero(cand.importance);
    let focus = weighted(params.focus_weight, cand.focus);
    let motion = weighted(params.motion_weight, cand.motion);
    size * importance * focus * motion
}

/// The finest LOD whose average polygon covers at least `px_per_tri` pixels
/// (`pixels / triangles ≥ px_per_tri`), else the coarsest; `None` if there are no LODs (§4.2.1).
pub fn static_lod(lods: &[LodOption], pixels: f32, px_per_tri: f64) -> Option<usize> {
    let pixels = finite_or_zero(pixels);
    let fits = |l: &LodOption| l.triangles == 0 || pixels / f64::from(l.triangles) >= px_per_tri;
    lods.iter()
        .position(fits)
        .or_else(|| lods.len().checked_sub(1))
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
            .map_or(0.0, |l| accuracy(&self.params, l.triangles, cand.pixels));
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

    /// Feedback rule (§4.2.2): scales the threshold by `last / budget`, both clamped.
    fn update_threshold(&mut self, last_frame_s: Option<f64>) {
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

/// Choices for a per-object rule followed by the residency fallback.
fn by_rule(cands: &[Candidate], rule: impl Fn(&Candidate) -> Option<usize>) -> Vec<Choice> {
    cands
        .iter()
        .map(|c| resident_fallback(&c.lods, rule(c)))
        .collect()
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
fn hysteresis(params: &Params, acc: f64, previous: Option<f64>) -> f64 {
    previous.map_or(acc, |p| acc - params.hysteresis * (acc - p).abs())
}

/// Accuracy of last frame's choice for `cand` at this frame's size: `None` when the object was
/// not a candidate last frame or its LOD index is no longer valid, 0 when it was not drawn.
fn previous_accuracy(
    params: &Params,
    cand: &Candidate,
    prev: Option<Option<usize>>,
) -> Option<f64> {
    match prev? {
        None => Some(0.0),
        Some(l) => cand
            .lods
            .get(l)
            .map(|lod| accuracy(params, lod.triangles, cand.pixels)),
    }
}

fn lod_cost(model: &CostModel, lod: &LodOption, pixels: f32) -> f64 {
    let c = model.cost(
        u64::from(lod.triangles),
        u64::from(lod.vertices),
        finite_or_zero(pixels),
    );
    if c.is_finite() {
        c.max(0.0)
    } else {
        f64::INFINITY
    }
}

/// What the optimiser needs besides the candidates.
struct Context<'a> {
    params: &'a Params,
    model: &'a CostModel,
    previous: &'a IdMap,
}

/// `lod` value of the "not drawn" option.
const NOT_DRAWN: u32 = u32::MAX;

/// One option of an object: a LOD (or not drawn) with its cost and benefit.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Point {
    lod: u32,
    resident: bool,
    cost: f64,
    benefit: f64,
}

impl Point {
    fn lod(&self) -> Option<usize> {
        (self.lod != NOT_DRAWN).then_some(self.lod as usize)
    }
}

/// `ΔBenefit / ΔCost` from `a` to `b` (hull steps always have `ΔCost > 0`).
fn slope(a: &Point, b: &Point) -> f64 {
    (b.benefit - a.benefit) / (b.cost - a.cost)
}

/// Appends the options of one object: "not drawn", then every LOD with a finite cost, coarsest
/// first (so nearly sorted by cost), with its hysteresis-adjusted benefit.
fn object_points(
    cand: &Candidate,
    ctx: &Context<'_>,
    prev: Option<Option<usize>>,
    out: &mut Vec<Point>,
) {
    let weight = object_weight(ctx.params, cand);
    let prev = previous_accuracy(ctx.params, cand, prev);
    let benefit = |acc: f64| weight * hysteresis(ctx.params, acc, prev);
    out.push(Point {
        lod: NOT_DRAWN,
        resident: true,
        cost: 0.0,
        benefit: benefit(0.0),
    });
    for (j, lod) in cand.lods.iter().enumerate().rev() {
        let cost = lod_cost(ctx.model, lod, cand.pixels);
        if cost.is_finite() {
            let acc = accuracy(ctx.params, lod.triangles, cand.pixels);
            out.push(Point {
                lod: j as u32,
                resident: lod.resident,
                cost,
                benefit: benefit(acc),
            });
        }
    }
}

/// Appends to `out` the upper concave hull of `points` (sorted here): strictly increasing cost
/// and benefit, non-increasing slope. Dominated points (no more benefit for more cost) and
/// points below the hull are dropped; collinear ones are kept as extra steps.
fn upper_hull(points: &mut [Point], out: &mut Vec<Point>) {
    points.sort_by(|a, b| {
        a.cost
            .total_cmp(&b.cost)
            .then(b.benefit.total_cmp(&a.benefit))
    });
    let begin = out.len();
    for &p in points.iter() {
        if out.len() > begin && p.benefit <= out[out.len() - 1].benefit {
            continue;
        }
        while out.len() >= begin + 2 && below(&out[out.len() - 2], &out[out.len() - 1], &p) {
            out.pop();
        }
        out.push(p);
    }
}

/// Whether `b` lies strictly below the segment from `a` to `p` (so it is not on the hull).
fn below(a: &Point, b: &Point, p: &Point) -> bool {
    (b.benefit - a.benefit) * (p.cost - b.cost) < (p.benefit - b.benefit) * (b.cost - a.cost)
}

/// A heap entry: the value of one object's next (or current) step, tagged with the object's
/// version so that entries made stale by a later change are skipped when popped.
#[derive(Debug, Clone, Copy)]
struct Entry {
    value: f64,
    idx: u32,
    version: u32,
}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        self.value
            .total_cmp(&other.value)
            .then(other.idx.cmp(&self.idx))
            .then(self.version.cmp(&other.version))
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Entry {}

/// Working state of the incremental greedy, kept between frames to reuse its allocations.
#[derive(Debug, Clone, Default)]
struct Optimizer {
    /// Hull points of all objects, object `i` at `start[i]..start[i + 1]`.
    points: Vec<Point>,
    start: Vec<usize>,
    /// Current position of each object on its hull (0 = cheapest option).
    state: Vec<usize>,
    /// The warm-start positions, kept as the incumbent solution.
    incumbent: Vec<usize>,
    version: Vec<u32>,
    /// Max-heap on the value of each object's next step.
    next: BinaryHeap<Entry>,
    /// Min-heap on the value of each object's current step.
    current: BinaryHeap<Reverse<Entry>>,
    /// Running `Σ Cost` of the current positions.
    cost: f64,
    /// Every option of every object (resident or not), object `i` at
    /// `all_start[i]..all_start[i + 1]`: the input of the hulls and of `desired`.
    all: Vec<Point>,
    all_start: Vec<usize>,
    scratch: Vec<Point>,
    full_hull: Vec<Point>,
}

impl Optimizer {
    /// Runs the whole optimisation for one frame and returns the choices.
    fn solve(&mut self, cands: &[Candidate], ctx: &Context<'_>, budget: f64) -> Vec<Choice> {
        self.build(cands, ctx);
        let mut lambda = self.run(budget);
        self.fill(budget);
        self.enforce(budget);
        if self.keep_best_alternative(budget) {
            lambda = f64::INFINITY;
        }
        self.choices(lambda)
    }

    fn len(&self) -> usize {
        self.state.len()
    }

    fn point(&self, i: usize, s: usize) -> &Point {
        &self.points[self.start[i] + s]
    }

    fn hull_len(&self, i: usize) -> usize {
        self.start[i + 1] - self.start[i]
    }

    /// Builds every object's hull and warm-start position, and fills both queues.
    fn build(&mut self, cands: &[Candidate], ctx: &Context<'_>) {
        for v in [&mut self.points, &mut self.all] {
            v.clear();
        }
        for v in [&mut self.start, &mut self.all_start, &mut self.state] {
            v.clear();
        }
        self.start.push(0);
        self.all_start.push(0);
        for cand in cands {
            let prev = ctx.previous.get(&cand.id).copied();
            object_points(cand, ctx, prev, &mut self.all);
            self.all_start.push(self.all.len());
            let i = self.state.len();
            self.scratch.clear();
            let options = &self.all[self.all_start[i]..self.all_start[i + 1]];
            self.scratch.extend(options.iter().filter(|p| p.resident));
            upper_hull(&mut self.scratch, &mut self.points);
            self.start.push(self.points.len());
            self.state.push(self.warm_state(i, prev));
        }
        self.incumbent.clone_from(&self.state);
        self.version.clear();
        self.version.resize(self.len(), 0);
        self.cost = self.total(&self.state).0;
        self.fill_queues();
    }

    /// Warm start (§4.2.3): last frame's LOD snapped down to this frame's hull (the most
    /// expensive hull point costing no more than it); newly visible objects start at their
    /// cheapest drawn option; invalid or undrawn choices start undrawn.
    fn warm_state(&self, i: usize, prev: Option<Option<usize>>) -> usize {
        let hull = &self.points[self.start[i]..self.start[i + 1]];
        let options = &self.all[self.all_start[i]..self.all_start[i + 1]];
        match prev {
            None => 1.min(hull.len() - 1),
            Some(None) => 0,
            Some(Some(l)) => options.iter().find(|p| p.lod == l as u32).map_or(0, |o| {
                hull.iter().rposition(|p| p.cost <= o.cost).unwrap_or(0)
            }),
        }
    }

    fn fill_queues(&mut self) {
        let mut next = std::mem::take(&mut self.next).into_vec();
        let mut current = std::mem::take(&mut self.current).into_vec();
        next.clear();
        current.clear();
        for i in 0..self.len() {
            next.extend(self.next_entry(i));
            current.extend(self.current_entry(i).map(Reverse));
        }
        self.next = BinaryHeap::from(next);
        self.current = BinaryHeap::from(current);
    }

    fn next_entry(&self, i: usize) -> Option<Entry> {
        let s = self.state[i];
        (s + 1 < self.hull_len(i)).then(|| Entry {
            value: slope(self.point(i, s), self.point(i, s + 1)),
            idx: i as u32,
            version: self.version[i],
        })
    }

    fn current_entry(&self, i: usize) -> Option<Entry> {
        let s = self.state[i];
        (s > 0).then(|| Entry {
            value: slope(self.point(i, s - 1), self.point(i, s)),
            idx: i as u32,
            version: self.version[i],
        })
    }

    /// The object with the most valuable next step (stale entries skipped).
    fn pop_next(&mut self) -> Option<Entry> {
        while let Some(e) = self.next.pop() {
            if e.version == self.version[e.idx as usize] {
                return Some(e);
            }
        }
        None
    }

    /// The object with the least valuable current step (stale entries skipped).
    fn pop_current(&mut self) -> Option<Entry> {
        while let Some(Reverse(e)) = self.current.pop() {
            if e.version == self.version[e.idx as usize] {
                return Some(e);
            }
        }
        None
    }

    /// Moves object `i` one hull step up or down and requeues it.
    fn step(&mut self, i: usize, up: bool) {
        let from = *self.point(i, self.state[i]);
        self.state[i] = if up {
            self.state[i] + 1
        } else {
            self.state[i] - 1
        };
        self.cost += self.point(i, self.state[i]).cost - from.cost;
        self.version[i] = self.version[i].wrapping_add(1);
        if let Some(e) = self.next_entry(i) {
            self.next.push(e);
        }
        if let Some(e) = self.current_entry(i) {
            self.current.push(Reverse(e));
        }
    }

    /// Funkhouser's Fig. 4.20: increment the best next step while under budget, decrement the
    /// worst current steps while over; stop when one step is both incremented and decremented.
    /// Returns λ, the value of that step (0 if every object reached its finest option).
    fn run(&mut self, budget: f64) -> f64 {
        let mut guard = 2 * self.points.len() + 64;
        while guard > 0 {
            guard -= 1;
            let mut best = None;
            if self.cost <= budget {
                let Some(e) = self.pop_next() else {
                    return 0.0;
                };
                self.step(e.idx as usize, true);
                best = Some((e.idx, self.state[e.idx as usize]));
            }
            while self.cost > budget {
                let Some(w) = self.pop_current() else {
                    return f64::INFINITY;
                };
                let undone = (w.idx, self.state[w.idx as usize]);
                self.step(w.idx as usize, false);
                if best == Some(undone) {
                    return w.value;
                }
            }
        }
        f64::INFINITY
    }

    /// Spends leftover budget on the remaining steps in value order, skipping any that do not
    /// fit (an object whose next step does not fit gets no further step).
    fn fill(&mut self, budget: f64) {
        while let Some(e) = self.pop_next() {
            let i = e.idx as usize;
            let s = self.state[i];
            let extra = self.point(i, s + 1).cost - self.point(i, s).cost;
            if self.cost + extra <= budget {
                self.step(i, true);
            }
        }
    }

    /// Recomputes `Σ Cost` exactly and drops the least valuable steps while it is over budget
    /// (guards against rounding drift of the running sum).
    fn enforce(&mut self, budget: f64) {
        loop {
            self.cost = self.total(&self.state).0;
            if self.cost <= budget {
                return;
            }
            while self.cost > budget {
                let Some(w) = self.pop_current() else {
                    return;
                };
                self.step(w.idx as usize, false);
            }
        }
    }

    /// `(Σ Cost, Σ Benefit)` of the given hull positions, summed in object order.
    fn total(&self, state: &[usize]) -> (f64, f64) {
        state
            .iter()
            .enumerate()
            .map(|(i, &s)| self.point(i, s))
            .fold((0.0, 0.0), |(c, b), p| (c + p.cost, b + p.benefit))
    }

    /// Replaces the greedy solution by the incumbent (last frame's choices) if that still fits
    /// and scores at least as much, or by the best single object if that scores more. Returns
    /// whether the single object was taken.
    fn keep_best_alternative(&mut self, budget: f64) -> bool {
        let greedy = self.total(&self.state).1;
        let (inc_cost, inc_benefit) = self.total(&self.incumbent);
        let (mut best, mut single) = (greedy, false);
        if inc_cost <= budget && inc_benefit >= greedy {
            self.state.clone_from(&self.incumbent);
            best = inc_benefit;
        }
        if let Some((i, s, benefit)) = self.best_single(budget)
            && benefit > best
        {
            self.state.iter_mut().for_each(|s| *s = 0);
            self.state[i] = s;
            single = true;
        }
        single
    }

    /// The single object and hull position that, with every other object at its cheapest
    /// option, fits the budget and scores most: `(object, position, Σ Benefit)`.
    fn best_single(&self, budget: f64) -> Option<(usize, usize, f64)> {
        let (base_cost, base_benefit) = self.total(&vec![0; self.len()]);
        let mut best: Option<(usize, usize, f64)> = None;
        for i in 0..self.len() {
            let p0 = *self.point(i, 0);
            for s in 1..self.hull_len(i) {
                let p = self.point(i, s);
                let fits = base_cost + (p.cost - p0.cost) <= budget;
                let benefit = base_benefit + (p.benefit - p0.benefit);
                if fits && best.is_none_or(|b| benefit > b.2) {
                    best = Some((i, s, benefit));
                }
            }
        }
        best
    }

    /// Turns hull positions into choices, with `desired` and skip counts at price `lambda`.
    fn choices(&mut self, lambda: f64) -> Vec<Choice> {
        let mut out = Vec::with_capacity(self.len());
        for i in 0..self.len() {
            let lod = self.point(i, self.state[i]).lod();
            let options = &self.all[self.all_start[i]..self.all_start[i + 1]];
            let all_resident = options.iter().all(|p| p.resident);
            let wanted = if all_resident {
                lod
            } else {
                self.desired(i, lambda)
            };
            out.push(optimized_choice(lod, wanted));
        }
        out
    }

    /// The LOD object `i` would get at price `lambda` if all its LODs were resident: walk its
    /// full hull while the next step's value exceeds `lambda`.
    fn desired(&mut self, i: usize, lambda: f64) -> Option<usize> {
        let options = &self.all[self.all_start[i]..self.all_start[i + 1]];
        if !worth_drawing(options, lambda) {
            return None;
        }
        self.scratch.clear();
        self.scratch
            .extend_from_slice(&self.all[self.all_start[i]..self.all_start[i + 1]]);
        self.full_hull.clear();
        upper_hull(&mut self.scratch, &mut self.full_hull);
        let hull = &self.full_hull;
        let mut s = 0;
        while s + 1 < hull.len() && slope(&hull[s], &hull[s + 1]) > lambda {
            s += 1;
        }
        hull[s].lod()
    }
}

/// Whether any option beats "not drawn" (`options[0]`) by more than `lambda` per second: the
/// first step of the upper hull is the steepest line from its cheapest point, so if no option
/// clears `lambda`, the hull walk would stay at "not drawn" (a shortcut for most undrawn objects).
fn worth_drawing(options: &[Point], lambda: f64) -> bool {
    let base = options[0];
    options[1..].iter().any(|p| {
        let gain = p.benefit - base.benefit;
        gain > 0.0 && (p.cost <= base.cost || gain / (p.cost - base.cost) > lambda)
    })
}

/// An optimised choice: `desired` is the finer of the wanted and the drawn LOD.
fn optimized_choice(lod: Option<usize>, wanted: Option<usize>) -> Choice {
    let desired = match (lod, wanted) {
        (Some(l), Some(w)) => Some(l.min(w)),
        (l, w) => l.or(w),
    };
    Choice {
        lod,
        desired,
        lods_skipped: match (lod, desired) {
            (Some(l), Some(d)) => (l - d) as u32,
            _ => 0,
        },
        object_skipped: lod.is_none() && desired.is_some(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tiny deterministic xorshift64* generator for randomised tests.
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

        fn chance(&mut self, p: f64) -> bool {
            self.range(0.0, 1.0) < p
        }
    }

    fn lod(triangles: u32, resident: bool) -> LodOption {
        LodOption {
            triangles,
            vertices: triangles / 2 + 3,
            error: 0.0,
            resident,
        }
    }

    /// LODs of `finest`, `finest/4`, … triangles (finest first), all resident.
    fn chain(finest: u32, levels: usize) -> Vec<LodOption> {
        (0..levels)
            .map(|k| lod((finest >> (2 * k)).max(1), true))
            .collect()
    }

    fn random_candidates(
        rng: &mut Rng,
        n: usize,
        levels: usize,
        resident_p: f64,
    ) -> Vec<Candidate> {
        (0..n)
            .map(|i| {
                let finest = rng.range(50.0, 20_000.0) as u32;
                let mut lods = chain(finest, levels);
                for l in &mut lods {
                    l.resident = rng.chance(resident_p);
                }
                let mut c = Candidate::new(i as u32, lods, rng.range(10.0, 200_000.0) as f32);
                c.focus = rng.range(0.0, 1.0) as f32;
                c.motion = rng.range(0.0, 1.0) as f32;
                c.importance = rng.range(0.5, 2.0) as f32;
                c
            })
            .collect()
    }

    fn frame_cost(cands: &[Candidate], frame: &Frame, model: &CostModel) -> f64 {
        cands
            .iter()
            .zip(&frame.choices)
            .filter_map(|(c, ch)| ch.lod.map(|l| lod_cost(model, &c.lods[l], c.pixels)))
            .sum()
    }

    fn lods_of(frame: &Frame) -> Vec<Option<usize>> {
        frame.choices.iter().map(|c| c.lod).collect()
    }

    #[test]
    fn algorithm_names_round_trip() {
        for a in Algorithm::ALL {
            assert_eq!(a.to_string().parse::<Algorithm>(), Ok(a));
        }
        assert_eq!(" Optimise ".parse::<Algorithm>(), Ok(Algorithm::Optimize));
        let err = "fast".parse::<Algorithm>().unwrap_err();
        assert!(err.to_string().contains("`fast`"), "{err}");
        assert_eq!(Algorithm::default(), Algorithm::Optimize);
    }

    #[test]
    fn accuracy_follows_funkhouser() {
        let p = Params::default();
        assert_eq!(accuracy(&p, 1, 1000.0), 0.5);
        assert_eq!(accuracy(&p, 100, 1000.0), 0.995);
        // Samples never exceed the pixels covered.
        assert_eq!(accuracy(&p, 10_000, 100.0), accuracy(&p, 100, 100.0));
        assert_eq!(accuracy(&p, 0, 100.0), 0.0);
        assert_eq!(accuracy(&p, 50, f32::NAN), 0.5);
    }

    #[test]
    fn object_weight_multiplies_size_importance_focus_motion() {
        let p = Params::default();
        let mut c = Candidate::new(1, chain(100, 2), 1000.0);
        assert_eq!(object_weight(&p, &c), 1000.0);
        c.focus = 0.0;
        c.motion = 0.0;
        c.importance = 2.0;
        assert_eq!(object_weight(&p, &c), 1000.0 * 2.0 * 0.5 * 0.5);
        c.pixels = f32::INFINITY;
        assert_eq!(object_weight(&p, &c), 0.0);
    }

    #[test]
    fn none_draws_the_finest_lod() {
        let cands = vec![
            Candidate::new(1, chain(4096, 3), 10.0),
            Candidate::new(2, vec![], 10.0),
        ];
        let f = Elider::new(Algorithm::None, 0.0).choose(&cands, &CostModel::default(), None);
        assert_eq!(lods_of(&f), vec![Some(0), None]);
        assert_eq!(f.objects_skipped, 0);
        assert!(f.predicted_s > 0.0);
    }

    #[test]
    fn static_picks_the_finest_lod_with_1024_pixels_per_polygon() {
        let lods = chain(4096, 4); // 4096, 1024, 256, 64 triangles
        let t = 1024.0;
        assert_eq!(static_lod(&lods, 4096.0 * 1024.0, t), Some(0));
        assert_eq!(static_lod(&lods, 4096.0 * 1024.0 - 1.0, t), Some(1));
        assert_eq!(static_lod(&lods, 256.0 * 1024.0, t), Some(2));
        assert_eq!(static_lod(&lods, 64.0 * 1024.0, t), Some(3));
        assert_eq!(static_lod(&lods, 10.0, t), Some(3), "else the coarsest");
        assert_eq!(static_lod(&[], 10.0, t), None);
        let cands = vec![Candidate::new(7, lods, 300_000.0)];
        let f = Elider::new(Algorithm::Static, 0.1).choose(&cands, &CostModel::default(), None);
        assert_eq!(f.choices[0].lod, Some(2));
    }

    #[test]
    fn residency_fallback_counts_skips() {
        let lods = vec![
            lod(1000, false),
            lod(250, false),
            lod(60, true),
            lod(15, true),
        ];
        let c = resident_fallback(&lods, Some(0));
        assert_eq!(
            (c.lod, c.desired, c.lods_skipped, c.object_skipped),
            (Some(2), Some(0), 2, false)
        );
        assert_eq!(resident_fallback(&lods, Some(3)).lods_skipped, 0);
        let none = vec![lod(1000, false), lod(250, false)];
        let c = resident_fallback(&none, Some(0));
        assert_eq!((c.lod, c.lods_skipped, c.object_skipped), (None, 0, true));
        // Never draws a finer LOD than desired, even if only that one is resident.
        let fine_only = vec![lod(1000, true), lod(250, false)];
        assert!(resident_fallback(&fine_only, Some(1)).object_skipped);
        assert_eq!(resident_fallback(&lods, None), Choice::default());
    }

    #[test]
    fn static_frame_totals_skips() {
        let cands = vec![
            Candidate::new(1, vec![lod(1000, false), lod(250, true)], 1.0e7),
            Candidate::new(2, vec![lod(1000, false), lod(250, false)], 1.0e7),
        ];
        let f = Elider::new(Algorithm::Static, 0.1).choose(&cands, &CostModel::default(), None);
        assert_eq!(lods_of(&f), vec![Some(1), None]);
        assert_eq!((f.lods_skipped, f.objects_skipped), (1, 1));
    }

    #[test]
    fn feedback_threshold_follows_frame_time() {
        let mut e = Elider::new(Algorithm::Feedback, 0.1);
        let model = CostModel::default();
        let cands = vec![Candidate::new(1, chain(4096, 4), 256.0 * 1024.0)];
        assert_eq!(e.choose(&cands, &model, None).choices[0].lod, Some(2));
        // Too slow: the threshold doubles (clamped step), so coarser LODs are chosen.
        let f = e.choose(&cands, &model, Some(0.5));
        assert_eq!(e.threshold_px(), 2048.0);
        assert_eq!(f.choices[0].lod, Some(3));
        // Too fast: it falls again.
        e.choose(&cands, &model, Some(0.025));
        e.choose(&cands, &model, Some(0.025));
        assert_eq!(e.threshold_px(), 512.0);
        for _ in 0..100 {
            e.choose(&cands, &model, Some(0.0));
        }
        assert_eq!(e.threshold_px(), e.params().feedback_min_px_per_tri);
        e.choose(&cands, &model, Some(f64::NAN));
        assert_eq!(e.threshold_px(), e.params().feedback_min_px_per_tri);
    }

    #[test]
    fn optimize_never_exceeds_the_budget() {
        let mut rng = Rng(0x5eed);
        let model = CostModel::default();
        for round in 0..200 {
            let n = 1 + (rng.next() % 60) as usize;
            let levels = 1 + (rng.next() % 5) as usize;
            let cands = random_candidates(&mut rng, n, levels, 0.8);
            let budget = rng.range(0.0, 0.05);
            let mut e = Elider::new(Algorithm::Optimize, budget);
            for _ in 0..3 {
                let f = e.choose(&cands, &model, None);
                let cost = frame_cost(&cands, &f, &model);
                assert!(
                    cost <= budget * (1.0 + 1e-12),
                    "round {round}: {cost} > {budget}"
                );
                assert!((cost - f.predicted_s).abs() <= 1e-12 * budget.max(1e-9));
            }
        }
    }

    #[test]
    fn optimize_never_picks_a_non_resident_lod() {
        let mut rng = Rng(42);
        let model = CostModel::default();
        for _ in 0..100 {
            let cands = random_candidates(&mut rng, 40, 5, 0.5);
            let mut e = Elider::new(Algorithm::Optimize, rng.range(0.0, 0.1));
            for _ in 0..2 {
                let f = e.choose(&cands, &model, None);
                for (c, ch) in cands.iter().zip(&f.choices) {
                    if let Some(l) = ch.lod {
                        assert!(c.lods[l].resident);
                    }
                    if c.lods.iter().all(|l| !l.resident) {
                        assert_eq!(ch.lod, None);
                    }
                }
            }
        }
    }

    #[test]
    fn huge_budget_draws_the_finest_resident_lod() {
        let mut rng = Rng(9);
        let mut cands = random_candidates(&mut rng, 50, 4, 0.6);
        for c in &mut cands {
            c.pixels = 1.0e6; // more pixels than triangles: finer LODs always add accuracy
        }
        let f = Elider::new(Algorithm::Optimize, 1.0e9).choose(&cands, &CostModel::default(), None);
        for (c, ch) in cands.iter().zip(&f.choices) {
            assert_eq!(ch.lod, c.lods.iter().position(|l| l.resident));
            assert_eq!(ch.object_skipped, ch.lod.is_none());
            assert_eq!(ch.desired, Some(0), "everything is wanted at full detail");
        }
    }

    #[test]
    fn zero_budget_draws_nothing() {
        let mut rng = Rng(10);
        let cands = random_candidates(&mut rng, 30, 3, 1.0);
        let mut e = Elider::new(Algorithm::Optimize, 0.0);
        for _ in 0..2 {
            let f = e.choose(&cands, &CostModel::default(), None);
            assert!(f.choices.iter().all(|c| c.lod.is_none()));
            assert_eq!(f.predicted_s, 0.0);
            assert_eq!(
                f.objects_skipped, 0,
                "not drawn for lack of time, not of data"
            );
        }
        e.set_budget(-1.0);
        assert_eq!(e.budget_s(), 0.0);
    }

    #[test]
    fn optimize_prefers_larger_objects() {
        let cands = vec![
            Candidate::new(1, chain(1000, 1), 100.0),
            Candidate::new(2, chain(1000, 1), 100_000.0),
        ];
        let model = CostModel::default();
        let one = model.cost(1000, 503, 100_000.0);
        let f = Elider::new(Algorithm::Optimize, one * 1.5).choose(&cands, &model, None);
        assert_eq!(lods_of(&f), vec![None, Some(0)]);
    }

    #[test]
    fn optimize_reports_lods_skipped_for_missing_detail() {
        // With everything resident the object gets LOD 0 under a generous budget; with LOD 0
        // missing it gets LOD 1 and one LOD is reported skipped.
        let mut lods = chain(1000, 3);
        let model = CostModel::default();
        let mut e = Elider::new(Algorithm::Optimize, 1.0);
        let full = e.choose(&[Candidate::new(1, lods.clone(), 1.0e6)], &model, None);
        assert_eq!((full.choices[0].lod, full.lods_skipped), (Some(0), 0));
        lods[0].resident = false;
        let mut e = Elider::new(Algorithm::Optimize, 1.0);
        let f = e.choose(&[Candidate::new(1, lods.clone(), 1.0e6)], &model, None);
        assert_eq!(f.choices[0].lod, Some(1));
        assert_eq!(f.choices[0].desired, Some(0));
        assert_eq!((f.lods_skipped, f.objects_skipped), (1, 0));
        for l in &mut lods {
            l.resident = false;
        }
        let f = e.choose(&[Candidate::new(1, lods, 1.0e6)], &model, None);
        assert_eq!(f.choices[0].lod, None);
        assert_eq!(f.objects_skipped, 1);
    }

    #[test]
    fn warm_start_is_stable_and_never_worse() {
        let mut rng = Rng(77);
        let model = CostModel::default();
        let (mut same, rounds) = (0, 100);
        for _ in 0..rounds {
            let cands = random_candidates(&mut rng, 50, 5, 0.9);
            let mut e = Elider::new(Algorithm::Optimize, rng.range(0.001, 0.03));
            let first = e.choose(&cands, &model, None);
            let second = e.choose(&cands, &model, None);
            assert!(second.benefit >= first.benefit - 1e-9 * first.benefit.abs());
            same += usize::from(lods_of(&first) == lods_of(&second));
            let third = e.choose(&cands, &model, None);
            assert_eq!(
                lods_of(&second),
                lods_of(&third),
                "a repeated frame is a fixed point"
            );
        }
        assert!(
            same * 10 >= rounds * 9,
            "only {same} of {rounds} repeated frames unchanged"
        );
    }

    #[test]
    fn warm_start_same_input_same_result() {
        let cands = random_candidates(&mut Rng(5), 200, 5, 1.0);
        let model = CostModel::default();
        let mut e = Elider::new(Algorithm::Optimize, 0.01);
        let first = e.choose(&cands, &model, None);
        let second = e.choose(&cands, &model, None);
        assert_eq!(lods_of(&first), lods_of(&second));
        assert!(second.benefit >= first.benefit);
    }

    /// Best `Σ Benefit` over all assignments (each object: not drawn or one resident LOD).
    fn brute_force(cands: &[Candidate], model: &CostModel, budget: f64) -> f64 {
        let params = Params::default();
        let options: Vec<Vec<(f64, f64)>> = cands
            .iter()
            .map(|c| {
                let w = object_weight(&params, c);
                let mut o = vec![(0.0, 0.0)];
                for l in c.lods.iter().filter(|l| l.resident) {
                    o.push((
                        lod_cost(model, l, c.pixels),
                        w * accuracy(&params, l.triangles, c.pixels),
                    ));
                }
                o
            })
            .collect();
        let mut best = 0.0f64;
        let mut pick = vec![0usize; cands.len()];
        loop {
            let (c, b) = pick.iter().enumerate().fold((0.0, 0.0), |(c, b), (i, &k)| {
                (c + options[i][k].0, b + options[i][k].1)
            });
            if c <= budget {
                best = best.max(b);
            }
            let Some(i) = (0..pick.len()).find(|&i| pick[i] + 1 < options[i].len()) else {
                return best;
            };
            pick[i] += 1;
            pick[..i].iter_mut().for_each(|k| *k = 0);
        }
    }

    #[test]
    fn greedy_is_close_to_brute_force() {
        let mut rng = Rng(2024);
        let model = CostModel::default();
        let (mut sum_ratio, rounds) = (0.0, 300);
        for _ in 0..rounds {
            let cands = random_candidates(&mut rng, 3, 3, 0.9);
            let budget = rng.range(0.0, 0.003);
            let optimum = brute_force(&cands, &model, budget);
            let f = Elider::new(Algorithm::Optimize, budget).choose(&cands, &model, None);
            assert!(f.benefit <= optimum * (1.0 + 1e-9) + 1e-9);
            let ratio = if optimum > 0.0 {
                f.benefit / optimum
            } else {
                1.0
            };
            assert!(ratio >= 0.5, "greedy {} vs optimum {optimum}", f.benefit);
            sum_ratio += ratio;
        }
        let mean = sum_ratio / rounds as f64;
        assert!(mean >= 0.95, "mean ratio to the optimum {mean}");
    }

    /// Two objects competing for a budget that fits one of them at LOD 0 and one at LOD 1.
    fn rivals(pixels_b: f32) -> Vec<Candidate> {
        let lods = || vec![lod(400, true), lod(100, true)];
        vec![
            Candidate::new(1, lods(), 100_000.0),
            Candidate::new(2, lods(), pixels_b),
        ]
    }

    #[test]
    fn hysteresis_keeps_choices_through_small_changes() {
        // Geometry-bound costs, so that LOD 0 costs more than LOD 1.
        let model = CostModel {
            c3: 0.0,
            ..CostModel::default()
        };
        let budget = model.cost(400, 203, 0.0) + model.cost(100, 53, 0.0) + 1e-7;
        let run = |h: f64| {
            let params = Params {
                hysteresis: h,
                ..Params::default()
            };
            let mut e = Elider::new(Algorithm::Optimize, budget).with_params(params);
            let before = lods_of(&e.choose(&rivals(98_000.0), &model, None));
            let after = lods_of(&e.choose(&rivals(102_000.0), &model, None));
            (before, after)
        };
        let (before, after) = run(0.0);
        assert_eq!(before, vec![Some(0), Some(1)]);
        assert_eq!(
            after,
            vec![Some(1), Some(0)],
            "without hysteresis a 4 % change flips"
        );
        let (before, after) = run(0.1);
        assert_eq!(before, after, "with hysteresis it does not");
        let far = {
            let mut e = Elider::new(Algorithm::Optimize, budget);
            e.choose(&rivals(98_000.0), &model, None);
            lods_of(&e.choose(&rivals(150_000.0), &model, None))
        };
        assert_eq!(far, vec![Some(1), Some(0)], "a large change still switches");
    }

    #[test]
    fn objects_that_leave_the_view_are_dropped_from_the_warm_start() {
        let model = CostModel::default();
        let mut e = Elider::new(Algorithm::Optimize, 0.01);
        let a = random_candidates(&mut Rng(1), 20, 3, 1.0);
        e.choose(&a, &model, None);
        let mut b: Vec<Candidate> = a[10..].to_vec();
        b[0].lods.truncate(1); // an index from last frame may now be out of range
        let f = e.choose(&b, &model, None);
        assert_eq!(f.choices.len(), b.len());
        assert!(frame_cost(&b, &f, &model) <= 0.01);
    }

    #[test]
    fn optimize_10k_candidates_timing() {
        let cands = random_candidates(&mut Rng(123), 10_000, 5, 0.9);
        let model = CostModel::default();
        let mut e = Elider::new(Algorithm::Optimize, 0.05);
        let t = std::time::Instant::now();
        let cold = e.choose(&cands, &model, None);
        let cold_s = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let warm = e.choose(&cands, &model, None);
        let warm_s = t.elapsed().as_secs_f64();
        e.reset();
        let t = std::time::Instant::now();
        e.choose(&cands, &model, None);
        let reset_s = t.elapsed().as_secs_f64();
        println!(
            "optimize 10k×5: first {:.2} ms, warm {:.2} ms, after reset {:.2} ms; \
             {} drawn, predicted {:.4} s",
            cold_s * 1e3,
            warm_s * 1e3,
            reset_s * 1e3,
            warm.choices.iter().filter(|c| c.lod.is_some()).count(),
            warm.predicted_s
        );
        assert!(cold.predicted_s <= 0.05 && warm.predicted_s <= 0.05);
    }
}
