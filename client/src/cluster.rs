//! Choosing between clusters and objects each frame (Maciel §6.4), on top of cells-and-portals
//! visibility: the `impostors` elision.
//!
//! 1. Assign (§6.4.1): a cluster is visible when an object beneath it is (eye-to-object from the
//!    cells); its benefit is the largest of its visible children's (object benefit: screen size
//!    × focus × importance); its cost is its box's (12 triangles and its projected pixels under
//!    the cost model); its children's cost is the sum of their cheapest representations — a
//!    child cluster's box, a child object's coarsest RESIDENT LOD.
//! 2. Refine best first (§6.4.2): starting from the root's box, expand the most beneficial
//!    visible cluster while the frame's predicted cost stays within the budget; a cluster with a
//!    visible object that has nothing resident cannot be expanded (as if there were no budget
//!    left: its box stands in), unless the eye is inside its box, which no box can stand in for;
//!    one whose children cost less than its box (Maciel's cost rule broken at run time, e.g.
//!    by a fill-bound renderer) is always expanded.
//!    Every visible object is always represented: by itself or by a box above it.
//! 3. Upgrade (Maciel's "better representation"): the expanded objects, most beneficial first,
//!    get their finest resident LOD that still fits.
//!
//! Against flicker (§6.4.3), a cluster drawn as a box must want to expand for
//! [`EXPAND_AFTER`] frames in a row before it does; collapsing is immediate (it happens when
//! the budget is spent, and delaying it would miss the frame time).

use crate::cost::CostModel;
use crate::elision::Candidate;
use portico_data::hierarchy::{BOX_TRIANGLES, BOX_VERTICES, Hierarchy};
use std::collections::{BinaryHeap, HashMap, HashSet};

/// Frames a cluster must want to expand before it does.
pub const EXPAND_AFTER: u32 = 3;
/// Below this many pixels on screen a cluster is drawn as its average-colour box even when its
/// textured box is resident (Maciel §5.2.3: "a few pixels").
pub const COLOUR_BOX_PIXELS: f32 = 64.0;

/// How a cluster is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stand {
    /// The average-colour box (always available: its colours are in the header).
    Colour,
    /// The textured box (its atlas is resident).
    Textured,
}

/// What the traversal knows about the frame besides the candidates.
pub struct Frame<'a> {
    /// Projected pixels of a cluster's box.
    pub pixels: &'a dyn Fn(u32) -> f32,
    /// Whether the eye is inside a cluster's box.
    pub eye_inside: &'a dyn Fn(u32) -> bool,
    /// Whether a cluster's textured box is resident.
    pub textured: &'a dyn Fn(u32) -> bool,
    /// The cost model.
    pub cost: &'a CostModel,
    /// The frame budget (s).
    pub budget_s: f64,
}

/// The frame's choice.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Cut {
    /// Clusters drawn as boxes.
    pub boxes: Vec<(u32, Stand)>,
    /// Per candidate, the LOD to draw (`None`: stood in for by a box, or nothing resident).
    pub lods: Vec<Option<usize>>,
    /// Visible objects stood in for by a box.
    pub stood_in: u32,
    /// Per candidate, whether a box stands in for it.
    pub stood: Vec<bool>,
    /// Visible objects with nothing drawn for them (no resident LOD and no box above).
    pub objects_skipped: u32,
    /// Predicted render time of everything chosen (s).
    pub predicted_s: f64,
}

/// Per-cluster facts of one frame.
#[derive(Debug, Default)]
struct Node {
    benefit: f64,
    box_cost: f64,
    child_nodes: Vec<u32>,
    child_objects: Vec<usize>,
    children_cost: f64,
    expandable: bool,
}

/// A heap entry: a visible cluster by benefit.
#[derive(Debug, PartialEq)]
struct ByBenefit(f64, u32);
impl Eq for ByBenefit {}
impl PartialOrd for ByBenefit {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for ByBenefit {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&o.0).then(o.1.cmp(&self.1))
    }
}

/// The traversal with its frame-to-frame memory (temporal coherence).
#[derive(Debug, Default)]
pub struct Traversal {
    /// Clusters drawn as boxes last frame.
    boxed: HashSet<u32>,
    /// Frames in a row each box-drawn cluster has wanted to expand.
    wanting: HashMap<u32, u32>,
}

impl Traversal {
    /// Chooses boxes and object LODs for one frame.
    pub fn choose(&mut self, h: &Hierarchy, cands: &[Candidate], f: &Frame<'_>) -> Cut {
        let mut cut = Cut {
            lods: vec![None; cands.len()],
            stood: vec![false; cands.len()],
            ..Cut::default()
        };
        let cheapest: Vec<Option<(usize, f64)>> = cands
            .iter()
            .map(|c| {
                let l = c.lods.iter().rposition(|l| l.resident)?;
                let lod = &c.lods[l];
                let px = f64::from(c.pixels);
                Some((
                    l,
                    f.cost.cost_of(
                        u64::from(lod.triangles),
                        u64::from(lod.vertices),
                        px,
                        lod.textured(),
                    ),
                ))
            })
            .collect();
        let (nodes, loose) = assign(h, cands, &cheapest, f);
        let mut total: f64 = loose
            .iter()
            .filter_map(|&i| cheapest[i].map(|(_, c)| c))
            .sum();
        let mut drawn: Vec<usize> = loose;
        let mut boxed = HashSet::new();
        if let Some(root) = h.root().filter(|r| nodes.contains_key(r)) {
            total += nodes[&root].box_cost;
            let mut heap = BinaryHeap::from([ByBenefit(nodes[&root].benefit, root)]);
            while let Some(ByBenefit(_, id)) = heap.pop() {
                let n = &nodes[&id];
                let delta = n.children_cost - n.box_cost;
                let must = (f.eye_inside)(id);
                // A box that costs more than what it stands for (fill-bound renderers, boxes
                // much larger than their objects' footprint) never pays: open it.
                let fits = n.expandable && (delta <= 0.0 || total + delta <= f.budget_s);
                if must || (fits && self.settled(id)) {
                    total += delta;
                    drawn.extend(&n.child_objects);
                    heap.extend(
                        n.child_nodes
                            .iter()
                            .map(|&c| ByBenefit(nodes[&c].benefit, c)),
                    );
                } else {
                    if !fits {
                        self.wanting.remove(&id);
                    }
                    let textured = (f.textured)(id) && (f.pixels)(id) >= COLOUR_BOX_PIXELS;
                    let stand = if textured {
                        Stand::Textured
                    } else {
                        Stand::Colour
                    };
                    cut.boxes.push((id, stand));
                    boxed.insert(id);
                    for i in objects_under(&nodes, id) {
                        cut.stood[i] = true;
                        cut.stood_in += 1;
                    }
                }
            }
        }
        self.wanting.retain(|id, _| boxed.contains(id));
        self.boxed = boxed;
        total = upgrade(cands, &cheapest, &mut drawn, &mut cut, total, f);
        cut.predicted_s = total;
        cut
    }

    /// Whether a cluster may expand now: it was not drawn as a box last frame (expanded, or
    /// not visible: nothing on screen would pop), or has wanted to for long enough.
    fn settled(&mut self, id: u32) -> bool {
        if !self.boxed.contains(&id) {
            return true;
        }
        let n = self.wanting.entry(id).or_insert(0);
        *n += 1;
        *n >= EXPAND_AFTER
    }
}

/// Phase 1: the visible clusters with their benefit and costs, and the visible objects that hang
/// under no cluster.
fn assign(
    h: &Hierarchy,
    cands: &[Candidate],
    cheapest: &[Option<(usize, f64)>],
    f: &Frame<'_>,
) -> (HashMap<u32, Node>, Vec<usize>) {
    let mut nodes: HashMap<u32, Node> = HashMap::new();
    let mut loose = Vec::new();
    for (i, c) in cands.iter().enumerate() {
        let benefit = f64::from(c.pixels) * f64::from(c.focus.max(0.05)) * f64::from(c.importance);
        let Some(&parent) = h
            .instance_parent
            .get(c.id as usize)
            .filter(|&&p| p != u32::MAX)
        else {
            loose.push(i);
            continue;
        };
        let node = nodes.entry(parent).or_default();
        node.child_objects.push(i);
        node.benefit = node.benefit.max(benefit);
        // Mark the ancestors visible, linking each to its parent once.
        let mut child = parent;
        while let Some(&up) = h.nodes.get(child as usize).map(|n| &n.parent) {
            if up == u32::MAX {
                break;
            }
            let fresh = !nodes.contains_key(&up) || !nodes[&up].child_nodes.contains(&child);
            let p = nodes.entry(up).or_default();
            if fresh {
                p.child_nodes.push(child);
            }
            p.benefit = p.benefit.max(benefit);
            child = up;
        }
    }
    let ids: Vec<u32> = nodes.keys().copied().collect();
    for id in &ids {
        let px = f64::from((f.pixels)(*id));
        // A textured box samples its atlas: it pays the texture's fill cost as objects do.
        let cost = f.cost.cost_of(
            u64::from(BOX_TRIANGLES),
            u64::from(BOX_VERTICES),
            px,
            (f.textured)(*id),
        );
        if let Some(n) = nodes.get_mut(id) {
            n.box_cost = cost;
        }
    }
    for id in ids {
        let n = &nodes[&id];
        let objects: Option<f64> = n
            .child_objects
            .iter()
            .map(|&i| cheapest[i].map(|(_, c)| c))
            .sum();
        let boxes: f64 = n.child_nodes.iter().map(|c| nodes[c].box_cost).sum();
        let (children_cost, expandable) = (objects.unwrap_or(0.0) + boxes, objects.is_some());
        if let Some(n) = nodes.get_mut(&id) {
            n.children_cost = children_cost;
            n.expandable = expandable;
        }
    }
    (nodes, loose)
}

/// The visible objects (candidate indices) beneath a visible cluster.
fn objects_under(nodes: &HashMap<u32, Node>, id: u32) -> Vec<usize> {
    let mut out = Vec::new();
    let mut stack = vec![id];
    while let Some(c) = stack.pop() {
        if let Some(node) = nodes.get(&c) {
            out.extend(&node.child_objects);
            stack.extend(&node.child_nodes);
        }
    }
    out
}

/// Phase 3: every drawn object starts at its coarsest resident LOD; the most beneficial first
/// move to the finest resident LOD that still fits. Returns the new total.
fn upgrade(
    cands: &[Candidate],
    cheapest: &[Option<(usize, f64)>],
    drawn: &mut [usize],
    cut: &mut Cut,
    mut total: f64,
    f: &Frame<'_>,
) -> f64 {
    drawn.sort_by(|&a, &b| cands[b].pixels.total_cmp(&cands[a].pixels));
    for &i in drawn.iter() {
        let Some((coarse, coarse_cost)) = cheapest[i] else {
            cut.objects_skipped += 1;
            continue;
        };
        let c = &cands[i];
        let mut pick = (coarse, coarse_cost);
        for (l, lod) in c.lods.iter().enumerate().take(coarse) {
            if !lod.resident {
                continue;
            }
            let cost = f.cost.cost_of(
                u64::from(lod.triangles),
                u64::from(lod.vertices),
                f64::from(c.pixels),
                lod.textured(),
            );
            if total - coarse_cost + cost <= f.budget_s {
                pick = (l, cost);
                break;
            }
        }
        total += pick.1 - coarse_cost;
        cut.lods[i] = Some(pick.0);
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elision::LodOption;
    use portico_data::geometry::Aabb;

    fn lod(triangles: u32) -> LodOption {
        LodOption::new(triangles, triangles, 0.0, true)
    }

    /// Two rooms of four objects each, 10 m apart.
    fn world() -> (Hierarchy, Vec<Candidate>) {
        let mut b = Vec::new();
        for room in 0..2 {
            for k in 0..4 {
                let x = room as f32 * 10.0 + k as f32 * 0.6;
                b.push(Aabb {
                    min: [x, 0.0, 0.0],
                    max: [x + 0.5, 0.5, 0.5],
                });
            }
        }
        let h = Hierarchy::build(&b, 2.0);
        h.check(&b).unwrap();
        let cands = (0..8)
            .map(|i| Candidate::new(i, vec![lod(4000), lod(400), lod(12)], 2000.0))
            .collect();
        (h, cands)
    }

    fn frame<'a>(cost: &'a CostModel, budget_s: f64, inside: &'a dyn Fn(u32) -> bool) -> Frame<'a> {
        Frame {
            pixels: &|_| 5000.0,
            eye_inside: inside,
            textured: &|_| true,
            cost,
            budget_s,
        }
    }

    fn settle(t: &mut Traversal, h: &Hierarchy, c: &[Candidate], f: &Frame<'_>) -> Cut {
        (0..=EXPAND_AFTER)
            .map(|_| t.choose(h, c, f))
            .last()
            .unwrap()
    }

    #[test]
    fn the_cut_never_exceeds_the_budget_and_represents_every_visible_object() {
        let (h, cands) = world();
        let cost = CostModel::default();
        let no = |_: u32| false;
        for budget in [1e-9, 1e-5, 1e-4, 1e-3, 1e-2, 1.0] {
            let f = frame(&cost, budget, &no);
            let mut t = Traversal::default();
            let cut = settle(&mut t, &h, &cands, &f);
            let root_box = cost.cost_of(12, 24, 5000.0, true);
            assert!(
                cut.predicted_s <= budget.max(root_box) + 1e-12,
                "budget {budget}: {} > {budget}",
                cut.predicted_s
            );
            let drawn = cut.lods.iter().filter(|l| l.is_some()).count() as u32;
            assert_eq!(drawn + cut.stood_in, 8, "budget {budget}: {cut:?}");
            assert!(
                cut.lods
                    .iter()
                    .zip(&cut.stood)
                    .all(|(l, s)| l.is_some() != *s),
                "each object drawn or stood in for, never both: {cut:?}"
            );
        }
    }

    #[test]
    fn more_budget_means_objects_instead_of_boxes_and_finer_lods() {
        let (h, cands) = world();
        let cost = CostModel::default();
        let no = |_: u32| false;
        let mut t = Traversal::default();
        let small = settle(&mut t, &h, &cands, &frame(&cost, 1e-5, &no));
        let mut t = Traversal::default();
        let big = settle(&mut t, &h, &cands, &frame(&cost, 1.0, &no));
        assert!(small.stood_in > 0, "{small:?}");
        assert_eq!(big.stood_in, 0);
        assert!(big.lods.iter().all(|l| *l == Some(0)), "{big:?}");
    }

    #[test]
    fn a_box_around_the_eye_is_always_opened_and_expansion_waits_a_few_frames() {
        let (h, cands) = world();
        let cost = CostModel::default();
        let root = h.root().unwrap();
        let inside = move |n: u32| n == root;
        let mut t = Traversal::default();
        let cut = t.choose(&h, &cands, &frame(&cost, 1e-9, &inside));
        assert!(cut.boxes.iter().all(|(n, _)| *n != root), "{cut:?}");
        // A cluster drawn as a box waits EXPAND_AFTER frames of room before it opens.
        let no = |_: u32| false;
        let mut t = Traversal::default();
        let tight = t.choose(&h, &cands, &frame(&cost, 1e-9, &no));
        assert_eq!(tight.boxes, vec![(root, Stand::Textured)]);
        for _ in 1..EXPAND_AFTER {
            let waiting = t.choose(&h, &cands, &frame(&cost, 1.0, &no));
            assert_eq!(waiting.boxes, vec![(root, Stand::Textured)]);
        }
        let opened = t.choose(&h, &cands, &frame(&cost, 1.0, &no));
        assert!(opened.boxes.is_empty(), "{opened:?}");
        // Without a box last frame, nothing waits.
        let mut fresh = Traversal::default();
        assert!(
            fresh
                .choose(&h, &cands, &frame(&cost, 1.0, &no))
                .boxes
                .is_empty()
        );
    }

    #[test]
    fn an_object_with_nothing_resident_keeps_its_cluster_boxed() {
        let (h, mut cands) = world();
        for l in &mut cands[0].lods {
            l.resident = false;
        }
        let cost = CostModel::default();
        let no = |_: u32| false;
        let mut t = Traversal::default();
        let cut = settle(&mut t, &h, &cands, &frame(&cost, 1.0, &no));
        let parent = h.instance_parent[0];
        assert!(cut.boxes.iter().any(|(n, _)| *n == parent), "{cut:?}");
        assert_eq!(cut.objects_skipped, 0, "the box stands in for it");
    }
}
