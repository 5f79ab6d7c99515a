//! `portico cull FILE.portico [--views N] [--seed S] [--json]`: Funkhouser Table 4.1 — how
//! much each visibility method keeps, over random eye points and view directions.

use anyhow::{Context, Result};
use glam::Vec3;
use portico_data::Database;
use portico_data::cells::CellGraph;
use portico_data::cells::realtime::{Frustum, compare_culling};
use portico_data::path::{PathKind, generate};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;

/// Arguments of `portico cull`.
#[derive(clap::Args)]
pub struct Args {
    /// The display database.
    file: PathBuf,
    /// Number of random views (eye in a random live cell, horizontal view direction).
    #[arg(long, default_value_t = 500)]
    views: usize,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Instead of random views, walk the standard tour (`portico path --kind tour`) of this
    /// many legs, one view every half metre, looking where the tour looks.
    #[arg(long)]
    tour: Option<usize>,
    /// Horizontal field of view in degrees.
    #[arg(long, default_value_t = 60.0)]
    fov: f32,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// Samples the views, runs every culling method, prints the table.
pub fn run(a: Args) -> Result<()> {
    let db = Database::open(&a.file)?;
    let graph = db
        .cell_graph()?
        .with_context(|| format!("{}: built without cells (--no-cells)", a.file.display()))?;
    let stabs = (0..graph.cells.len() as u32)
        .map(|c| db.stab_list(c))
        .collect::<Result<Vec<_>, _>>()?;
    let h = db.header();
    let objects: Vec<_> = h.instances.iter().map(|i| i.bounds).collect();
    let polygons: Vec<u64> = h
        .instances
        .iter()
        .map(|i| h.lods_of(i).first().map_or(0, |l| l.triangles as u64))
        .collect();
    let live: Vec<u32> = (0..graph.cells.len() as u32)
        .filter(|&c| graph.cells[c as usize].live)
        .collect();
    anyhow::ensure!(!live.is_empty(), "{}: no live cells", a.file.display());
    let mut rng = ChaCha8Rng::seed_from_u64(a.seed);
    let half_x = (a.fov * 0.5).to_radians();
    let views: Vec<Frustum> = match a.tour {
        Some(legs) => tour(&graph, legs, a.seed)
            .into_iter()
            .map(|(eye, dir)| Frustum::new(eye, dir, Vec3::Y, half_x, half_x * 0.75))
            .collect(),
        None => random_views(&graph, &live, a.views, half_x, &mut rng),
    };
    let rows = compare_culling(&graph, &stabs, &objects, &polygons, &views);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    let kind = if a.tour.is_some() { "tour" } else { "random" };
    println!(
        "{} {kind} views of {} ({} live cells, {} objects)",
        views.len(),
        a.file.display(),
        live.len(),
        objects.len()
    );
    println!(
        "{:<26} {:>9} {:>6} {:>10} {:>7} {:>12} {:>9}",
        "method", "cells", "max", "objects", "max", "polygons", "max"
    );
    for r in rows {
        println!(
            "{:<26} {:>9.1} {:>6} {:>10.1} {:>7} {:>12.0} {:>9}",
            r.method, r.cells.0, r.cells.1, r.objects.0, r.objects.1, r.polygons.0, r.polygons.1
        );
    }
    Ok(())
}

/// Random eye points in live cells with random horizontal view directions.
fn random_views(
    graph: &CellGraph,
    live: &[u32],
    n: usize,
    half_x: f32,
    rng: &mut ChaCha8Rng,
) -> Vec<Frustum> {
    (0..n)
        .map(|_| {
            let b = graph.cells[live[rng.random_range(0..live.len())] as usize].bounds;
            let eye = Vec3::from(std::array::from_fn::<f32, 3, _>(|k| {
                b.min[k] + (b.max[k] - b.min[k]) * rng.random_range(0.05f32..0.95)
            }));
            let angle = rng.random_range(0.0..std::f32::consts::TAU);
            let dir = Vec3::new(angle.cos(), 0.0, angle.sin());
            Frustum::new(eye, dir, Vec3::Y, half_x, half_x * 0.75)
        })
        .collect()
}

/// A walk through the building: the standard tour of `legs` legs (`portico path --kind tour`:
/// through doors and stair holes at eye height where the building can be walked), one view
/// every half metre along it, each looking where the tour looks.
fn tour(graph: &CellGraph, legs: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
    let Some(path) = generate(graph, PathKind::Tour, legs, seed, 1.4, 1.0) else {
        return Vec::new();
    };
    let mut views = Vec::new();
    for w in path.keyframes.windows(2) {
        let (a, b) = (Vec3::from(w[0].eye), Vec3::from(w[1].eye));
        let n = ((b - a).length() / 0.5).ceil().max(1.0) as usize;
        let dir = Vec3::from(w[1].dir);
        views.extend((0..n).map(|i| (a.lerp(b, i as f32 / n as f32), dir)));
    }
    views
}
