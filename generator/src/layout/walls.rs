//! The shell of a storey: walls along and across the bands with their door and window
//! openings, the doors between rooms and corridors, the floor and ceiling slabs of each room
//! with their stair openings, and the stair "doors" that join stairwells on consecutive
//! storeys.

use super::{
    Band, BandRole, DOOR_HEIGHT, DOOR_WIDTH, Footprint, PlannedRoom, STAIR_RUN, STAIR_START,
    STOREY_HEIGHT, SlabPlan, StoreyPlan, WALL, WINDOW_HEAD, WINDOW_SILL, WallPlan, ceiling_bottom,
    floor_top, stair_lane,
};
use crate::structure::Opening;
use crate::{Door, RoomKind};

/// Doors through the slab openings between stairwells stacked on consecutive storeys.
pub(super) fn stair_doors(storeys: &[StoreyPlan]) -> Vec<Door> {
    let mut doors = Vec::new();
    for (s, pair) in storeys.windows(2).enumerate() {
        let s = s as u32;
        for lower in pair[0]
            .rooms
            .iter()
            .filter(|r| r.room.kind == RoomKind::Stairwell)
        {
            let upper = pair[1]
                .rooms
                .iter()
                .find(|r| r.room.kind == RoomKind::Stairwell && r.x == lower.x && r.z == lower.z);
            if let Some(upper) = upper {
                let lane = stair_lane(lower.frame.width, s);
                let r = lower
                    .frame
                    .world_rect(lane, [STAIR_START, STAIR_START + STAIR_RUN]);
                doors.push(Door {
                    rooms: (lower.room.id, upper.room.id),
                    min: [r[0], ceiling_bottom(s), r[2]],
                    max: [r[1], floor_top(s + 1), r[3]],
                });
            }
        }
    }
    doors
}

/// Window openings spread evenly over `[a, b]` along a wall.
fn windows(a: f32, b: f32) -> Vec<Opening> {
    let span = b - a;
    let n = ((span / 2.8).floor() as u32).max(1);
    let pitch = span / n as f32;
    let width = (pitch - 0.8).clamp(0.6, 1.6);
    (0..n)
        .map(|k| {
            let c = a + pitch * (k as f32 + 0.5);
            Opening {
                u0: c - width / 2.0,
                u1: c + width / 2.0,
                v0: WINDOW_SILL,
                v1: WINDOW_HEAD,
            }
        })
        .collect()
}

fn door_opening(center: f32) -> Opening {
    Opening {
        u0: center - DOOR_WIDTH / 2.0,
        u1: center + DOOR_WIDTH / 2.0,
        v0: 0.0,
        v1: DOOR_HEIGHT,
    }
}

/// Walls and doors of the rooms `plan.rooms[first..]` of a room band.
pub(super) fn band_structure(
    fp: &Footprint,
    s: u32,
    band: &Band,
    first: usize,
    corridors: (Option<usize>, Option<usize>),
    plan: &mut StoreyPlan,
) {
    let length = fp.length();
    let half = WALL / 2.0;
    let (ft, height) = (floor_top(s), ceiling_bottom(s) - floor_top(s));
    let count = plan.rooms.len() - first;
    for i in 0..count {
        let room = plan.rooms[first + i].clone();
        let tag = Some((room.room.kind, room.room.id));
        let wx0 = if room.x[0] <= 0.0 { -half } else { room.x[0] };
        let wx1 = if room.x[1] >= length {
            length + half
        } else {
            room.x[1]
        };
        let ix = [room.room.min[0], room.room.max[0]];
        for (line, high) in [(band.z0, false), (band.z1, true)] {
            let exterior = match band.role {
                BandRole::South => !high,
                BandRole::North => high,
                _ => false,
            };
            let mut openings = Vec::new();
            if exterior {
                openings = windows(ix[0] - wx0, ix[1] - wx0);
            } else {
                // Near doors lie on the corridor side; far doors only exist in middle bands.
                let near_high = band.role == BandRole::South;
                let (us, corridor) = if high == near_high {
                    (
                        &room.near_doors,
                        if high { corridors.1 } else { corridors.0 },
                    )
                } else {
                    (
                        &room.far_doors,
                        if high { corridors.1 } else { corridors.0 },
                    )
                };
                let w = if high == near_high {
                    0.0
                } else {
                    room.frame.depth
                };
                for &u in us {
                    let x = room.frame.world_xz(u, w)[0];
                    openings.push(door_opening(x - wx0));
                    if let Some(c) = corridor {
                        plan.doors.push(Door {
                            rooms: (room.room.id, plan.rooms[c].room.id),
                            min: [x - DOOR_WIDTH / 2.0, ft, line - half],
                            max: [x + DOOR_WIDTH / 2.0, ft + DOOR_HEIGHT, line + half],
                        });
                    }
                }
            }
            plan.walls.push(WallPlan {
                origin: [wx0, ft, line - half],
                along_x: true,
                length: wx1 - wx0,
                height,
                openings,
                exterior,
                room: tag,
            });
        }
        let z_len = band.z1 - band.z0 - WALL;
        let end_wall = |x: f32| WallPlan {
            origin: [x - half, ft, band.z0 + half],
            along_x: false,
            length: z_len,
            height,
            openings: windows(0.0, z_len),
            exterior: true,
            room: tag,
        };
        if i == 0 {
            plan.walls.push(end_wall(0.0));
        }
        if i + 1 == count {
            plan.walls.push(end_wall(length));
        } else {
            plan.walls.push(WallPlan {
                origin: [room.x[1] - half, ft, band.z0 + half],
                along_x: false,
                length: z_len,
                height,
                openings: Vec::new(),
                exterior: false,
                room: None,
            });
        }
    }
}

/// End walls of the corridors, and the corridors' own lists of doors (local u).
pub(super) fn corridor_structure(
    fp: &Footprint,
    s: u32,
    bands: &[Band],
    corridor_of_band: &[Option<usize>],
    plan: &mut StoreyPlan,
) {
    let half = WALL / 2.0;
    let (ft, height) = (floor_top(s), ceiling_bottom(s) - floor_top(s));
    for (b, band) in bands.iter().enumerate() {
        let Some(c) = corridor_of_band[b] else {
            continue;
        };
        let id = plan.rooms[c].room.id;
        let x0 = plan.rooms[c].frame.origin[0];
        let mut near = Vec::new();
        let mut far = Vec::new();
        for d in plan.doors.iter().filter(|d| d.rooms.1 == id) {
            let u = (d.min[0] + d.max[0]) / 2.0 - x0;
            if d.max[2] <= band.z0 + half + 1e-3 {
                near.push(u);
            } else {
                far.push(u);
            }
        }
        plan.rooms[c].near_doors = near;
        plan.rooms[c].far_doors = far;
        let z_len = band.z1 - band.z0 - WALL;
        for x in [0.0, fp.length()] {
            plan.walls.push(WallPlan {
                origin: [x - half, ft, band.z0 + half],
                along_x: false,
                length: z_len,
                height,
                openings: windows(0.0, z_len),
                exterior: true,
                room: Some((RoomKind::Corridor, id)),
            });
        }
    }
}

/// Floor and ceiling slabs of one room, with stair openings for stairwells.
pub(super) fn room_slabs(
    fp: &Footprint,
    s: u32,
    room: &PlannedRoom,
    bands: &[Band],
) -> Vec<SlabPlan> {
    let half = WALL / 2.0;
    let depth = bands.last().map_or(0.0, |b| b.z1);
    let gx0 = if room.x[0] <= 0.0 { -half } else { room.x[0] };
    let gx1 = if room.x[1] >= fp.length() {
        fp.length() + half
    } else {
        room.x[1]
    };
    let gz0 = if room.z[0] <= 0.0 { -half } else { room.z[0] };
    let gz1 = if room.z[1] >= depth {
        depth + half
    } else {
        room.z[1]
    };
    let hole = |lane: u32| {
        let r = room.frame.world_rect(
            stair_lane(room.frame.width, lane),
            [STAIR_START, STAIR_START + STAIR_RUN],
        );
        Opening {
            u0: r[0] - gx0,
            u1: r[1] - gx0,
            v0: r[2] - gz0,
            v1: r[3] - gz0,
        }
    };
    let stair = room.room.kind == RoomKind::Stairwell;
    let floor_holes = if stair && s > 0 {
        vec![hole(s - 1)]
    } else {
        Vec::new()
    };
    let ceiling_holes = if stair && room.stairs_up {
        vec![hole(s)]
    } else {
        Vec::new()
    };
    let tag = (room.room.kind, room.room.id);
    vec![
        SlabPlan {
            origin: [gx0, s as f32 * STOREY_HEIGHT, gz0],
            size: [gx1 - gx0, gz1 - gz0],
            holes: floor_holes,
            ceiling: false,
            room: tag,
        },
        SlabPlan {
            origin: [gx0, ceiling_bottom(s), gz0],
            size: [gx1 - gx0, gz1 - gz0],
            holes: ceiling_holes,
            ceiling: true,
            room: tag,
        },
    ]
}
