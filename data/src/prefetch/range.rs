//! The observer range and the range cells (Funkhouser §5.2.1–5.2.2).
//!
//! The observer range is every eye position reachable in the next N frames (a sphere of radius
//! N·v_p·Δt around the eye) and every view direction (a range frustum widened by N·v_r·Δt whose
//! eye sits behind the observer so that it contains the sphere). Range cells are found by
//! Dijkstra's method over the cell adjacency graph in "frames before the observer can enter the
//! cell"; the range cull algorithm keeps only cells that satisfy a directional constraint.

use crate::cells::realtime::Frustum;
use crate::cells::{CellGraph, touches};
use crate::geometry::Aabb;
use crate::geometry::slab;
use glam::Vec3;
use portico_protocol::{LookaheadCull, Observer, Policy, RangeCull};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// The observer range for one request.
#[derive(Debug, Clone)]
pub struct ObserverRange {
    /// Eye position now.
    pub eye: Vec3,
    /// Unit view direction.
    pub dir: Vec3,
    /// Metres the observer can move in one frame (v_p·Δt).
    pub step: f32,
    /// Lookahead depth N in frames.
    pub depth: u32,
    /// Radius of the range sphere (N·step).
    pub radius: f32,
    /// The range frustum, or `None` when widening made it cover every direction.
    pub frustum: Option<Frustum>,
    /// Metres the eye may be from [`ObserverRange::eye`] (0 for one observer; half a cell's
    /// diagonal for a range shared by every observer in the cell, see
    /// [`ObserverRange::for_cell`]).
    pub slack: f32,
    /// Radians the view direction may be from [`ObserverRange::dir`] (0 for one observer).
    pub spread: f32,
    /// The cell Dijkstra starts from (`None`: the cell holding the eye).
    pub start: Option<u32>,
    /// Where the eye may be: the eye itself, or the shared cell's box.
    pub eyes: Aabb,
    /// With `spread`, the cone every view ray of the shared observers lies in (the direction
    /// range cull's test); `None` when it covers every direction.
    pub ray_cone: Option<Frustum>,
}

impl ObserverRange {
    /// The range of `obs` under `policy`.
    pub fn new(obs: &Observer, policy: &Policy) -> ObserverRange {
        let eye = Vec3::from(obs.eye);
        let dir = Vec3::from(obs.dir).try_normalize().unwrap_or(Vec3::NEG_Z);
        let step = (obs.max_speed.max(0.0) * policy.frame_time_s.max(0.0)).max(0.0);
        let depth = policy.depth_frames;
        let radius = step * depth as f32;
        let turn = obs.max_turn.max(0.0) * policy.frame_time_s.max(0.0) * depth as f32;
        let (hx, hy) = (obs.half_fov_x + turn, obs.half_fov_y + turn);
        let limit = std::f32::consts::FRAC_PI_2 - 0.02;
        let frustum = (hx < limit && hy < limit && hx > 0.0 && hy > 0.0).then(|| {
            // Move the eye back until the frustum contains the range sphere.
            let back = radius / hx.min(hy).sin();
            let mut up = Vec3::from(obs.up).try_normalize().unwrap_or(Vec3::Y);
            if up.cross(dir).length_squared() < 1e-6 {
                up = if dir.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
            }
            Frustum::new(eye - dir * back, dir, up, hx, hy)
        });
        ObserverRange {
            eye,
            dir,
            step,
            depth,
            radius,
            frustum,
            slack: 0.0,
            spread: 0.0,
            start: None,
            eyes: Aabb {
                min: eye.into(),
                max: eye.into(),
            },
            ray_cone: None,
        }
    }

    /// One range that holds the range of every observer in `cell` (box `bounds`) whose view
    /// direction is within `spread` radians of `dir`, with `obs`'s speed, turn rate and field of
    /// view: the sphere is centred on the cell and grown by half its diagonal, and the frustum
    /// (and the direction cull's cone) open by `spread` and step back until they hold the cell.
    /// Every cone from a point inside a convex cone, opening no wider than it, lies inside it,
    /// so each test below is a superset of the one observer's. Plane culls cannot be widened
    /// that way and keep everything.
    pub fn for_cell(
        cell: u32,
        bounds: &Aabb,
        dir: Vec3,
        spread: f32,
        obs: &Observer,
        policy: &Policy,
    ) -> ObserverRange {
        let centre = (Vec3::from(bounds.min) + Vec3::from(bounds.max)) * 0.5;
        let slack = (Vec3::from(bounds.max) - Vec3::from(bounds.min)).length() * 0.5;
        let dir = dir.try_normalize().unwrap_or(Vec3::NEG_Z);
        let step = (obs.max_speed.max(0.0) * policy.frame_time_s.max(0.0)).max(0.0);
        let depth = policy.depth_frames;
        let radius = step * depth as f32 + slack;
        let turn = obs.max_turn.max(0.0) * policy.frame_time_s.max(0.0) * depth as f32;
        let up = if dir.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
        let limit = std::f32::consts::FRAC_PI_2 - 0.02;
        let cone = |half: f32, reach: f32| {
            (half < limit && half > 0.0).then(|| {
                let back = reach / half.sin();
                Frustum::new(centre - dir * back, dir, up, half, half)
            })
        };
        // One observer's range frustum (see `new`): half-angles widened by the turn, its apex
        // stepped back by `r / sin(min)`. Whatever its roll, its rays are within the corner
        // angle of its axis, and its apex within `slack + r / sin(min)` of the cell's centre:
        // a cone opened by the corner angle plus the spread, stepped back that far, holds it.
        let (hx, hy) = (obs.half_fov_x + turn, obs.half_fov_y + turn);
        let frustum = if hx > 0.0 && hy > 0.0 && hx < limit && hy < limit {
            let (tx, ty) = (hx.tan(), hy.tan());
            let corner = (tx * tx + ty * ty).sqrt().atan();
            let back = step * depth as f32 / hx.min(hy).sin();
            cone(corner + spread, slack + back)
        } else {
            None // the one observer keeps a half-space, which no cone holds
        };
        ObserverRange {
            eye: centre,
            dir,
            step,
            depth,
            radius,
            frustum,
            slack,
            spread,
            start: Some(cell),
            eyes: *bounds,
            ray_cone: cone(spread, slack),
        }
    }

    /// Frames before the observer can reach the box `b` (0 when the eye is inside it).
    pub fn frames_to(&self, b: &Aabb) -> u32 {
        let d = distance_to_box(self.eye, b) - self.slack;
        if d <= 0.0 {
            0
        } else if self.step <= 0.0 {
            u32::MAX
        } else {
            (d / self.step).ceil().min(u32::MAX as f32) as u32
        }
    }

    /// Whether a box is at least partly in front of the observer plane, moved back by the
    /// range radius so that every position in the range counts.
    pub fn in_front(&self, b: &Aabb) -> bool {
        if self.spread > 0.0 {
            return true; // no half-space holds every shared observer's
        }
        let far = Vec3::new(
            if self.dir.x >= 0.0 {
                b.max[0]
            } else {
                b.min[0]
            },
            if self.dir.y >= 0.0 {
                b.max[1]
            } else {
                b.min[1]
            },
            if self.dir.z >= 0.0 {
                b.max[2]
            } else {
                b.min[2]
            },
        );
        (far - self.eye).dot(self.dir) >= -self.radius
    }

    /// Whether a box touches the range frustum.
    pub fn in_frustum(&self, b: &Aabb) -> bool {
        match &self.frustum {
            Some(f) => f.touches(b),
            None => self.in_front(b),
        }
    }

    /// Whether a ray from the eye along the view direction hits the box.
    pub fn on_ray(&self, b: &Aabb) -> bool {
        if self.spread > 0.0 {
            return self.ray_cone.as_ref().is_none_or(|c| c.touches(b));
        }
        slab(self.eye, self.dir, b).is_some_and(|(_, t1)| t1 >= 0.0)
    }

    /// The range cull algorithm's test for a candidate range cell.
    pub fn range_keeps(&self, cull: RangeCull, b: &Aabb) -> bool {
        match cull {
            RangeCull::Any => true,
            RangeCull::Plane => self.in_front(b),
            RangeCull::Frustum => self.in_frustum(b),
            RangeCull::Direction => self.on_ray(b),
        }
    }

    /// The lookahead cull algorithm's test for a cell visible from a range cell.
    pub fn lookahead_keeps(&self, cull: LookaheadCull, region: &Aabb) -> bool {
        match cull {
            LookaheadCull::Any => true,
            LookaheadCull::Plane => self.in_front(region),
            LookaheadCull::Frustum => self.in_frustum(region),
            // The predicted lookahead does not cull range cells' visibility; where it falls
            // back to it, it keeps everything.
            LookaheadCull::Predicted => true,
        }
    }
}

/// Euclidean distance from a point to a box (0 inside).
pub fn distance_to_box(p: Vec3, b: &Aabb) -> f32 {
    let mut d2 = 0.0;
    for k in 0..3 {
        let e = (b.min[k] - p[k]).max(p[k] - b.max[k]).max(0.0);
        d2 += e * e;
    }
    d2.sqrt()
}

/// The live cell the observer is in, or the nearest live cell when the eye is in a wall or
/// outside the model (a client may be slightly off; it still gets an answer).
pub fn start_cell(graph: &CellGraph, eye: Vec3) -> Option<u32> {
    if let Some(c) = graph.locate(eye).filter(|&c| graph.cells[c as usize].live) {
        return Some(c);
    }
    (0..graph.cells.len() as u32)
        .filter(|&c| graph.cells[c as usize].live)
        .min_by(|&a, &b| {
            let da = distance_to_box(eye, &graph.cells[a as usize].bounds);
            let db = distance_to_box(eye, &graph.cells[b as usize].bounds);
            da.total_cmp(&db)
        })
}

/// Range cells in order of frames-to-enter: Dijkstra over the adjacency graph, where entering a
/// neighbour through a portal takes at least the straight-line distance from the eye to the
/// portal (a lower bound on any walk, so the range stays a superset of the reachable cells).
/// Observers cannot walk through walls: only portals connect cells.
pub fn range_cells(graph: &CellGraph, range: &ObserverRange, cull: RangeCull) -> Vec<(u32, u32)> {
    let Some(start) = range.start.or_else(|| start_cell(graph, range.eye)) else {
        return Vec::new();
    };
    let mut best = vec![u32::MAX; graph.cells.len()];
    let mut done = vec![false; graph.cells.len()];
    let mut heap = BinaryHeap::from([Reverse((0u32, start))]);
    best[start as usize] = 0;
    let mut out = Vec::new();
    while let Some(Reverse((frames, cell))) = heap.pop() {
        if std::mem::replace(&mut done[cell as usize], true) {
            continue;
        }
        out.push((cell, frames));
        for &p in &graph.cells[cell as usize].portals {
            let portal = &graph.portals[p as usize];
            let next = portal.other(cell) as usize;
            let nb = &graph.cells[next];
            if done[next] || !nb.live || !range.range_keeps(cull, &nb.bounds) {
                continue;
            }
            // A shared range's slack would put the next rooms at frame 0, where everything is
            // mandatory: only the eye cell is reached now.
            let f = frames
                .max(range.frames_to(&portal.rect))
                .max(u32::from(range.slack > 0.0));
            if f <= range.depth && f < best[next] {
                best[next] = f;
                heap.push(Reverse((f, next as u32)));
            }
        }
    }
    out
}

/// Whether two boxes overlap (touching counts); re-exported for the lookahead.
pub fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    touches(a, b)
}

#[cfg(test)]
#[path = "range_tests.rs"]
mod tests;
