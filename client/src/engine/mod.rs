//! The client engine without IO (in the style of `quinn-proto`): state machines that take
//! events and the time as arguments and return what to send, with no sockets, threads or clock
//! of their own. Every front end (the native client's IO thread, the browser page, the load
//! tester's simulated clients) is a shell that does the IO these machines ask for, so they
//! share every decision and are tested on a simulated clock in milliseconds.
//!
//! - [`pull`]: reads over `POST /v1/prefetch` and `GET /v1/batch` (Funkhouser §5.2.3, Ch. 6).
//! - [`push`]: one `/v1/stream` session: what to send each frame, what a pushed frame is.
//! - [`catalogue`]: what the client knows of the segments (rows, kinds, decoded sizes), and the
//!   model it starts from, whole or paged ([`catalogue::Start`]).
//! - [`holdings`]: what a frame loop holds between frames (the cache, what is held beside it, what
//!   the last frame lacked) and the steps every front end runs on it.
//! - [`pages`]: the paged manifest, learnt cell by cell with the stab lists.
//! - [`reopen`]: when to try a push session again (back-off), pull reading meanwhile.
//! - [`switch`]: which transport carries the segments now, and when to open a session.

pub mod catalogue;
pub mod holdings;
pub mod pages;
pub mod pull;
pub mod push;
pub mod reopen;
pub mod switch;

/// An observer standing at `x` on the x axis at eye height, looking along -z: the engine tests'.
#[cfg(test)]
fn test_observer(x: f32) -> portico_protocol::Observer {
    portico_protocol::Observer {
        eye: [x, 1.6, 0.0],
        dir: [0.0, 0.0, -1.0],
        up: [0.0, 1.0, 0.0],
        velocity: [0.0; 3],
        half_fov_x: 0.5,
        half_fov_y: 0.4,
        max_speed: 2.0,
        max_turn: 1.0,
        turn: [0.0; 3],
    }
}
