//! Room generators that furnish each room (Funkhouser §3.1.1).
//!
//! Soda Hall's furniture was placed by automatic placement programs written for each room type:
//! "the conference room generator places a rectangular or elliptical table in the middle of a
//! room, chairs around it, a blackboard on one wall, a transparency projector on the table … The
//! office generator places a desk against one wall, a chair in front of the desk, some
//! bookshelves against the walls". The generators here do the same in a room's local frame
//! (`u` along the door wall, `w` into the room), keeping door approaches and stair openings
//! clear and never letting two floor-standing pieces overlap.
//!
//! This module dispatches by room kind and adds what every room gets (door approaches and leaves,
//! ceiling lights); `placer` holds the overlap-checking placement primitives and `kinds` one
//! generator per room kind.

use rand_chacha::ChaCha8Rng;

use crate::RoomKind;
use crate::furniture::{FurnitureType as F, Library};
use crate::layout::{DOOR_WIDTH, PlannedRoom};

mod kinds;
mod placer;

use kinds::{auditorium, classroom, conference, corridor, lab, library, office, stairwell};
use placer::{Placer, Rect};

/// A piece of furniture placed in a room's local frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Placed {
    /// Index of the definition in the [`Library`].
    pub def: usize,
    /// Local position `(u, height above the floor, w)`.
    pub pos: [f32; 3],
    /// Quarter turns about +Y (the piece's front, +Z, turned towards +u for one turn).
    pub quarter: u8,
    /// Extra yaw in radians (small jitter on chairs).
    pub jitter: f32,
}

/// Furnishes `room`, returning its pieces in the room's local frame.
pub(crate) fn furnish(room: &PlannedRoom, lib: &mut Library, rng: &mut ChaCha8Rng) -> Vec<Placed> {
    let mut pl = Placer {
        lib,
        rng,
        width: room.frame.width,
        depth: room.frame.depth,
        height: room.room.max[1] - room.room.min[1],
        blocked: Vec::new(),
        items: Vec::new(),
    };
    doors(&mut pl, room);
    match room.room.kind {
        RoomKind::Office => office(&mut pl),
        RoomKind::Lab => lab(&mut pl),
        RoomKind::Classroom => classroom(&mut pl),
        RoomKind::Conference => conference(&mut pl),
        RoomKind::Auditorium => auditorium(&mut pl),
        RoomKind::Library => library(&mut pl),
        RoomKind::Corridor => corridor(&mut pl),
        RoomKind::Stairwell => stairwell(&mut pl, room),
    }
    ceiling_lights(&mut pl, room.room.kind);
    pl.items
}

/// Reserves the approach to every door and, in rooms, hangs the door leaf wide open beside the
/// opening so that the opening stays a true gap.
fn doors(pl: &mut Placer, room: &PlannedRoom) {
    let leaf = pl.pick(F::Door);
    let with_leaf = room.room.kind != RoomKind::Corridor;
    let half = DOOR_WIDTH / 2.0;
    for (list, far) in [(&room.near_doors, false), (&room.far_doors, true)] {
        for &u in list {
            let w = if far {
                [pl.depth - 1.3, pl.depth]
            } else {
                [0.0, 1.3]
            };
            pl.blocked.push(Rect {
                u: [u - half - 0.3, u + half + 0.4],
                w,
            });
            if with_leaf {
                let lw = if far { pl.depth - 0.5 } else { 0.5 };
                pl.place(leaf, [u + half + 0.03, 0.0, lw], 0, false);
            }
        }
    }
}

/// Ceiling lights on a grid of about 2.6 m (Funkhouser §3.1.1 lists lights among the procedural
/// objects). They hang from the ceiling, so they are not checked against floor furniture; in a
/// stairwell the only light is over the landing, clear of the stair openings.
fn ceiling_lights(pl: &mut Placer, kind: RoomKind) {
    let light = pl.pick(F::CeilingLight);
    let (w, d, h) = (pl.width, pl.depth, pl.height);
    if kind == RoomKind::Stairwell {
        pl.place(light, [w * 0.5, h, d - 0.45], 0, false);
        return;
    }
    let (nu, nw) = (
        (w / 2.6).round().max(1.0) as u32,
        (d / 2.6).round().max(1.0) as u32,
    );
    for i in 0..nu {
        for j in 0..nw {
            let at = [
                w * (i as f32 + 0.5) / nu as f32,
                h,
                d * (j as f32 + 0.5) / nw as f32,
            ];
            pl.place(light, at, 0, false);
        }
    }
}
