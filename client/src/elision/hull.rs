//! The options the optimiser chooses among (Funkhouser 1993 §4.2.3): each object's (cost,
//! benefit) points, "not drawn" included, reduced to their upper convex hull so that value
//! (`ΔBenefit / ΔCost`) falls with every step up, the "diminishing returns" that the
//! incremental greedy of Fig. 4.20 needs.

use crate::cost::CostModel;

use super::benefit::{hysteresis, lod_accuracy, lod_cost, object_weight, previous_accuracy};
use super::{Candidate, IdMap, Params};

/// What the optimiser needs besides the candidates.
pub(super) struct Context<'a> {
    pub(super) params: &'a Params,
    pub(super) model: &'a CostModel,
    pub(super) previous: &'a IdMap,
}

/// `lod` value of the "not drawn" option.
const NOT_DRAWN: u32 = u32::MAX;

/// One option of an object: a LOD (or not drawn) with its cost and benefit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Point {
    pub(super) lod: u32,
    pub(super) resident: bool,
    pub(super) cost: f64,
    pub(super) benefit: f64,
}

impl Point {
    pub(super) fn lod(&self) -> Option<usize> {
        (self.lod != NOT_DRAWN).then_some(self.lod as usize)
    }
}

/// `ΔBenefit / ΔCost` from `a` to `b` (hull steps always have `ΔCost > 0`).
pub(super) fn slope(a: &Point, b: &Point) -> f64 {
    (b.benefit - a.benefit) / (b.cost - a.cost)
}

/// Appends the options of one object: "not drawn", then every LOD with a finite cost, coarsest
/// first (so nearly sorted by cost), with its hysteresis-adjusted benefit.
pub(super) fn object_points(
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
            let acc = lod_accuracy(ctx.params, lod, cand.pixels);
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
pub(super) fn upper_hull(points: &mut [Point], out: &mut Vec<Point>) {
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

/// Whether any option beats "not drawn" (`options[0]`) by more than `lambda` per second: the
/// first step of the upper hull is the steepest line from its cheapest point, so if no option
/// clears `lambda`, the hull walk would stay at "not drawn" (a shortcut for most undrawn objects).
pub(super) fn worth_drawing(options: &[Point], lambda: f64) -> bool {
    let base = options[0];
    options[1..].iter().any(|p| {
        let gain = p.benefit - base.benefit;
        gain > 0.0 && (p.cost <= base.cost || gain / (p.cost - base.cost) > lambda)
    })
}
