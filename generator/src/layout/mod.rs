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

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::structure::Opening;
use crate::{Door, Preset, Room, RoomKind};

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

/// A run of bays in a band holding one room.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Slot {
    bay: u32,
    len: u32,
    kind: RoomKind,
    connector: bool,
}

fn bays_of(kind: RoomKind) -> u32 {
    match kind {
        RoomKind::Office | RoomKind::Stairwell | RoomKind::Corridor => 1,
        RoomKind::Lab | RoomKind::Conference => 2,
        RoomKind::Classroom => 3,
        RoomKind::Library => 4,
        RoomKind::Auditorium => 5,
    }
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

/// Doors through the slab openings between stairwells stacked on consecutive storeys.
fn stair_doors(storeys: &[StoreyPlan]) -> Vec<Door> {
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

/// Stairwell bays in the outer bands: both ends, plus one every 16 bays on long buildings.
fn stairwell_slots(fp: &Footprint, role: BandRole) -> Vec<Slot> {
    if fp.storeys < 2 || fp.bays < 3 {
        return Vec::new();
    }
    let bays: Vec<u32> = match role {
        BandRole::South => (0..fp.bays - 1).step_by(16).collect(),
        BandRole::North => (0..fp.bays - 1)
            .step_by(16)
            .map(|b| fp.bays - 1 - b)
            .collect(),
        _ => Vec::new(),
    };
    bays.into_iter()
        .map(|bay| Slot {
            bay,
            len: 1,
            kind: RoomKind::Stairwell,
            connector: false,
        })
        .collect()
}

/// Kinds every storey must contain (placed before the random fill), per room band index.
fn required_kinds(fp: &Footprint, s: u32, bands: &[Band], rng: &mut ChaCha8Rng) -> Vec<Vec<Slot>> {
    let room_bands: Vec<usize> = (0..bands.len())
        .filter(|&b| bands[b].role != BandRole::Corridor)
        .collect();
    let middle: Vec<usize> = (0..bands.len())
        .filter(|&b| bands[b].role == BandRole::Middle)
        .collect();
    let mut required: Vec<Vec<Slot>> = vec![Vec::new(); bands.len()];
    let slot = |kind, connector| Slot {
        bay: 0,
        len: bays_of(kind),
        kind,
        connector,
    };
    for &b in &middle {
        for _ in 0..(1 + fp.bays / 20) {
            required[b].push(slot(RoomKind::Corridor, true));
        }
    }
    let mut kinds = vec![RoomKind::Conference];
    let big = fp.bays >= 8;
    if big {
        let (aud, lib) = if fp.storeys < 3 {
            (s == 0, s + 1 == fp.storeys)
        } else {
            (s % 3 == 1, s % 3 == 2)
        };
        let extra = (fp.bays / 24) * (fp.corridors.saturating_sub(1)).max(1);
        for _ in 0..extra.max(1) {
            if aud {
                kinds.push(RoomKind::Auditorium);
            }
            if lib {
                kinds.push(RoomKind::Library);
            }
        }
    }
    for kind in kinds {
        let prefer_middle = matches!(kind, RoomKind::Auditorium | RoomKind::Library);
        let pool = if prefer_middle && !middle.is_empty() {
            &middle
        } else {
            &room_bands
        };
        let b = pool[rng.random_range(0..pool.len())];
        required[b].push(slot(kind, false));
    }
    required
}

/// Partitions a band of `bays` bays into rooms: fixed slots, then required kinds at random free
/// positions, then a random mix of offices, labs, classrooms and conference rooms.
fn fill_band(rng: &mut ChaCha8Rng, bays: u32, fixed: Vec<Slot>, required: &[Slot]) -> Vec<Slot> {
    let mut slots = fixed;
    for req in required {
        let gaps = free_gaps(&slots, bays);
        let fitting: Vec<(u32, u32)> = gaps.into_iter().filter(|g| g.1 >= req.len).collect();
        if fitting.is_empty() {
            continue;
        }
        let (start, len) = fitting[rng.random_range(0..fitting.len())];
        let bay = start + rng.random_range(0..=len - req.len);
        slots.push(Slot { bay, ..*req });
    }
    for (start, len) in free_gaps(&slots, bays) {
        let mut bay = start;
        while bay < start + len {
            let kind = random_fill_kind(rng, start + len - bay);
            slots.push(Slot {
                bay,
                len: bays_of(kind),
                kind,
                connector: false,
            });
            bay += bays_of(kind);
        }
    }
    slots.sort_by_key(|s| s.bay);
    slots
}

/// Free runs `(first bay, length)` between occupied slots.
fn free_gaps(slots: &[Slot], bays: u32) -> Vec<(u32, u32)> {
    let mut occupied: Vec<(u32, u32)> = slots.iter().map(|s| (s.bay, s.bay + s.len)).collect();
    occupied.sort_unstable();
    let mut gaps = Vec::new();
    let mut at = 0;
    for (a, b) in occupied {
        if a > at {
            gaps.push((at, a - at));
        }
        at = at.max(b);
    }
    if at < bays {
        gaps.push((at, bays - at));
    }
    gaps
}

fn random_fill_kind(rng: &mut ChaCha8Rng, room_left: u32) -> RoomKind {
    const MIX: [(RoomKind, f32); 4] = [
        (RoomKind::Office, 6.0),
        (RoomKind::Lab, 2.0),
        (RoomKind::Classroom, 1.2),
        (RoomKind::Conference, 0.5),
    ];
    let fits: Vec<(RoomKind, f32)> = MIX
        .into_iter()
        .filter(|(k, _)| bays_of(*k) <= room_left)
        .collect();
    let total: f32 = fits.iter().map(|f| f.1).sum();
    let mut pick = rng.random_range(0.0..total);
    for (kind, weight) in &fits {
        if pick < *weight {
            return *kind;
        }
        pick -= weight;
    }
    RoomKind::Office
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

fn interior(x: [f32; 2], z: [f32; 2]) -> ([f32; 2], [f32; 2]) {
    let h = WALL / 2.0;
    ([x[0] + h, x[1] - h], [z[0] + h, z[1] - h])
}

fn make_room(id: u32, kind: RoomKind, s: u32, ix: [f32; 2], iz: [f32; 2]) -> Room {
    Room {
        id,
        kind,
        storey: s,
        min: [ix[0], floor_top(s), iz[0]],
        max: [ix[1], ceiling_bottom(s), iz[1]],
    }
}

fn corridor_room(fp: &Footprint, s: u32, band: &Band, next_id: &mut u32) -> PlannedRoom {
    let x = [0.0, fp.length()];
    let z = [band.z0, band.z1];
    let (ix, iz) = interior(x, z);
    let id = *next_id;
    *next_id += 1;
    PlannedRoom {
        room: make_room(id, RoomKind::Corridor, s, ix, iz),
        x,
        z,
        frame: Frame {
            origin: [ix[0], iz[0]],
            rot2: false,
            width: ix[1] - ix[0],
            depth: iz[1] - iz[0],
            floor_y: floor_top(s),
        },
        near_doors: Vec::new(),
        far_doors: Vec::new(),
        windows_far: false,
        stairs_up: false,
    }
}

fn band_room(
    fp: &Footprint,
    s: u32,
    band: &Band,
    slot: &Slot,
    rng: &mut ChaCha8Rng,
    next_id: &mut u32,
) -> PlannedRoom {
    let x = [slot.bay as f32 * BAY, (slot.bay + slot.len) as f32 * BAY];
    let z = [band.z0, band.z1];
    let (ix, iz) = interior(x, z);
    let rot2 = band.role == BandRole::South;
    let frame = Frame {
        origin: if rot2 { [ix[1], iz[1]] } else { [ix[0], iz[0]] },
        rot2,
        width: ix[1] - ix[0],
        depth: iz[1] - iz[0],
        floor_y: floor_top(s),
    };
    let w = frame.width;
    let near_doors = if slot.kind == RoomKind::Stairwell || slot.connector {
        vec![w / 2.0]
    } else if w > 9.0 {
        vec![1.0, w - 1.0]
    } else {
        vec![((rng.random_range(0.9..w - 0.9) * 10.0).round() / 10.0).clamp(0.9, w - 0.9)]
    };
    let far_doors = match (band.role, slot.kind) {
        (BandRole::Middle, _) if slot.connector => vec![w / 2.0],
        (BandRole::Middle, RoomKind::Auditorium | RoomKind::Library | RoomKind::Classroom) => {
            vec![w - 1.0]
        }
        _ => Vec::new(),
    };
    let id = *next_id;
    *next_id += 1;
    PlannedRoom {
        room: make_room(id, slot.kind, s, ix, iz),
        x,
        z,
        frame,
        near_doors,
        far_doors,
        windows_far: band.role != BandRole::Middle,
        stairs_up: slot.kind == RoomKind::Stairwell && s + 1 < fp.storeys,
    }
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
fn band_structure(
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
fn corridor_structure(
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
fn room_slabs(fp: &Footprint, s: u32, room: &PlannedRoom, bands: &[Band]) -> Vec<SlabPlan> {
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
