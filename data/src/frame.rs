//! A source file's frame: the length unit its coordinates are in and the axis that points up.
//!
//! Everything after import is in metres with Y up, as glTF says: the person-scale numbers a
//! walkthrough assumes ([`crate::person`]) are metres, and a model in centimetres or with Z up
//! would otherwise be walked 1.6 cm above its floor or along a wall. Importers find the frame
//! (the file format says, the model's own geometry says, or the user gives it:
//! [`crate::import::frame`]) and convert at import; the database keeps each source's frame in
//! its header, beside the local origin, so a model built from one source can be placed back in
//! its coordinates: `source = frame.to_metres_y_up()⁻¹ · (local + origin)`.

use glam::{DMat4, DVec3};
use serde::{Deserialize, Serialize};

/// A length unit a model file's coordinates may be in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum LengthUnit {
    /// Millimetres (IFC from most BIM tools, CAD).
    Millimetre,
    /// Centimetres (SketchUp, 3ds Max, Crytek's Sponza).
    Centimetre,
    /// Decimetres (seen in hand-made glTF).
    Decimetre,
    /// Metres (glTF by its specification; most OBJ).
    Metre,
    /// Inches (SketchUp's default, US CAD).
    Inch,
    /// Feet (US BIM).
    Foot,
}

impl LengthUnit {
    /// Every unit, the order ties are broken in (the commonest first).
    pub const ALL: [LengthUnit; 6] = [
        LengthUnit::Metre,
        LengthUnit::Centimetre,
        LengthUnit::Millimetre,
        LengthUnit::Inch,
        LengthUnit::Foot,
        LengthUnit::Decimetre,
    ];

    /// Metres per unit.
    pub fn metres(self) -> f64 {
        match self {
            LengthUnit::Millimetre => 0.001,
            LengthUnit::Centimetre => 0.01,
            LengthUnit::Decimetre => 0.1,
            LengthUnit::Metre => 1.0,
            LengthUnit::Inch => 0.0254,
            LengthUnit::Foot => 0.3048,
        }
    }

    /// The short name the command line takes (`mm`, `cm`, `dm`, `m`, `in`, `ft`).
    pub fn symbol(self) -> &'static str {
        match self {
            LengthUnit::Millimetre => "mm",
            LengthUnit::Centimetre => "cm",
            LengthUnit::Decimetre => "dm",
            LengthUnit::Metre => "m",
            LengthUnit::Inch => "in",
            LengthUnit::Foot => "ft",
        }
    }

    /// The plural name for reports ("centimetres").
    pub fn name(self) -> &'static str {
        match self {
            LengthUnit::Millimetre => "millimetres",
            LengthUnit::Centimetre => "centimetres",
            LengthUnit::Decimetre => "decimetres",
            LengthUnit::Metre => "metres",
            LengthUnit::Inch => "inches",
            LengthUnit::Foot => "feet",
        }
    }

    /// Parses a symbol or name (`cm`, `centimetres`, `ft`, `feet`, ...).
    pub fn parse(s: &str) -> Option<LengthUnit> {
        let s = s.trim().to_ascii_lowercase();
        LengthUnit::ALL.into_iter().find(|u| {
            s == u.symbol()
                || s == u.name()
                || s == u.name().replace("metres", "meters")
                || s == u.name().trim_end_matches('s')
                || (u == &LengthUnit::Foot && s == "foot")
                || (u == &LengthUnit::Inch && s == "inch")
        })
    }

    /// The unit whose size is `metres` (within 0.1 %), if one is.
    pub fn of_metres(metres: f64) -> Option<LengthUnit> {
        LengthUnit::ALL
            .into_iter()
            .find(|u| (u.metres() / metres - 1.0).abs() < 1e-3)
    }
}

/// The axis a model file has pointing up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum UpAxis {
    /// +Y up (glTF, most OBJ, Portico itself).
    Y,
    /// +Z up, right-handed (IFC, Revit, 3ds Max, Rhino, Blender's own frame): `(x, y, z)`
    /// becomes `(x, z, −y)`.
    Z,
}

impl UpAxis {
    /// The axis index (1 for Y, 2 for Z).
    pub fn index(self) -> usize {
        match self {
            UpAxis::Y => 1,
            UpAxis::Z => 2,
        }
    }

    /// `y` or `z`.
    pub fn symbol(self) -> &'static str {
        match self {
            UpAxis::Y => "y",
            UpAxis::Z => "z",
        }
    }

    /// Parses `y` or `z` (either case).
    pub fn parse(s: &str) -> Option<UpAxis> {
        match s.trim().to_ascii_lowercase().as_str() {
            "y" | "+y" => Some(UpAxis::Y),
            "z" | "+z" => Some(UpAxis::Z),
            _ => None,
        }
    }

    /// The rotation from this frame to Y up.
    pub fn to_y_up(self) -> DMat4 {
        match self {
            UpAxis::Y => DMat4::IDENTITY,
            UpAxis::Z => DMat4::from_cols_array(&[
                1.0, 0.0, 0.0, 0.0, //
                0.0, 0.0, -1.0, 0.0, //
                0.0, 1.0, 0.0, 0.0, //
                0.0, 0.0, 0.0, 1.0,
            ]),
        }
    }
}

/// How a frame was settled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FrameSource {
    /// The file format fixes it (glTF: metres, Y up) or the file declares it (IFC's unit
    /// assignment; IFC is Z up).
    Format,
    /// Found from the model's geometry with confidence.
    Found,
    /// The geometry did not say clearly; the importer's default was kept (and a warning
    /// named the option to give).
    Assumed,
    /// Given on the command line (`--units`, `--up`).
    Given,
}

impl FrameSource {
    /// A word for reports.
    pub fn word(self) -> &'static str {
        match self {
            FrameSource::Format => "as the format says",
            FrameSource::Found => "found",
            FrameSource::Assumed => "assumed",
            FrameSource::Given => "given",
        }
    }
}

/// One source file's unit and up axis, how each was settled and what the geometry showed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourceFrame {
    /// The unit the file's coordinates are in.
    pub unit: LengthUnit,
    /// How the unit was settled.
    pub unit_source: FrameSource,
    /// What said so ("wall heights 300, thicknesses 20"), for reports.
    pub unit_why: String,
    /// The axis pointing up in the file.
    pub up: UpAxis,
    /// How the up axis was settled.
    pub up_source: FrameSource,
    /// What said so ("62 % of pieces start on 3 levels along Z, 20 % along Y").
    pub up_why: String,
}

impl SourceFrame {
    /// Metres and Y up as the format says (glTF).
    pub fn metres_y_up() -> SourceFrame {
        SourceFrame {
            unit: LengthUnit::Metre,
            unit_source: FrameSource::Format,
            unit_why: String::new(),
            up: UpAxis::Y,
            up_source: FrameSource::Format,
            up_why: String::new(),
        }
    }

    /// The change from the file's coordinates to metres with Y up: scale, then rotation.
    pub fn to_metres_y_up(&self) -> DMat4 {
        self.up.to_y_up() * DMat4::from_scale(DVec3::splat(self.unit.metres()))
    }

    /// Whether the change is the identity (metres, Y up).
    pub fn is_identity(&self) -> bool {
        self.unit == LengthUnit::Metre && self.up == UpAxis::Y
    }

    /// One line for `build` and `inspect`: "units: centimetres (found: wall heights 300),
    /// up: Z (given)".
    pub fn describe(&self) -> String {
        let part = |what: &str, source: FrameSource, why: &str| {
            if why.is_empty() {
                format!("{what} ({})", source.word())
            } else {
                format!("{what} ({}: {why})", source.word())
            }
        };
        format!(
            "units: {}, up: {}",
            part(self.unit.name(), self.unit_source, &self.unit_why),
            part(
                &self.up.symbol().to_ascii_uppercase(),
                self.up_source,
                &self.up_why
            )
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn z_up_turns_to_y_up_as_ifc_and_revit_write_it() {
        let f = SourceFrame {
            unit: LengthUnit::Centimetre,
            up: UpAxis::Z,
            ..SourceFrame::metres_y_up()
        };
        // 300 cm up in a Z-up file is 3 m up in Y; +Y (north, into the screen) becomes −Z.
        let p = f
            .to_metres_y_up()
            .transform_point3(DVec3::new(100.0, 200.0, 300.0));
        assert!((p - DVec3::new(1.0, 3.0, -2.0)).length() < 1e-12, "{p}");
    }

    #[test]
    fn units_parse_from_symbols_and_names() {
        assert_eq!(LengthUnit::parse("cm"), Some(LengthUnit::Centimetre));
        assert_eq!(
            LengthUnit::parse("Millimeters"),
            Some(LengthUnit::Millimetre)
        );
        assert_eq!(LengthUnit::parse("feet"), Some(LengthUnit::Foot));
        assert_eq!(LengthUnit::parse("inch"), Some(LengthUnit::Inch));
        assert_eq!(LengthUnit::parse("furlong"), None);
        assert_eq!(LengthUnit::of_metres(0.3048), Some(LengthUnit::Foot));
        assert_eq!(LengthUnit::of_metres(0.5), None);
        assert_eq!(UpAxis::parse("Z"), Some(UpAxis::Z));
        assert_eq!(UpAxis::parse("x"), None);
    }
}
