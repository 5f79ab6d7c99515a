//! Where a body may be, from the cells and portals alone: the open space of a building is its
//! live cells, and one goes from a cell to the next only through a portal between them
//! (Funkhouser §3.2.1: cells are the empty space between the occluders; portals the open parts
//! of their shared faces). A point moves along a segment cell by cell, as the eye-to-cell
//! traversal does with sightlines (§4.1.1), and stops where the segment leaves a cell through
//! a face no portal opens; the floor below a point is the first cell bottom, going down, that
//! no portal opens. All lengths in metres.

use glam::Vec3;
use portico_data::cells::CellGraph;
use portico_data::geometry::Aabb;

/// How far (metres) a point may stand off a face or a portal's rectangle and still be on it.
const ON: f32 = 1e-3;
/// Most cells one segment or one fall crosses (a guard against a malformed graph).
const MAX_CROSSINGS: usize = 64;

/// Whether `p` is inside `b` (closed box).
pub(super) fn inside(b: &Aabb, p: Vec3) -> bool {
    (0..3).all(|i| b.min[i] <= p[i] && p[i] <= b.max[i])
}

/// The live cell holding `p`: first `hint` and the cells across its portals (where a body
/// usually is from one frame to the next), then the whole graph.
pub(super) fn locate(graph: &CellGraph, hint: Option<u32>, p: Vec3) -> Option<u32> {
    let live = |c: u32| {
        graph
            .cells
            .get(c as usize)
            .is_some_and(|cell| cell.live && inside(&cell.bounds, p))
    };
    if let Some(h) = hint {
        if live(h) {
            return Some(h);
        }
        let across = graph.cells.get(h as usize).map(|c| c.portals.as_slice());
        for &q in across.unwrap_or_default() {
            if let Some(other) = graph.portals.get(q as usize).map(|p| p.other(h))
                && live(other)
            {
                return Some(other);
            }
        }
    }
    graph.locate(p).filter(|&c| live(c))
}

/// The portal of `cell` on its face along `axis` at `plane` whose rectangle holds `p`, and
/// the live cell across it.
fn opening(graph: &CellGraph, cell: u32, axis: usize, plane: f32, p: Vec3) -> Option<u32> {
    let c = graph.cells.get(cell as usize)?;
    c.portals.iter().find_map(|&q| {
        let portal = graph.portals.get(q as usize)?;
        let r = &portal.rect;
        let on = portal.axis as usize == axis
            && (portal.plane() - plane).abs() <= ON
            && (0..3)
                .filter(|&k| k != axis)
                .all(|k| r.min[k] - ON <= p[k] && p[k] <= r.max[k] + ON);
        let other = portal.other(cell);
        (on && graph.cells.get(other as usize).is_some_and(|o| o.live)).then_some(other)
    })
}

/// How far along the segment `a → b` (0..=1) a point gets through open space, and the cell it
/// ends in. `None` when `a` is in no live cell the graph knows (outside the building, or
/// inside a wall): nothing can be said there, and the caller does not hold the point back.
pub(super) fn trace(graph: &CellGraph, hint: Option<u32>, a: Vec3, b: Vec3) -> Option<(f32, u32)> {
    let mut cell = locate(graph, hint, a)?;
    let d = b - a;
    let mut t = 0.0f32;
    for _ in 0..MAX_CROSSINGS {
        let bounds = graph.cells[cell as usize].bounds;
        // Where the segment leaves this cell: the nearest face ahead.
        let mut exit = (f32::INFINITY, 0usize, 0.0f32);
        for k in 0..3 {
            if d[k].abs() < 1e-9 {
                continue;
            }
            let plane = if d[k] > 0.0 {
                bounds.max[k]
            } else {
                bounds.min[k]
            };
            let tk = ((plane - a[k]) / d[k]).max(t);
            if tk < exit.0 {
                exit = (tk, k, plane);
            }
        }
        let (te, axis, plane) = exit;
        if te >= 1.0 {
            return Some((1.0, cell));
        }
        let at = a + d * te;
        match opening(graph, cell, axis, plane, at) {
            Some(next) => {
                cell = next;
                // Past the face, so the next cell's exit is ahead of it.
                t = te + 1e-6;
            }
            None => return Some((te, cell)),
        }
    }
    Some((t, cell))
}

/// The height of the floor below `p`: down from the live cell holding `p` through every portal
/// in a cell's bottom under `p` (a hole in a floor, a stair's well, a cell cut mid-air) to the
/// first bottom no portal opens. `None` when `p` is in no live cell.
pub(super) fn floor(graph: &CellGraph, hint: Option<u32>, p: Vec3) -> Option<f32> {
    let mut cell = locate(graph, hint, p)?;
    for _ in 0..MAX_CROSSINGS {
        let bottom = graph.cells[cell as usize].bounds.min[1];
        let at = Vec3::new(p.x, bottom, p.z);
        match opening(graph, cell, 1, bottom, at) {
            Some(below) if graph.cells[below as usize].bounds.min[1] < bottom => cell = below,
            _ => return Some(bottom),
        }
    }
    None
}
