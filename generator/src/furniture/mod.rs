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

use std::collections::BTreeMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::layout::{BAY, STAIR_RUN, STOREY_HEIGHT, WALL};
use crate::mesh::{Axis, MeshData, Rgba};

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

fn desk(p: &mut Params, s: &mut Shape) {
    let (w, d, h) = (p.f(1.2, 1.8), p.f(0.65, 0.85), p.f(0.72, 0.76));
    let (wood, metal) = (p.pick(&WOODS), p.pick(&METALS));
    let pedestal = p.chance(0.6);
    let sides = p.pick(&[8, 12, 16]);
    let drawers = p.n(2, 4);
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, h - 0.03, -hd], [hw, h, hd], wood);
    if pedestal {
        let px = hw - 0.42;
        s.bx(
            [px, 0.02, -hd + 0.02],
            [hw - 0.02, h - 0.03, hd - 0.04],
            wood,
        );
        let dh = (h - 0.08) / drawers as f32;
        for k in 0..drawers {
            let y0 = 0.04 + dh * k as f32;
            if s.medium() {
                s.bx(
                    [px + 0.02, y0, hd - 0.04],
                    [hw - 0.04, y0 + dh - 0.02, hd - 0.02],
                    wood,
                );
            }
            if s.fine() {
                let y = y0 + dh / 2.0;
                s.cyl(Axis::X, [px + 0.13, y, hd - 0.005], 0.14, 0.008, 8, metal);
            }
        }
        for z in [-hd + 0.05, hd - 0.05] {
            s.cyl(Axis::Y, [-hw + 0.05, 0.0, z], h - 0.03, 0.025, sides, metal);
        }
    } else {
        legs(s, hw - 0.05, hd - 0.05, h - 0.03, 0.025, sides, metal);
    }
    if s.medium() {
        s.bx(
            [-hw + 0.06, 0.3, -hd + 0.02],
            [hw - 0.06, h - 0.03, -hd + 0.04],
            wood,
        );
    }
}

fn chair(p: &mut Params, s: &mut Shape) {
    let (sw, sd, sh) = (p.f(0.42, 0.5), p.f(0.42, 0.5), p.f(0.43, 0.47));
    let bh = p.f(0.35, 0.5);
    let r = p.f(0.014, 0.022);
    let sides = p.pick(&[6, 8]);
    let (frame, seat) = (
        p.pick(&[WOODS[0], WOODS[2], METALS[1], METALS[2]]),
        p.pick(&FABRICS),
    );
    let slats = p.n(3, 5);
    let arms = p.chance(0.35);
    let (hw, hd) = (sw / 2.0, sd / 2.0);
    legs(s, hw - 0.03, hd - 0.03, sh - 0.04, r, sides, frame);
    s.bx([-hw, sh - 0.04, -hd], [hw, sh, hd], frame);
    if s.fine() {
        s.bx(
            [-hw + 0.02, sh, -hd + 0.02],
            [hw - 0.02, sh + 0.03, hd - 0.02],
            seat,
        );
        for x in [-hw + 0.02, hw - 0.04] {
            s.bx([x, 0.14, -hd + 0.03], [x + 0.02, 0.16, hd - 0.03], frame);
        }
    }
    for x in [-hw + 0.01, hw - 0.05] {
        s.bx([x, sh, -hd + 0.01], [x + 0.04, sh + bh, -hd + 0.05], frame);
    }
    let back_z = [-hd + 0.015, -hd + 0.045];
    if s.fine() {
        let pitch = (sw - 0.1) / slats as f32;
        for k in 0..slats {
            let x0 = -hw + 0.06 + pitch * k as f32;
            s.bx(
                [x0, sh + 0.08, back_z[0]],
                [x0 + pitch * 0.6, sh + bh - 0.08, back_z[1]],
                seat,
            );
        }
        s.bx(
            [-hw + 0.03, sh + bh - 0.08, back_z[0]],
            [hw - 0.03, sh + bh, back_z[1]],
            frame,
        );
    } else {
        s.bx(
            [-hw + 0.03, sh + 0.08, back_z[0]],
            [hw - 0.03, sh + bh, back_z[1]],
            seat,
        );
    }
    if arms && s.medium() {
        for x in [-hw - 0.02, hw - 0.02] {
            s.bx(
                [x, sh + 0.2, -hd + 0.03],
                [x + 0.04, sh + 0.23, hd - 0.05],
                frame,
            );
            s.cyl(Axis::Y, [x + 0.02, sh, hd - 0.08], 0.2, 0.012, sides, frame);
        }
    }
}

fn office_chair(p: &mut Params, s: &mut Shape) {
    let (sw, sh, bh) = (p.f(0.46, 0.54), p.f(0.44, 0.5), p.f(0.4, 0.65));
    let (fabric, metal) = (p.pick(&FABRICS), p.pick(&METALS));
    let arms = p.chance(0.6);
    let hw = sw / 2.0;
    s.bx([-0.3, 0.05, -0.03], [0.3, 0.09, 0.03], metal);
    s.bx([-0.03, 0.05, -0.3], [0.03, 0.09, 0.3], metal);
    for (x, z) in [(-0.28, 0.0), (0.28, 0.0), (0.0, -0.28), (0.0, 0.28)] {
        if s.fine() {
            s.ball([x, 0.025, z], [0.025; 3], 6, BLACK);
        } else if s.medium() {
            s.cyl(Axis::X, [x - 0.015, 0.025, z], 0.03, 0.025, 8, BLACK);
        }
    }
    s.cyl(Axis::Y, [0.0, 0.09, 0.0], sh - 0.17, 0.03, 10, metal);
    s.bx([-0.12, sh - 0.1, -0.12], [0.12, sh - 0.08, 0.12], metal);
    s.bx([-hw, sh - 0.08, -hw], [hw, sh, hw], fabric);
    if s.fine() {
        s.cyl(Axis::X, [-hw, sh - 0.02, hw - 0.03], sw, 0.03, 12, fabric);
    }
    if s.medium() {
        s.bx(
            [-0.03, sh - 0.05, -hw - 0.06],
            [0.03, sh + 0.2, -hw - 0.02],
            metal,
        );
    }
    s.bx(
        [-hw + 0.03, sh + 0.1, -hw - 0.1],
        [hw - 0.03, sh + bh, -hw - 0.03],
        fabric,
    );
    if arms && s.medium() {
        for x in [-hw - 0.04, hw] {
            s.bx([x + 0.01, sh, -0.05], [x + 0.03, sh + 0.2, 0.0], metal);
            s.bx([x, sh + 0.2, -0.15], [x + 0.04, sh + 0.23, 0.12], BLACK);
        }
    }
}

/// Books standing on a shelf: `(x offset, width, height, colour)`, drawn once per definition.
fn shelf_books(p: &mut Params, width: f32, max_h: f32, count: u32) -> Vec<(f32, f32, f32, Rgba)> {
    let mut books = Vec::new();
    let mut x = 0.01;
    for _ in 0..count {
        let bw = p.f(0.03, 0.075);
        let bh = p.f(0.55, 0.95) * max_h;
        let c = p.pick(&BOOK_COLORS);
        if x + bw > width - 0.01 {
            break;
        }
        books.push((x, bw, bh, c));
        x += bw + p.f(0.0, 0.01);
    }
    books
}

/// Books of one shelf as boxes (fine) or one block of their average colour (medium).
fn place_books(s: &mut Shape, books: &[(f32, f32, f32, Rgba)], x0: f32, y: f32, z: [f32; 2]) {
    if s.fine() {
        for &(x, w, h, c) in books {
            s.bx([x0 + x, y, z[0]], [x0 + x + w, y + h, z[1]], c);
        }
    } else if s.medium()
        && let (Some(first), Some(last)) = (books.first(), books.last())
    {
        let mean_h = books.iter().map(|b| b.2).sum::<f32>() / books.len() as f32;
        let mut m = MeshData::default();
        for b in books {
            m.add_box([0.0; 3], [0.01; 3], b.3);
        }
        let x1 = x0 + last.0 + last.1;
        s.bx(
            [x0 + first.0, y, z[0]],
            [x1, y + mean_h, z[1]],
            m.average_color(),
        );
    }
}

fn bookshelf(p: &mut Params, s: &mut Shape) {
    let (w, d, h) = (p.f(0.8, 1.2), p.f(0.3, 0.4), p.f(1.2, 2.1));
    let wood = p.pick(&WOODS);
    let levels = ((h - 0.1) / 0.36).floor().max(1.0) as u32;
    let pitch = (h - 0.1) / levels as f32;
    let rows: Vec<_> = (0..levels)
        .map(|_| shelf_books(p, w - 0.04, pitch - 0.04, 14))
        .collect();
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, 0.0, -hd], [-hw + 0.02, h, hd], wood);
    s.bx([hw - 0.02, 0.0, -hd], [hw, h, hd], wood);
    s.bx([-hw, h - 0.02, -hd], [hw, h, hd], wood);
    s.bx([-hw + 0.02, 0.0, -hd + 0.02], [hw - 0.02, 0.08, hd], wood);
    if s.medium() {
        s.bx(
            [-hw + 0.02, 0.08, -hd],
            [hw - 0.02, h - 0.02, -hd + 0.01],
            wood,
        );
    }
    for (k, books) in rows.iter().enumerate() {
        let y = 0.08 + pitch * k as f32;
        if k > 0 && s.medium() {
            s.bx([-hw + 0.02, y - 0.02, -hd + 0.01], [hw - 0.02, y, hd], wood);
        }
        place_books(s, books, -hw + 0.02, y, [-hd + 0.03, hd - 0.03]);
    }
}

fn library_shelf(p: &mut Params, s: &mut Shape) {
    let (w, h) = (p.f(0.9, 1.2), p.f(1.8, 2.2));
    let d = 0.6;
    let wood = p.pick(&WOODS);
    let levels = ((h - 0.1) / 0.36).floor().max(1.0) as u32;
    let pitch = (h - 0.1) / levels as f32;
    let rows: Vec<_> = (0..levels * 2)
        .map(|_| shelf_books(p, w - 0.04, pitch - 0.04, 12))
        .collect();
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, 0.0, -hd], [-hw + 0.02, h, hd], wood);
    s.bx([hw - 0.02, 0.0, -hd], [hw, h, hd], wood);
    s.bx([-hw, h - 0.02, -hd], [hw, h, hd], wood);
    s.bx([-hw + 0.02, 0.0, -hd], [hw - 0.02, 0.08, hd], wood);
    s.bx([-hw + 0.02, 0.08, -0.01], [hw - 0.02, h - 0.02, 0.01], wood);
    for k in 0..levels {
        let y = 0.08 + pitch * k as f32;
        if k > 0 && s.medium() {
            s.bx([-hw + 0.02, y - 0.02, -hd], [hw - 0.02, y, hd], wood);
        }
        let (a, b) = (&rows[2 * k as usize], &rows[2 * k as usize + 1]);
        place_books(s, a, -hw + 0.02, y, [0.02, hd - 0.03]);
        place_books(s, b, -hw + 0.02, y, [-hd + 0.03, -0.02]);
    }
}

fn desk_lamp(p: &mut Params, s: &mut Shape) {
    let (metal, shade) = (
        p.pick(&METALS),
        p.pick(&[rgb(30, 90, 40), rgb(200, 40, 30), BLACK, WHITE]),
    );
    let (h, reach) = (p.f(0.3, 0.45), p.f(0.15, 0.28));
    let sides = p.pick(&[8, 12, 16]);
    let x0 = -reach / 2.0;
    s.cyl(Axis::Y, [x0, 0.0, 0.0], 0.02, 0.075, sides, metal);
    s.cyl(Axis::Y, [x0, 0.02, 0.0], h, 0.01, 8, metal);
    s.cyl(Axis::X, [x0, h, 0.0], reach, 0.01, 8, metal);
    if s.fine() {
        s.ball([x0, h, 0.0], [0.018; 3], 6, metal);
    }
    s.cone(
        [x0 + reach, h - 0.14, 0.0],
        0.13,
        (0.09, 0.025),
        sides,
        shade,
    );
    if s.fine() {
        s.ball([x0 + reach, h - 0.11, 0.0], [0.03; 3], 6, LIGHT);
    }
}

fn floor_lamp(p: &mut Params, s: &mut Shape) {
    let (metal, shade) = (
        p.pick(&METALS),
        p.pick(&[WHITE, rgb(220, 200, 150), rgb(150, 40, 30)]),
    );
    let h = p.f(1.4, 1.8);
    s.cyl(Axis::Y, [0.0, 0.0, 0.0], 0.03, 0.16, 20, metal);
    s.cyl(Axis::Y, [0.0, 0.03, 0.0], h - 0.3, 0.015, 8, metal);
    s.cone([0.0, h - 0.3, 0.0], 0.3, (0.22, 0.13), 20, shade);
    if s.fine() {
        s.ball([0.0, h - 0.2, 0.0], [0.04; 3], 8, LIGHT);
    }
}

fn plant(p: &mut Params, s: &mut Shape) {
    let tall = p.chance(0.6);
    let scale = if tall { p.f(1.0, 1.6) } else { p.f(0.35, 0.5) };
    let pot = p.pick(&[POT, WHITE, BLACK, rgb(120, 120, 140)]);
    let green = p.pick(&GREENS);
    let blobs = p.n(3, 5);
    let r = 0.16 * scale.sqrt();
    let pot_h = 0.3 * scale.sqrt();
    let offsets: Vec<[f32; 3]> = (0..blobs)
        .map(|_| {
            [
                p.f(-0.5, 0.5) * r,
                p.f(0.45, 0.95) * scale,
                p.f(-0.5, 0.5) * r,
            ]
        })
        .collect();
    let sizes: Vec<f32> = (0..blobs).map(|_| p.f(0.8, 1.3) * r).collect();
    s.cone([0.0, 0.0, 0.0], pot_h, (r * 0.75, r), 12, pot);
    if s.fine() {
        s.cyl(Axis::Y, [0.0, pot_h, 0.0], 0.01, r * 0.9, 12, SOIL);
    }
    if s.fine() {
        s.cyl(
            Axis::Y,
            [0.0, pot_h, 0.0],
            scale * 0.6,
            0.012,
            6,
            rgb(90, 70, 40),
        );
    }
    if s.medium() {
        for (o, size) in offsets.iter().zip(&sizes) {
            s.ball(
                [o[0], pot_h + o[1] * 0.8, o[2]],
                [*size, *size * 1.1, *size],
                8,
                green,
            );
        }
    } else {
        let top = pot_h + scale * 0.6;
        s.ball([0.0, top, 0.0], [r * 1.4, scale * 0.45, r * 1.4], 4, green);
    }
}

fn books(p: &mut Params, s: &mut Shape) {
    let count = p.n(3, 6);
    let flat = p.chance(0.5);
    let sizes: Vec<(f32, f32, f32, Rgba)> = (0..count)
        .map(|_| {
            (
                p.f(0.02, 0.05),
                p.f(0.18, 0.28),
                p.f(0.13, 0.2),
                p.pick(&BOOK_COLORS),
            )
        })
        .collect();
    let mut at = 0.0;
    for &(t, h, d, c) in &sizes {
        if !s.medium() {
            break;
        }
        if flat {
            s.bx([-h / 2.0, at, -d / 2.0], [h / 2.0, at + t, d / 2.0], c);
        } else {
            s.bx([at - 0.1, 0.0, -d / 2.0], [at - 0.1 + t, h, d / 2.0], c);
        }
        at += t;
    }
    if !s.medium() {
        let (t, h, d, c) = sizes[0];
        s.bx(
            [-h / 2.0, 0.0, -d / 2.0],
            [h / 2.0, t * count as f32, d / 2.0],
            c,
        );
    }
}

fn monitor(p: &mut Params, s: &mut Shape) {
    let (w, h) = (p.f(0.45, 0.6), p.f(0.3, 0.4));
    let body = p.pick(&[BLACK, rgb(200, 200, 195), METALS[1]]);
    let hw = w / 2.0;
    s.cyl(Axis::Y, [0.0, 0.0, 0.0], 0.015, 0.1, 12, body);
    s.cyl(Axis::Y, [0.0, 0.015, -0.03], 0.12, 0.02, 8, body);
    s.bx([-hw, 0.12, -0.05], [hw, 0.12 + h, 0.0], body);
    if s.medium() {
        s.bx(
            [-hw + 0.015, 0.135, 0.0],
            [hw - 0.015, 0.105 + h, 0.005],
            rgb(20, 30, 45),
        );
    }
    if s.fine() {
        for k in 0..3 {
            let x = hw - 0.05 - 0.03 * k as f32;
            s.cyl(Axis::Z, [x, 0.127, 0.0], 0.006, 0.005, 8, rgb(90, 200, 90));
        }
    }
}

fn computer(p: &mut Params, s: &mut Shape) {
    let (h, d) = (p.f(0.36, 0.46), p.f(0.4, 0.5));
    let body = p.pick(&[BLACK, rgb(200, 200, 195), METALS[0]]);
    s.bx([-0.09, 0.02, -d / 2.0], [0.09, h, d / 2.0], body);
    if s.medium() {
        s.bx(
            [-0.07, h - 0.1, d / 2.0],
            [0.07, h - 0.05, d / 2.0 + 0.005],
            METALS[1],
        );
        s.bx(
            [-0.07, h - 0.17, d / 2.0],
            [0.07, h - 0.12, d / 2.0 + 0.005],
            METALS[1],
        );
    }
    if s.fine() {
        s.cyl(
            Axis::Z,
            [0.0, h - 0.25, d / 2.0],
            0.008,
            0.012,
            12,
            rgb(90, 200, 90),
        );
        for (x, z) in [(-0.07, -0.15), (0.07, -0.15), (-0.07, 0.15), (0.07, 0.15)] {
            s.cyl(Axis::Y, [x, 0.0, z * d * 2.0], 0.02, 0.012, 8, BLACK);
        }
    }
}

fn keyboard(p: &mut Params, s: &mut Shape) {
    let w = p.f(0.42, 0.48);
    let keys = p.pick(&[BLACK, rgb(210, 210, 200)]);
    let hw = w / 2.0;
    s.bx([-hw, 0.0, -0.075], [hw, 0.02, 0.075], METALS[1]);
    for row in 0..5 {
        let z = -0.06 + 0.025 * row as f32;
        if s.fine() {
            for seg in 0..2 {
                let x = -hw + 0.02 + (w - 0.04) / 2.0 * seg as f32;
                s.bx(
                    [x, 0.02, z],
                    [x + (w - 0.04) / 2.0 - 0.01, 0.03, z + 0.02],
                    keys,
                );
            }
        } else if s.medium() {
            s.bx([-hw + 0.02, 0.02, z], [hw - 0.02, 0.03, z + 0.02], keys);
        }
    }
}

fn coffee_cup(p: &mut Params, s: &mut Shape) {
    let c = p.pick(&[WHITE, rgb(180, 40, 40), rgb(40, 80, 160), BLACK]);
    let h = p.f(0.08, 0.11);
    s.cyl(Axis::Y, [0.0, 0.0, 0.0], h, 0.04, 16, c);
    if s.fine() {
        s.bx([0.04, h * 0.2, -0.005], [0.065, h * 0.3, 0.005], c);
        s.bx([0.055, h * 0.2, -0.005], [0.065, h * 0.8, 0.005], c);
        s.bx([0.04, h * 0.7, -0.005], [0.065, h * 0.8, 0.005], c);
    }
}

fn table(p: &mut Params, s: &mut Shape) {
    let (w, d, h) = (p.f(1.6, 2.8), p.f(0.9, 1.2), p.f(0.72, 0.76));
    let (top, leg) = (p.pick(&WOODS), p.pick(&[WOODS[2], METALS[0], METALS[3]]));
    let sides = p.pick(&[12, 16, 20]);
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, h - 0.04, -hd], [hw, h, hd], top);
    legs(s, hw - 0.08, hd - 0.08, h - 0.04, 0.03, sides, leg);
    if w > 2.2 {
        for z in [-hd + 0.08, hd - 0.08] {
            s.cyl(Axis::Y, [0.0, 0.0, z], h - 0.04, 0.03, sides, leg);
        }
    }
    if s.fine() {
        s.bx(
            [-hw + 0.1, h - 0.12, -hd + 0.07],
            [hw - 0.1, h - 0.04, -hd + 0.09],
            top,
        );
        s.bx(
            [-hw + 0.1, h - 0.12, hd - 0.09],
            [hw - 0.1, h - 0.04, hd - 0.07],
            top,
        );
        s.bx(
            [-hw + 0.07, h - 0.12, -hd + 0.1],
            [-hw + 0.09, h - 0.04, hd - 0.1],
            top,
        );
        s.bx(
            [hw - 0.09, h - 0.12, -hd + 0.1],
            [hw - 0.07, h - 0.04, hd - 0.1],
            top,
        );
    }
}

fn student_desk(p: &mut Params, s: &mut Shape) {
    let (w, d, h) = (p.f(1.0, 1.3), p.f(0.5, 0.6), p.f(0.72, 0.76));
    let (top, metal) = (p.pick(&WOODS), p.pick(&METALS));
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, h - 0.03, -hd], [hw, h, hd], top);
    legs(s, hw - 0.04, hd - 0.04, h - 0.03, 0.018, 8, metal);
    if s.medium() {
        s.bx(
            [-hw + 0.05, h - 0.2, -hd + 0.02],
            [hw - 0.05, h - 0.18, hd - 0.1],
            metal,
        );
    }
    if s.fine() {
        for x in [-hw + 0.04, hw - 0.04] {
            s.cyl(Axis::Z, [x, 0.12, -hd + 0.04], d - 0.08, 0.01, 8, metal);
        }
    }
}

fn round_table(p: &mut Params, s: &mut Shape) {
    let (r, h) = (p.f(0.5, 0.75), p.f(0.72, 0.76));
    let (top, metal) = (p.pick(&WOODS), p.pick(&METALS));
    s.cyl(Axis::Y, [0.0, h - 0.04, 0.0], 0.04, r, 32, top);
    s.cyl(Axis::Y, [0.0, 0.04, 0.0], h - 0.08, 0.05, 12, metal);
    if s.medium() {
        s.cyl(Axis::Y, [0.0, 0.0, 0.0], 0.04, r * 0.6, 16, metal);
    } else {
        s.bx([-r * 0.5, 0.0, -r * 0.5], [r * 0.5, 0.04, r * 0.5], metal);
    }
    if s.fine() {
        s.cyl(Axis::Y, [0.0, h - 0.1, 0.0], 0.06, 0.15, 12, metal);
    }
}

fn lab_bench(p: &mut Params, s: &mut Shape) {
    let (w, d, h) = (p.f(1.8, 2.4), p.f(0.7, 0.8), p.f(0.88, 0.92));
    let (body, metal) = (
        p.pick(&[WOODS[3], rgb(200, 200, 190), rgb(150, 170, 190)]),
        p.pick(&METALS),
    );
    let rack = p.chance(0.6);
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, h - 0.04, -hd], [hw, h, hd], BLACK);
    for x0 in [-hw + 0.02, hw - 0.62] {
        s.bx([x0, 0.1, -hd + 0.05], [x0 + 0.6, h - 0.04, hd - 0.05], body);
        if s.medium() {
            s.bx(
                [x0 + 0.02, 0.0, -hd + 0.1],
                [x0 + 0.58, 0.1, hd - 0.1],
                BLACK,
            );
            s.bx(
                [x0 + 0.02, 0.12, hd - 0.05],
                [x0 + 0.29, h - 0.06, hd - 0.04],
                body,
            );
            s.bx(
                [x0 + 0.31, 0.12, hd - 0.05],
                [x0 + 0.58, h - 0.06, hd - 0.04],
                body,
            );
        }
        if s.fine() {
            for x in [x0 + 0.25, x0 + 0.35] {
                s.cyl(Axis::Y, [x, h - 0.3, hd - 0.035], 0.12, 0.007, 8, metal);
            }
        }
    }
    if s.medium() {
        s.bx(
            [-hw + 0.62, h - 0.2, -hd + 0.05],
            [hw - 0.62, h - 0.04, -hd + 0.07],
            body,
        );
    }
    if rack && s.medium() {
        for x in [-hw + 0.1, hw - 0.1] {
            s.cyl(Axis::Y, [x, h, -hd + 0.1], 0.7, 0.015, 12, metal);
        }
        s.bx(
            [-hw + 0.05, h + 0.55, -hd + 0.02],
            [hw - 0.05, h + 0.57, -hd + 0.3],
            body,
        );
    }
    if s.fine() {
        for x in [-0.5, 0.5] {
            s.cyl(Axis::Y, [x * hw, h, -hd + 0.08], 0.2, 0.012, 8, metal);
            s.cyl(
                Axis::Z,
                [x * hw, h + 0.18, -hd + 0.08],
                0.1,
                0.008,
                8,
                metal,
            );
        }
    }
}

fn stool(p: &mut Params, s: &mut Shape) {
    let (h, r) = (p.f(0.55, 0.7), p.f(0.15, 0.19));
    let (seat, metal) = (p.pick(&FABRICS), p.pick(&METALS));
    s.cyl(Axis::Y, [0.0, h - 0.04, 0.0], 0.04, r, 16, seat);
    legs(s, r * 0.65, r * 0.65, h - 0.04, 0.012, 6, metal);
    if s.fine() {
        let a = r * 0.65;
        s.bx([-a, 0.2, a - 0.01], [a, 0.22, a + 0.01], metal);
        s.bx([-a, 0.2, -a - 0.01], [a, 0.22, -a + 0.01], metal);
    }
}

fn auditorium_seat(p: &mut Params, s: &mut Shape) {
    let w = p.f(0.5, 0.56);
    let (fabric, frame) = (p.pick(&FABRICS), p.pick(&[METALS[1], METALS[3], WOODS[2]]));
    let tablet = p.chance(0.5);
    let hw = w / 2.0;
    s.bx([-0.05, 0.0, -0.2], [0.05, 0.42, -0.1], frame);
    s.bx([-hw + 0.03, 0.38, -0.2], [hw - 0.03, 0.45, 0.22], fabric);
    s.bx([-hw + 0.03, 0.45, -0.28], [hw - 0.03, 0.95, -0.2], fabric);
    for x in [-hw, hw - 0.03] {
        s.bx([x, 0.0, -0.25], [x + 0.03, 0.62, 0.15], frame);
        if s.fine() {
            s.cyl(Axis::Z, [x + 0.015, 0.64, -0.25], 0.4, 0.025, 12, frame);
        }
    }
    if s.medium() {
        s.bx([-hw + 0.05, 0.45, -0.18], [hw - 0.05, 0.5, 0.2], fabric);
        s.bx([-hw + 0.05, 0.5, -0.2], [hw - 0.05, 0.9, -0.15], fabric);
    }
    if tablet && s.fine() {
        s.bx([hw - 0.03, 0.62, -0.25], [hw + 0.02, 0.64, 0.05], WOODS[1]);
    }
}

fn whiteboard(p: &mut Params, s: &mut Shape) {
    let (w, h) = (p.f(1.8, 3.6), p.f(1.0, 1.2));
    let frame = p.pick(&METALS);
    let hw = w / 2.0;
    let y0 = 0.9;
    s.bx([-hw, y0, -0.025], [hw, y0 + h, 0.0], WHITE);
    if s.medium() {
        s.bx(
            [-hw - 0.02, y0 - 0.02, -0.025],
            [hw + 0.02, y0, 0.01],
            frame,
        );
        s.bx(
            [-hw - 0.02, y0 + h, -0.025],
            [hw + 0.02, y0 + h + 0.02, 0.01],
            frame,
        );
        s.bx([-hw - 0.02, y0, -0.025], [-hw, y0 + h, 0.01], frame);
        s.bx([hw, y0, -0.025], [hw + 0.02, y0 + h, 0.01], frame);
        s.bx(
            [-hw * 0.6, y0 - 0.04, -0.025],
            [hw * 0.6, y0 - 0.02, 0.07],
            frame,
        );
    }
    if s.fine() {
        for (k, c) in [BLACK, rgb(200, 30, 30), rgb(30, 60, 200)]
            .into_iter()
            .enumerate()
        {
            let x = -hw * 0.5 + 0.15 * k as f32;
            s.cyl(Axis::X, [x, y0 - 0.01, 0.03], 0.12, 0.008, 8, c);
        }
        s.bx(
            [hw * 0.3, y0 - 0.02, 0.01],
            [hw * 0.3 + 0.14, y0 + 0.02, 0.06],
            BLACK,
        );
    }
}

fn filing_cabinet(p: &mut Params, s: &mut Shape) {
    let h = p.f(0.7, 1.35);
    let body = p.pick(&[METALS[0], METALS[2], rgb(120, 130, 110), WOODS[1]]);
    let drawers = ((h / 0.33).round() as u32).max(2);
    s.bx([-0.225, 0.0, -0.3], [0.225, h, 0.28], body);
    let dh = (h - 0.04) / drawers as f32;
    for k in 0..drawers {
        let y = 0.02 + dh * k as f32;
        if s.medium() {
            s.bx([-0.21, y + 0.01, 0.28], [0.21, y + dh - 0.01, 0.3], body);
        }
        if s.fine() {
            s.cyl(
                Axis::X,
                [-0.07, y + dh * 0.7, 0.31],
                0.14,
                0.008,
                8,
                METALS[3],
            );
            s.bx(
                [-0.04, y + dh * 0.4, 0.3],
                [0.04, y + dh * 0.5, 0.305],
                WHITE,
            );
        }
    }
}

fn lectern(p: &mut Params, s: &mut Shape) {
    let wood = p.pick(&WOODS);
    let h = p.f(1.05, 1.2);
    s.bx([-0.3, 0.0, -0.22], [0.3, 0.05, 0.22], wood);
    s.bx([-0.25, 0.05, -0.18], [0.25, h - 0.05, 0.18], wood);
    s.bx([-0.32, h - 0.05, -0.25], [0.32, h, 0.25], wood);
    if s.medium() {
        s.bx([-0.32, h, -0.25], [0.32, h + 0.03, -0.22], wood);
        s.bx([-0.23, 0.5, 0.18], [0.23, 0.52, 0.22], wood);
    }
    if s.fine() {
        s.cyl(Axis::Y, [0.2, h, 0.1], 0.35, 0.006, 8, METALS[3]);
        s.ball([0.2, h + 0.37, 0.1], [0.02; 3], 8, BLACK);
    }
}

fn sofa(p: &mut Params, s: &mut Shape) {
    let w = p.f(1.5, 2.2);
    let fabric = p.pick(&FABRICS);
    let cushions = p.n(2, 3);
    let (hw, d) = (w / 2.0, 0.85);
    let hd = d / 2.0;
    s.bx([-hw + 0.15, 0.1, -hd], [hw - 0.15, 0.4, hd], fabric);
    s.bx([-hw + 0.15, 0.4, -hd], [hw - 0.15, 0.85, -hd + 0.2], fabric);
    for x in [-hw, hw - 0.15] {
        s.bx([x, 0.1, -hd], [x + 0.15, 0.5, hd], fabric);
        s.cyl(Axis::Z, [x + 0.075, 0.55, -hd], d, 0.09, 16, fabric);
    }
    if s.medium() {
        let cw = (w - 0.3) / cushions as f32;
        for k in 0..cushions {
            let x = -hw + 0.15 + cw * k as f32;
            s.bx(
                [x + 0.01, 0.4, -hd + 0.2],
                [x + cw - 0.01, 0.52, hd - 0.02],
                fabric,
            );
            if s.fine() {
                s.bx(
                    [x + 0.02, 0.52, -hd + 0.2],
                    [x + cw - 0.02, 0.8, -hd + 0.3],
                    fabric,
                );
            }
        }
    }
    if s.fine() {
        legs(s, hw - 0.08, hd - 0.08, 0.1, 0.02, 8, WOODS[4]);
    }
}

fn trash_bin(p: &mut Params, s: &mut Shape) {
    let c = p.pick(&[METALS[1], rgb(40, 80, 160), rgb(60, 120, 60)]);
    let h = p.f(0.3, 0.45);
    s.cone([0.0, 0.0, 0.0], h, (0.12, 0.15), 16, c);
    if s.fine() {
        s.cyl(Axis::Y, [0.0, h, 0.0], 0.02, 0.16, 16, c);
    }
}

fn coat_rack(p: &mut Params, s: &mut Shape) {
    let c = p.pick(&[WOODS[2], METALS[3]]);
    let h = p.f(1.7, 1.9);
    s.cyl(Axis::Y, [0.0, 0.0, 0.0], 0.03, 0.2, 12, c);
    s.cyl(Axis::Y, [0.0, 0.03, 0.0], h - 0.03, 0.02, 8, c);
    if s.fine() {
        s.cyl(Axis::X, [-0.15, h - 0.15, 0.0], 0.3, 0.01, 8, c);
        s.cyl(Axis::Z, [0.0, h - 0.2, -0.15], 0.3, 0.01, 8, c);
        s.ball([0.0, h, 0.0], [0.035; 3], 8, c);
    }
}

/// A door leaf, 4.5 cm thick along X, 0.92 m wide along Z; its handles are the N-sided prisms of
/// Funkhouser's Fig. 3.6.
fn door(p: &mut Params, s: &mut Shape) {
    let (leaf, metal) = (
        p.pick(&[WOODS[1], WOODS[3], rgb(180, 180, 175)]),
        p.pick(&METALS),
    );
    let (t, w, h) = (0.045, 0.92, 2.05);
    s.bx([-t / 2.0, 0.0, -w / 2.0], [t / 2.0, h, w / 2.0], leaf);
    if s.medium() {
        for sx in [-1.0f32, 1.0] {
            let x0 = sx * t / 2.0;
            let x1 = x0 + sx * 0.006;
            let (a, b) = (x0.min(x1), x0.max(x1));
            s.bx([a, 0.2, -w / 2.0 + 0.12], [b, 0.95, w / 2.0 - 0.12], leaf);
            s.bx([a, 1.1, -w / 2.0 + 0.12], [b, 1.9, w / 2.0 - 0.12], leaf);
        }
    }
    if s.fine() {
        let z = w / 2.0 - 0.07;
        s.cyl(
            Axis::X,
            [-t / 2.0 - 0.06, 1.0, z],
            t + 0.12,
            0.025,
            12,
            metal,
        );
        for x in [-t / 2.0 - 0.06, t / 2.0 + 0.05] {
            s.cyl(Axis::Z, [x + 0.005, 1.0, z], -0.12, 0.01, 8, metal);
        }
    }
}

/// One straight flight climbing +Z by one storey height, sized for a stairwell lane.
fn stairs(_p: &mut Params, s: &mut Shape) {
    let lane = ((BAY - WALL) - 0.6) / 2.0;
    let (steps, hw) = (20u32, lane / 2.0);
    let (rise, tread) = (STOREY_HEIGHT / steps as f32, STAIR_RUN / steps as f32);
    let z0 = -STAIR_RUN / 2.0;
    let concrete = rgb(150, 150, 145);
    let rail = METALS[1];
    if s.medium() {
        for i in 0..steps {
            let z = z0 + tread * i as f32;
            let top = rise * (i + 1) as f32;
            s.bx(
                [-hw, (top - 0.25).max(0.0), z],
                [hw, top, z + tread],
                concrete,
            );
            if s.fine() {
                s.cyl(
                    Axis::Y,
                    [hw - 0.05, top, z + tread / 2.0],
                    0.9,
                    0.012,
                    8,
                    rail,
                );
                s.bx(
                    [hw - 0.07, top + 0.88, z],
                    [hw - 0.03, top + 0.92, z + tread],
                    rail,
                );
            }
        }
        if !s.fine() {
            for k in 0..4 {
                let z = z0 + STAIR_RUN / 4.0 * k as f32;
                let top = STOREY_HEIGHT / 4.0 * (k + 1) as f32;
                s.bx(
                    [hw - 0.07, top + 0.5, z],
                    [hw - 0.03, top + 0.54, z + STAIR_RUN / 4.0],
                    rail,
                );
            }
        }
    } else {
        for k in 0..5 {
            let z = z0 + STAIR_RUN / 5.0 * k as f32;
            let top = STOREY_HEIGHT / 5.0 * (k + 1) as f32;
            s.bx(
                [-hw, (top - 0.9).max(0.0), z],
                [hw, top, z + STAIR_RUN / 5.0],
                concrete,
            );
        }
    }
}

fn projector(p: &mut Params, s: &mut Shape) {
    let body = p.pick(&[rgb(210, 210, 205), METALS[1]]);
    s.bx([-0.15, 0.03, -0.17], [0.15, 0.14, 0.15], body);
    s.cyl(Axis::Z, [0.08, 0.085, 0.15], 0.03, 0.04, 16, BLACK);
    if s.fine() {
        for k in 0..4 {
            let x = -0.12 + 0.04 * k as f32;
            s.bx([x, 0.14, -0.1], [x + 0.02, 0.142, 0.05], BLACK);
        }
        for (x, z) in [(-0.12, -0.14), (0.12, -0.14), (-0.12, 0.12), (0.12, 0.12)] {
            s.cyl(Axis::Y, [x, 0.0, z], 0.03, 0.012, 8, BLACK);
        }
    }
}

fn water_cooler(p: &mut Params, s: &mut Shape) {
    let body = p.pick(&[WHITE, METALS[0]]);
    s.bx([-0.16, 0.0, -0.16], [0.16, 1.0, 0.16], body);
    s.cyl(Axis::Y, [0.0, 1.0, 0.0], 0.4, 0.13, 20, rgb(150, 190, 230));
    if s.medium() {
        s.cyl(Axis::Y, [0.0, 1.4, 0.0], 0.05, 0.05, 12, rgb(40, 80, 160));
    }
    if s.fine() {
        for x in [-0.06, 0.06] {
            s.cyl(
                Axis::Z,
                [x, 0.85, 0.16],
                0.04,
                0.012,
                8,
                if x < 0.0 {
                    rgb(40, 80, 200)
                } else {
                    rgb(200, 40, 40)
                },
            );
        }
        s.bx([-0.1, 0.6, 0.16], [0.1, 0.62, 0.24], METALS[1]);
    }
}

/// A ceiling light hanging *down* from y = 0 (placed at ceiling height): a fluorescent troffer
/// with tubes, or a round pendant.
fn ceiling_light(p: &mut Params, s: &mut Shape) {
    let pendant = p.chance(0.35);
    let frame = p.pick(&[WHITE, METALS[2], METALS[0]]);
    if pendant {
        let r = p.f(0.2, 0.3);
        s.cyl(Axis::Y, [0.0, -0.6, 0.0], 0.6, 0.006, 6, METALS[1]);
        s.cone([0.0, -0.8, 0.0], 0.2, (r, 0.05), 16, frame);
        if s.fine() {
            s.ball([0.0, -0.75, 0.0], [0.05; 3], 8, LIGHT);
        }
        return;
    }
    let (w, d) = (p.f(1.2, 1.5), p.f(0.3, 0.6));
    let tubes = p.n(2, 3);
    s.bx([-w / 2.0, -0.08, -d / 2.0], [w / 2.0, 0.0, d / 2.0], frame);
    if s.medium() {
        s.bx(
            [-w / 2.0 + 0.02, -0.09, -d / 2.0 + 0.02],
            [w / 2.0 - 0.02, -0.08, d / 2.0 - 0.02],
            LIGHT,
        );
    }
    if s.fine() {
        for k in 0..tubes {
            let z = -d / 2.0 + d * (k as f32 + 1.0) / (tubes + 1) as f32;
            s.cyl(
                Axis::X,
                [-w / 2.0 + 0.05, -0.1, z],
                w - 0.1,
                0.013,
                6,
                LIGHT,
            );
        }
    }
}

/// A desk telephone: body, handset and (finest LOD) keypad buttons.
fn phone(p: &mut Params, s: &mut Shape) {
    let c = p.pick(&[BLACK, rgb(210, 205, 190)]);
    s.bx([-0.1, 0.0, -0.1], [0.1, 0.05, 0.1], c);
    s.bx([-0.1, 0.05, -0.09], [0.1, 0.08, -0.03], c);
    if s.fine() {
        for k in 0..4 {
            let z = -0.01 + 0.025 * k as f32;
            s.bx([-0.05, 0.05, z], [0.05, 0.055, z + 0.015], METALS[0]);
        }
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
