//! Funkhouser's incremental greedy for the multiple-choice knapsack (Funkhouser 1993 §4.2.3,
//! Fig. 4.20): the *NEXT* and *CURRENT* heaps over the objects' hulls, warm-started from the
//! previous frame; then the fill, incumbent and best-single refinements, and each object's
//! `desired` LOD at the frame's marginal value of time.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

use super::hull::{Context, Point, object_points, slope, upper_hull, worth_drawing};
use super::{Candidate, Choice};

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
pub(super) struct Optimizer {
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
    pub(super) fn solve(
        &mut self,
        cands: &[Candidate],
        ctx: &Context<'_>,
        budget: f64,
    ) -> Vec<Choice> {
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
