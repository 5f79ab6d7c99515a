//! The client's defaults, written once for every front end (the native walk and window, the
//! browser page, the load tester's simulated clients, the demo, the benchmark): a person's view
//! and pace, and what the IO stage keeps going.

/// Vertical field of view, degrees.
pub const FOV_Y_DEGREES: f32 = 60.0;

/// Vertical field of view, radians ([`FOV_Y_DEGREES`]).
pub fn fov_y() -> f32 {
    FOV_Y_DEGREES.to_radians()
}

/// The walking speed an interactive observer announces to the server's lookahead (metres per
/// second; Funkhouser §5.2.1's `v_p`): a brisk walk, a little above
/// [`portico_data::person::WALK_SPEED`], so the lookahead is not outrun.
pub const MAX_SPEED: f32 = 2.0;

/// The turn rate an interactive observer announces (radians per second; §5.2.1's `v_r`).
pub const MAX_TURN: f32 = 2.0;

/// Read requests (segment batches) in flight at once over pull.
pub const PARALLEL: usize = 8;

/// The byte budget of the cache (and the IO window beside it), MiB.
pub const CACHE_MB: u64 = 64;

/// The frame-time budget, milliseconds (20 frames a second).
pub const FRAME_BUDGET_MS: f64 = 50.0;
