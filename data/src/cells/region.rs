//! Region-to-cell visibility: the cells a box of eye positions may see through portals, and
//! through which halfspaces. It is eye-to-cell visibility (Funkhouser §4.1.1) from a box of
//! eyes rather than a point: where a point's wedge through a portal is the planes through the
//! eye and the portal's edges, a box's is bounded by the planes separating the box from the
//! (clipped) portal, an edge of one and a corner of the other with the two on opposite sides
//! (the anti-penumbra's bounding planes, Teller 1992, as the stab lists use between portals).
//! Every sightline from a point of the box through the portal sequence stays inside them, so
//! what a point of the box sees ([`super::realtime::eye_to_object_exact`]) is inside what this
//! keeps: the shared predicted lookahead (`crate::prefetch::swept`) uses it for the regions
//! its observers' predicted eyes may be in.

use super::polytope::{Plane, box_separating_planes, clip_polygon};
use super::{CellGraph, StabList};
use crate::geometry::Aabb;
use glam::Vec3;

/// A cell a box of eyes may see, and the halfspaces holding what of it they may see (none: the
/// whole cell).
#[derive(Debug, Clone, PartialEq)]
pub struct RegionReached {
    /// The cell.
    pub cell: u32,
    /// Halfspaces every sightline from the box into the cell stays inside.
    pub planes: Vec<Plane>,
}

/// The cells the box `eyes` (inside live cell `start`) may see through portals, each with the
/// halfspaces of one portal sequence reaching it (a cell reached along several sequences is
/// listed once per sequence); `start` first, whole. `None` past `max_sequences` portal
/// sequences (the caller falls back to the cell-to-cell visibility, which holds it), or once
/// `going` says to stop (asked every 64 sequences: a deadline).
pub fn region_to_cell(
    graph: &CellGraph,
    start: u32,
    eyes: &Aabb,
    max_sequences: usize,
    going: &mut dyn FnMut() -> bool,
) -> Option<Vec<RegionReached>> {
    let mut out = vec![RegionReached {
        cell: start,
        planes: Vec::new(),
    }];
    let mut stack: Vec<(u32, Vec<Plane>, Vec<u32>)> = vec![(start, Vec::new(), vec![start])];
    let mut followed = 0usize;
    while let Some((cell, planes, path)) = stack.pop() {
        followed += 1;
        if followed > max_sequences || (followed.is_multiple_of(64) && !going()) {
            return None;
        }
        for &p in &graph.cells[cell as usize].portals {
            let portal = &graph.portals[p as usize];
            let next = portal.other(cell);
            if path.contains(&next) {
                continue;
            }
            let mut poly = portal.corners().to_vec();
            for pl in &planes {
                poly = clip_polygon(&poly, pl);
                if poly.len() < 3 {
                    break;
                }
            }
            if poly.len() < 3 {
                continue;
            }
            // Beyond the portal, and on the portal's side of every plane separating it from
            // the box. The planes of the portals before are left behind: they clipped this
            // portal already, and a sightline through its clipped part stays inside the new
            // planes (fewer planes only keep more).
            let dir = portal.direction_from(cell);
            let mut n = Vec3::ZERO;
            n[portal.axis as usize] = -dir;
            let mut narrowed = Vec::with_capacity(12);
            narrowed.push(Plane {
                normal: n.into(),
                d: -dir * portal.plane(),
            });
            narrowed.extend(box_separating_planes(eyes, &poly));
            out.push(RegionReached {
                cell: next,
                planes: narrowed.clone(),
            });
            let mut next_path = path.clone();
            next_path.push(next);
            stack.push((next, narrowed, next_path));
        }
    }
    Some(out)
}

/// The objects of `stab` (the stab list of the cell the region search started from) that a box
/// of eyes may see: each reached cell's objects whose boxes touch every halfspace of a
/// sequence reaching it. Sorted, deduplicated.
pub fn region_to_object(reached: &[RegionReached], stab: &StabList, objects: &[Aabb]) -> Vec<u32> {
    let mut out = Vec::new();
    for r in reached {
        let Some(entry) = stab.entry(r.cell) else {
            continue;
        };
        // Within the exact test's margin (a box that close to a point's wedge counts as
        // meeting it there, and a plane here may run along that wedge's edge).
        out.extend(entry.objects.iter().copied().filter(|&o| {
            let b = &objects[o as usize];
            r.planes
                .iter()
                .all(|p| p.touches_box_within(b, super::cone::MEETS_MARGIN))
        }));
    }
    out.sort_unstable();
    out.dedup();
    out
}
