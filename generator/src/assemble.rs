//! Assembly: storey plans and room generators become instances of shared definitions.
//!
//! Funkhouser §3.1.2 stores a model as object *instances* (a transform) referencing shared
//! object *definitions* (geometry per LOD). Here every furniture piece is an instance of a
//! furniture definition with its own LODs (§3.1.3), and walls and slabs are instances of
//! structural meshes deduplicated by shape, so identical offices share their walls' geometry.

use std::collections::BTreeMap;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::furniture::Library;
use crate::layout::{self, Footprint, PlannedRoom, SLAB, SlabPlan, WALL, WallPlan};
use crate::mesh::{MeshData, Rgba};
use crate::structure::{slab_mesh, wall_mesh};
use crate::{Door, Room, RoomKind, Stats, rooms};

/// Semantic tags written into a node's `extras`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Tags {
    /// Structural occluder (walls, floors, ceilings).
    pub occluder: bool,
    /// `"wall"`, `"floor"`, `"ceiling"` or `"furniture"`.
    pub kind: &'static str,
    /// Furniture type, for furniture.
    pub ty: Option<&'static str>,
    /// Owning room, if one.
    pub room: Option<(RoomKind, u32)>,
    /// Storey index.
    pub storey: u32,
}

/// What an instance draws.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum MeshRef {
    /// A structural mesh, by index in [`Scene::structures`].
    Structure(usize),
    /// A furniture definition, by index in the library.
    Furniture(usize),
}

/// One scene node with a mesh.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Instance {
    /// Its geometry.
    pub mesh: MeshRef,
    /// World translation.
    pub translation: [f32; 3],
    /// World rotation quaternion (x, y, z, w); identity for structure.
    pub rotation: [f32; 4],
    /// Extras.
    pub tags: Tags,
}

/// The whole generated model before serialisation.
#[derive(Debug)]
pub(crate) struct Scene {
    /// Distinct structural meshes with their names.
    pub structures: Vec<(String, MeshData)>,
    /// Furniture definitions.
    pub library: Library,
    /// Instances grouped by storey.
    pub storeys: Vec<Vec<Instance>>,
    /// Rooms by id.
    pub rooms: Vec<Room>,
    /// Doors and stair openings.
    pub doors: Vec<Door>,
}

impl Scene {
    /// Counts for [`Stats`].
    pub(crate) fn stats(&self) -> Stats {
        let mut stats = Stats {
            storeys: self.storeys.len() as u32,
            rooms: self.rooms.len() as u32,
            definitions: (self.structures.len() + self.library.defs.len()) as u64,
            furniture_definitions: self.library.defs.len() as u64,
            ..Stats::default()
        };
        for inst in self.storeys.iter().flatten() {
            let (highest, all) = match inst.mesh {
                MeshRef::Structure(i) => {
                    let t = self.structures[i].1.triangle_count();
                    (t, t)
                }
                MeshRef::Furniture(i) => {
                    let lods = &self.library.defs[i].lods;
                    let all = lods.iter().map(MeshData::triangle_count).sum();
                    (lods.first().map_or(0, MeshData::triangle_count), all)
                }
            };
            stats.instances += 1;
            stats.triangles_highest += highest;
            stats.triangles_all_lods += all;
        }
        stats
    }
}

/// Deduplicates structural meshes by their quantised geometry and colour.
#[derive(Debug, Default)]
struct StructureCache {
    index: BTreeMap<Vec<i32>, usize>,
    meshes: Vec<(String, MeshData)>,
}

impl StructureCache {
    fn get(&mut self, name: &str, mesh: MeshData) -> usize {
        let mut key: Vec<i32> = Vec::with_capacity(mesh.positions.len() * 3 + 4);
        if let Some(c) = mesh.colors.first() {
            key.extend(c.iter().map(|&v| i32::from(v)));
        }
        for p in &mesh.positions {
            key.extend(p.iter().map(|v| (v * 1000.0).round() as i32));
        }
        let next = self.meshes.len();
        *self.index.entry(key).or_insert_with(|| {
            self.meshes.push((format!("{name}.{next}"), mesh));
            next
        })
    }
}

const fn rgb(r: u8, g: u8, b: u8) -> Rgba {
    [r, g, b, 255]
}

fn floor_color(kind: RoomKind) -> Rgba {
    match kind {
        RoomKind::Office => rgb(110, 115, 130),
        RoomKind::Lab => rgb(190, 190, 180),
        RoomKind::Classroom => rgb(150, 130, 110),
        RoomKind::Conference => rgb(120, 60, 60),
        RoomKind::Auditorium => rgb(100, 40, 40),
        RoomKind::Library => rgb(90, 110, 80),
        RoomKind::Corridor => rgb(170, 165, 150),
        RoomKind::Stairwell => rgb(150, 150, 145),
    }
}

/// Builds the scene for `fp`, reporting each finished storey through `progress`.
pub(crate) fn assemble(fp: &Footprint, seed: u64, progress: &mut dyn FnMut(u64)) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (plans, stair_doors) = layout::plan_building(fp, &mut rng);
    let mut library = Library::new(seed);
    let mut cache = StructureCache::default();
    let mut storeys = Vec::with_capacity(plans.len());
    let mut rooms = Vec::new();
    let mut doors = Vec::new();
    for (s, plan) in plans.iter().enumerate() {
        let s = s as u32;
        let mut instances = Vec::new();
        for wall in &plan.walls {
            instances.push(wall_instance(wall, s, &mut cache));
        }
        for slab in &plan.slabs {
            instances.push(slab_instance(slab, s, &mut cache));
        }
        for room in &plan.rooms {
            furnish_room(room, &mut library, &mut rng, &mut instances);
            rooms.push(room.room.clone());
        }
        doors.extend(plan.doors.iter().cloned());
        storeys.push(instances);
        progress(u64::from(s) + 1);
    }
    doors.extend(stair_doors);
    Scene {
        structures: cache.meshes,
        library,
        storeys,
        rooms,
        doors,
    }
}

const IDENTITY: [f32; 4] = [0.0, 0.0, 0.0, 1.0];

fn wall_instance(wall: &WallPlan, storey: u32, cache: &mut StructureCache) -> Instance {
    let color = if wall.exterior {
        rgb(214, 200, 170)
    } else {
        rgb(235, 232, 220)
    };
    let mesh = wall_mesh(
        wall.along_x,
        wall.length,
        wall.height,
        WALL,
        &wall.openings,
        color,
    );
    Instance {
        mesh: MeshRef::Structure(cache.get("wall", mesh)),
        translation: wall.origin,
        rotation: IDENTITY,
        tags: Tags {
            occluder: true,
            kind: "wall",
            ty: None,
            room: wall.room,
            storey,
        },
    }
}

fn slab_instance(slab: &SlabPlan, storey: u32, cache: &mut StructureCache) -> Instance {
    let (kind, color) = if slab.ceiling {
        ("ceiling", rgb(245, 245, 240))
    } else {
        ("floor", floor_color(slab.room.0))
    };
    let mesh = slab_mesh(slab.size, SLAB, &slab.holes, color);
    Instance {
        mesh: MeshRef::Structure(cache.get(kind, mesh)),
        translation: slab.origin,
        rotation: IDENTITY,
        tags: Tags {
            occluder: true,
            kind,
            ty: None,
            room: Some(slab.room),
            storey,
        },
    }
}

/// Rotation about +Y by `quarters` quarter turns plus `jitter` radians, as a quaternion.
fn yaw_quaternion(quarters: u8, jitter: f32) -> [f32; 4] {
    const H: f32 = std::f32::consts::FRAC_1_SQRT_2;
    if jitter == 0.0 {
        return match quarters % 4 {
            0 => IDENTITY,
            1 => [0.0, H, 0.0, H],
            2 => [0.0, 1.0, 0.0, 0.0],
            _ => [0.0, -H, 0.0, H],
        };
    }
    let angle = f32::from(quarters % 4) * std::f32::consts::FRAC_PI_2 + jitter;
    let (s, c) = (angle / 2.0).sin_cos();
    [0.0, s, 0.0, c]
}

fn furnish_room(
    room: &PlannedRoom,
    library: &mut Library,
    rng: &mut ChaCha8Rng,
    out: &mut Vec<Instance>,
) {
    let frame = room.frame;
    let turn = if frame.rot2 { 2 } else { 0 };
    for piece in rooms::furnish(room, library, rng) {
        let [x, z] = frame.world_xz(piece.pos[0], piece.pos[2]);
        let def = &library.defs[piece.def];
        out.push(Instance {
            mesh: MeshRef::Furniture(piece.def),
            translation: [x, frame.floor_y + piece.pos[1], z],
            rotation: yaw_quaternion(piece.quarter + turn, piece.jitter),
            tags: Tags {
                occluder: false,
                kind: "furniture",
                ty: Some(def.key.ty.name()),
                room: Some((room.room.kind, room.room.id)),
                storey: room.room.storey,
            },
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quarter_turn_quaternions_are_unit_and_about_y() {
        for q in 0..4 {
            let r = yaw_quaternion(q, 0.0);
            let n: f32 = r.iter().map(|v| v * v).sum();
            assert!((n - 1.0).abs() < 1e-6);
            assert_eq!((r[0], r[2]), (0.0, 0.0));
        }
        let j = yaw_quaternion(1, 0.1);
        assert!((j[1] - (std::f32::consts::FRAC_PI_4 + 0.05).sin()).abs() < 1e-6);
    }
}
