//! Cell-to-cell and cell-to-object visibility (Funkhouser §3.2.2, after Teller 1992): a
//! depth-first search from each source cell through portal sequences that admit a sightline.
//!
//! - The source cell and its neighbours are entirely visible (the special case of §3.2.2).
//! - Stepping through a further portal needs a line stabbing the whole sequence
//!   ([`sightline::exists`]).
//! - The part of a reached cell visible through portals `P1 … Pn` lies beyond `Pn` and on the far
//!   side of every plane separating some `Pi` from `Pn` (an edge of one and a vertex of the
//!   other, the two portals on opposite sides): the anti-penumbra. Objects whose boxes touch that
//!   region are visible; the region's bounding box is stored with the entry.
//! - A search that exceeds [`MAX_STEPS`] falls back to every cell connected to the source, with
//!   all their objects: less tight, never wrong.
//!
//! Sources are independent, so they run in parallel (rayon).

use super::polytope::{Plane, clipped_box_bounds, ring, separating_planes_of};
use super::{CellGraph, Portal, StabEntry, StabList, sightline, touches};
use crate::geometry::Aabb;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::{BTreeMap, BTreeSet};

/// Portal steps one source cell's search may take before falling back.
pub const MAX_STEPS: usize = 20_000;
/// Longest portal sequence followed before falling back.
pub const MAX_DEPTH: usize = 48;

/// Objects completely and partially inside each cell (§3.2.1), by k-D traversal of each
/// object's box. Returned as per-cell (inside, partial) lists.
pub fn incidence(graph: &CellGraph, objects: &[Aabb]) -> Vec<(Vec<u32>, Vec<u32>)> {
    let mut out = vec![(Vec::new(), Vec::new()); graph.cells.len()];
    for (i, o) in objects.iter().enumerate() {
        for c in graph.cells_touching(o) {
            let cell = &graph.cells[c as usize];
            if !cell.live {
                continue;
            }
            if super::subdivide::contains(&cell.bounds, o) {
                out[c as usize].0.push(i as u32);
            } else {
                out[c as usize].1.push(i as u32);
            }
        }
    }
    out
}

/// Stab lists for every cell, in parallel; `on_cell` is called as each finishes.
pub fn all_stab_lists(
    graph: &CellGraph,
    objects: &[Aabb],
    incidence: Vec<(Vec<u32>, Vec<u32>)>,
    on_cell: &(dyn Fn() + Sync),
) -> Vec<StabList> {
    let incident: Vec<Vec<u32>> = incidence
        .iter()
        .map(|(a, b)| {
            let mut all: Vec<u32> = a.iter().chain(b).copied().collect();
            all.sort_unstable();
            all
        })
        .collect();
    let mut lists: Vec<StabList> = (0..graph.cells.len() as u32)
        .into_par_iter()
        .map(|c| {
            let s = if !graph.cells[c as usize].live {
                StabList::default()
            } else if graph.grid_fallback {
                // No occluders at all: everything connected is visible, exactly.
                StabList {
                    fallback: false,
                    ..fallback(graph, &incident, c)
                }
            } else {
                stab_list(graph, objects, &incident, c)
            };
            on_cell();
            s
        })
        .collect();
    for (list, (inside, partial)) in lists.iter_mut().zip(incidence) {
        list.inside = inside;
        list.partial = partial;
    }
    lists
}

/// The stab list of one source cell.
pub fn stab_list(
    graph: &CellGraph,
    objects: &[Aabb],
    incident: &[Vec<u32>],
    source: u32,
) -> StabList {
    let mut search = Search {
        graph,
        objects,
        incident,
        reached: BTreeMap::new(),
        steps: 0,
        path: Vec::new(),
        on_path: BTreeSet::new(),
    };
    search.whole(source);
    search.on_path.insert(source);
    let mut exhausted = false;
    for &p in &graph.cells[source as usize].portals {
        let portal = &graph.portals[p as usize];
        let next = portal.other(source);
        search.whole(next);
        search.path.push((p, portal.direction_from(source)));
        search.on_path.insert(next);
        if !search.dfs(next) {
            exhausted = true;
        }
        search.on_path.remove(&next);
        search.path.pop();
    }
    if exhausted {
        return fallback(graph, incident, source);
    }
    let mut entries: Vec<StabEntry> = search
        .reached
        .into_iter()
        .map(|(cell, (region, objs))| StabEntry {
            cell,
            region,
            objects: objs.into_iter().collect(),
        })
        .collect();
    // The source first.
    entries.sort_by_key(|e| (e.cell != source, e.cell));
    StabList {
        entries,
        ..StabList::default()
    }
}

struct Search<'a> {
    graph: &'a CellGraph,
    objects: &'a [Aabb],
    incident: &'a [Vec<u32>],
    /// Reached cell → (bounding box of visible regions, visible objects).
    reached: BTreeMap<u32, (Aabb, BTreeSet<u32>)>,
    steps: usize,
    /// Portal sequence (portal index, direction along its axis).
    path: Vec<(u32, f32)>,
    on_path: BTreeSet<u32>,
}

impl Search<'_> {
    /// Marks a whole cell and all its objects visible.
    fn whole(&mut self, cell: u32) {
        let b = self.graph.cells[cell as usize].bounds;
        let entry = self
            .reached
            .entry(cell)
            .or_insert((Aabb::EMPTY, BTreeSet::new()));
        entry.0 = entry.0.union(&b);
        entry.1.extend(self.incident[cell as usize].iter().copied());
    }

    /// Continues from `cell`, reached through `self.path`. False when the work limit is hit.
    fn dfs(&mut self, cell: u32) -> bool {
        if self.path.len() >= MAX_DEPTH {
            return false;
        }
        let g = self.graph;
        for &q in &g.cells[cell as usize].portals {
            let portal = &g.portals[q as usize];
            let next = portal.other(cell);
            if self.on_path.contains(&next) {
                continue;
            }
            self.steps += 1;
            if self.steps > MAX_STEPS {
                return false;
            }
            self.path.push((q, portal.direction_from(cell)));
            let seq: Vec<(&Portal, f32)> = self
                .path
                .iter()
                .map(|&(i, d)| (&g.portals[i as usize], d))
                .collect();
            let mut ok = true;
            if let Some(planes) = region_planes(&seq).filter(|_| sightline::exists(&seq)) {
                ok = self.visit(next, &planes);
            }
            self.path.pop();
            if !ok {
                return false;
            }
        }
        true
    }

    /// Records what of `cell` is visible inside `planes`, and recurses if anything is.
    fn visit(&mut self, cell: u32, planes: &[Plane]) -> bool {
        let b = self.graph.cells[cell as usize].bounds;
        let Some(region) = clipped_box_bounds(&b, planes) else {
            return true;
        };
        let visible: Vec<u32> = self.incident[cell as usize]
            .iter()
            .copied()
            .filter(|&o| {
                let ob = &self.objects[o as usize];
                touches(ob, &region) && planes.iter().all(|p| p.touches_box(ob))
            })
            .collect();
        let entry = self
            .reached
            .entry(cell)
            .or_insert((Aabb::EMPTY, BTreeSet::new()));
        entry.0 = entry.0.union(&region);
        entry.1.extend(visible);
        self.on_path.insert(cell);
        let ok = self.dfs(cell);
        self.on_path.remove(&cell);
        ok
    }
}

/// Halfspaces bounding what is visible beyond the last portal of a sequence: beyond its plane,
/// and on the far side of every plane separating an earlier portal from it. `None` when the
/// last portal faces back (nothing beyond it can be reached).
pub fn region_planes(seq: &[(&Portal, f32)]) -> Option<Vec<Plane>> {
    let &(last, dir) = seq.last()?;
    let a = last.axis as usize;
    let mut n = Vec3::ZERO;
    n[a] = -dir;
    // Beyond the last portal: dir * x_a >= plane, i.e. (-dir e_a) · x <= -dir * plane.
    let mut planes = vec![Plane {
        normal: n.into(),
        d: -dir * last.plane(),
    }];
    let target = last.corners();
    for &(p, _) in &seq[..seq.len() - 1] {
        planes.extend(separating_planes(&p.corners(), &target));
    }
    Some(planes)
}

/// Planes through an edge of one rectangle and a vertex of the other with the two rectangles
/// on opposite sides, as halfspaces containing the far side (where `b` is).
pub fn separating_planes(a: &[Vec3; 4], b: &[Vec3; 4]) -> Vec<Plane> {
    separating_planes_of(a, &ring(4), b, &ring(4))
}

/// The conservative answer when the search is too long: every cell connected to the source.
fn fallback(graph: &CellGraph, incident: &[Vec<u32>], source: u32) -> StabList {
    let mut seen = BTreeSet::from([source]);
    let mut queue = std::collections::VecDeque::from([source]);
    while let Some(c) = queue.pop_front() {
        for &p in &graph.cells[c as usize].portals {
            let n = graph.portals[p as usize].other(c);
            if seen.insert(n) {
                queue.push_back(n);
            }
        }
    }
    let mut entries: Vec<StabEntry> = seen
        .into_iter()
        .map(|c| StabEntry {
            cell: c,
            region: graph.cells[c as usize].bounds,
            objects: incident[c as usize].clone(),
        })
        .collect();
    entries.sort_by_key(|e| (e.cell != source, e.cell));
    StabList {
        entries,
        fallback: true,
        ..StabList::default()
    }
}
