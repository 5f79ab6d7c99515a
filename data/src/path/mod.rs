//! Observer paths: timed keyframes (eye, view direction) that walkthroughs and benchmarks replay
//! frame by frame (Funkhouser §7 replays recorded paths), and generators for standard paths:
//! tours between the rooms of a building's cells, walked looking ahead as a person does
//! ([`gaze`]), and, for models without rooms, an orbit and a
//! fly-through ([`survey`]).
//!
//! On disk a path is JSON: `{"kind": "tour", "keyframes": [{"t": 0.0, "eye": [x, y, z],
//! "dir": [x, y, z]}, ...]}`, times in seconds, increasing; positions in the model's metres.

pub mod detour;
pub mod gaze;
mod rooms;
pub mod survey;

use rooms::{DOOR_APPROACH_M, room_loop, roomy};
pub use rooms::{EYE_HEIGHT, has_rooms, walkable};

use crate::cells::CellGraph;
use crate::geometry::Aabb;
use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, VecDeque};

/// One keyframe.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Keyframe {
    /// Seconds from the start.
    pub t: f32,
    /// Eye position.
    pub eye: [f32; 3],
    /// View direction (unit length).
    pub dir: [f32; 3],
}

/// A timed camera path (JSON on disk).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraPath {
    /// What made it (`tour`, `spin`, `revisit`, `recorded`).
    pub kind: String,
    /// Keyframes in time order.
    pub keyframes: Vec<Keyframe>,
}

/// The kinds of standard paths.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathKind {
    /// Walks between random rooms along portal chains.
    Tour,
    /// Turns on the spot in one room (everything visible from one cell, at every angle).
    Spin,
    /// A tour out and the same way back (tests how well the cache keeps what it saw).
    Revisit,
    /// Once around the model, looking at it from outside.
    Orbit,
    /// Straight through the model along its longer side, through the least solid.
    Flythrough,
}

/// A standard path of `kind` for a model: `graph` its cells (if built), `bounds` and `objects`
/// its boxes. A tour, revisit or spin in a model without rooms ([`has_rooms`]) becomes an orbit
/// followed by a fly-through (a spin: the orbit), so every model gets a path that sees it.
/// `None` only when the model is empty.
#[allow(clippy::too_many_arguments)]
pub fn standard(
    graph: Option<&CellGraph>,
    bounds: &Aabb,
    objects: &[Aabb],
    kind: PathKind,
    legs: usize,
    seed: u64,
    speed: f32,
    turn: f32,
) -> Option<CameraPath> {
    if bounds.is_empty() {
        return None;
    }
    let rooms = graph.filter(|g| has_rooms(g));
    match (kind, rooms) {
        (PathKind::Orbit, _) | (PathKind::Spin, None) => Some(survey::orbit(bounds, speed)),
        (PathKind::Flythrough, _) => Some(survey::flythrough(bounds, objects, speed)),
        (PathKind::Tour | PathKind::Revisit, None) => Some(survey::then(
            survey::orbit(bounds, speed),
            survey::flythrough(bounds, objects, speed),
            std::f32::consts::PI / turn.max(0.01),
        )),
        (_, Some(g)) => generate_around(g, objects, kind, legs, seed, speed, turn),
    }
}

impl CameraPath {
    /// Length in seconds.
    pub fn duration(&self) -> f32 {
        self.keyframes.last().map_or(0.0, |k| k.t)
    }

    /// Eye and view direction at time `t` (clamped to the path): the eye moves in a straight
    /// line between keyframes and the view turns from one direction to the next at a steady
    /// rate ([`turn_between`]).
    pub fn sample(&self, t: f32) -> (Vec3, Vec3) {
        let k = &self.keyframes;
        let Some(first) = k.first() else {
            return (Vec3::ZERO, Vec3::NEG_Z);
        };
        let i = k.partition_point(|f| f.t <= t);
        if i == 0 {
            return (first.eye.into(), first.dir.into());
        }
        if i >= k.len() {
            let l = k[k.len() - 1];
            return (l.eye.into(), l.dir.into());
        }
        let (a, b) = (k[i - 1], k[i]);
        let s = ((t - a.t) / (b.t - a.t).max(1e-6)).clamp(0.0, 1.0);
        let eye = Vec3::from(a.eye).lerp(b.eye.into(), s);
        (eye, turn_between(a.dir.into(), b.dir.into(), s))
    }

    /// Checks that times increase and every number is finite.
    pub fn validate(&self) -> Result<(), String> {
        if self.keyframes.is_empty() {
            return Err("the path has no keyframes".into());
        }
        for (i, k) in self.keyframes.iter().enumerate() {
            let finite = k
                .eye
                .iter()
                .chain(&k.dir)
                .chain([&k.t])
                .all(|x| x.is_finite());
            if !finite {
                return Err(format!("keyframe {i} has a non-finite number"));
            }
            if i > 0 && k.t < self.keyframes[i - 1].t {
                return Err(format!("keyframe {i} goes back in time"));
            }
        }
        Ok(())
    }

    /// A hash of the path (for reports: which path a figure was measured on).
    pub fn hash(&self) -> u64 {
        xxhash_rust::xxh3::xxh3_64(&serde_json::to_vec(self).unwrap_or_default())
    }
}

/// Makes a standard path through the live cells of `graph`, walking at `speed` m/s and turning
/// at most `turn` rad/s, looking along the direction of travel and turning on the spot at
/// corners. A tour here crosses each room it visits to its middle and turns there: the load
/// tests' and benchmarks' path, on which their figures were measured. [`generate_around`]
/// walks as a visitor does.
pub fn generate(
    graph: &CellGraph,
    kind: PathKind,
    legs: usize,
    seed: u64,
    speed: f32,
    turn: f32,
) -> Option<CameraPath> {
    make(graph, None, kind, legs, seed, speed, turn)
}

/// [`generate`] as a visitor walks: looking ahead along the way ([`gaze`]), round each room
/// visited, along its walls (not to its middle to turn there, facing the wall beside them),
/// and round `objects` (world boxes; the model's instances) where they stand in the way
/// ([`detour`]). The tour of `portico demo`, `portico path`, the server's `/v1/tour` and the
/// browser.
#[allow(clippy::too_many_arguments)]
pub fn generate_around(
    graph: &CellGraph,
    objects: &[Aabb],
    kind: PathKind,
    legs: usize,
    seed: u64,
    speed: f32,
    turn: f32,
) -> Option<CameraPath> {
    make(graph, Some(objects), kind, legs, seed, speed, turn)
}

#[allow(clippy::too_many_arguments)]
fn make(
    graph: &CellGraph,
    visitor: Option<&[Aabb]>,
    kind: PathKind,
    legs: usize,
    seed: u64,
    speed: f32,
    turn: f32,
) -> Option<CameraPath> {
    let mut live: Vec<u32> = (0..graph.cells.len() as u32)
        .filter(|&c| graph.cells[c as usize].live && roomy(graph, c))
        .collect();
    if live.is_empty() {
        live = (0..graph.cells.len() as u32)
            .filter(|&c| graph.cells[c as usize].live)
            .collect();
    }
    if live.is_empty() {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (kind_name, points) = match kind {
        PathKind::Tour => {
            let p = tour_points(graph, &live, legs, visitor.is_some(), &mut rng);
            ("tour", p)
        }
        PathKind::Orbit => return Some(survey::orbit(&graph.bounds, speed)),
        PathKind::Flythrough => return Some(survey::flythrough(&graph.bounds, &[], speed)),
        PathKind::Revisit => {
            let mut p = tour_points(graph, &live, legs.div_ceil(2), visitor.is_some(), &mut rng);
            let back: Vec<Vec3> = p.iter().rev().skip(1).copied().collect();
            p.extend(back);
            ("revisit", p)
        }
        PathKind::Spin => {
            let c = biggest_cell(graph, &live);
            return Some(spin(graph.cells[c as usize].bounds.center(), turn));
        }
    };
    Some(match visitor {
        Some(objects) => gaze::walk(
            kind_name,
            &detour::round_objects(graph, objects, &points),
            speed.max(0.01),
            turn.max(0.01),
        ),
        None => gaze::along_travel(kind_name, &points, speed.max(0.01), turn.max(0.01)),
    })
}

/// Random rooms joined by their shortest portal chains. Where the building can be walked
/// (through doors and stair holes, never out and back in through a window: [`walkable`]), the
/// tour keeps to the rooms so reached and crosses each door at eye height; otherwise it takes
/// any chain, through portal centres.
fn tour_points(
    graph: &CellGraph,
    live: &[u32],
    legs: usize,
    round_rooms: bool,
    rng: &mut ChaCha8Rng,
) -> Vec<Vec3> {
    let walk: Vec<bool> = (0..graph.portals.len() as u32)
        .map(|p| walkable(graph, p))
        .collect();
    // The walkable part of the building: the largest set of rooms joined through walkable
    // portals (one flood fill over them).
    let mut is_live = vec![false; graph.cells.len()];
    live.iter().for_each(|&c| is_live[c as usize] = true);
    let mut seen = vec![false; graph.cells.len()];
    let mut rooms: Vec<u32> = Vec::new();
    for &start in live {
        if seen[start as usize] {
            continue;
        }
        let mut stack = vec![start];
        seen[start as usize] = true;
        let mut members = Vec::new();
        while let Some(c) = stack.pop() {
            if is_live[c as usize] {
                members.push(c);
            }
            for &p in &graph.cells[c as usize].portals {
                let n = graph.portals[p as usize].other(c);
                if walk[p as usize] && !seen[n as usize] {
                    seen[n as usize] = true;
                    stack.push(n);
                }
            }
        }
        if members.len() > rooms.len() {
            rooms = members;
        }
    }
    rooms.sort_unstable();
    // A closed room alone is walked too, between points inside it.
    let walking = rooms.len() >= 2 || live.len() == 1;
    let (live, through): (Vec<u32>, &dyn Fn(u32) -> bool) = if walking {
        (rooms, &|p| walk[p as usize])
    } else {
        (live.to_vec(), &|_| true)
    };
    // Rooms are visited at eye height above their floor when walking, else at their centre.
    let stand = |c: u32| {
        let b = &graph.cells[c as usize].bounds;
        let mut p = b.center();
        if walking {
            p.y = (b.min[1] + EYE_HEIGHT).min(b.max[1] - 0.1).max(b.min[1]);
        }
        p
    };
    // Start in a roomy cell so the first frames see something.
    let mut at = biggest_cell(graph, &live);
    let mut points = vec![stand(at)];
    for _ in 0..legs {
        let target = live[rng.random_range(0..live.len())];
        if target == at && live.len() == 1 {
            // One room: to a random point of its floor, half a metre from its walls.
            let b = &graph.cells[at as usize].bounds;
            let mut p = stand(at);
            for k in [0, 2] {
                let m = (0.5f32).min(0.25 * (b.max[k] - b.min[k]));
                p[k] = rng.random_range(b.min[k] + m..=b.max[k] - m);
            }
            points.push(p);
            continue;
        }
        let Some(chain) = portal_chain_by(graph, at, target, through) else {
            continue;
        };
        // Walk straight through each opening: a point before it in the cell left and one after
        // it in the cell entered, on the line through its centre across it (a visitor's last
        // steps to a door run square to its wall, beside a door leaf open against it, not
        // through it), each kept inside its cell. Consecutive points then share a cell, which is
        // convex: the path never leaves the live cells, and the observer turns inside rooms,
        // never standing in a portal's plane.
        let mut cell = at;
        for &p in &chain {
            let portal = &graph.portals[p as usize];
            let next = portal.other(cell);
            let (here, there) = (
                &graph.cells[cell as usize].bounds,
                &graph.cells[next as usize].bounds,
            );
            let a = portal.axis as usize;
            let mut n = Vec3::ZERO;
            n[a] = (there.center()[a] - here.center()[a]).signum();
            let c = portal.rect.center();
            // A visitor lines up a metre out, at most 0.45 of the cell's depth (so in a door's
            // own thin cell the point after one opening stays before the point before the
            // next: no step back); the benchmarks' path keeps its 0.4 m.
            let depth = |b: &Aabb| {
                if round_rooms {
                    (0.45 * (b.max[a] - b.min[a])).min(DOOR_APPROACH_M)
                } else {
                    0.4
                }
            };
            let (mut before, mut after) = (
                within(here, c - n * depth(here)),
                within(there, c + n * depth(there)),
            );
            if walking && a == 1 {
                // Up or down a stair's hole: standing on each side's floor.
                before.y = stand(cell).y.clamp(here.min[1], here.max[1]);
                after.y = stand(next).y.clamp(there.min[1], there.max[1]);
            } else if walking {
                let y = (portal.rect.min[1] + EYE_HEIGHT)
                    .min(portal.rect.max[1] - 0.1)
                    .max(portal.rect.min[1]);
                before.y = y.clamp(here.min[1], here.max[1]);
                after.y = y.clamp(there.min[1], there.max[1]);
            }
            points.push(before);
            points.push(after);
            cell = next;
        }
        match (walking && round_rooms)
            .then(|| {
                room_loop(
                    &graph.cells[target as usize].bounds,
                    points.last().copied(),
                    stand(target).y,
                )
            })
            .flatten()
        {
            // Look round the room, walking along its walls (a turn on the spot in a room's
            // middle would look at the wall beside it).
            Some(round) => points.extend(round),
            None => points.push(stand(target)),
        }
        at = target;
    }
    points
}

/// `p` moved inside `b`, at least a little (5 cm, or a quarter of a thin box) from its faces.
fn within(b: &Aabb, p: Vec3) -> Vec3 {
    let mut q = p;
    for i in 0..3 {
        let margin = (0.25 * (b.max[i] - b.min[i])).min(0.05);
        q[i] = p[i].clamp(b.min[i] + margin, b.max[i] - margin);
    }
    q
}

fn biggest_cell(graph: &CellGraph, live: &[u32]) -> u32 {
    let volume = |c: u32| {
        let s = graph.cells[c as usize].bounds.size();
        s.x * s.y.min(3.0) * s.z
    };
    live.iter()
        .copied()
        .max_by(|&a, &b| volume(a).total_cmp(&volume(b)))
        .unwrap_or(live[0])
}

/// One full turn on the spot.
fn spin(eye: Vec3, turn: f32) -> CameraPath {
    let steps = 16;
    let period = std::f32::consts::TAU / turn.max(0.01);
    let keyframes = (0..=steps)
        .map(|i| {
            let a = std::f32::consts::TAU * i as f32 / steps as f32;
            Keyframe {
                t: period * i as f32 / steps as f32,
                eye: eye.into(),
                dir: [a.cos(), 0.0, a.sin()],
            }
        })
        .collect();
    CameraPath {
        kind: "spin".into(),
        keyframes,
    }
}

/// Portals along a shortest cell path (breadth-first) from `from` to `to`, if connected.
pub fn portal_chain(graph: &CellGraph, from: u32, to: u32) -> Option<Vec<u32>> {
    portal_chain_by(graph, from, to, |_| true)
}

/// [`portal_chain`] through the portals `through` accepts only.
pub fn portal_chain_by(
    graph: &CellGraph,
    from: u32,
    to: u32,
    through: impl Fn(u32) -> bool,
) -> Option<Vec<u32>> {
    let mut came: HashMap<u32, (u32, u32)> = HashMap::new();
    let mut queue = VecDeque::from([from]);
    while let Some(c) = queue.pop_front() {
        if c == to {
            let mut chain = Vec::new();
            let mut cur = to;
            while cur != from {
                let (prev, portal) = came[&cur];
                chain.push(portal);
                cur = prev;
            }
            chain.reverse();
            return Some(chain);
        }
        for &p in &graph.cells[c as usize].portals {
            if !through(p) {
                continue;
            }
            let n = graph.portals[p as usize].other(c);
            if n != from && !came.contains_key(&n) {
                came.insert(n, (c, p));
                queue.push_back(n);
            }
        }
    }
    None
}

/// The unit direction a share `s` (0 to 1) of the way from `a` to `b`, turning at a steady
/// angular rate along the great circle (a linear blend would stand still and then flip at
/// once between opposite directions). Opposite directions turn about the vertical (about X
/// when they are vertical themselves); a zero direction is replaced by the other one.
pub fn turn_between(a: Vec3, b: Vec3, s: f32) -> Vec3 {
    let (Some(a), Some(b)) = (a.try_normalize(), b.try_normalize()) else {
        return b
            .try_normalize()
            .or(a.try_normalize())
            .unwrap_or(Vec3::NEG_Z);
    };
    let cross = a.cross(b);
    let angle = cross.length().atan2(a.dot(b));
    if angle < 1e-4 {
        return a.lerp(b, s).try_normalize().unwrap_or(b);
    }
    let axis = cross.try_normalize().unwrap_or_else(|| {
        let up = if a.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
        a.cross(up).cross(a).try_normalize().unwrap_or(Vec3::Y)
    });
    let turned = glam::Quat::from_axis_angle(axis, angle * s.clamp(0.0, 1.0)) * a;
    turned.try_normalize().unwrap_or(b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_view_turns_at_a_steady_rate_even_between_opposite_directions() {
        let (a, b) = (Vec3::Z, Vec3::NEG_Z);
        for (s, degrees) in [
            (0.0f32, 0.0f32),
            (0.25, 45.0),
            (0.5, 90.0),
            (0.75, 135.0),
            (1.0, 180.0),
        ] {
            let d = turn_between(a, b, s);
            assert!((d.length() - 1.0).abs() < 1e-5);
            assert!(d.y.abs() < 1e-5, "{d}: turning about the vertical");
            assert!(
                (a.angle_between(d).to_degrees() - degrees).abs() < 0.01,
                "{s}: {d}"
            );
        }
        // A quarter turn: 30° a third of the way.
        let d = turn_between(Vec3::X, Vec3::Z, 1.0 / 3.0);
        assert!((Vec3::X.angle_between(d).to_degrees() - 30.0).abs() < 0.01);
        // Looking straight up and then down turns about X.
        assert!(turn_between(Vec3::Y, Vec3::NEG_Y, 0.5).y.abs() < 1e-5);
        assert_eq!(turn_between(Vec3::ZERO, Vec3::X, 0.5), Vec3::X);
    }

    fn path() -> CameraPath {
        CameraPath {
            kind: "test".into(),
            keyframes: vec![
                Keyframe {
                    t: 0.0,
                    eye: [0.0; 3],
                    dir: [1.0, 0.0, 0.0],
                },
                Keyframe {
                    t: 2.0,
                    eye: [2.0, 0.0, 0.0],
                    dir: [1.0, 0.0, 0.0],
                },
                Keyframe {
                    t: 3.0,
                    eye: [2.0, 0.0, 0.0],
                    dir: [0.0, 0.0, 1.0],
                },
            ],
        }
    }

    #[test]
    fn sampling_interpolates_and_clamps() {
        let p = path();
        assert_eq!(p.duration(), 3.0);
        assert!((p.sample(1.0).0 - Vec3::new(1.0, 0.0, 0.0)).length() < 1e-6);
        assert!((p.sample(-5.0).0).length() < 1e-6);
        assert!((p.sample(9.0).1 - Vec3::Z).length() < 1e-6);
        let mid = p.sample(2.5).1;
        assert!((mid.length() - 1.0).abs() < 1e-5 && mid.x > 0.5 && mid.z > 0.5);
    }

    #[test]
    fn validation_rejects_bad_paths() {
        let mut p = path();
        assert!(p.validate().is_ok());
        p.keyframes[1].t = -1.0;
        assert!(p.validate().unwrap_err().contains("back in time"));
        p.keyframes[1].t = f32::NAN;
        assert!(p.validate().is_err());
        assert!(
            CameraPath {
                kind: "x".into(),
                keyframes: vec![]
            }
            .validate()
            .is_err()
        );
    }
}
