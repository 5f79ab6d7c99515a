//! `portico build MODEL... -o FILE.portico [--units UNIT] [--up AXIS] [--flatten] [--no-compress]
//! [--threads N]`

use crate::cmd::values;
use crate::progress::Bars;
use anyhow::{Context, Result};
use portico_data::build::{BuildOptions, build_with};
use portico_data::frame::{LengthUnit, UpAxis};
use portico_data::hierarchy::ImpostorPainter;
use portico_data::import::frame::FrameOptions;
use portico_data::import::import_file_with;
use portico_render::impostor::Painter;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `portico build`.
#[derive(clap::Args)]
pub struct Args {
    /// Model files: .obj (with .mtl), .gltf, .glb or .ifc.
    #[arg(required = true)]
    models: Vec<PathBuf>,
    /// Output display database (.portico).
    #[arg(
        short = 'o',
        long = "out",
        visible_alias = "output",
        value_name = "FILE"
    )]
    output: PathBuf,
    /// The unit the models' coordinates are in, whatever their geometry or format says
    /// (default: the format's, or found from the geometry for OBJ).
    #[arg(long, value_name = "UNIT", value_parser = values::unit(), ignore_case = true)]
    units: Option<LengthUnit>,
    /// The axis pointing up in the models (default: the format's, or found from the geometry
    /// for OBJ).
    #[arg(long, value_name = "AXIS", value_parser = values::up(), ignore_case = true)]
    up: Option<UpAxis>,
    /// Store every instance's geometry separately with baked lighting (large: the out-of-core case).
    #[arg(long)]
    flatten: bool,
    /// Store geometry plain (44.8 bytes per triangle on flattened `mega`) instead of quantised,
    /// meshopt-encoded and deflated (the default: 7.9; 16-bit positions in each segment's
    /// bounds, normals and colours exact, decoded by the client).
    #[arg(long)]
    no_compress: bool,
    /// Compressed geometry: the default, accepted for older scripts.
    #[arg(long, hide = true, conflicts_with = "no_compress")]
    compress: bool,
    /// Most KiB of a texture segment on the wire (default 64: about 52 ms at 10 Mbit/s); a
    /// longer one is cut into parts the client joins. Smaller for slower links (at least 1).
    #[arg(long, value_name = "KB", value_parser = clap::value_parser!(u64).range(1..=1 << 20))]
    part_kb: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Model name stored in the database (default: the first model's file name).
    #[arg(long)]
    name: Option<String>,
    /// Skip the cells, portals and visibility precomputation.
    #[arg(long)]
    no_cells: bool,
    /// Skip the hierarchy of clusters and its impostors.
    #[arg(long)]
    no_hierarchy: bool,
    /// Cluster the model but paint no textured boxes (average-colour boxes only; no renderer
    /// needed at build time).
    #[arg(long)]
    no_textures: bool,
}

/// Imports the models, builds, and prints a one-line summary.
pub fn run(a: Args) -> Result<()> {
    if let Some(n) = a.threads {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n.max(1))
            .build_global()
            .context("setting up worker threads")?;
    }
    let frame = FrameOptions {
        units: a.units,
        up: a.up,
    };
    let opts = BuildOptions {
        flatten: a.flatten,
        compress: !a.no_compress,
        name: a.name,
        no_cells: a.no_cells,
        no_hierarchy: a.no_hierarchy,
        part_bytes: a.part_kb.map(|k| (k as usize) << 10),
    };
    build_files(&a.models, &a.output, &frame, &opts, a.no_textures)
}

/// Imports `models` (in `frame`'s units and up axis where given), builds them into `output`
/// with `opts` (average-colour impostor boxes only when `no_textures`), with progress bars, and
/// prints what it found and a summary. Errors: a model that does not import, the build's.
pub fn build_files(
    models: &[PathBuf],
    output: &Path,
    frame: &FrameOptions,
    opts: &BuildOptions,
    no_textures: bool,
) -> Result<()> {
    let t0 = Instant::now();
    let mut model = portico_data::model::Model::default();
    for path in models {
        let m = import_file_with(path, frame)?;
        for w in &m.warnings {
            eprintln!("warning: {}: {w}", path.display());
        }
        for f in &m.frames {
            eprintln!("{}: {}", path.display(), f.describe());
        }
        model.merge(m);
    }
    let origin = model.origin;
    let names: Vec<String> = model.instances.iter().map(|i| i.name.clone()).collect();
    let import_time = t0.elapsed();
    let bars = Bars::new();
    let mut painter = painter(opts.no_hierarchy || no_textures);
    let report = build_with(
        model,
        output,
        opts,
        &bars,
        painter.as_mut().map(|p| p as &mut dyn ImpostorPainter),
    )?;
    bars.finish();
    eprintln!(
        "wrote {} ({:.1} MB, {} segments) in {:.2} s (import {:.2} s, LODs {:.2} s, write {:.2} s)",
        report.written.path.display(),
        report.written.file_bytes as f64 / 1e6,
        report.written.segments,
        t0.elapsed().as_secs_f64(),
        import_time.as_secs_f64(),
        report.lod_time.as_secs_f64(),
        report.write_time.as_secs_f64(),
    );
    if origin != [0.0; 3] {
        eprintln!(
            "local origin: ({:.3}, {:.3}, {:.3}) m, Y up (kept in the database)",
            origin[0], origin[1], origin[2]
        );
    }
    if !opts.no_hierarchy {
        eprintln!(
            "impostors: {} in {:.2} s",
            if painter.is_some() {
                "clusters with textured and average-colour boxes"
            } else {
                "clusters with average-colour boxes only"
            },
            report.hierarchy_seconds
        );
    }
    if let Some(c) = &report.cells {
        eprintln!(
            "cells: {} ({} live), {} portals from {} occluder faces; subdivision {:.2} s, visibility {:.2} s{}",
            c.cells,
            c.live_cells,
            c.portals,
            c.occluder_boxes,
            report.subdivision_seconds,
            report.visibility_seconds,
            if c.grid_fallback {
                " (no occluders: grid fallback)"
            } else {
                ""
            },
        );
    }
    if let Some(g) = &report.guard {
        for &(cell, object) in &g.repaired {
            let name = names.get(object as usize).map_or("", String::as_str);
            eprintln!(
                "warning: visibility guard: a ray from cell {cell} sees object {object} ('{name}'), \
                 which its stab list lacked; added (a false negative the precompute made)"
            );
        }
        eprintln!(
            "visibility guard: {} rays from {} live cells in {:.2} s, {} false negatives repaired",
            g.rays,
            g.cells,
            g.seconds,
            g.repaired.len()
        );
    }
    Ok(())
}

/// The impostor painter, unless not wanted; a machine without any graphics adapter builds with
/// average-colour boxes only, and says so.
fn painter(skip: bool) -> Option<Painter> {
    if skip {
        return None;
    }
    match Painter::new() {
        Ok(p) => Some(p),
        Err(e) => {
            eprintln!(
                "warning: no renderer for textured impostors ({e}); average-colour boxes only"
            );
            None
        }
    }
}
