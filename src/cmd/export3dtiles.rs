//! `portico export-3dtiles FILE.portico -o DIR`: the database as OGC 3D Tiles 1.1
//! (`DIR/tileset.json`, `DIR/tiles/N.glb`) for Cesium, 3DTilesRenderer and other viewers.

use crate::progress::Bars;
use anyhow::{Context, Result};
use portico_data::Database;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `portico export-3dtiles`.
#[derive(clap::Args)]
pub struct Args {
    /// The display database.
    file: PathBuf,
    /// The folder to write `tileset.json` and `tiles/` into (created if missing).
    #[arg(short, long)]
    output: PathBuf,
    /// A tile is split until its instances hold at most this many triangles at their finest
    /// LODs.
    #[arg(long, default_value_t = portico_data::tileset::LEAF_TRIANGLES)]
    leaf_triangles: u64,
}

/// Writes the tileset and says what it wrote.
pub fn run(a: Args) -> Result<()> {
    let t0 = Instant::now();
    let db = Database::open(&a.file)?;
    let bars = Bars::new();
    let mut started = false;
    let leaf = a.leaf_triangles;
    let written = portico_data::tileset::write(&db, &a.output, leaf, &mut |_, total| {
        if !started {
            bars.start("tiles", total as u64);
            started = true;
        }
        bars.inc(1);
    })
    .with_context(|| format!("exporting {} as 3D Tiles", a.file.display()))?;
    bars.finish();
    println!(
        "wrote {} tiles ({:.1} MB, {} triangles at the finest LODs, each object once) to {} in {:.1} s",
        written.tiles,
        written.bytes as f64 / 1e6,
        written.triangles,
        a.output.join("tileset.json").display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}
