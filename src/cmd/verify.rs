//! `portico verify FILE.portico [--rays N] [--seed S] [--boxes] [--json]`: rays from random
//! points of the live cells against the objects' real triangles (or, with `--boxes`, against
//! the occluder boxes the precompute used); everything a ray sees must be in its cell's stab
//! list.

use anyhow::{Context, Result, bail};
use portico_data::Database;
use portico_data::cells::sight::Triangles;
use portico_data::cells::verify::{verify, verify_against_triangles};
use std::path::PathBuf;

/// Arguments of `portico verify`.
#[derive(clap::Args)]
pub struct Args {
    /// The display database.
    file: PathBuf,
    /// Rays to cast.
    #[arg(long, default_value_t = 20_000)]
    rays: u64,
    /// Random seed for ray origins and directions.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Cast against the occluder boxes and the objects' boxes (the precompute's own model of
    /// the building) instead of the objects' triangles.
    #[arg(long)]
    boxes: bool,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

/// Casts the rays and fails (exit 1) if any visible object is missing from the stored sets.
pub fn run(a: Args) -> Result<()> {
    let db = Database::open(&a.file)?;
    let graph = db
        .cell_graph()?
        .with_context(|| format!("{}: built without cells (--no-cells)", a.file.display()))?;
    let stabs = (0..graph.cells.len() as u32)
        .map(|c| db.stab_list(c))
        .collect::<Result<Vec<_>, _>>()?;
    let t0 = std::time::Instant::now();
    let r = if a.boxes {
        let occluders = db.occluders()?;
        let objects: Vec<_> = db.header().instances.iter().map(|i| i.bounds).collect();
        verify(&graph, &stabs, &occluders, &objects, a.rays, a.seed)
    } else {
        let scene = Triangles::of_database(&db)?;
        verify_against_triangles(&graph, &stabs, &scene, a.rays, a.seed)
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!(
            "{} rays against the {} from {} cells in {:.2} s: false negatives {}, overestimate ratio {:.2} (stored {:.1} objects per cell, rays saw {:.1})",
            r.rays,
            if a.boxes {
                "occluder boxes"
            } else {
                "objects' triangles"
            },
            r.cells_sampled,
            t0.elapsed().as_secs_f64(),
            r.false_negatives,
            r.overestimate_ratio,
            r.stored_objects_mean,
            r.ray_visible_mean
        );
    }
    if r.false_negatives > 0 {
        bail!(
            "{}: {} false negatives, e.g. (cell, object) {:?}",
            a.file.display(),
            r.false_negatives,
            r.false_negative_examples
        );
    }
    Ok(())
}
