//! Checks of what clients send (prefetch requests, observers, policies), so that hostile values
//! cannot make an answer huge or slow; the HTTP prefetch and the push stream both use them.

use crate::error::Error;
use portico_protocol::{PROTOCOL_VERSION, PrefetchRequest};
use std::collections::HashSet;

/// Largest read budget a prefetch request may ask for (bytes).
pub const MAX_READ_BYTES: u64 = 1 << 30;
/// Longest frame time a policy may give (seconds): a frame is a person's step at most, and
/// the server counts deadlines and pacing in frames (a huge one overflowed its clock).
pub const MAX_FRAME_TIME_S: f32 = 10.0;

/// Checks a prefetch request's numbers, so hostile values cannot make the answer huge or slow:
/// finite, non-negative observer and policy numbers, a bounded depth, screen and read budget, and
/// a held set of at most `segments` ids, each below `segments`.
pub fn validate(req: &PrefetchRequest, segments: usize) -> Result<HashSet<u32>, Error> {
    if req.version != PROTOCOL_VERSION {
        return Err(Error::bad_request(format!(
            "protocol version {} is not supported (server speaks {PROTOCOL_VERSION})",
            req.version
        )));
    }
    validate_observer(&req.observer)?;
    validate_policy(&req.policy)?;
    let held = portico_protocol::decode_held(&req.held)
        .ok_or_else(|| Error::bad_request("held set is not a valid delta-coded id list"))?;
    if held.len() > segments {
        return Err(Error::bad_request(format!(
            "the held set lists {} ids; the database has {segments} segments",
            held.len()
        )));
    }
    if let Some(bad) = held.iter().find(|&&id| id as usize >= segments) {
        return Err(Error::bad_request(format!(
            "held segment {bad} does not exist (the database has {segments})"
        )));
    }
    Ok(held.into_iter().collect())
}

/// An observer's numbers are finite, its angles and speeds not negative.
pub fn validate_observer(o: &portico_protocol::Observer) -> Result<(), Error> {
    let floats = (o.eye.iter().chain(&o.dir).chain(&o.up)).chain(o.velocity.iter().chain(&o.turn));
    let scalars = [o.half_fov_x, o.half_fov_y, o.max_speed, o.max_turn];
    if floats.chain(&scalars).any(|x| !x.is_finite()) || scalars.iter().any(|&x| x < 0.0) {
        return Err(Error::bad_request(
            "observer numbers must be finite, its angles and speeds not negative",
        ));
    }
    Ok(())
}

/// A policy's numbers are finite and within bounds (a frame time of at most
/// [`MAX_FRAME_TIME_S`]).
pub fn validate_policy(p: &portico_protocol::Policy) -> Result<(), Error> {
    let scalars = [p.frame_time_s, p.size_threshold_px];
    if scalars.iter().any(|x| !x.is_finite() || *x < 0.0) {
        return Err(Error::bad_request(
            "policy numbers must be finite and not negative",
        ));
    }
    if p.frame_time_s > MAX_FRAME_TIME_S {
        return Err(Error::bad_request(format!(
            "frame_time_s {} is more than {MAX_FRAME_TIME_S} s",
            p.frame_time_s
        )));
    }
    if p.depth_frames > 100_000 || p.screen.iter().any(|&d| d == 0 || d > 32_768) {
        return Err(Error::bad_request(
            "depth_frames ≤ 100000 and a screen of 1..=32768 pixels per side",
        ));
    }
    if p.read_bytes > MAX_READ_BYTES {
        return Err(Error::bad_request(format!(
            "read_bytes {} is more than {MAX_READ_BYTES}",
            p.read_bytes
        )));
    }
    Ok(())
}
