//! The predicted lookahead shared by place: one need list for every observer in the same
//! metre of the same cell, looking and moving the same way within a bucket, that holds the
//! predicted lookahead ([`super::predicted`]) of each of them.
//!
//! The predicted lookahead of one observer is eye-to-object visibility (Funkhouser §4.1.2)
//! from the eye and from points ahead of it along its velocity, in a view turned by its
//! angular velocity and widened as time passes (§5.2.1's motion prediction). Fix only where
//! the observer is to a [`VOXEL_M`] cube of its cell, its view direction and its velocity's
//! direction to direction buckets ([`VIEW_AZIMUTH`] × [`VIEW_ELEVATION`],
//! [`VELOCITY_BUCKETS`]), its speed to a band of its maximum speed ([`SPEED_BANDS`]) and its
//! turn to [`TURN_STEP`] bands ([`Motion`]), and:
//!
//! - every predicted eye of every such observer lies in a box swept from the cube along the
//!   velocities of the bucket (the region of frame `f`: the cube grown by every velocity of the
//!   bucket times `f` frames, and by none, for an observer whose walk stopped at a wall);
//! - what an eye in a cell's part of the last (largest) region may see through portals is
//!   inside what region-to-cell visibility keeps from that box ([`crate::cells::region`]: the
//!   planes separating the box from each portal stand where a point's wedge would);
//! - the view of every observer at frame `f` is inside one cone, opened by the bucket's spread
//!   and the turn band's drift, its apex stepped back until it holds the region (every cone
//!   from a point inside a convex cone, opening no wider, lies inside it).
//!
//! So each object and each of its geometry LODs is listed from a frame no later than in any
//! one observer's answer, at an LOD no coarser: the list holds the answer of every observer it
//! serves (up to the cache bound where both stop; a texture's useful mip may be a finer one,
//! due with the finer LOD it goes with), and a stream session
//! computes nothing while its observer stays in its place. On the tiny building it is 2.2
//! times the bytes of the answers it holds (`data/tests/shared_predicted.rs`).

use super::range::{self, ObserverRange};
use super::shared::direction_bucket_in;
use super::sight::sight_key;
use super::{Budget, Candidate, Prefetcher, need};
use crate::cells::realtime::{Frustum, MAX_EYE_SEQUENCES};
use crate::cells::region::{region_to_cell, region_to_object};
use crate::cells::{CellGraph, touches};
use crate::error::Result;
use crate::geometry::Aabb;
use glam::{Quat, Vec3};
use portico_protocol::{NeedItem, NeedKind, Observer, Policy};
use std::collections::{HashMap, HashSet, VecDeque};
use std::f32::consts::{FRAC_PI_2, PI};

/// Edge of the cubes an eye position is bucketed to (metres): a walker crosses one in about
/// 0.7 s, a dozen observer updates.
pub const VOXEL_M: f32 = 1.0;
/// Azimuth sectors of the view buckets of a predicted place (10° each).
pub const VIEW_AZIMUTH: u32 = 36;
/// Elevation bands of the view buckets of a predicted place (12° each; an odd number, so a
/// level view is in the middle of one, not on the edge between two).
pub const VIEW_ELEVATION: u32 = 15;
/// Radians any view direction may be from its bucket's centre (half a sector plus half a band,
/// as [`super::shared::BUCKET_SPREAD`]).
pub const VIEW_SPREAD: f32 = PI / VIEW_AZIMUTH as f32 + PI / (2.0 * VIEW_ELEVATION as f32);
/// Azimuth sectors and elevation bands of the velocity buckets (15° by 20°): a walker's path
/// bends all the time, and its velocity moves its eye by a metre at most within the
/// lookahead, so the buckets can be coarser than the view's.
pub const VELOCITY_BUCKETS: (u32, u32) = (24, 9);
/// Radians any velocity may be from its bucket's centre.
pub const VELOCITY_SPREAD: f32 =
    PI / VELOCITY_BUCKETS.0 as f32 + PI / (2.0 * VELOCITY_BUCKETS.1 as f32);
/// Speed bands per maximum speed: band `b` holds speeds within an eighth of the maximum of
/// `b / 4` of it, so walking at the maximum speed is in the middle of a band; band 0 (below an
/// eighth) ignores the direction.
pub const SPEED_BANDS: f32 = 4.0;
/// Width of a turn band per component of the angular velocity (rad/s); a turn of 0 is in the
/// middle of one.
pub const TURN_STEP: f32 = 0.25;
/// Fastest speed (m/s) and turn (rad/s) bucketed: an observer past either gets its own answer.
const MAX_BUCKETED: f32 = 100.0;

/// The predicted part of a place: the eye's cube, the velocity's bucket and speed band, and
/// the turn's bands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Motion {
    voxel: [i32; 3],
    velocity: u16,
    speed: u16,
    turn: [i16; 3],
}

impl Motion {
    /// The motion bucket of `obs`; `None` for numbers that are not finite or too large to
    /// bucket (that observer gets its own answer).
    pub fn of(obs: &Observer) -> Option<Motion> {
        let eye = Vec3::from(obs.eye);
        let v = Vec3::from(obs.velocity);
        let turn = Vec3::from(obs.turn);
        let ok = |x: Vec3, max: f32| x.is_finite() && x.length() < max;
        if !ok(eye, 1e7) || !ok(v, MAX_BUCKETED) || !ok(turn, MAX_BUCKETED) {
            return None;
        }
        let voxel = (eye / VOXEL_M).floor().as_ivec3().to_array();
        let speed = (v.length() / speed_unit(obs) + 0.5) as u16;
        let velocity = if speed == 0 {
            0
        } else {
            direction_bucket_in(v, VELOCITY_BUCKETS.0, VELOCITY_BUCKETS.1).0
        };
        let band = |x: f32| (x / TURN_STEP).round() as i16;
        Some(Motion {
            voxel,
            velocity,
            speed,
            turn: [band(turn.x), band(turn.y), band(turn.z)],
        })
    }

    fn voxel_box(&self) -> Aabb {
        let lo = glam::IVec3::from_array(self.voxel).as_vec3() * VOXEL_M;
        Aabb {
            min: lo.into(),
            max: (lo + Vec3::splat(VOXEL_M)).into(),
        }
    }

    /// A box holding every velocity of the bucket (m/s).
    fn velocities(&self, obs: &Observer) -> Aabb {
        let unit = speed_unit(obs);
        let (s0, s1) = (
            (self.speed as f32 - 0.5).max(0.0) * unit,
            (self.speed as f32 + 0.5) * unit * 1.001,
        );
        if self.speed == 0 {
            return Aabb {
                min: [-s1; 3],
                max: [s1; 3],
            };
        }
        // The velocities s·d, s in [s0, s1], d within the spread of the bucket's centre c, lie
        // in the ball about c·(s0 + s1)/2 reaching the furthest of them (at s0 or s1, at the
        // spread's edge).
        let v = Vec3::from(obs.velocity);
        let (_, c) = direction_bucket_in(v, VELOCITY_BUCKETS.0, VELOCITY_BUCKETS.1);
        let mid = (s0 + s1) * 0.5;
        let reach = |s: f32| (s * s + mid * mid - 2.0 * s * mid * VELOCITY_SPREAD.cos()).sqrt();
        let r = reach(s0).max(reach(s1)) * 1.001 + 1e-4;
        let m = c * mid;
        Aabb {
            min: (m - Vec3::splat(r)).into(),
            max: (m + Vec3::splat(r)).into(),
        }
    }

    fn turn_centre(&self) -> Vec3 {
        Vec3::new(
            self.turn[0] as f32,
            self.turn[1] as f32,
            self.turn[2] as f32,
        ) * TURN_STEP
    }
}

/// The speed (m/s) of one speed band: a [`SPEED_BANDS`]th of the observer's maximum speed (of
/// 1.5 m/s where that is not a usable number).
fn speed_unit(obs: &Observer) -> f32 {
    let max = if obs.max_speed.is_finite() && obs.max_speed > 0.01 {
        obs.max_speed.min(MAX_BUCKETED)
    } else {
        1.5
    };
    max / SPEED_BANDS
}

/// Radians per second a turn may be from its bands' centre (half a band on each axis).
const TURN_DRIFT: f32 = TURN_STEP * 0.5 * 1.732_051 * 1.001;

/// The region every predicted eye of the place may be in `t` seconds from now: the eye's cube
/// (within its cell) grown by every velocity of the bucket times `t`, and by none.
fn region(start: &Aabb, velocities: &Aabb, t: f32) -> Aabb {
    let mut r = *start;
    for k in 0..3 {
        r.min[k] += (velocities.min[k] * t).min(0.0);
        r.max[k] += (velocities.max[k] * t).max(0.0);
    }
    r
}

fn intersect(a: &Aabb, b: &Aabb) -> Aabb {
    let mut r = *a;
    for k in 0..3 {
        r.min[k] = a.min[k].max(b.min[k]);
        r.max[k] = a.max[k].min(b.max[k]).max(r.min[k]);
    }
    r
}

/// The distance between two boxes (0 when they touch).
pub fn box_distance(a: &Aabb, b: &Aabb) -> f32 {
    let mut d2 = 0.0;
    for k in 0..3 {
        let e = (b.min[k] - a.max[k]).max(a.min[k] - b.max[k]).max(0.0);
        d2 += e * e;
    }
    d2.sqrt()
}

/// A cone along `dir` opening `half` radians that holds every such cone from a point of
/// `eyes`; `None` (everything) once it opens past a half-space.
fn cone_from(eyes: &Aabb, dir: Vec3, half: f32) -> Option<Frustum> {
    if !(half > 0.0 && half < FRAC_PI_2 - 0.02) {
        return None;
    }
    let (lo, hi) = (Vec3::from(eyes.min), Vec3::from(eyes.max));
    let slack = (hi - lo).length() * 0.5;
    let up = if dir.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
    let apex = (lo + hi) * 0.5 - dir * (slack / half.sin());
    Some(Frustum::new(apex, dir, up, half, half))
}

/// The live cells a walk from `start` may pass through inside `reach`: those joined to it by
/// portals through cells that overlap `reach` (a predicted walk goes from cell to neighbour).
fn walkable_cells(graph: &CellGraph, start: u32, reach: &Aabb) -> Vec<u32> {
    let mut seen = HashSet::from([start]);
    let mut out = vec![start];
    let mut queue = VecDeque::from([start]);
    while let Some(c) = queue.pop_front() {
        for &p in &graph.cells[c as usize].portals {
            let n = graph.portals[p as usize].other(c);
            let cell = &graph.cells[n as usize];
            if cell.live && touches(&cell.bounds, reach) && seen.insert(n) {
                out.push(n);
                queue.push_back(n);
            }
        }
    }
    out
}

impl Prefetcher {
    /// The predicted lookahead of every observer of a place (see the module): the stab lists
    /// of the range cells of the place's cube, then every object the swept regions may see,
    /// each from the first frame one may, at the finest LOD the size threshold allows at the
    /// region's nearest point. `cell` is the place's cell; `obs` any observer of the place.
    pub(super) fn lookahead_swept(
        &self,
        graph: &CellGraph,
        cell: u32,
        motion: &Motion,
        obs: &Observer,
        policy: &Policy,
        budget: &Budget,
    ) -> Result<(u32, Vec<NeedItem>, Vec<Candidate>, u32)> {
        let start = intersect(&motion.voxel_box(), &graph.cells[cell as usize].bounds);
        let (_, view) = direction_bucket_in(Vec3::from(obs.dir), VIEW_AZIMUTH, VIEW_ELEVATION);
        let range = ObserverRange::for_cell(cell, &start, view, VIEW_SPREAD, obs, policy);
        let ranged = range::range_cells(graph, &range, policy.range_cull);
        budget.check()?;
        // A cell the cube touches is entered now by an observer on its face (whose own range
        // starts from both cells there): its stab list is needed at once.
        let stab_items: Vec<NeedItem> = ranged
            .iter()
            .filter_map(|&(c, frames)| {
                let seg = self.stab_segment(c)?;
                let frames = if touches(&graph.cells[c as usize].bounds, &start) {
                    0
                } else {
                    frames
                };
                Some(need(
                    seg,
                    NeedKind::Stab,
                    0,
                    self.segment_bytes(seg),
                    frames,
                ))
            })
            .collect();

        // The predicted eyes' frames (as `predicted_eyes` samples them) and their regions.
        let dt = policy.frame_time_s.max(0.0);
        let velocities = motion.velocities(obs);
        let frames: Vec<u32> = (0..=policy.depth_frames)
            .step_by(super::predicted::STEP_FRAMES as usize)
            .collect();
        let regions: Vec<Aabb> = frames
            .iter()
            .map(|&f| region(&start, &velocities, f as f32 * dt))
            .collect();
        let last = regions.last().copied().unwrap_or(start);
        let cells = walkable_cells(graph, cell, &last);
        let turn = motion.turn_centre();

        // What each cell's part of the last (largest) region may see through portals: every
        // predicted eye in the cell is in it. Past the search's bound, the cell's whole stab
        // list.
        let mut visible: HashMap<u32, std::sync::Arc<[u32]>> = HashMap::new();
        for &c in &cells {
            let here = &graph.cells[c as usize].bounds;
            if !touches(here, &last) {
                continue;
            }
            budget.check()?;
            let eyes = intersect(&last, here);
            // The same box for every view and turn of this cube and velocity: searched once
            // ([`super::sight`]).
            let objects = self.sight.get_or(sight_key(c, &eyes), || {
                let stab = self.stab(c)?;
                let mut going = || !budget.spent();
                Ok(
                    match region_to_cell(graph, c, &eyes, MAX_EYE_SEQUENCES, &mut going) {
                        Some(reached) => region_to_object(&reached, &stab, &self.bounds),
                        None => {
                            budget.check()?; // stopped for the deadline, not the bound
                            stab.objects()
                        }
                    },
                )
            })?;
            visible.insert(c, objects);
        }

        // Objects in the order the regions first may see them, with that sample's index.
        let mut first: HashMap<u32, usize> = HashMap::new();
        let mut order: Vec<u32> = Vec::new();
        for (k, (&f, r)) in frames.iter().zip(&regions).enumerate() {
            budget.check()?;
            let t = f as f32 * dt;
            // `view_at`'s frustum for every observer of the place: its rays are within the
            // corner angle of its axis, and its axis within the spread and the turn's drift of
            // this one.
            let widen = super::predicted::TURN_SHARE * obs.max_turn.max(0.0) * t;
            let (hx, hy) = (obs.half_fov_x + widen, obs.half_fov_y + widen);
            let limit = FRAC_PI_2 - 0.02;
            let opens = hx > 0.0 && hy > 0.0 && hx < limit && hy < limit;
            let half = if opens {
                let (tx, ty) = (hx.tan(), hy.tan());
                (tx * tx + ty * ty).sqrt().atan() + VIEW_SPREAD + TURN_DRIFT * t
            } else {
                PI
            };
            let axis = (Quat::from_scaled_axis(turn * t) * view)
                .try_normalize()
                .unwrap_or(view);
            for &c in &cells {
                let here = &graph.cells[c as usize].bounds;
                if !touches(here, r) {
                    continue;
                }
                let cone = cone_from(&intersect(r, here), axis, half);
                for &o in visible.get(&c).map_or(&[][..], |v| &v[..]) {
                    if first.contains_key(&o) {
                        continue;
                    }
                    let seen = cone
                        .as_ref()
                        .is_none_or(|v| v.touches(&self.bounds[o as usize]));
                    if seen {
                        first.insert(o, k);
                        order.push(o);
                    }
                }
            }
        }

        let cands = self.timed_candidates(
            (&order, &first),
            &frames,
            |j, b| box_distance(&regions[j], b),
            |_, k| k == 0,
            (&range, obs, policy),
            budget,
        )?;
        let stab_items = if policy.impostors {
            self.with_textures(stab_items, &cands, &range.eyes)
        } else {
            stab_items
        };
        Ok((ranged.len() as u32, stab_items, cands, visible.len() as u32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_velocity_of_a_bucket_is_in_its_box() {
        let obs = |v: Vec3| Observer {
            eye: [0.5; 3],
            dir: [1.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            velocity: v.into(),
            half_fov_x: 0.6,
            half_fov_y: 0.45,
            max_speed: 2.0,
            max_turn: 1.0,
            turn: [0.0; 3],
        };
        let inside = |b: &Aabb, v: Vec3| (0..3).all(|k| b.min[k] <= v[k] && v[k] <= b.max[k]);
        for i in 0..2000 {
            let a = i as f32 * 0.731;
            let s = (i % 37) as f32 * 0.05;
            let v = Vec3::new(a.cos() * s, ((i % 5) as f32 - 2.0) * 0.1 * s, a.sin() * s);
            let m = Motion::of(&obs(v)).unwrap();
            // Another velocity of the same bucket, in the box made for this one.
            let b = m.velocities(&obs(v));
            assert!(inside(&b, v), "{v} not in {b:?}");
            let w = v * 1.01 + Vec3::new(0.0, 0.0, 0.005);
            if Motion::of(&obs(w)) == Some(m) {
                assert!(inside(&b, w), "{w} not in {b:?}");
            }
        }
        // Too fast, or not a number: not bucketed.
        assert!(Motion::of(&obs(Vec3::new(1e3, 0.0, 0.0))).is_none());
        assert!(Motion::of(&obs(Vec3::new(f32::NAN, 0.0, 0.0))).is_none());
    }

    #[test]
    fn a_turn_is_within_the_drift_of_its_bands_centre() {
        for i in 0..500 {
            let t = Vec3::new(
                (i as f32 * 0.37).sin() * 2.0,
                (i as f32 * 0.11).cos() * 3.0,
                (i as f32 * 0.05).sin(),
            );
            let obs = Observer {
                eye: [0.0; 3],
                dir: [1.0, 0.0, 0.0],
                up: [0.0, 1.0, 0.0],
                velocity: [0.0; 3],
                half_fov_x: 0.6,
                half_fov_y: 0.45,
                max_speed: 2.0,
                max_turn: 1.0,
                turn: t.into(),
            };
            let c = Motion::of(&obs).unwrap().turn_centre();
            assert!((t - c).length() <= TURN_DRIFT, "{t} {c}");
        }
    }

    #[test]
    fn box_distance_is_zero_when_touching_and_euclidean_apart() {
        let a = Aabb {
            min: [0.0; 3],
            max: [1.0; 3],
        };
        let b = Aabb {
            min: [4.0, 0.5, 5.0],
            max: [5.0, 2.0, 6.0],
        };
        assert_eq!(box_distance(&a, &a), 0.0);
        assert!((box_distance(&a, &b) - 5.0).abs() < 1e-6);
    }
}
