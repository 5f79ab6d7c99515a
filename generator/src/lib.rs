//! Procedural furnished multi-storey buildings, written as standard glTF 2.0 binary (GLB).
//!
//! Funkhouser's thesis (§3.1.1) built Soda Hall from architects' floorplans plus furniture placed
//! by *room generators* ("the office generator places a desk against one wall, a chair in front
//! of the desk, some bookshelves against the walls…"), and gave every piece of furniture several
//! levels of detail made by *procedural* and *CSG* simplification (§3.1.3: prisms with fewer
//! sides, small shapes removed). This crate reproduces that pipeline deterministically:
//!
//! * `layout` plans storeys of corridors, rooms, stairwells, doors and windows;
//! * `structure` turns walls and slabs (with their openings) into unions of axis-aligned boxes;
//! * `furniture` holds parametric furniture generators that emit their own LODs;
//! * `rooms` holds the room generators that place furniture;
//! * `assemble` ties these together into instances of shared definitions;
//! * `glb` writes the result as GLB with `MSFT_lod` LOD chains and `extras` tags that mark
//!   walls, floors and ceilings as occluders for the cell/portal builder.
//!
//! The same [`Params`] always give the same bytes.

#![forbid(unsafe_code)]

mod assemble;
mod furniture;
mod glb;

pub use glb::without_tags;
pub use textures::with_textures;
mod layout;
mod mesh;
mod rooms;
mod structure;
mod textures;

use std::fmt;
use std::str::FromStr;

use serde::Serialize;

/// Largest accepted storey count: beyond this the GLB would exceed the 4 GiB GLB limit for the
/// wider presets anyway, so a bigger value is treated as a typo.
pub const MAX_FLOORS: u32 = 200;

/// A named building size. Presets fix the footprint (bays along the corridors, number of
/// parallel corridors) and the default storey count.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// One storey, a handful of rooms: for unit tests and CI (milliseconds).
    Tiny,
    /// Two storeys, about two thousand instances: for demos that must run end to end quickly.
    Small,
    /// Soda Hall scale (Funkhouser §3.1.4): 7 storeys, ≥ 14,000 instances, ≥ 1.4 M triangles at
    /// the highest LOD.
    Soda,
    /// At least ten times `Soda`: the out-of-core stress case.
    Mega,
}

impl Preset {
    /// All presets, smallest first.
    pub const ALL: [Preset; 4] = [Preset::Tiny, Preset::Small, Preset::Soda, Preset::Mega];

    /// The lowercase name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Tiny => "tiny",
            Preset::Small => "small",
            Preset::Soda => "soda",
            Preset::Mega => "mega",
        }
    }

    /// The storey count used when [`Params::floors`] is `None`.
    pub fn default_floors(self) -> u32 {
        layout::Footprint::of(self).storeys
    }
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Error returned when parsing an unknown preset name.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown preset {0:?} (expected tiny, small, soda or mega)")]
pub struct ParsePresetError(pub String);

impl FromStr for Preset {
    type Err = ParsePresetError;

    /// Parses `tiny`, `small`, `soda` or `mega` (case-insensitive), so clap can use it as a
    /// value parser.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| ParsePresetError(s.to_owned()))
    }
}

/// What to generate. Equal parameters give byte-identical output.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Params {
    /// The building size.
    pub preset: Preset,
    /// Seed of the ChaCha8 generator that drives every random choice (room mix, furniture
    /// variants, placement jitter).
    pub seed: u64,
    /// Overrides the preset's storey count (1..=[`MAX_FLOORS`]).
    pub floors: Option<u32>,
}

/// Progress report passed to the caller's callback: `done` out of `total` steps (one step per
/// storey, plus one for writing the GLB).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Progress {
    /// Steps finished.
    pub done: u64,
    /// Steps in all.
    pub total: u64,
}

/// Why generation failed.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    /// `floors` was 0 or larger than [`MAX_FLOORS`].
    #[error("invalid storey count {0}: expected 1..={MAX_FLOORS}")]
    InvalidFloors(u32),
    /// The binary chunk would not fit the 32-bit lengths of the GLB container.
    #[error("the building is too large for one GLB file ({0} bytes of binary data)")]
    TooLarge(u64),
    /// Serialising the glTF JSON failed.
    #[error("cannot serialise glTF JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// Assembling the GLB container failed.
    #[error("cannot write GLB: {0}")]
    Glb(#[from] gltf::Error),
    /// Painting or placing the textured materials failed.
    #[error("cannot add textures: {0}")]
    Texture(String),
}

/// The kind of a room; drives which room generator furnishes it (Funkhouser §3.1.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RoomKind {
    /// One- or two-person office: desks, chairs, lamps, bookshelves, plants.
    Office,
    /// Laboratory: benches with computers and stools.
    Lab,
    /// Classroom: rows of desks facing a whiteboard.
    Classroom,
    /// Conference room: a table with chairs around it, a whiteboard, a projector.
    Conference,
    /// Auditorium: rows of seats facing a lectern.
    Auditorium,
    /// Library: rows of double-sided bookshelves and reading tables.
    Library,
    /// Corridor (also the short passages that connect parallel corridors).
    Corridor,
    /// Stairwell: a flight of stairs through openings in the floor and ceiling slabs.
    Stairwell,
}

impl RoomKind {
    /// The lowercase name used in glTF `extras` (`"room": "office"`).
    pub fn name(self) -> &'static str {
        match self {
            RoomKind::Office => "office",
            RoomKind::Lab => "lab",
            RoomKind::Classroom => "classroom",
            RoomKind::Conference => "conference",
            RoomKind::Auditorium => "auditorium",
            RoomKind::Library => "library",
            RoomKind::Corridor => "corridor",
            RoomKind::Stairwell => "stairwell",
        }
    }
}

impl fmt::Display for RoomKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A room: its free interior volume (between wall faces, floor top and ceiling bottom), in
/// metres, Y up.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Room {
    /// Unique id, also written as `room_id` in the `extras` of nodes belonging to the room.
    pub id: u32,
    /// What kind of room it is.
    pub kind: RoomKind,
    /// Storey index, 0 = ground floor.
    pub storey: u32,
    /// Minimum corner of the interior.
    pub min: [f32; 3],
    /// Maximum corner of the interior.
    pub max: [f32; 3],
}

/// An opening that connects two rooms: a door in a wall, or the opening in the slabs through
/// which a flight of stairs joins two stairwells on consecutive storeys. Doors are the ground
/// truth for reachability tests and for checking portals found by the builder.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Door {
    /// Ids of the two rooms joined (the lower id is not necessarily first).
    pub rooms: (u32, u32),
    /// Minimum corner of the opening's box.
    pub min: [f32; 3],
    /// Maximum corner of the opening's box.
    pub max: [f32; 3],
}

/// Counts describing the generated model, comparable with Funkhouser's Table 3.1.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Stats {
    /// Storeys.
    pub storeys: u32,
    /// Rooms, including corridors and stairwells.
    pub rooms: u32,
    /// Scene nodes that have a mesh (walls, slabs and furniture instances).
    pub instances: u64,
    /// Distinct object definitions: distinct structural meshes plus furniture definitions
    /// (a furniture definition with several LODs counts once).
    pub definitions: u64,
    /// Distinct furniture definitions (Soda Hall had 129 unique pieces of furniture).
    pub furniture_definitions: u64,
    /// Sum over instances of the triangles of their highest LOD.
    pub triangles_highest: u64,
    /// Sum over instances of the triangles of all their LODs.
    pub triangles_all_lods: u64,
}

/// A generated building: the GLB bytes plus the ground truth the builder's output can be
/// checked against.
#[derive(Clone, Debug, PartialEq)]
pub struct Building {
    /// The glTF 2.0 binary file.
    pub glb: Vec<u8>,
    /// Summary counts.
    pub stats: Stats,
    /// Every room, ordered by id.
    pub rooms: Vec<Room>,
    /// Every door and stair opening.
    pub doors: Vec<Door>,
}

/// Generates the building described by `params`, calling `progress` after each storey and once
/// more when the GLB is written.
pub fn generate(
    params: &Params,
    progress: &mut dyn FnMut(Progress),
) -> Result<Building, GenerateError> {
    let mut footprint = layout::Footprint::of(params.preset);
    if let Some(floors) = params.floors {
        if floors == 0 || floors > MAX_FLOORS {
            return Err(GenerateError::InvalidFloors(floors));
        }
        footprint.storeys = floors;
    }
    let total = u64::from(footprint.storeys) + 1;
    let scene = assemble::assemble(&footprint, params.seed, &mut |done| {
        progress(Progress { done, total })
    });
    let glb = glb::write(&scene)?;
    progress(Progress { done: total, total });
    Ok(Building {
        glb,
        stats: scene.stats(),
        rooms: scene.rooms,
        doors: scene.doors,
    })
}
