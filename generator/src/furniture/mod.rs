//! Parametric furniture that emits its own levels of detail.
//!
//! Funkhouser §3.1.1: bookshelves, plants, lights and door handles in Soda Hall came from
//! *procedural object generators*. §3.1.3: such generators can output "not only a very detailed
//! model of the object, but also simpler representations" — prisms with fewer sides (the door
//! handle of Fig. 3.6), simpler shapes and removed shapes (CSG abstraction, Fig. 3.7). Every
//! generator here is a function of a seeded parameter stream and a detail level `lod`:
//! cylinders get `sides >> lod` sides, spheres fewer slices, small parts (handles, casters, books)
//! disappear or merge into blocks. The LOD chain of a definition keeps only levels with at most
//! half the triangles of the level above and ends with a single box of the average colour
//! (≤ 100 triangles in the lowest LOD, §3.1.4's guideline).
//!
//! Each generator builds the piece standing on y = 0, roughly centred on the Y axis, with its
//! *front* (the side a user faces or sits on) towards +Z.
//!
//! This module holds what the generators share (the definition library and LOD filtering, the
//! parameter stream, the detail-aware `Shape` builder, the palettes) and the dispatch by
//! [`FurnitureType`]; the generators live in one submodule per family: `seating`, `tables`,
//! `storage`, `lighting`, `equipment`, `fixtures` and `accessories`.

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::mesh::{Axis, MeshData, Rgba};

mod accessories;
mod equipment;
mod fixtures;
mod lighting;
mod seating;
mod storage;
mod tables;

use accessories::{coat_rack, coffee_cup, plant, trash_bin};
use equipment::{computer, keyboard, monitor, phone, projector, water_cooler};
use fixtures::{door, stairs, whiteboard};
use lighting::{ceiling_light, desk_lamp, floor_lamp};
use seating::{auditorium_seat, chair, office_chair, sofa, stool};
use storage::{books, bookshelf, filing_cabinet, library_shelf};
use tables::{desk, lab_bench, lectern, round_table, student_desk, table};

/// The furniture generators (Funkhouser §3.1.1's procedural object generators).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) enum FurnitureType {
    Desk,
    Chair,
    OfficeChair,
    Bookshelf,
    DeskLamp,
    Plant,
    Books,
    Monitor,
    Computer,
    Keyboard,
    CoffeeCup,
    Table,
    StudentDesk,
    RoundTable,
    LabBench,
    Stool,
    AuditoriumSeat,
    Whiteboard,
    FilingCabinet,
    Lectern,
    Sofa,
    TrashBin,
    CoatRack,
    Door,
    Stairs,
    Projector,
    LibraryShelf,
    FloorLamp,
    WaterCooler,
    CeilingLight,
    Phone,
}

impl FurnitureType {
    /// Name written as `"type"` in the node extras.
    pub(crate) fn name(self) -> &'static str {
        use FurnitureType::*;
        match self {
            Desk => "desk",
            Chair => "chair",
            OfficeChair => "office_chair",
            Bookshelf => "bookshelf",
            DeskLamp => "desk_lamp",
            Plant => "plant",
            Books => "books",
            Monitor => "monitor",
            Computer => "computer",
            Keyboard => "keyboard",
            CoffeeCup => "coffee_cup",
            Table => "table",
            StudentDesk => "student_desk",
            RoundTable => "round_table",
            LabBench => "lab_bench",
            Stool => "stool",
            AuditoriumSeat => "auditorium_seat",
            Whiteboard => "whiteboard",
            FilingCabinet => "filing_cabinet",
            Lectern => "lectern",
            Sofa => "sofa",
            TrashBin => "trash_bin",
            CoatRack => "coat_rack",
            Door => "door",
            Stairs => "stairs",
            Projector => "projector",
            LibraryShelf => "library_shelf",
            FloorLamp => "floor_lamp",
            WaterCooler => "water_cooler",
            CeilingLight => "ceiling_light",
            Phone => "phone",
        }
    }

    /// How many parameter variants (distinct definitions) the generator offers.
    pub(crate) fn variants(self) -> u32 {
        use FurnitureType::*;
        match self {
            Desk | Chair | Bookshelf => 8,
            OfficeChair | Plant | Books | Table | LibraryShelf => 6,
            DeskLamp | LabBench => 5,
            Monitor | RoundTable | AuditoriumSeat | Whiteboard | FilingCabinet | Sofa
            | CoffeeCup | StudentDesk => 4,
            Computer | Stool | TrashBin | Door | FloorLamp | CeilingLight => 3,
            Keyboard | Lectern | CoatRack | Projector | WaterCooler | Phone => 2,
            Stairs => 1,
        }
    }

    fn generator(self) -> fn(&mut Params, &mut Shape) {
        use FurnitureType::*;
        match self {
            Desk => desk,
            Chair => chair,
            OfficeChair => office_chair,
            Bookshelf => bookshelf,
            DeskLamp => desk_lamp,
            Plant => plant,
            Books => books,
            Monitor => monitor,
            Computer => computer,
            Keyboard => keyboard,
            CoffeeCup => coffee_cup,
            Table => table,
            StudentDesk => student_desk,
            RoundTable => round_table,
            LabBench => lab_bench,
            Stool => stool,
            AuditoriumSeat => auditorium_seat,
            Whiteboard => whiteboard,
            FilingCabinet => filing_cabinet,
            Lectern => lectern,
            Sofa => sofa,
            TrashBin => trash_bin,
            CoatRack => coat_rack,
            Door => door,
            Stairs => stairs,
            Projector => projector,
            LibraryShelf => library_shelf,
            FloorLamp => floor_lamp,
            WaterCooler => water_cooler,
            CeilingLight => ceiling_light,
            Phone => phone,
        }
    }
}

/// Identifies one furniture definition: a generator and one of its parameter variants.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub(crate) struct DefKey {
    /// The generator.
    pub ty: FurnitureType,
    /// The parameter variant, `0..ty.variants()`.
    pub variant: u32,
}

/// A furniture definition: its LOD meshes (finest first) and the bounds of the finest.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct FurnitureDef {
    /// Which generator and variant.
    pub key: DefKey,
    /// LOD meshes, finest first; each has at most half the triangles of the previous one.
    pub lods: Vec<MeshData>,
    /// Minimum corner of the finest LOD.
    pub min: [f32; 3],
    /// Maximum corner of the finest LOD.
    pub max: [f32; 3],
}

/// All furniture definitions built so far, in first-use order (deterministic).
#[derive(Debug)]
pub(crate) struct Library {
    seed: u64,
    index: BTreeMap<DefKey, usize>,
    /// Definitions, by index.
    pub defs: Vec<FurnitureDef>,
}

impl Library {
    /// An empty library whose generators draw their parameters from `seed`.
    pub(crate) fn new(seed: u64) -> Self {
        Library {
            seed,
            index: BTreeMap::new(),
            defs: Vec::new(),
        }
    }

    /// The index of the definition for `key`, building it on first use.
    pub(crate) fn get(&mut self, key: DefKey) -> usize {
        if let Some(&i) = self.index.get(&key) {
            return i;
        }
        let def = build_def(key, self.seed);
        self.defs.push(def);
        let i = self.defs.len() - 1;
        self.index.insert(key, i);
        i
    }
}

/// Number of detail levels asked of each generator before the final box.
const CANDIDATE_LODS: u32 = 4;

fn param_seed(key: DefKey, seed: u64) -> u64 {
    let ty = key.ty as u64;
    seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (ty << 32) ^ u64::from(key.variant) ^ 0x5EED
}

/// Builds a definition: candidate meshes at detail 0.., filtered so each kept level has at most
/// half the triangles of the previous kept one, then an average-colour box.
pub(crate) fn build_def(key: DefKey, seed: u64) -> FurnitureDef {
    let generator = key.ty.generator();
    let mut lods: Vec<MeshData> = Vec::new();
    for lod in 0..CANDIDATE_LODS {
        let mut params = Params(ChaCha8Rng::seed_from_u64(param_seed(key, seed)));
        let mut shape = Shape {
            mesh: MeshData::default(),
            lod,
        };
        generator(&mut params, &mut shape);
        push_if_halved(&mut lods, shape.mesh);
    }
    let (min, max) = lods
        .first()
        .and_then(MeshData::bounds)
        .unwrap_or(([-0.1; 3], [0.1; 3]));
    let mut coarse = MeshData::default();
    let color = lods.first().map_or([200; 4], MeshData::average_color);
    coarse.add_box(min, max, color);
    push_if_halved(&mut lods, coarse);
    FurnitureDef {
        key,
        lods,
        min,
        max,
    }
}

fn push_if_halved(lods: &mut Vec<MeshData>, mesh: MeshData) {
    if mesh.triangle_count() == 0 {
        return;
    }
    match lods.last() {
        Some(last) if mesh.triangle_count() * 2 > last.triangle_count() => {}
        _ => lods.push(mesh),
    }
}

/// The parameter stream of one definition.
struct Params(ChaCha8Rng);

impl Params {
    fn f(&mut self, lo: f32, hi: f32) -> f32 {
        if hi > lo {
            self.0.random_range(lo..hi)
        } else {
            lo
        }
    }

    fn n(&mut self, lo: u32, hi: u32) -> u32 {
        if hi > lo {
            self.0.random_range(lo..=hi)
        } else {
            lo
        }
    }

    fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.0.random_range(0..items.len())]
    }

    fn chance(&mut self, p: f64) -> bool {
        self.0.random_bool(p)
    }
}

/// A mesh under construction at a given detail level.
struct Shape {
    mesh: MeshData,
    lod: u32,
}

impl Shape {
    /// Whether small parts (handles, casters, individual books…) are present.
    fn fine(&self) -> bool {
        self.lod == 0
    }

    /// Whether medium parts (drawer fronts, shelves, cushions…) are present.
    fn medium(&self) -> bool {
        self.lod <= 1
    }

    fn sides(&self, n: u32) -> u32 {
        (n >> self.lod).max(4)
    }

    fn bx(&mut self, min: [f32; 3], max: [f32; 3], c: Rgba) {
        self.mesh.add_box(min, max, c);
    }

    fn cyl(&mut self, axis: Axis, base: [f32; 3], len: f32, r: f32, sides: u32, c: Rgba) {
        let s = self.sides(sides);
        self.mesh.add_cylinder(axis, base, len, r, s, c);
    }

    fn cone(&mut self, base: [f32; 3], len: f32, radii: (f32, f32), sides: u32, c: Rgba) {
        let s = self.sides(sides);
        self.mesh.add_frustum(Axis::Y, base, len, radii, s, c);
    }

    fn ball(&mut self, center: [f32; 3], radii: [f32; 3], slices: u32, c: Rgba) {
        let sl = (slices >> self.lod).max(4);
        let st = (sl / 2 + 1).max(3);
        self.mesh.add_sphere(center, radii, sl, st, c);
    }
}

const fn rgb(r: u8, g: u8, b: u8) -> Rgba {
    [r, g, b, 255]
}

const WOODS: [Rgba; 5] = [
    rgb(150, 111, 51),
    rgb(181, 136, 86),
    rgb(110, 72, 40),
    rgb(205, 170, 125),
    rgb(90, 60, 35),
];
const METALS: [Rgba; 4] = [
    rgb(160, 160, 165),
    rgb(60, 60, 65),
    rgb(200, 200, 205),
    rgb(35, 35, 38),
];
const FABRICS: [Rgba; 7] = [
    rgb(40, 60, 120),
    rgb(120, 30, 30),
    rgb(50, 90, 60),
    rgb(70, 70, 70),
    rgb(150, 120, 60),
    rgb(30, 30, 30),
    rgb(90, 50, 110),
];
const GREENS: [Rgba; 4] = [
    rgb(40, 110, 40),
    rgb(60, 140, 50),
    rgb(30, 90, 45),
    rgb(80, 130, 60),
];
const BOOK_COLORS: [Rgba; 9] = [
    rgb(140, 20, 20),
    rgb(20, 50, 120),
    rgb(30, 100, 40),
    rgb(200, 170, 40),
    rgb(90, 40, 100),
    rgb(30, 30, 30),
    rgb(200, 200, 190),
    rgb(160, 80, 30),
    rgb(20, 110, 120),
];
const WHITE: Rgba = rgb(235, 235, 230);
const BLACK: Rgba = rgb(25, 25, 28);
const POT: Rgba = rgb(170, 90, 50);
const SOIL: Rgba = rgb(70, 45, 25);
const LIGHT: Rgba = rgb(250, 240, 200);

/// Four vertical legs of radius `r`, `h` tall, at (±x, ±z).
fn legs(s: &mut Shape, x: f32, z: f32, h: f32, r: f32, sides: u32, c: Rgba) {
    for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        s.cyl(Axis::Y, [sx * x, 0.0, sz * z], h, r, sides, c);
    }
}

/// Every furniture definition the generators can produce (used by tests and the variety count).
#[cfg(test)]
pub(crate) fn all_keys() -> Vec<DefKey> {
    use FurnitureType::*;
    let types = [
        Desk,
        Chair,
        OfficeChair,
        Bookshelf,
        DeskLamp,
        Plant,
        Books,
        Monitor,
        Computer,
        Keyboard,
        CoffeeCup,
        Table,
        StudentDesk,
        RoundTable,
        LabBench,
        Stool,
        AuditoriumSeat,
        Whiteboard,
        FilingCabinet,
        Lectern,
        Sofa,
        TrashBin,
        CoatRack,
        Door,
        Stairs,
        Projector,
        LibraryShelf,
        FloorLamp,
        WaterCooler,
        CeilingLight,
        Phone,
    ];
    types
        .into_iter()
        .flat_map(|ty| (0..ty.variants()).map(move |variant| DefKey { ty, variant }))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_definition_has_halving_lods_ending_small() {
        let keys = all_keys();
        assert!(keys.len() >= 100, "only {} definitions", keys.len());
        for key in keys {
            let def = build_def(key, 7);
            assert!(!def.lods.is_empty());
            for pair in def.lods.windows(2) {
                assert!(
                    pair[1].triangle_count() * 2 <= pair[0].triangle_count(),
                    "{key:?}"
                );
            }
            let lowest = def.lods.last().map_or(0, MeshData::triangle_count);
            assert!(lowest <= 100, "{key:?} lowest LOD has {lowest} triangles");
            let top = def.lods[0].triangle_count();
            assert!(top >= 12, "{key:?}");
            for k in 0..3 {
                assert!(def.min[k] < def.max[k], "{key:?} is flat");
            }
        }
    }

    #[test]
    fn variants_differ_and_are_deterministic() {
        let a = build_def(
            DefKey {
                ty: FurnitureType::Chair,
                variant: 0,
            },
            1,
        );
        let b = build_def(
            DefKey {
                ty: FurnitureType::Chair,
                variant: 1,
            },
            1,
        );
        let a2 = build_def(
            DefKey {
                ty: FurnitureType::Chair,
                variant: 0,
            },
            1,
        );
        assert_eq!(a, a2);
        assert_ne!(a.lods[0], b.lods[0]);
    }
}
