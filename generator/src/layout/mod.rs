//! Storey plans: corridors, rooms, stairwells, doors, windows, walls and slabs.
//!
//! Funkhouser §3.1.1 started from the architects' 2½-D floorplans of Soda Hall. We generate a
//! comparable plan instead: every storey is a strip of *bays* (3.6 m modules) along X, cut across Z
//! into bands — outer room bands with windows, one or more corridors, and windowless middle room
//! bands between parallel corridors. Each room band is partitioned into rooms of whole bays
//! (offices, labs, classrooms, conference rooms, an auditorium or library on some storeys) and
//! stairwells that sit at the same place on every storey. Walls are centred on grid lines and
//! carry door and window openings; floor and ceiling slabs are split per room and carry the
//! openings through which stairs pass. Y is up; storeys stack along +Y.
//!
//! This module holds the dimensions, the plan types and the per-storey driver; `partition` cuts
//! the bands into rooms and `walls` builds the walls, doors, windows, slabs and stair openings
//! around them.

use rand_chacha::ChaCha8Rng;

use crate::structure::Opening;
use crate::{Door, Preset, Room, RoomKind};

mod partition;
mod walls;

use partition::{band_room, corridor_room, fill_band, required_kinds, stairwell_slots};
use walls::{band_structure, corridor_structure, room_slabs, stair_doors};

/// Width of one structural bay along X (m).
pub(crate) const BAY: f32 = 3.6;
/// Floor-to-floor height (m).
pub(crate) const STOREY_HEIGHT: f32 = 3.8;
/// Thickness of a floor slab and of a ceiling slab (m); they are stacked between storeys.
pub(crate) const SLAB: f32 = 0.15;
/// Wall thickness (m).
pub(crate) const WALL: f32 = 0.2;
/// Depth across Z of an outer (windowed) room band, grid line to grid line (m).
const OUTER_DEPTH: f32 = 7.2;
/// Depth of a middle room band between two corridors (m).
const MIDDLE_DEPTH: f32 = 9.6;
/// Corridor width, grid line to grid line (m).
const CORRIDOR_WIDTH: f32 = 2.4;
/// Door opening width (m).
pub(crate) const DOOR_WIDTH: f32 = 1.0;
/// Door opening height (m).
pub(crate) const DOOR_HEIGHT: f32 = 2.1;
/// Window sill and head heights above the floor (m).
const WINDOW_SILL: f32 = 0.9;
const WINDOW_HEAD: f32 = 2.5;
/// Distance from the stairwell door wall to the foot of a flight, and the flight's run (m).
pub(crate) const STAIR_START: f32 = 1.3;
pub(crate) const STAIR_RUN: f32 = 4.8;

/// Size of a building: storeys, bays along X and parallel corridors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Footprint {
    /// Storey count.
    pub storeys: u32,
    /// Bays along the corridors.
    pub bays: u32,
    /// Parallel corridors (≥ 1); `corridors − 1` windowless middle bands lie between them.
    pub corridors: u32,
}

impl Footprint {
    /// The footprint of a preset.
    pub(crate) fn of(preset: Preset) -> Self {
        let (storeys, bays, corridors) = match preset {
            Preset::Tiny => (1, 3, 1),
            Preset::Small => (2, 10, 2),
            Preset::Soda => (7, 26, 2),
            Preset::Mega => (18, 48, 5),
        };
        Footprint {
            storeys,
            bays,
            corridors,
        }
    }

    /// Length along X (m).
    pub(crate) fn length(&self) -> f32 {
        self.bays as f32 * BAY
    }

    /// The bands across Z, from z = 0.
    pub(crate) fn bands(&self) -> Vec<Band> {
        let mut roles = vec![BandRole::South];
        for c in 0..self.corridors.max(1) {
            roles.push(BandRole::Corridor);
            if c + 1 < self.corridors {
                roles.push(BandRole::Middle);
            }
        }
        roles.push(BandRole::North);
        let mut z = 0.0;
        roles
            .into_iter()
            .map(|role| {
                let depth = match role {
                    BandRole::South | BandRole::North => OUTER_DEPTH,
                    BandRole::Middle => MIDDLE_DEPTH,
                    BandRole::Corridor => CORRIDOR_WIDTH,
                };
                let band = Band {
                    z0: z,
                    z1: z + depth,
                    role,
                };
                z += depth;
                band
            })
            .collect()
    }
}

/// Height of the top of storey `s`'s floor slab.
pub(crate) fn floor_top(s: u32) -> f32 {
    s as f32 * STOREY_HEIGHT + SLAB
}

/// Height of the underside of storey `s`'s ceiling slab.
pub(crate) fn ceiling_bottom(s: u32) -> f32 {
    (s + 1) as f32 * STOREY_HEIGHT - SLAB
}

/// What a band across the footprint holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum BandRole {
    /// Rooms with windows on z = 0 and doors on the corridor at larger z.
    South,
    /// Rooms with doors on the corridor at smaller z and windows on the far side.
    North,
    /// Windowless rooms between two corridors.
    Middle,
    /// A corridor running the whole length.
    Corridor,
}

/// A band of the footprint between `z0` and `z1` (grid lines).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Band {
    /// Grid line at the low-Z side.
    pub z0: f32,
    /// Grid line at the high-Z side.
    pub z1: f32,
    /// What it holds.
    pub role: BandRole,
}

/// A room's local frame: `u` runs along its door wall, `w` away from it into the room, both from
/// the interior corner; the frame is the world X/Z frame, possibly turned by 180° about Y.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Frame {
    /// World (x, z) of local (0, 0).
    pub origin: [f32; 2],
    /// Whether the frame is rotated by 180° (u = −x, w = −z).
    pub rot2: bool,
    /// Interior extent along u.
    pub width: f32,
    /// Interior extent along w.
    pub depth: f32,
    /// World height of the floor top.
    pub floor_y: f32,
}

impl Frame {
    /// World (x, z) of a local point.
    pub(crate) fn world_xz(&self, u: f32, w: f32) -> [f32; 2] {
        if self.rot2 {
            [self.origin[0] - u, self.origin[1] - w]
        } else {
            [self.origin[0] + u, self.origin[1] + w]
        }
    }

    /// World rectangle `[x0, x1, z0, z1]` of a local rectangle.
    pub(crate) fn world_rect(&self, u: [f32; 2], w: [f32; 2]) -> [f32; 4] {
        let a = self.world_xz(u[0], w[0]);
        let b = self.world_xz(u[1], w[1]);
        [
            a[0].min(b[0]),
            a[0].max(b[0]),
            a[1].min(b[1]),
            a[1].max(b[1]),
        ]
    }
}

/// A planned room with what its furnishing generator needs.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct PlannedRoom {
    /// The public description.
    pub room: Room,
    /// Grid lines along X.
    pub x: [f32; 2],
    /// Grid lines along Z.
    pub z: [f32; 2],
    /// Local frame.
    pub frame: Frame,
    /// Door centres (local u) on the w = 0 wall.
    pub near_doors: Vec<f32>,
    /// Door centres (local u) on the w = depth wall.
    pub far_doors: Vec<f32>,
    /// Whether the w = depth wall is an exterior wall with windows.
    pub windows_far: bool,
    /// For stairwells: whether a flight goes up from this storey.
    pub stairs_up: bool,
}

/// A wall: a `length × height × WALL` box along X or Z, minus its openings.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct WallPlan {
    /// World position of the wall's minimum corner.
    pub origin: [f32; 3],
    /// Whether the wall runs along X (else along Z).
    pub along_x: bool,
    /// Length along its axis.
    pub length: f32,
    /// Height.
    pub height: f32,
    /// Openings in (along, up) coordinates from the minimum corner.
    pub openings: Vec<Opening>,
    /// Whether it is part of the facade.
    pub exterior: bool,
    /// The room it belongs to, if exactly one.
    pub room: Option<(RoomKind, u32)>,
}

/// A floor or ceiling slab under/over one room, minus stair openings.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SlabPlan {
    /// World position of the minimum corner.
    pub origin: [f32; 3],
    /// Size along X and Z.
    pub size: [f32; 2],
    /// Openings in (x, z) coordinates from the minimum corner.
    pub holes: Vec<Opening>,
    /// Ceiling (else floor).
    pub ceiling: bool,
    /// The room it covers.
    pub room: (RoomKind, u32),
}

/// One storey's plan.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct StoreyPlan {
    /// Rooms, corridors first.
    pub rooms: Vec<PlannedRoom>,
    /// Doors between rooms of this storey.
    pub doors: Vec<Door>,
    /// Walls.
    pub walls: Vec<WallPlan>,
    /// Floor and ceiling slabs.
    pub slabs: Vec<SlabPlan>,
}

/// Local u range of stair lane `lane` (0 or 1) in a stairwell of interior width `width`.
pub(crate) fn stair_lane(width: f32, lane: u32) -> [f32; 2] {
    let lane_width = (width - 0.6) / 2.0;
    if lane.is_multiple_of(2) {
        [0.2, 0.2 + lane_width]
    } else {
        [width - 0.2 - lane_width, width - 0.2]
    }
}

/// Plans every storey of the building and the stair openings that join them.
pub(crate) fn plan_building(fp: &Footprint, rng: &mut ChaCha8Rng) -> (Vec<StoreyPlan>, Vec<Door>) {
    let mut next_id = 0u32;
    let storeys: Vec<StoreyPlan> = (0..fp.storeys)
        .map(|s| plan_storey(fp, s, rng, &mut next_id))
        .collect();
    let stairs = stair_doors(&storeys);
    (storeys, stairs)
}

/// Plans storey `s`.
fn plan_storey(fp: &Footprint, s: u32, rng: &mut ChaCha8Rng, next_id: &mut u32) -> StoreyPlan {
    let bands = fp.bands();
    let required = required_kinds(fp, s, &bands, rng);
    let mut plan = StoreyPlan::default();
    let mut corridor_of_band: Vec<Option<usize>> = vec![None; bands.len()];
    for (b, band) in bands.iter().enumerate() {
        if band.role == BandRole::Corridor {
            corridor_of_band[b] = Some(plan.rooms.len());
            plan.rooms.push(corridor_room(fp, s, band, next_id));
        }
    }
    for (b, band) in bands.iter().enumerate() {
        if band.role == BandRole::Corridor {
            continue;
        }
        let fixed = stairwell_slots(fp, band.role);
        let slots = fill_band(rng, fp.bays, fixed, &required[b]);
        let first = plan.rooms.len();
        for slot in &slots {
            plan.rooms.push(band_room(fp, s, band, slot, rng, next_id));
        }
        let below = b.checked_sub(1).and_then(|i| corridor_of_band[i]);
        let above = corridor_of_band.get(b + 1).copied().flatten();
        band_structure(fp, s, band, first, (below, above), &mut plan);
    }
    corridor_structure(fp, s, &bands, &corridor_of_band, &mut plan);
    for i in 0..plan.rooms.len() {
        let slabs = room_slabs(fp, s, &plan.rooms[i], &bands);
        plan.slabs.extend(slabs);
    }
    plan
}
