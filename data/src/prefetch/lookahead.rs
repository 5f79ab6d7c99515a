//! The lookahead set and each object's maximum LOD (Funkhouser §5.2.2).
//!
//! For every range cell (in the order Dijkstra found them) the cells in its cell-to-cell
//! visibility that pass the lookahead cull contribute objects: the ones in the range cell's
//! cell-to-object visibility (object granularity) or every object incident upon the visible cell
//! (cell granularity). Each object is stored only up to the LOD a static size threshold allows
//! at the nearest point of the observer range, so near objects get finer LODs than far ones
//! (Fig. 5.8). The search stops once the lookahead claims more than the client's cache holds
//! (condition 2 of §5.2.2), but never before everything visible from the eye cell is in.

use super::range::{self, ObserverRange, distance_to_box};
use super::{Budget, Candidate, Prefetcher, need};
use crate::cells::CellGraph;
use crate::cells::realtime::{Frustum, eye_to_cell, eye_to_object};
use crate::error::Result;
use crate::format::LodRecord;
use crate::geometry::Aabb;
use portico_protocol::{Granularity, NeedItem, NeedKind, Observer, Policy};
use std::collections::HashSet;

/// Projected screen area (pixels) of a box seen from `distance` metres: the area of its
/// bounding sphere's disc, capped at the screen.
pub fn projected_pixels(bounds: &Aabb, distance: f32, policy: &Policy, half_fov_y: f32) -> f32 {
    let screen = policy.screen[0] as f32 * policy.screen[1] as f32;
    let radius = bounds.size().length() * 0.5;
    let focal = policy.screen[1] as f32 * 0.5 / half_fov_y.clamp(0.05, 1.5).tan();
    if distance <= radius {
        return screen;
    }
    let r_px = radius * focal / distance;
    (std::f32::consts::PI * r_px * r_px).min(screen)
}

/// Index (0 = finest) of the finest LOD whose average polygon covers at least `threshold`
/// pixels when the object covers `pixels`; the coarsest LOD when none does.
pub fn max_lod(lods: &[LodRecord], pixels: f32, threshold: f32) -> usize {
    let last = lods.len().saturating_sub(1);
    lods.iter()
        .position(|l| pixels / (l.triangles.max(1) as f32) >= threshold)
        .unwrap_or(last)
}

/// The finest LOD an observer anywhere in the range could want for an object.
pub fn max_lod_in_range(
    lods: &[LodRecord],
    bounds: &Aabb,
    range: &ObserverRange,
    policy: &Policy,
    half_fov_y: f32,
) -> usize {
    let nearest = (distance_to_box(range.eye, bounds) - range.radius).max(0.0);
    let px = projected_pixels(bounds, nearest, policy, half_fov_y);
    max_lod(lods, px, policy.size_threshold_px.max(0.0))
}

impl Prefetcher {
    /// Range cells → visible cells → objects → LOD candidates.
    #[allow(clippy::type_complexity)]
    pub(super) fn lookahead_with_cells(
        &self,
        graph: &CellGraph,
        range: &ObserverRange,
        now: &HashSet<u32>,
        half_fov_y: f32,
        policy: &Policy,
        budget: &Budget,
    ) -> Result<(u32, Vec<NeedItem>, Vec<Candidate>, u32)> {
        let ranged = range::range_cells(graph, range, policy.range_cull);
        budget.check()?;
        let mut stab_items = Vec::new();
        let mut seen_obj = vec![false; self.db.header().instances.len()];
        let mut seen_cell = vec![false; graph.cells.len()];
        let mut cands = Vec::new();
        let mut claimed = 0u64;
        let mut claimed_mips = HashSet::new();
        let mut lookahead_cells = 0u32;
        'outer: for &(cell, frames) in &ranged {
            if let Some(seg) = self.stab_segment(cell) {
                stab_items.push(need(
                    seg,
                    NeedKind::Stab,
                    0,
                    self.segment_bytes(seg),
                    frames,
                ));
            }
            let stab = self.stab(cell)?;
            for entry in &stab.entries {
                budget.check()?;
                if !range.lookahead_keeps(policy.lookahead_cull, &entry.region) {
                    continue;
                }
                if !std::mem::replace(&mut seen_cell[entry.cell as usize], true) {
                    lookahead_cells += 1;
                }
                let objects = match policy.granularity {
                    Granularity::Object => entry.objects.clone(),
                    Granularity::Cell => {
                        let s = self.stab(entry.cell)?;
                        s.inside.iter().chain(&s.partial).copied().collect()
                    }
                };
                for o in objects {
                    if std::mem::replace(&mut seen_obj[o as usize], true) {
                        continue;
                    }
                    let first = cands.len();
                    claimed += self.add_object(
                        o,
                        frames,
                        None,
                        range,
                        half_fov_y,
                        policy,
                        &mut cands,
                        &mut claimed_mips,
                    );
                    if now.contains(&o) {
                        cands[first..].iter_mut().for_each(|c| c.now = true);
                    }
                }
                // §5.2.2 condition 2: memory is claimed, and everything visible now is in.
                if frames > 0 && claimed > policy.cache_bytes {
                    break 'outer;
                }
            }
        }
        let stab_items = if policy.impostors {
            self.with_textures(stab_items, &cands, &range.eyes)
        } else {
            stab_items
        };
        Ok((ranged.len() as u32, stab_items, cands, lookahead_cells))
    }

    /// The objects in the observer's view right now: eye-to-object visibility from the eye
    /// cell's stab list through the portals (§4.1.2), as the client culls. Empty outside every
    /// live cell.
    pub(super) fn visible_now(&self, graph: &CellGraph, obs: &Observer) -> Result<HashSet<u32>> {
        let eye = glam::Vec3::from(obs.eye);
        let Some(cell) = graph.locate(eye).filter(|&c| graph.cells[c as usize].live) else {
            return Ok(HashSet::new());
        };
        let dir = glam::Vec3::from(obs.dir)
            .try_normalize()
            .unwrap_or(glam::Vec3::NEG_Z);
        let mut up = glam::Vec3::from(obs.up)
            .try_normalize()
            .unwrap_or(glam::Vec3::Y);
        if up.cross(dir).length_squared() < 1e-6 {
            up = if dir.y.abs() < 0.9 {
                glam::Vec3::Y
            } else {
                glam::Vec3::X
            };
        }
        let (hx, hy) = (
            obs.half_fov_x.clamp(0.01, 1.55),
            obs.half_fov_y.clamp(0.01, 1.55),
        );
        let view = Frustum::new(eye, dir, up, hx, hy);
        let reached = eye_to_cell(graph, &view);
        let stab = self.stab(cell)?;
        Ok(eye_to_object(&reached, &stab, &self.bounds)
            .into_iter()
            .collect())
    }

    /// Without cells every object is a lookahead object, needed when the observer can reach it.
    pub(super) fn lookahead_without_cells(
        &self,
        range: &ObserverRange,
        obs: &Observer,
        policy: &Policy,
        budget: &Budget,
    ) -> Result<Vec<Candidate>> {
        let mut cands = Vec::new();
        let mut claimed = 0u64;
        let mut claimed_mips = HashSet::new();
        let mut order: Vec<(u32, u32)> = self
            .db
            .header()
            .instances
            .iter()
            .enumerate()
            .map(|(i, inst)| (range.frames_to(&inst.bounds), i as u32))
            .collect();
        order.sort_unstable();
        for (i, (frames, o)) in order.into_iter().enumerate() {
            if i % 1024 == 0 {
                budget.check()?;
            }
            if frames > 0 && claimed > policy.cache_bytes {
                break;
            }
            let frames = frames.min(range.depth);
            claimed += self.add_object(
                o,
                frames,
                None,
                range,
                obs.half_fov_y,
                policy,
                &mut cands,
                &mut claimed_mips,
            );
        }
        Ok(cands)
    }

    /// Adds the LODs of one object from the coarsest up to its maximum, the finest the size
    /// threshold allows at `nearest` metres (default: the nearest point of `range`); returns
    /// the bytes they will occupy in the client's cache (decoded: a compressed segment claims
    /// its plain size).
    /// A textured object's coarse texture segment comes right after its coarsest LOD with
    /// texture coordinates, and the segment of the finest mip useful at the nearest point of
    /// the range ([`crate::texture::TextureRecord::useful_segment`]) right after its finest;
    /// texture bytes are claimed once per segment (`claimed_mips`).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn add_object(
        &self,
        o: u32,
        frames: u32,
        nearest: Option<f32>,
        range: &ObserverRange,
        half_fov_y: f32,
        policy: &Policy,
        cands: &mut Vec<Candidate>,
        claimed_mips: &mut HashSet<u32>,
    ) -> u64 {
        let header = self.db.header();
        let Some(inst) = header.instances.get(o as usize) else {
            return 0;
        };
        let lods = header.lods_of(inst);
        let nearest = nearest
            .unwrap_or_else(|| (distance_to_box(range.eye, &inst.bounds) - range.radius).max(0.0));
        let px = projected_pixels(&inst.bounds, nearest, policy, half_fov_y);
        let max = max_lod(lods, px, policy.size_threshold_px.max(0.0));
        let texture = header.texture_of(inst).map(|t| {
            let px = px.sqrt();
            let span = header
                .objects
                .get(inst.object as usize)
                .map_or(1.0, |r| r.uv_span);
            (t, t.useful_segment(px, span))
        });
        let coarsest_uv = lods.iter().rposition(|l| l.uv);
        let mut bytes = 0;
        let push = |cands: &mut Vec<Candidate>, item: NeedItem, level: u32| {
            cands.push(Candidate {
                now: false,
                object: o,
                level,
                frames,
                seq: cands.len() as u32,
                item,
            });
        };
        for (i, l) in lods.iter().enumerate().skip(max) {
            let b = self.segment_bytes(l.segment);
            bytes += crate::geometry::plain_size(l.vertices, l.triangles, l.uv).max(b);
            let level = (lods.len() - 1 - i) as u32;
            push(
                cands,
                need(l.segment, NeedKind::Geometry, i as u8, b, frames),
                level,
            );
            let Some((t, useful)) = texture else {
                continue;
            };
            // The coarse mips with the coarsest LOD that has coordinates (the average-colour
            // box below it draws without); the useful ones with the finest, never mandatory
            // (level 1 at least). A texture shared by several objects is claimed once.
            // A segment cut into parts lists them right after it, in order (the client joins
            // them: `portico_client::parts`).
            let mut mips = |k: usize, level: u32| {
                let Some(m) = t.segments.get(k) else {
                    return 0;
                };
                for s in m.ids() {
                    let part = self.segment_bytes(s);
                    push(cands, need(s, NeedKind::Mips, k as u8, part, frames), level);
                }
                // Claimed at what the client's cache holds of it (its GPU's texel format).
                let held = self.cache_charge(m.segment, policy.block_textures);
                if claimed_mips.insert(m.segment) {
                    held
                } else {
                    0
                }
            };
            if Some(i) == coarsest_uv {
                bytes += mips(0, level);
            }
            if i == max && l.uv && useful > 0 {
                bytes += mips(useful, level.max(1));
            }
        }
        bytes
    }
}
