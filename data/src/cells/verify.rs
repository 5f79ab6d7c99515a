//! `portico verify`: checks the stored visibility by ray casting.
//!
//! Rays start at random points of up to [`CELLS_SAMPLED`] random live cells, the same number
//! from each, and go in random directions. What a ray sees is visible from its start cell and
//! must be in that cell's stored cell-to-object set — otherwise it is a false negative (must be
//! 0). [`verify_against_triangles`] (what `portico verify` runs) takes what a ray sees from the
//! objects' own triangles ([`super::sight`]): the first one it hits. [`verify`] takes every
//! object whose box the ray enters before the first occluder box — the precompute's own
//! occluders, so it cannot catch occluders extracted wrongly. The overestimate ratio compares
//! the stored sets with the objects rays actually saw from the sampled cells; rays see less
//! than everything, so the ratio is an upper bound on the true overestimate.

use super::sight::Triangles;
use super::{CellGraph, StabList};
use crate::geometry::{Aabb, slab};
use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};

/// Most source cells sampled; the rays are shared among them, so each gets many.
pub const CELLS_SAMPLED: usize = 256;

/// What `verify` found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct VerifyReport {
    /// Rays cast.
    pub rays: u64,
    /// Distinct source cells sampled.
    pub cells_sampled: u64,
    /// (cell, object) pairs a ray saw that the stored visibility misses. Must be 0.
    pub false_negatives: u64,
    /// Up to ten examples: (cell, object).
    pub false_negative_examples: Vec<(u32, u32)>,
    /// Stored objects per sampled cell / objects rays saw from it (≥ 1; 1 = tight).
    pub overestimate_ratio: f64,
    /// Mean stored cell-to-object set size over the sampled cells.
    pub stored_objects_mean: f64,
    /// Mean number of objects rays saw per sampled cell.
    pub ray_visible_mean: f64,
}

/// Casts `rays` rays (deterministic for a `seed`) against the occluder boxes and the objects'
/// boxes, and compares with the stab lists.
pub fn verify(
    graph: &CellGraph,
    stabs: &[StabList],
    occluders: &[Aabb],
    objects: &[Aabb],
    rays: u64,
    seed: u64,
) -> VerifyReport {
    verify_with(graph, stabs, rays, seed, &|origin, dir| {
        cast(origin, dir, &graph.bounds, occluders, objects)
    })
}

/// Casts `rays` rays (deterministic for a `seed`) against the objects' triangles: each sees the
/// first object it hits inside the subdivision, which must be in its start cell's stab list.
pub fn verify_against_triangles(
    graph: &CellGraph,
    stabs: &[StabList],
    scene: &Triangles,
    rays: u64,
    seed: u64,
) -> VerifyReport {
    verify_with(graph, stabs, rays, seed, &|origin, dir| {
        let exit = slab(origin, dir, &graph.bounds).map_or(0.0, |(_, t1)| t1);
        scene.first_hit(origin, dir, exit).into_iter().collect()
    })
}

/// The ray casting shared by both checks: `cast(origin, dir)` gives what one ray sees.
fn verify_with(
    graph: &CellGraph,
    stabs: &[StabList],
    rays: u64,
    seed: u64,
    cast: &(dyn Fn(Vec3, Vec3) -> Vec<u32> + Sync),
) -> VerifyReport {
    let live: Vec<u32> = (0..graph.cells.len() as u32)
        .filter(|&c| graph.cells[c as usize].live)
        .collect();
    if live.is_empty() || rays == 0 {
        return VerifyReport {
            rays: 0,
            cells_sampled: 0,
            false_negatives: 0,
            false_negative_examples: Vec::new(),
            overestimate_ratio: 1.0,
            stored_objects_mean: 0.0,
            ray_visible_mean: 0.0,
        };
    }
    let mut pick = ChaCha8Rng::seed_from_u64(seed);
    let sampled: Vec<u32> =
        rand::seq::IndexedRandom::choose_multiple(&live[..], &mut pick, CELLS_SAMPLED)
            .copied()
            .collect();
    let seen: Vec<(u32, Vec<u32>)> = (0..rays)
        .into_par_iter()
        .map(|i| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ i.wrapping_mul(0x9E37_79B9_7F4A_7C15));
            let cell = sampled[i as usize % sampled.len()];
            let b = &graph.cells[cell as usize].bounds;
            let origin = Vec3::from(std::array::from_fn::<f32, 3, _>(|k| {
                b.min[k] + (b.max[k] - b.min[k]) * rng.random_range(0.001f32..0.999)
            }));
            let dir = random_direction(&mut rng);
            (cell, cast(origin, dir))
        })
        .collect();
    let mut per_cell: BTreeMap<u32, BTreeSet<u32>> = BTreeMap::new();
    for (cell, objs) in seen {
        per_cell.entry(cell).or_default().extend(objs);
    }
    let mut report = VerifyReport {
        rays,
        cells_sampled: per_cell.len() as u64,
        false_negatives: 0,
        false_negative_examples: Vec::new(),
        overestimate_ratio: 1.0,
        stored_objects_mean: 0.0,
        ray_visible_mean: 0.0,
    };
    let (mut stored_total, mut seen_total) = (0usize, 0usize);
    for (cell, objs) in &per_cell {
        let stored = stabs[*cell as usize].objects();
        for o in objs {
            if stored.binary_search(o).is_err() {
                report.false_negatives += 1;
                if report.false_negative_examples.len() < 10 {
                    report.false_negative_examples.push((*cell, *o));
                }
            }
        }
        stored_total += stored.len();
        seen_total += objs.len();
    }
    let n = per_cell.len().max(1) as f64;
    report.stored_objects_mean = stored_total as f64 / n;
    report.ray_visible_mean = seen_total as f64 / n;
    report.overestimate_ratio = stored_total as f64 / seen_total.max(1) as f64;
    report
}

/// A direction uniform on the sphere.
pub(crate) fn random_direction(rng: &mut ChaCha8Rng) -> Vec3 {
    loop {
        let v = Vec3::new(
            rng.random_range(-1.0f32..1.0),
            rng.random_range(-1.0f32..1.0),
            rng.random_range(-1.0f32..1.0),
        );
        let l = v.length_squared();
        if l > 1e-4 && l <= 1.0 {
            return v / l.sqrt();
        }
    }
}

/// Objects whose boxes the ray enters before it enters an occluder or leaves `bounds`.
pub fn cast(
    origin: Vec3,
    dir: Vec3,
    bounds: &Aabb,
    occluders: &[Aabb],
    objects: &[Aabb],
) -> Vec<u32> {
    let exit = slab(origin, dir, bounds).map_or(0.0, |(_, t1)| t1);
    let stop = occluders
        .iter()
        .filter_map(|o| slab(origin, dir, o))
        .filter(|&(t0, _)| t0 > 1e-4)
        .map(|(t0, _)| t0)
        .fold(exit, f32::min);
    (0..objects.len() as u32)
        .filter(|&o| {
            slab(origin, dir, &objects[o as usize])
                .is_some_and(|(t0, t1)| t1 >= 0.0 && t0 <= stop + 1e-3)
        })
        .collect()
}
