//! What a person does in a building's cells: which cells are rooms (room-sized, or a closed
//! room alone), and which portals are doors and stair holes a person walks through. All in
//! metres.

use crate::cells::CellGraph;
use crate::geometry::Aabb;
use glam::Vec3;

/// Whether the cells have rooms to tour: two or more room-sized live cells joined through
/// portals, or one closed room alone (a hall without openings), found by occluders (not a grid
/// of open cells, not one box around an object).
pub fn has_rooms(graph: &CellGraph) -> bool {
    if graph.grid_fallback {
        return false;
    }
    let rooms = (0..graph.cells.len() as u32)
        .filter(|&c| graph.cells[c as usize].live && roomy(graph, c))
        .count();
    (rooms >= 2 && !graph.portals.is_empty()) || closed_room(graph).is_some()
}

/// The one live cell of a model that is a closed room: room-sized, without portals, and walled
/// in on every side (it does not reach the model's box anywhere, as the whole box of an
/// object's grid cell would).
fn closed_room(graph: &CellGraph) -> Option<u32> {
    let mut live = (0..graph.cells.len() as u32).filter(|&c| graph.cells[c as usize].live);
    let (c, None) = (live.next()?, live.next()) else {
        return None;
    };
    let b = &graph.cells[c as usize].bounds;
    let inside = (0..3)
        .all(|k| b.min[k] > graph.bounds.min[k] + 0.01 && b.max[k] < graph.bounds.max[k] - 0.01);
    (roomy(graph, c) && graph.cells[c as usize].portals.is_empty() && inside).then_some(c)
}

/// A live cell an observer can stand in and look around: not the thin opening of a door or a
/// window, which is live too but leads nowhere worth seeing.
pub(super) fn roomy(graph: &CellGraph, c: u32) -> bool {
    let s = graph.cells[c as usize].bounds.size();
    s.x >= ROOM_WIDTH && s.z >= ROOM_WIDTH && s.y >= ROOM_HEIGHT
}

pub use crate::person::EYE_HEIGHT;
use crate::person::{DOOR_HEIGHT, DOOR_SILL, DOOR_WIDTH, ROOM_HEIGHT, ROOM_WIDTH};

/// Whether a person walks through this portal: both its cells inside the building (not
/// touching the sides of the model's box, where the outside is), and it is a door (an
/// opening at floor level, tall enough) or a hole in a floor (a stair's).
pub fn walkable(graph: &CellGraph, portal: u32) -> bool {
    let p = &graph.portals[portal as usize];
    let [a, b] = p.cells.map(|c| &graph.cells[c as usize].bounds);
    let inside = |c: &Aabb| {
        [0, 2].iter().all(|&k| {
            c.min[k] > graph.bounds.min[k] + 1e-3 && c.max[k] < graph.bounds.max[k] - 1e-3
        })
    };
    if !inside(a) || !inside(b) {
        return false;
    }
    let size = p.rect.size();
    if p.axis == 1 {
        return size.x >= DOOR_WIDTH && size.z >= DOOR_WIDTH;
    }
    let width = if p.axis == 0 { size.z } else { size.x };
    width >= DOOR_WIDTH
        && size.y >= DOOR_HEIGHT
        && p.rect.min[1] <= a.min[1].min(b.min[1]) + DOOR_SILL
}

/// Metres before and after a door at which the walk lines up with it (a door leaf is about
/// this wide).
pub(super) const DOOR_APPROACH_M: f32 = 1.0;

/// A walk round a room: the corners of its floor inset by about a metre from its walls, at
/// height `y`, starting with the far corner on the side of the corner nearest `entry` (where
/// the room was entered) and ending at the other near corner (the nearest one lies behind the
/// entry: the way out would step back). Every point is inside the room's
/// (convex) cell. `None` when the room is too small to walk round (then the walk stands in its
/// middle) or no entry is known.
pub(super) fn room_loop(b: &Aabb, entry: Option<Vec3>, y: f32) -> Option<Vec<Vec3>> {
    let entry = entry?;
    let mut inset = [0.0f32; 3];
    for k in [0, 2] {
        let extent = b.max[k] - b.min[k];
        inset[k] = (0.3 * extent).clamp(0.5, 1.0);
        if extent - 2.0 * inset[k] < 0.8 {
            return None;
        }
    }
    let (x0, x1) = (b.min[0] + inset[0], b.max[0] - inset[0]);
    let (z0, z1) = (b.min[2] + inset[2], b.max[2] - inset[2]);
    // Corners in order round the room.
    let corners = [
        Vec3::new(x0, y, z0),
        Vec3::new(x1, y, z0),
        Vec3::new(x1, y, z1),
        Vec3::new(x0, y, z1),
    ];
    let near = (0..4)
        .min_by(|&i, &j| {
            corners[i]
                .distance(entry)
                .total_cmp(&corners[j].distance(entry))
        })
        .unwrap_or(0);
    // Of the near corner's two neighbours, the other near one is the closer to the entry: go
    // round the other way, first along the side wall to the far corner.
    let (left, right) = ((near + 3) % 4, (near + 1) % 4);
    let step = if corners[left].distance(entry) < corners[right].distance(entry) {
        1
    } else {
        3
    };
    Some((1..=3).map(|i| corners[(near + step * i) % 4]).collect())
}
