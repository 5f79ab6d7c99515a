//! Partitioning room bands into rooms: the stairwell slots fixed on every storey, the room
//! kinds each storey must hold, a random mix of whole-bay rooms to fill the rest, and the
//! planned corridors and rooms with their local frames and door positions.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::{BAY, Band, BandRole, Footprint, Frame, PlannedRoom, WALL, ceiling_bottom, floor_top};
use crate::{Room, RoomKind};

/// A run of bays in a band holding one room.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Slot {
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

/// Stairwell bays in the outer bands: both ends, plus one every 16 bays on long buildings.
pub(super) fn stairwell_slots(fp: &Footprint, role: BandRole) -> Vec<Slot> {
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
pub(super) fn required_kinds(
    fp: &Footprint,
    s: u32,
    bands: &[Band],
    rng: &mut ChaCha8Rng,
) -> Vec<Vec<Slot>> {
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
pub(super) fn fill_band(
    rng: &mut ChaCha8Rng,
    bays: u32,
    fixed: Vec<Slot>,
    required: &[Slot],
) -> Vec<Slot> {
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

pub(super) fn corridor_room(fp: &Footprint, s: u32, band: &Band, next_id: &mut u32) -> PlannedRoom {
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

pub(super) fn band_room(
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
