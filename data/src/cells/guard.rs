//! The visibility guard every build runs after the precompute: rays from every live cell
//! against the objects' own triangles (the machinery of `portico verify`, [`super::sight`]),
//! and every object a ray sees that the cell's stab list lacks is added to it.
//!
//! Conservative visibility (Funkhouser §4.1: the visible set holds every visible object) is the
//! one promise a walkthrough cannot bend, and the precompute rests on occluders extracted from
//! real files, where a mistake hides part of a building. The guard turns such a mistake from a
//! silent hole into a warning naming the cell and the object, and a list that stays
//! conservative: the object goes into the source cell's own entry, which the client filters by
//! the view frustum alone ([`super::realtime::eye_to_object`]), so it is drawn whenever it is in
//! view from that cell, whatever the portals say.
//!
//! Rays walk the k-D cells in order, testing only the objects touching each cell, so a ray
//! costs what its path crosses, not the model's size. Their number is bounded
//! ([`MAX_RAYS`], at least [`MIN_RAYS_PER_CELL`] a cell) and seeded per cell, so the same input
//! always gives the same database.

use super::sight::Triangles;
use super::verify::random_direction;
use super::{CellGraph, StabList};
use crate::geometry::slab;
use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::HashSet;

/// Rays the guard casts over the whole model, at most (unless every live cell at
/// [`MIN_RAYS_PER_CELL`] needs more).
pub const MAX_RAYS: u64 = 200_000;
/// Rays cast from each live cell, at least.
pub const MIN_RAYS_PER_CELL: u64 = 8;
/// Rays cast from each live cell, at most.
pub const MAX_RAYS_PER_CELL: u64 = 512;

/// What the guard did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct GuardReport {
    /// Rays cast.
    pub rays: u64,
    /// Live cells rays were cast from.
    pub cells: u64,
    /// (cell, object) pairs a ray saw that the stab list lacked, now added; sorted.
    pub repaired: Vec<(u32, u32)>,
    /// Wall-clock seconds it took.
    pub seconds: f64,
}

/// Casts rays from every live cell of `graph` against `scene` and adds each object a ray sees
/// that the cell's stab list lacks to that list's own entry (the source cell's, first).
pub fn guard(
    graph: &CellGraph,
    stabs: &mut [StabList],
    scene: &Triangles,
    seed: u64,
) -> GuardReport {
    let t0 = std::time::Instant::now();
    let live: Vec<u32> = (0..graph.cells.len() as u32)
        .filter(|&c| graph.cells[c as usize].live && stabs.get(c as usize).is_some())
        .collect();
    if live.is_empty() {
        return GuardReport::default();
    }
    let per_cell = (MAX_RAYS / live.len() as u64).clamp(MIN_RAYS_PER_CELL, MAX_RAYS_PER_CELL);
    let touching = touching_cells(graph, scene);
    let found: Vec<(u32, Vec<u32>)> = live
        .par_iter()
        .map(|&c| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (c as u64).wrapping_mul(0x9E37_79B9));
            let b = graph.cells[c as usize].bounds;
            let stored = stabs[c as usize].objects();
            let mut missing = Vec::new();
            for _ in 0..per_cell {
                let origin = Vec3::from(std::array::from_fn::<f32, 3, _>(|k| {
                    b.min[k] + (b.max[k] - b.min[k]) * rng.random_range(0.001f32..0.999)
                }));
                let dir = random_direction(&mut rng);
                if let Some(o) = first_hit(graph, &touching, scene, origin, dir)
                    && stored.binary_search(&o).is_err()
                {
                    missing.push(o);
                }
            }
            missing.sort_unstable();
            missing.dedup();
            (c, missing)
        })
        .collect();
    let mut repaired = Vec::new();
    for (c, missing) in found {
        if missing.is_empty() {
            continue;
        }
        let list = &mut stabs[c as usize];
        if list.entries.first().is_none_or(|e| e.cell != c) {
            list.entries.insert(
                0,
                super::StabEntry {
                    cell: c,
                    region: graph.cells[c as usize].bounds,
                    objects: Vec::new(),
                },
            );
        }
        let own = &mut list.entries[0].objects;
        own.extend(&missing);
        own.sort_unstable();
        own.dedup();
        repaired.extend(missing.into_iter().map(|o| (c, o)));
    }
    GuardReport {
        rays: per_cell * live.len() as u64,
        cells: live.len() as u64,
        repaired,
        seconds: t0.elapsed().as_secs_f64(),
    }
}

/// For each cell (live or dead), the objects whose boxes touch it.
fn touching_cells(graph: &CellGraph, scene: &Triangles) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); graph.cells.len()];
    for (o, b) in scene.bounds().iter().enumerate() {
        for c in graph.cells_touching(b) {
            out[c as usize].push(o as u32);
        }
    }
    out
}

/// The object whose triangles the ray hits first inside the subdivision, found by walking the
/// cells the ray crosses in order: a hit inside the cell being crossed is the first, since
/// every object a later cell holds is hit, if at all, beyond that cell. Each object is tested
/// once per ray, however many cells it touches.
fn first_hit(
    graph: &CellGraph,
    touching: &[Vec<u32>],
    scene: &Triangles,
    origin: Vec3,
    dir: Vec3,
) -> Option<u32> {
    let (_, end) = slab(origin, dir, &graph.bounds)?;
    let mut best: Option<(f32, u32)> = None;
    let mut tested: HashSet<u32> = HashSet::new();
    let mut t = 0.0f32;
    let mut last = u32::MAX;
    let mut step = 1e-4f32;
    // A ray crosses each cell once; the bound only guards against a walk that stalls.
    for _ in 0..2 * graph.cells.len() + 8 {
        let Some(c) = graph.locate(origin + dir * t) else {
            break;
        };
        let Some((_, exit)) = slab(origin, dir, &graph.cells[c as usize].bounds) else {
            break;
        };
        let fresh: Vec<u32> = touching[c as usize]
            .iter()
            .copied()
            .filter(|&o| tested.insert(o))
            .collect();
        if let Some(hit) = scene.nearest(&fresh, origin, dir, end)
            && best.is_none_or(|b| hit.0 < b.0)
        {
            best = Some(hit);
        }
        if best.is_some_and(|b| b.0 <= exit) || exit >= end {
            break;
        }
        // Past the exit face; further each time rounding lands the point back in one cell.
        step = if c == last { step * 10.0 } else { 1e-4 };
        last = c;
        t = exit.max(t) + step;
    }
    best.map(|(_, o)| o)
}
