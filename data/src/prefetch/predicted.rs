//! The predicted-view lookahead (`look=predicted`): the objects visible from where the observer
//! is going, rather than from anywhere in the cells it could reach.
//!
//! Funkhouser's lookahead (§5.2.2) takes every object of every range cell's cell-to-object
//! visibility: what can be seen from anywhere in those cells, looking anywhere. Along a tour
//! most of it is never seen (the load tester's breakdown of bytes never drawn: on flattened
//! `soda` 3.7 of the 4.0 MB per client were objects no frame drew at any LOD). Here the
//! lookahead is eye-to-object visibility (§4.1.2), looking all around, from the eye and from
//! points ahead of it along its velocity, every [`STEP_FRAMES`] frames up to the lookahead depth
//! (a walk goes on as it goes, within the next second: the motion prediction of Funkhouser
//! §5.2.1 with the velocity instead of the maximum speed in every direction). The points stop
//! where the walk would leave the live cells or pass from a cell to one that is not its
//! neighbour through a portal: nobody walks through walls.
//!
//! Objects are tested against the wedges through portals and the view exactly
//! ([`crate::cells::realtime::Cone::meets`]), not plane by plane: a big box beside the eye that
//! meets each plane's inside but no sightline was listed, and the places of
//! [`super::swept`], which must hold this answer, could not hold it.
//!
//! Each object is listed from the first point that sees it (its frames until visible), at the
//! finest LOD the size threshold allows at its distance from the nearest point at or after that
//! one. Looking all around from each point covers any turn; a change of course is seen by the
//! next answer, a round trip later.

use super::lookahead::{max_lod, projected_pixels};
use super::range::{self, ObserverRange, distance_to_box};
use super::{Budget, Candidate, Prefetcher, need};
use crate::cells::CellGraph;
use crate::cells::realtime::{Cone, Frustum, eye_to_cell, eye_to_object_exact};
use crate::error::Result;
use glam::Vec3;
use portico_protocol::{NeedItem, NeedKind, Observer, Policy};
use std::collections::{HashMap, HashSet};

/// Frames between two predicted eye positions.
pub const STEP_FRAMES: u32 = 2;

/// One predicted eye position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PredictedEye {
    /// Where the eye is predicted to be.
    pub at: Vec3,
    /// Frames from now.
    pub frames: u32,
    /// The live cell holding it.
    pub cell: u32,
}

/// The eye now and where it is predicted to be every [`STEP_FRAMES`] frames up to
/// `policy.depth_frames`: along `obs.velocity` until the walk would leave the live cells or pass
/// from a cell to one that is not its neighbour through a portal, standing there after that
/// (the view may still turn). Empty when the eye itself is in no live cell.
pub fn predicted_eyes(graph: &CellGraph, obs: &Observer, policy: &Policy) -> Vec<PredictedEye> {
    let eye = Vec3::from(obs.eye);
    let live = |p: Vec3| graph.locate(p).filter(|&c| graph.cells[c as usize].live);
    let Some(first) = live(eye) else {
        return Vec::new();
    };
    let mut out = vec![PredictedEye {
        at: eye,
        frames: 0,
        cell: first,
    }];
    let v = Vec3::from(obs.velocity);
    let dt = policy.frame_time_s.max(0.0);
    let mut moving = v.is_finite() && v.length_squared() >= 1e-6 && dt > 0.0;
    let mut frames = STEP_FRAMES;
    while frames <= policy.depth_frames {
        let last = out[out.len() - 1];
        let mut next = PredictedEye { frames, ..last };
        if moving {
            let at = eye + v * (frames as f32 * dt);
            let joined = live(at).filter(|&cell| {
                cell == last.cell
                    || graph.cells[last.cell as usize]
                        .portals
                        .iter()
                        .any(|&p| graph.portals[p as usize].other(last.cell) == cell)
            });
            match joined {
                Some(cell) => {
                    next.at = at;
                    next.cell = cell;
                }
                None => moving = false,
            }
        }
        out.push(next);
        frames += STEP_FRAMES;
    }
    out
}

/// What an eye at `e` may see: the view turned on by the observer's angular velocity until
/// then, widened by [`TURN_SHARE`] of its maximum turn rate over those frames (a turn it may
/// start: Funkhouser §5.2.1's range frustum, widened per frame); all around once that opens
/// past a half-space.
pub fn view_at(obs: &Observer, policy: &Policy, e: &PredictedEye) -> Frustum {
    let t = policy.frame_time_s.max(0.0) * e.frames as f32;
    let widen = TURN_SHARE * obs.max_turn.max(0.0) * t;
    let (hx, hy) = (obs.half_fov_x + widen, obs.half_fov_y + widen);
    let limit = std::f32::consts::FRAC_PI_2 - 0.02;
    let dir = Vec3::from(obs.dir);
    let opens = hx > 0.0 && hy > 0.0 && hx < limit && hy < limit;
    if !opens || !dir.is_finite() {
        return Frustum::all_around(e.at);
    }
    let turn = Vec3::from(obs.turn);
    let turned = if turn.is_finite() {
        glam::Quat::from_scaled_axis(turn * t) * dir
    } else {
        dir
    };
    let dir = turned.try_normalize().unwrap_or(Vec3::NEG_Z);
    let mut up = Vec3::from(obs.up).try_normalize().unwrap_or(Vec3::Y);
    if up.cross(dir).length_squared() < 1e-6 {
        up = if dir.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
    }
    Frustum::new(e.at, dir, up, hx, hy)
}

/// The share of the maximum turn rate a predicted view is widened by, for a turn the observer
/// may start: on `soda`'s tour (8 clients, 50 ms / 10 Mbit/s) a quarter kept the objects
/// skipped at the oracle's (0.31 against 0.33 per frame) for 0.9 MB per client; none skipped
/// 0.66 (the tour turns on the spot between rooms), a half fetched 1.0 MB, the whole 1.4 MB.
pub const TURN_SHARE: f32 = 0.25;

impl Prefetcher {
    /// The predicted-view lookahead (see the module): stab lists of the range cells, then
    /// every object seen from a predicted eye, with `now` marking the objects in view. `None`
    /// when the eye is in no live cell (the caller falls back to the range's lookahead).
    #[allow(clippy::type_complexity, clippy::too_many_arguments)]
    pub(super) fn lookahead_predicted(
        &self,
        graph: &CellGraph,
        range: &ObserverRange,
        now: &HashSet<u32>,
        obs: &Observer,
        policy: &Policy,
        budget: &Budget,
    ) -> Result<Option<(u32, Vec<NeedItem>, Vec<Candidate>, u32)>> {
        let eyes = predicted_eyes(graph, obs, policy);
        if eyes.is_empty() {
            return Ok(None);
        }
        let ranged = range::range_cells(graph, range, policy.range_cull);
        budget.check()?;
        let stab_items: Vec<NeedItem> = ranged
            .iter()
            .filter_map(|&(cell, frames)| {
                let seg = self.stab_segment(cell)?;
                Some(need(
                    seg,
                    NeedKind::Stab,
                    0,
                    self.segment_bytes(seg),
                    frames,
                ))
            })
            .collect();
        // Objects in the order the eyes first see them, with that eye's index.
        let mut first: HashMap<u32, usize> = HashMap::new();
        let mut order: Vec<u32> = Vec::new();
        let mut cells = HashSet::new();
        // What is seen all around from each position (searched once per position: a standing
        // observer's samples share one), then what of it each sample's view touches.
        let mut around: Option<(Vec3, Vec<u32>)> = None;
        for (k, e) in eyes.iter().enumerate() {
            budget.check()?;
            if around.as_ref().is_none_or(|(at, _)| *at != e.at) {
                let reached = eye_to_cell(graph, &Frustum::all_around(e.at));
                cells.extend(reached.iter().map(|r| r.cell));
                let stab = self.stab(e.cell)?;
                let seen = eye_to_object_exact(&reached, &stab, &self.bounds, e.at);
                around = Some((e.at, seen));
            }
            let view = view_at(obs, policy, e);
            let view = Cone::new(view.eye, &view.planes);
            let seen = around.as_ref().map_or(&[][..], |a| &a.1[..]);
            for &o in seen {
                if view.meets(&self.bounds[o as usize])
                    && let std::collections::hash_map::Entry::Vacant(v) = first.entry(o)
                {
                    v.insert(k);
                    order.push(o);
                }
            }
        }
        let sample_frames: Vec<u32> = eyes.iter().map(|e| e.frames).collect();
        let cands = self.timed_candidates(
            (&order, &first),
            &sample_frames,
            |j, b| distance_to_box(eyes[j].at, b),
            |o, _| now.contains(&o),
            (range, obs, policy),
            budget,
        )?;
        let stab_items = if policy.impostors {
            self.with_textures(stab_items, &cands, &range.eyes)
        } else {
            stab_items
        };
        Ok(Some((
            ranged.len() as u32,
            stab_items,
            cands,
            cells.len() as u32,
        )))
    }
}

impl Prefetcher {
    /// The candidates of the objects in `order`, object `o` first seen at sample `first[o]`
    /// (`frames[k]`: sample `k`'s frames ahead), each at the finest LOD the size threshold
    /// allows at its nearest sample from then on (`distance(j, bounds)`: metres from sample
    /// `j`), its finer LODs timed by [`Prefetcher::time_lods`] (`in_view(o, k)`: in view now);
    /// until memory is claimed past the cache once everything visible now is in (Funkhouser
    /// §5.2.2 condition 2). One observer's lookahead and a place's ([`super::swept`]) both end
    /// here.
    pub(super) fn timed_candidates(
        &self,
        (order, first): (&[u32], &HashMap<u32, usize>),
        frames: &[u32],
        distance: impl Fn(usize, &crate::geometry::Aabb) -> f32,
        in_view: impl Fn(u32, usize) -> bool,
        (range, obs, policy): (&ObserverRange, &Observer, &Policy),
        budget: &Budget,
    ) -> Result<Vec<Candidate>> {
        let mut cands = Vec::new();
        let mut claimed = 0u64;
        let mut claimed_mips = HashSet::new();
        for (i, &o) in order.iter().enumerate() {
            if i % 1024 == 0 {
                budget.check()?;
            }
            let k = first[&o];
            let bounds = &self.bounds[o as usize];
            let near: Vec<(u32, f32)> = (k..frames.len())
                .map(|j| (frames[j], distance(j, bounds)))
                .collect();
            let nearest = near.iter().map(|n| n.1).fold(f32::INFINITY, f32::min);
            let at = cands.len();
            claimed += self.add_object(
                o,
                frames[k],
                Some(nearest),
                range,
                obs.half_fov_y,
                policy,
                &mut cands,
                &mut claimed_mips,
            );
            self.time_lods(&mut cands[at..], o, &near, in_view(o, k), obs, policy);
            if frames[k] > 0 && claimed > policy.cache_bytes {
                break;
            }
        }
        Ok(cands)
    }

    /// Sets when each of object `o`'s candidates is needed: each finer LOD from the first
    /// sample near enough for it (`near`: the samples from the object's first, as frames and
    /// the distance to the object then; its deadline), the useful texture level with the finest
    /// LOD; `now` marks it in view.
    pub(super) fn time_lods(
        &self,
        cands: &mut [Candidate],
        o: u32,
        near: &[(u32, f32)],
        now: bool,
        obs: &Observer,
        policy: &Policy,
    ) {
        let Some(&(first, _)) = near.first() else {
            return;
        };
        let bounds = &self.bounds[o as usize];
        let finest = cands
            .iter()
            .filter(|c| c.item.kind == NeedKind::Geometry)
            .map(|c| c.item.lod)
            .min();
        let header = self.db.header();
        let lods = header.instances.get(o as usize).map(|i| header.lods_of(i));
        let needed_from = |lod: u8| -> u32 {
            let Some(lods) = lods else {
                return first;
            };
            near.iter()
                .find(|&&(_, d)| {
                    let px = projected_pixels(bounds, d, policy, obs.half_fov_y);
                    max_lod(lods, px, policy.size_threshold_px.max(0.0)) <= lod as usize
                })
                .map_or(first, |&(f, _)| f)
        };
        for c in cands {
            let lod = match c.item.kind {
                NeedKind::Geometry => Some(c.item.lod),
                NeedKind::Mips if c.item.lod > 0 => finest,
                _ => None,
            };
            if let Some(lod) = lod {
                c.frames = needed_from(lod);
                c.item.frames = c.frames;
            }
            c.now = now;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::{Cell, KdNode, Portal};
    use crate::geometry::Aabb;

    /// Three cells along x: [0,4] and [4,8] joined by a portal at x = 4, then [8,12] behind a
    /// wall (no portal from the middle one).
    fn corridor() -> CellGraph {
        let cell = |x0: f32, portals: Vec<u32>| Cell {
            bounds: Aabb {
                min: [x0, 0.0, 0.0],
                max: [x0 + 4.0, 3.0, 3.0],
            },
            live: true,
            portals,
        };
        CellGraph {
            bounds: Aabb {
                min: [0.0, 0.0, 0.0],
                max: [12.0, 3.0, 3.0],
            },
            cells: vec![cell(0.0, vec![0]), cell(4.0, vec![0]), cell(8.0, vec![])],
            portals: vec![Portal {
                axis: 0,
                rect: Aabb {
                    min: [4.0, 0.0, 0.0],
                    max: [4.0, 3.0, 3.0],
                },
                cells: [0, 1],
            }],
            tree: vec![
                KdNode::Split {
                    axis: 0,
                    at: 4.0,
                    lo: 1,
                    hi: 2,
                },
                KdNode::Leaf(0),
                KdNode::Split {
                    axis: 0,
                    at: 8.0,
                    lo: 3,
                    hi: 4,
                },
                KdNode::Leaf(1),
                KdNode::Leaf(2),
            ],
            grid_fallback: false,
        }
    }

    fn walking(eye: [f32; 3], velocity: [f32; 3]) -> Observer {
        Observer {
            eye,
            dir: [1.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            velocity,
            half_fov_x: 0.6,
            half_fov_y: 0.5,
            max_speed: 1.0,
            max_turn: 1.0,
            turn: [0.0; 3],
        }
    }

    #[test]
    fn eyes_follow_the_velocity_through_portals_and_stop_at_walls() {
        let g = corridor();
        let policy = Policy {
            depth_frames: 16,
            frame_time_s: 0.5,
            ..Policy::default()
        };
        // 1 m/s along +x from x = 1: a point every metre.
        // x = 4..8 is through the portal, and x = 8 is behind the wall, where the walk stops
        // (and the observer stands, for the rest of the depth).
        let eyes = predicted_eyes(&g, &walking([1.0, 1.5, 1.5], [1.0, 0.0, 0.0]), &policy);
        let xs: Vec<f32> = eyes.iter().map(|e| e.at.x).collect();
        assert_eq!(xs, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 7.0, 7.0]);
        assert_eq!(eyes[3].cell, 1);
        assert_eq!(eyes[8].cell, 1);
        let frames: Vec<u32> = eyes.iter().map(|e| e.frames).collect();
        assert_eq!(frames, vec![0, 2, 4, 6, 8, 10, 12, 14, 16]);
        // Standing still: the eye at every sample (the view may turn); outside every cell:
        // nothing.
        let still = predicted_eyes(&g, &walking([1.0, 1.5, 1.5], [0.0; 3]), &policy);
        assert_eq!(still.len(), 9);
        assert!(still.iter().all(|e| e.at.x == 1.0 && e.cell == 0));
        assert!(
            predicted_eyes(&g, &walking([-1.0, 1.5, 1.5], [1.0, 0.0, 0.0]), &policy).is_empty()
        );
    }
}
