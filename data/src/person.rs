//! The person a walkthrough assumes, in metres and seconds: how high the eyes are, how fast
//! they walk and turn, what a door is and what a room a tour visits is. These are the
//! person-scale numbers the paths use; they hold because the importers convert every model to
//! metres with Y up first ([`crate::frame`]).
//! The building's own structural tests are metres too (the wall test's 8 cm–1 m,
//! [`crate::cells::occluders::MIN_WALL_THICKNESS`] and [`crate::cells::cover::MAX_THICKNESS`]).

/// Eye height above the floor (metres), and the lowest eye height through an opening above
/// its sill.
pub const EYE_HEIGHT: f32 = 1.6;

/// Walking speed of the standard tours (metres per second; Funkhouser's observer walks at
/// about this pace).
pub const WALK_SPEED: f32 = 1.5;

/// Turning speed of the standard tours (degrees per second).
pub const TURN_DEGREES: f32 = 90.0;

/// A door: an opening at least this tall (metres)...
pub const DOOR_HEIGHT: f32 = 1.8;

/// ...whose sill is at most this far (metres) above the lower floor of the cells it joins...
pub const DOOR_SILL: f32 = 0.35;

/// ...and at least this wide (metres); holes in floors too, both ways. Narrower gaps (between
/// wall segments of an export) are not walked through.
pub const DOOR_WIDTH: f32 = 0.5;

/// A cell a tour visits is at least this wide and deep (metres)...
pub const ROOM_WIDTH: f32 = 1.0;

/// ...and this high (metres): a person stands in it.
pub const ROOM_HEIGHT: f32 = 2.0;
