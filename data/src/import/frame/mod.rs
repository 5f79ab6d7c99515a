//! Finding a model file's unit and up axis from its geometry ([`crate::frame`]).
//!
//! The model is cut into pieces: the connected parts of every object's triangles (vertices
//! joined where their positions are equal), so an OBJ that groups a whole building by material
//! still shows its walls, slabs, columns and chairs one by one. Then:
//!
//! - **Up**: things rest on things. Along the axis that points up, a wall, a column or a chair
//!   starts where something under it ends (its lowest point on another piece's highest, their
//!   footprints overlapping); along a horizontal axis only the walls that abut others do, and
//!   chairs stand clear of walls. The share of pieces resting so (pieces thin along the axis,
//!   slabs on walls or walls against walls, left out) is compared between Y and Z; one must beat
//!   the other by [`UP_MARGIN`], and reach [`MIN_RESTING`]. The share does not fall with the
//!   number of storeys, as a count of levels would.
//! - **Unit**: with the up axis known, the storey is the height of the pieces that rest on
//!   one piece and carry another (a wall between a floor and the slab above, a column under an
//!   arch; a gable wall or an atrium's façade rising through several storeys does not count),
//!   else the height of the walls (thin pieces standing on edge: their thinnest side
//!   horizontal, under a third of their next side). The storey (2.3–4 m), the thin pieces'
//!   thicknesses (5–50 cm) and the building's width (3 m–2 km) are read in each unit; the unit
//!   that puts them where buildings have them wins, and it must win by
//!   [`UNIT_MARGIN`] to be called found.
//!
//! A frame given on the command line is used as given; a guess that is not confident keeps
//! the format's default and says which option to give.

mod cues;

use crate::bulk::DBox;
use crate::frame::{FrameSource, LengthUnit, SourceFrame, UpAxis};
use cues::{contacts, unit_of};
use glam::{DMat4, DVec3};
use rustc_hash::FxHashMap;

/// How much larger the share of resting pieces must be along one axis than the other for it
/// to be called up.
pub const UP_MARGIN: f64 = 1.25;

/// The share of pieces that must rest on others along the up axis: a building's walls and
/// furniture stand on its floors; a spider or an engine has no floors to say which way is up.
pub const MIN_RESTING: f64 = 0.2;

/// Pieces (not thin along the axis) that must be asked for the share to say anything: a cube
/// of six faces is not a building standing on a floor.
pub const MIN_ASKED: usize = 6;

/// How much better (in log-plausibility: e-folds outside the storey, thickness and width ranges
/// of `cues.rs`) the best unit must fit than the next. Neighbouring units differ by 2.54× (cm
/// and in) or more, an e-fold of 0.93, of which the storey range's own width takes 0.55.
pub const UNIT_MARGIN: f64 = 0.45;

/// The share of the area in slabs below which a model is not read as a building, and its unit
/// not guessed from storeys and walls it does not have.
pub const MIN_SLAB_SHARE: f64 = 0.05;

/// Instances placed for the evidence at most (evenly spread over a larger model): the cues are
/// statistics, and a model of millions of instances need not be walked twice.
pub const MAX_SAMPLED: usize = 50_000;

/// What the user gave on the command line (`portico build --units cm --up z`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameOptions {
    /// The unit the file is in, whatever its geometry says.
    pub units: Option<LengthUnit>,
    /// The axis pointing up in the file, whatever its geometry says.
    pub up: Option<UpAxis>,
}

/// A connected part of an object: its box and its area, in the file's coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Piece {
    /// Bounding box.
    pub bounds: DBox,
    /// Total triangle area.
    pub area: f64,
}

impl Piece {
    /// The piece moved by `m`: its box's corners placed, its area scaled by `m`'s largest
    /// axis scale squared.
    pub fn placed(&self, m: &DMat4) -> Piece {
        let s = m.to_scale_rotation_translation().0.abs().max_element();
        self.placed_scaled(m, s)
    }

    /// [`Piece::placed`] with `m`'s largest axis scale already known.
    pub fn placed_scaled(&self, m: &DMat4, scale: f64) -> Piece {
        let mut bounds = DBox::EMPTY;
        for i in 0..8 {
            let pick = |bit: usize, axis: usize| {
                if i & bit == 0 {
                    self.bounds.min[axis]
                } else {
                    self.bounds.max[axis]
                }
            };
            bounds.include(m.transform_point3(DVec3::new(pick(1, 0), pick(2, 1), pick(4, 2))));
        }
        Piece {
            bounds,
            area: self.area * scale * scale,
        }
    }
}

/// The connected parts of one mesh (vertices joined where their positions are equal), placed
/// by `to_world`. `positions` and `indices` are the mesh's own; bad indices are skipped.
pub fn pieces_of(positions: &[DVec3], indices: &[u32], to_world: &DMat4) -> Vec<Piece> {
    let n = positions.len();
    // Weld by exact position: exporters split vertices along normal and UV seams.
    let mut weld: FxHashMap<[u64; 3], u32> = FxHashMap::default();
    let id: Vec<u32> = positions
        .iter()
        .map(|p| {
            let key = p.to_array().map(|x| (x + 0.0).to_bits());
            let next = weld.len() as u32;
            *weld.entry(key).or_insert(next)
        })
        .collect();
    let mut parent: Vec<u32> = (0..weld.len() as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    let tris: Vec<[usize; 3]> = indices
        .chunks_exact(3)
        .map(|t| [t[0] as usize, t[1] as usize, t[2] as usize])
        .filter(|t| t.iter().all(|&i| i < n))
        .collect();
    for t in &tris {
        let a = find(&mut parent, id[t[0]]);
        for &v in &t[1..] {
            let b = find(&mut parent, id[v]);
            if a != b {
                parent[b as usize] = a;
            }
        }
    }
    let mut slot: FxHashMap<u32, usize> = FxHashMap::default();
    let mut out: Vec<Piece> = Vec::new();
    for t in &tris {
        let root = find(&mut parent, id[t[0]]);
        let k = *slot.entry(root).or_insert_with(|| {
            out.push(Piece {
                bounds: DBox::EMPTY,
                area: 0.0,
            });
            out.len() - 1
        });
        let [a, b, c] = t.map(|i| to_world.transform_point3(positions[i]));
        let p = &mut out[k];
        p.bounds.include(a);
        p.bounds.include(b);
        p.bounds.include(c);
        p.area += 0.5 * (b - a).cross(c - a).length();
    }
    out.retain(|p| p.area.is_finite() && !p.bounds.is_empty());
    out
}

/// What the geometry says about the frame, before the options and defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct Evidence {
    /// The axis the pieces rest along, if one clearly does.
    pub up: Option<UpAxis>,
    /// The share of pieces resting on another along Y and along Z.
    pub resting: [f64; 2],
    /// The unit that puts the storeys, thicknesses and width where buildings have them, if
    /// one clearly does (read with `up`, or Y when that is unknown).
    pub unit: Option<LengthUnit>,
    /// Why, for reports: storeys (or wall heights), thicknesses and width in the file's units.
    pub unit_why: String,
    /// The share of the area in slabs (thin pieces lying flat): a building has floors
    /// ([`MIN_SLAB_SHARE`]); an engine or a spider has none, and its unit is not guessed.
    pub slab_share: f64,
}

/// Reads the pieces for their up axis and unit (see the module documentation).
pub fn evidence(pieces: &[Piece]) -> Evidence {
    let touching = [1, 2].map(|axis| contacts(pieces, axis));
    let resting = [touching[0].resting, touching[1].resting];
    let enough = |c: &cues::Contacts| c.resting >= MIN_RESTING && c.asked >= MIN_ASKED;
    let up = if resting[1] > resting[0] * UP_MARGIN && enough(&touching[1]) {
        Some(UpAxis::Z)
    } else if resting[0] > resting[1] * UP_MARGIN && enough(&touching[0]) {
        Some(UpAxis::Y)
    } else {
        None
    };
    let read_up = up.unwrap_or(UpAxis::Y);
    let (unit, unit_why, slab_share) =
        unit_of(pieces, read_up, &touching[read_up.index() - 1].between);
    Evidence {
        up,
        resting,
        unit,
        unit_why,
        slab_share,
    }
}

/// Settles a file's frame: the options first, else the geometry's evidence when `detect`
/// (OBJ, whose files carry neither), else `default` (what the format says). When the format
/// fixes the frame (`detect` false), evidence that clearly disagrees comes back as a warning
/// naming the options to give, and the format's frame is kept; so does evidence that clearly
/// disagrees with an option given (`--up z` on a Y-up building).
pub fn settle(
    pieces: &[Piece],
    default: &SourceFrame,
    detect: bool,
    options: &FrameOptions,
) -> (SourceFrame, Vec<String>) {
    let mut frame = default.clone();
    let mut warnings = Vec::new();
    let ev = evidence(pieces);
    let up_why = format!(
        "pieces rest on others along {}: {:.0} % along Y, {:.0} % along Z",
        ev.up.map_or("neither axis clearly", |u| match u {
            UpAxis::Y => "Y",
            UpAxis::Z => "Z",
        }),
        100.0 * ev.resting[0],
        100.0 * ev.resting[1]
    );
    match options.up {
        Some(u) => {
            frame.up = u;
            frame.up_source = FrameSource::Given;
            frame.up_why.clear();
            if let Some(seen) = ev.up.filter(|&seen| seen != u && ev.unit.is_some()) {
                warnings.push(format!(
                    "given --up {}, but the model looks {} up ({up_why}): is --up {} meant?",
                    u.symbol(),
                    seen.symbol().to_ascii_uppercase(),
                    seen.symbol()
                ));
            }
        }
        None if detect => match ev.up {
            Some(u) => {
                frame.up = u;
                frame.up_source = FrameSource::Found;
                frame.up_why = up_why;
            }
            None => {
                frame.up_source = FrameSource::Assumed;
                frame.up_why = up_why;
                warnings.push(format!(
                    "the up axis is not clear from the geometry ({}); assumed {}: give --up y \
                     or --up z if it is wrong",
                    frame.up_why,
                    frame.up.symbol().to_ascii_uppercase()
                ));
            }
        },
        None => {
            // Only a model that reads as a building with the other axis up (its unit found)
            // is named: a test board or an engine has no floors to say so.
            if let Some(u) = ev.up.filter(|&u| u != frame.up && ev.unit.is_some()) {
                warnings.push(format!(
                    "the format says {} is up, but the model looks {} up ({up_why}): give --up {} \
                     if it is",
                    frame.up.symbol().to_ascii_uppercase(),
                    u.symbol().to_ascii_uppercase(),
                    u.symbol()
                ));
            }
        }
    }
    // The unit read with the up axis settled above (for a format that fixes its frame, with
    // the axis the model looks up along, which the warning names too).
    let (unit, unit_why) = if !detect || frame.up == ev.up.unwrap_or(UpAxis::Y) {
        (ev.unit, ev.unit_why.clone())
    } else {
        let (u, why, _) = unit_of(
            pieces,
            frame.up,
            &contacts(pieces, frame.up.index()).between,
        );
        (u, why)
    };
    match options.units {
        Some(u) => {
            frame.unit = u;
            frame.unit_source = FrameSource::Given;
            frame.unit_why.clear();
            if let Some(seen) = unit.filter(|&seen| seen != u) {
                warnings.push(format!(
                    "given --units {}, but the model looks like {} ({unit_why}): is --units {} \
                     meant?",
                    u.symbol(),
                    seen.name(),
                    seen.symbol()
                ));
            }
        }
        None if detect => match unit {
            Some(u) => {
                frame.unit = u;
                frame.unit_source = FrameSource::Found;
                frame.unit_why = unit_why;
            }
            None => {
                frame.unit_source = FrameSource::Assumed;
                frame.unit_why = unit_why;
                warnings.push(format!(
                    "the unit is not clear from the geometry ({}); assumed {}: give --units \
                     m, cm, mm, in, ft or dm if it is wrong",
                    frame.unit_why,
                    frame.unit.name()
                ));
            }
        },
        None => {
            if let Some(u) = unit.filter(|&u| u != frame.unit) {
                warnings.push(format!(
                    "the file is in {}, but the model looks like {} ({unit_why}): give --units {} \
                     if it is",
                    frame.unit.name(),
                    u.name(),
                    u.symbol()
                ));
            }
        }
    }
    (frame, warnings)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boxed(min: [f64; 3], max: [f64; 3]) -> Piece {
        let (min, max) = (DVec3::from(min), DVec3::from(max));
        let s = max - min;
        Piece {
            bounds: DBox { min, max },
            area: 2.0 * (s.x * s.y + s.y * s.z + s.z * s.x),
        }
    }

    /// The two-room house of the import cases (metres, Y up), as boxes.
    fn house() -> Vec<Piece> {
        vec![
            boxed([0.0, -0.2, 0.0], [10.0, 0.0, 8.0]),
            boxed([0.0, 3.0, 0.0], [10.0, 3.2, 8.0]),
            boxed([0.0, 0.0, 0.0], [10.0, 3.0, 0.2]),
            boxed([0.0, 0.0, 7.8], [10.0, 3.0, 8.0]),
            boxed([0.0, 0.0, 0.2], [0.2, 3.0, 7.8]),
            boxed([9.8, 0.0, 0.2], [10.0, 3.0, 7.8]),
            boxed([4.9, 0.0, 0.2], [5.1, 3.0, 3.5]),
            boxed([4.9, 0.0, 4.5], [5.1, 3.0, 7.8]),
            boxed([4.9, 2.2, 3.5], [5.1, 3.0, 4.5]),
            boxed([2.0, 0.0, 3.0], [3.5, 0.8, 4.5]),
            boxed([7.0, 0.0, 2.0], [7.5, 0.5, 2.5]),
        ]
    }

    fn placed(pieces: &[Piece], m: DMat4) -> Vec<Piece> {
        pieces
            .iter()
            .map(|p| {
                let mut b = DBox::EMPTY;
                b.include(m.transform_point3(p.bounds.min));
                b.include(m.transform_point3(p.bounds.max));
                Piece {
                    bounds: b,
                    area: p.area,
                }
            })
            .collect()
    }

    #[test]
    fn the_house_in_every_unit_and_axis_is_found() {
        for unit in LengthUnit::ALL {
            for up in [UpAxis::Y, UpAxis::Z] {
                let frame = SourceFrame {
                    unit,
                    up,
                    ..SourceFrame::metres_y_up()
                };
                let pieces = placed(&house(), frame.to_metres_y_up().inverse());
                let ev = evidence(&pieces);
                assert_eq!(ev.up, Some(up), "{unit:?} {up:?}: {ev:?}");
                assert_eq!(ev.unit, Some(unit), "{unit:?} {up:?}: {ev:?}");
            }
        }
    }

    #[test]
    fn given_options_win_and_an_unclear_guess_warns_naming_the_option() {
        let given = FrameOptions {
            units: Some(LengthUnit::Foot),
            up: Some(UpAxis::Z),
        };
        let (f, w) = settle(&house(), &SourceFrame::metres_y_up(), true, &given);
        assert_eq!(
            (f.unit, f.up, f.unit_source),
            (LengthUnit::Foot, UpAxis::Z, FrameSource::Given)
        );
        // Given as told, but a Y-up house given Z up is named.
        assert!(w.iter().any(|w| w.contains("is --up y meant")), "{w:?}");
        let right = FrameOptions {
            units: Some(LengthUnit::Metre),
            up: Some(UpAxis::Y),
        };
        let (_, w) = settle(&house(), &SourceFrame::metres_y_up(), true, &right);
        assert!(w.is_empty(), "{w:?}");
        // One cube says nothing about storeys: assumed, with the option named.
        let cube = [boxed([0.0; 3], [1.0; 3])];
        let (f, w) = settle(
            &cube,
            &SourceFrame::metres_y_up(),
            true,
            &FrameOptions::default(),
        );
        assert_eq!(f.unit_source, FrameSource::Assumed);
        assert!(w.iter().any(|w| w.contains("--units")), "{w:?}");
        assert!(w.iter().any(|w| w.contains("--up")), "{w:?}");
    }

    #[test]
    fn a_fixed_format_keeps_its_frame_and_warns_when_the_model_disagrees() {
        let frame = SourceFrame {
            unit: LengthUnit::Centimetre,
            up: UpAxis::Z,
            ..SourceFrame::metres_y_up()
        };
        let pieces = placed(&house(), frame.to_metres_y_up().inverse());
        let (f, w) = settle(
            &pieces,
            &SourceFrame::metres_y_up(),
            false,
            &FrameOptions::default(),
        );
        assert!(f.is_identity());
        assert!(w.iter().any(|w| w.contains("--up z")), "{w:?}");
        assert!(w.iter().any(|w| w.contains("--units cm")), "{w:?}");
        let (_, w) = settle(
            &house(),
            &SourceFrame::metres_y_up(),
            false,
            &FrameOptions::default(),
        );
        assert!(w.is_empty(), "{w:?}");
    }

    #[test]
    fn pieces_are_the_connected_parts_joined_where_positions_meet() {
        // Two triangles sharing an edge by position only (split vertices), and one apart.
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [5.0, 0.0, 0.0],
            [6.0, 0.0, 0.0],
            [5.0, 1.0, 0.0],
        ]
        .map(DVec3::from);
        let pieces = pieces_of(&p, &[0, 1, 2, 3, 4, 5, 6, 7, 8, 0, 1, 99], &DMat4::IDENTITY);
        assert_eq!(pieces.len(), 2);
        assert!((pieces[0].area - 1.0).abs() < 1e-12);
        assert_eq!(pieces[1].bounds.min.x, 5.0);
    }
}
