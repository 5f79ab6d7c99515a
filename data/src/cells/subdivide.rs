//! Spatial subdivision into axis-aligned cells (Funkhouser §3.2.1; Teller 1992 §4): a k-D tree
//! whose splitting planes lie along the major occluders. The occluders are axis-aligned faces
//! ([`super::occluders`]); at each node the candidate planes are the planes of the faces
//! strictly inside it, scored by how much of the node's cross section they cover, and the best
//! plane splits the node while it covers at least [`MIN_COVERAGE`]. Floors and ceilings
//! (covering a whole storey) split first, then corridor walls, then the walls between rooms;
//! door and window openings end up as thin cells of their own between the rooms they join, and
//! the space inside walls and slabs as cells with no portals (marked dead by `portals`).
//!
//! Without occluders the subdivision falls back to a regular grid of open cells.
//!
//! A leaf that is mostly solid but not wholly (a roof layer with a skylight, a wall layer with a
//! window no face plane split off) is cut further along the solids' own faces
//! ([`super::solid::split_plane`]), so that its openings become cells of their own, which the
//! portals then join to the cells on either side.
//!
//! When the model has strays ([`crate::bulk`]), the first splits cut the root along the faces of
//! the bulk: the space between the bulk and each stray becomes a few cells of its own, never
//! split further, and only the bulk is subdivided. So the building keeps its cells however far
//! a stray lies, and no step's cost grows with the distance.

use super::{Cell, CellGraph, KdNode};
use crate::geometry::Aabb;
use std::collections::HashMap;

/// Smallest fraction of a node's cross section an occluder plane must cover to split it.
pub const MIN_COVERAGE: f32 = 0.3;
/// Thinnest cell the splitter makes (metres).
pub const MIN_THICKNESS: f32 = 0.005;
/// Grid fallback: largest cell edge as a fraction of the model's largest extent.
const GRID_DIVISIONS: f32 = 6.0;
/// Deepest tree we build.
const MAX_DEPTH: usize = 64;

/// Builds the k-D subdivision of `bounds` along the occluder faces.
///
/// The root is the model's bounding box and nothing beyond it: a sightline that leaves a box
/// never comes back into it, so space outside holds nothing visible (windows on the outside
/// walls are simply portals to nowhere). Courtyards and other outside space inside the box
/// are cells like any other.
pub fn subdivide(bounds: &Aabb, occluders: &[Aabb]) -> CellGraph {
    subdivide_around(bounds, bounds, occluders, &[], &[])
}

/// [`subdivide`] with the root `bounds` first cut along the faces of `core` (the model's bulk,
/// inside `bounds`): the space outside `core` becomes at most six cells, and only `core` is
/// subdivided further. `rooms` are the boxes of the rooms the source names (IFC spaces): once
/// no occluder plane splits a cell, it is split along the faces of the rooms in it, so that
/// rooms without a wall between them (an open kitchen) still get cells of their own; these
/// splits are open (they occlude nothing). A leaf at least half filled by `solids` but not
/// wholly is cut along the solids' faces until each piece is wholly solid or less than half.
pub fn subdivide_around(
    bounds: &Aabb,
    core: &Aabb,
    occluders: &[Aabb],
    solids: &[Aabb],
    rooms: &[Aabb],
) -> CellGraph {
    let root = *bounds;
    let mut graph = CellGraph {
        bounds: root,
        cells: Vec::new(),
        portals: Vec::new(),
        tree: vec![KdNode::Leaf(0)],
        grid_fallback: occluders.is_empty(),
    };
    let all: Vec<u32> = (0..occluders.len() as u32).collect();
    let all_solids: Vec<u32> = (0..solids.len() as u32).collect();
    // Explicit stack of (tree node index, box, occluders and solids overlapping it, depth).
    let mut stack = vec![(0usize, root, all, all_solids, 0usize)];
    while let Some((node, b, ids, sids, depth)) = stack.pop() {
        let outside = !super::touches(&b, core)
            || (0..3).any(|a| b.max[a] <= core.min[a] || b.min[a] >= core.max[a]);
        let split = if outside {
            None
        } else if let Some(cut) = isolate(&b, core) {
            Some(cut)
        } else if graph.grid_fallback {
            grid_split(&b, core)
        } else if depth < MAX_DEPTH {
            best_split(&b, &ids, occluders)
                .or_else(|| room_split(&b, rooms))
                .or_else(|| solid_split(&b, &sids, solids))
        } else {
            None
        };
        match split {
            Some((axis, at)) => {
                let (lo_box, hi_box) = halves(&b, axis, at);
                let lo = graph.tree.len();
                graph.tree.push(KdNode::Leaf(u32::MAX));
                graph.tree.push(KdNode::Leaf(u32::MAX));
                graph.tree[node] = KdNode::Split {
                    axis: axis as u8,
                    at,
                    lo: lo as u32,
                    hi: lo as u32 + 1,
                };
                let lo_ids = overlapping(&lo_box, &ids, occluders);
                let hi_ids = overlapping(&hi_box, &ids, occluders);
                let lo_sids = filling(&lo_box, &sids, solids);
                let hi_sids = filling(&hi_box, &sids, solids);
                stack.push((lo + 1, hi_box, hi_ids, hi_sids, depth + 1));
                stack.push((lo, lo_box, lo_ids, lo_sids, depth + 1));
            }
            None => {
                graph.tree[node] = KdNode::Leaf(graph.cells.len() as u32);
                graph.cells.push(Cell {
                    bounds: b,
                    live: true,
                    portals: Vec::new(),
                });
            }
        }
    }
    graph
}

/// The occluder face plane covering most of the node's cross section, if it covers enough.
fn best_split(b: &Aabb, ids: &[u32], occluders: &[Aabb]) -> Option<(usize, f32)> {
    let mut coverage: HashMap<(usize, u32), f32> = HashMap::new();
    for &i in ids {
        let o = &occluders[i as usize];
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let cross = (b.max[u] - b.min[u]) * (b.max[v] - b.min[v]);
            if cross <= 0.0 {
                continue;
            }
            let at = o.min[axis];
            if o.max[axis] - at > 1e-6 {
                continue; // not flat along this axis
            }
            let area = overlap(o, b, u) * overlap(o, b, v) / cross;
            if at > b.min[axis] + MIN_THICKNESS && at < b.max[axis] - MIN_THICKNESS && area > 0.0 {
                *coverage.entry((axis, at.to_bits())).or_default() += area;
            }
        }
    }
    let center = b.center();
    coverage
        .into_iter()
        .filter(|&(_, c)| c >= MIN_COVERAGE)
        .map(|((axis, bits), c)| {
            let at = f32::from_bits(bits);
            let size = (b.max[axis] - b.min[axis]).max(1e-6);
            // Most coverage first; among (nearly) equal coverage, the most central plane; the
            // exact key makes the choice independent of hash order.
            let balance = 1.0 - ((at - center[axis]).abs() / size);
            (
                (c.min(1.0) * 100.0).round() as i64,
                (balance * 1000.0) as i64,
                axis,
                bits,
                at,
            )
        })
        .max_by_key(|&(c, bal, axis, bits, _)| (c, bal, std::cmp::Reverse(axis), bits))
        .map(|(_, _, axis, _, at)| (axis, at))
}

/// A leaf's cut along the faces of the solids in it, when they fill at least half of it but not
/// all: its open part (a skylight, a window) is then split off from the solid part.
fn solid_split(b: &Aabb, sids: &[u32], solids: &[Aabb]) -> Option<(usize, f32)> {
    // A perforated screen would give a cell per hole: past this many solid pieces the leaf
    // stays whole (live, as it is not wholly solid: conservative, only less culling).
    if sids.is_empty() || sids.len() > MAX_SOLIDS_SPLIT {
        return None;
    }
    let near: Vec<Aabb> = sids.iter().map(|&i| solids[i as usize]).collect();
    let whole: f64 = (0..3).map(|k| (b.max[k] - b.min[k]) as f64).product();
    if super::solid::covered(b, &near) || super::solid::solid_volume(b, &near) < 0.5 * whole {
        return None;
    }
    super::solid::split_plane(b, &near, MIN_THICKNESS)
}

/// Most solid pieces in a leaf that is cut along its solids' faces (more: it stays whole).
pub const MAX_SOLIDS_SPLIT: usize = 64;

/// Solids overlapping the box's interior.
fn filling(b: &Aabb, ids: &[u32], solids: &[Aabb]) -> Vec<u32> {
    ids.iter()
        .copied()
        .filter(|&i| {
            let s = &solids[i as usize];
            (0..3).all(|a| overlap(s, b, a) > super::solid::TOLERANCE)
        })
        .collect()
}

/// Rooms' faces closer than this (metres) to a cell's face do not split it.
const ROOM_MARGIN: f32 = 0.05;

/// The room face plane covering most of the node's cross section (at least
/// [`MIN_COVERAGE`]), the most central among equals.
fn room_split(b: &Aabb, rooms: &[Aabb]) -> Option<(usize, f32)> {
    let center = b.center();
    let mut best: Option<((i64, i64), usize, f32)> = None;
    for r in rooms {
        if (0..3).any(|a| overlap(r, b, a) <= 0.0) {
            continue;
        }
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let cross = (b.max[u] - b.min[u]) * (b.max[v] - b.min[v]);
            let cover = overlap(r, b, u) * overlap(r, b, v) / cross.max(1e-9);
            if cover < MIN_COVERAGE {
                continue;
            }
            for at in [r.min[axis], r.max[axis]] {
                if at <= b.min[axis] + ROOM_MARGIN || at >= b.max[axis] - ROOM_MARGIN {
                    continue;
                }
                let size = (b.max[axis] - b.min[axis]).max(1e-6);
                let balance = 1.0 - (at - center[axis]).abs() / size;
                let key = (
                    (cover.min(1.0) * 100.0).round() as i64,
                    (balance * 1000.0) as i64,
                );
                if best.is_none_or(|(k, _, _)| key > k) {
                    best = Some((key, axis, at));
                }
            }
        }
    }
    best.map(|(_, axis, at)| (axis, at))
}

/// The first face of `core` that lies strictly inside `b`, as a split: cuts the space around
/// the bulk away from it.
fn isolate(b: &Aabb, core: &Aabb) -> Option<(usize, f32)> {
    (0..3).find_map(|a| {
        if core.min[a] > b.min[a] + MIN_THICKNESS {
            Some((a, core.min[a]))
        } else if core.max[a] < b.max[a] - MIN_THICKNESS {
            Some((a, core.max[a]))
        } else {
            None
        }
    })
}

/// Grid fallback: halve the longest axis until cells are small enough.
fn grid_split(b: &Aabb, root: &Aabb) -> Option<(usize, f32)> {
    let target = root.size().max_element() / GRID_DIVISIONS;
    let size = b.size();
    let axis = (0..3).max_by(|&i, &j| size[i].total_cmp(&size[j]))?;
    (size[axis] > target * 1.01).then(|| (axis, b.center()[axis]))
}

fn halves(b: &Aabb, axis: usize, at: f32) -> (Aabb, Aabb) {
    let mut lo = *b;
    let mut hi = *b;
    lo.max[axis] = at;
    hi.min[axis] = at;
    (lo, hi)
}

/// Length of the overlap of two boxes along one axis.
fn overlap(a: &Aabb, b: &Aabb, axis: usize) -> f32 {
    (a.max[axis].min(b.max[axis]) - a.min[axis].max(b.min[axis])).max(0.0)
}

/// Occluder faces inside the (closed) box with positive area overlap.
fn overlapping(b: &Aabb, ids: &[u32], occluders: &[Aabb]) -> Vec<u32> {
    ids.iter()
        .copied()
        .filter(|&i| {
            let o = &occluders[i as usize];
            super::touches(o, b) && (0..3).filter(|&a| overlap(o, b, a) > 0.0).count() >= 2
        })
        .collect()
}

/// Whether `outer` contains `inner` (closed).
pub fn contains(outer: &Aabb, inner: &Aabb) -> bool {
    (0..3).all(|i| outer.min[i] <= inner.min[i] + 1e-5 && inner.max[i] <= outer.max[i] + 1e-5)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn bx(min: [f32; 3], max: [f32; 3]) -> Aabb {
        Aabb { min, max }
    }

    /// The six faces of each box, as the occluder extraction would give them.
    pub(crate) fn faces_of(boxes: &[Aabb]) -> Vec<Aabb> {
        let mut out = Vec::new();
        for b in boxes {
            for a in 0..3 {
                for at in [b.min[a], b.max[a]] {
                    let mut f = *b;
                    f.min[a] = at;
                    f.max[a] = at;
                    out.push(f);
                }
            }
        }
        out
    }

    #[test]
    fn a_wall_with_a_door_splits_into_two_rooms_a_door_cell_and_dead_wall() {
        // Room 0..10 x 0..3 x 0..4, wall at x in [5, 5.2] with a door z in [1, 2], y < 2.
        let walls = faces_of(&[
            bx([5.0, 0.0, 0.0], [5.2, 3.0, 1.0]),
            bx([5.0, 0.0, 2.0], [5.2, 3.0, 4.0]),
            bx([5.0, 2.0, 1.0], [5.2, 3.0, 2.0]),
        ]);
        let g = subdivide(&bx([0.0; 3], [10.0, 3.0, 4.0]), &walls);
        // The door opening and the wall beside it are different cells of the wall slab.
        let door = g.locate(glam::Vec3::new(5.1, 1.0, 1.5)).unwrap();
        let inside_wall = g.locate(glam::Vec3::new(5.1, 1.0, 3.0)).unwrap();
        assert_ne!(door, inside_wall);
        let door_box = g.cells[door as usize].bounds;
        assert!(
            door_box.min[0] >= 5.0 - 1e-6 && door_box.max[0] <= 5.2 + 1e-6,
            "{door_box:?}"
        );
        // Both sides are live and different.
        let a = g.locate(glam::Vec3::new(2.0, 1.0, 2.0)).unwrap();
        let b = g.locate(glam::Vec3::new(8.0, 1.0, 2.0)).unwrap();
        assert_ne!(a, b);
    }

    #[test]
    fn no_occluders_gives_a_grid() {
        let g = subdivide(&bx([0.0; 3], [30.0, 3.0, 30.0]), &[]);
        assert!(g.grid_fallback);
        assert!(g.cells.len() >= 16, "{} cells", g.cells.len());
        assert!(g.cells.iter().all(|c| c.live));
    }

    #[test]
    fn a_far_core_is_cut_out_first_and_subdivided_alone() {
        let walls = faces_of(&[bx([5.0, 0.0, 0.0], [5.2, 3.0, 4.0])]);
        let core = bx([0.0; 3], [10.0, 3.0, 4.0]);
        let far = subdivide_around(
            &bx([0.0; 3], [3000.0, 3000.0, 3000.0]),
            &core,
            &walls,
            &[],
            &[],
        );
        let near = subdivide(&core, &walls);
        // The same cells inside the core, plus one cell per side the root extends past it.
        assert_eq!(far.cells.len(), near.cells.len() + 3);
        for c in &near.cells {
            let p = c.bounds.center();
            assert_eq!(far.cells[far.locate(p).unwrap() as usize].bounds, c.bounds);
        }
        // Without a core inside, no split at all is made outside it.
        let stray = far.locate(glam::Vec3::splat(2990.0)).unwrap();
        assert!(
            far.cells[stray as usize].bounds.min[0] >= 10.0 - 1e-3
                || far.cells[stray as usize].bounds.min[1] >= 3.0 - 1e-3
                || far.cells[stray as usize].bounds.min[2] >= 4.0 - 1e-3
        );
    }

    /// Found by the `reader` fuzz target: a graph read from a damaged (resealed) file with a split
    /// on axis 7 made `locate` index out of range. Such a graph is now refused when read.
    #[test]
    fn graphs_with_bad_references_are_refused() {
        let walls = faces_of(&[bx([5.0, 0.0, 0.0], [5.2, 3.0, 4.0])]);
        let good = subdivide(&bx([0.0; 3], [10.0, 3.0, 4.0]), &walls);
        assert_eq!(good.validate(), Ok(()));
        let mut bad = good.clone();
        if let Some(KdNode::Split { axis, .. }) = bad
            .tree
            .iter_mut()
            .find(|n| matches!(n, KdNode::Split { .. }))
        {
            *axis = 7;
        }
        assert!(bad.validate().unwrap_err().contains("axis 7"));
        let mut bad = good.clone();
        bad.tree[0] = KdNode::Split {
            axis: 0,
            at: 1.0,
            lo: 0,
            hi: 1,
        };
        assert!(bad.validate().is_err(), "a node that is its own child");
        let mut bad = good;
        bad.tree.push(KdNode::Leaf(999));
        assert!(bad.validate().is_err());
    }

    #[test]
    fn locate_is_consistent_with_cell_bounds() {
        let walls = faces_of(&[bx([5.0, 0.0, 0.0], [5.2, 3.0, 4.0])]);
        let g = subdivide(&bx([0.0; 3], [10.0, 3.0, 4.0]), &walls);
        for c in 0..g.cells.len() as u32 {
            let center = g.cells[c as usize].bounds.center();
            assert_eq!(g.locate(center), Some(c));
        }
        assert_eq!(g.locate(glam::Vec3::splat(-50.0)), None);
    }
}
