//! `portico generate --preset tiny|small|soda|mega [--seed N] [--floors F] [--untagged] [--textured] -o building.glb`
//! (or `-o building.obj [--units UNIT] [--up AXIS]`: OBJ as SketchUp or Revit write it)

use crate::cmd::values;
use crate::progress::Bars;
use anyhow::{Context, Result};
use portico_data::frame::{LengthUnit, SourceFrame, UpAxis};
use portico_generator::{Params, Preset, generate};
use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `portico generate`.
#[derive(clap::Args)]
pub struct Args {
    /// Size of the building.
    #[arg(long, default_value = "small", value_parser = values::preset())]
    preset: Preset,
    /// Random seed: the same seed gives the same bytes.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Number of storeys (overrides the preset's).
    #[arg(long)]
    floors: Option<u32>,
    /// Leave out every node's tags (no `occluder`, `kind`, `room`, `storey` extras), as a
    /// modelling tool's export would: `build` must then find the walls and slabs itself.
    #[arg(long)]
    untagged: bool,
    /// Give walls, floors and furniture textured materials (procedural brick, wood, carpet and
    /// tile PNGs in the GLB, box-mapped coordinates), to measure streaming with textures.
    #[arg(long)]
    textured: bool,
    /// With an `.obj` output: the unit to write it in (default m).
    #[arg(long, value_name = "UNIT", value_parser = values::unit(), ignore_case = true)]
    units: Option<LengthUnit>,
    /// With an `.obj` output: the axis to write pointing up (default y).
    #[arg(long, value_name = "AXIS", value_parser = values::up(), ignore_case = true)]
    up: Option<UpAxis>,
    /// Output file: `.glb`, or `.obj` (with its `.mtl`; untagged, without textures), in the
    /// unit and up axis given, as exporters write OBJ.
    #[arg(
        short = 'o',
        long = "out",
        visible_alias = "output",
        value_name = "FILE"
    )]
    output: PathBuf,
}

/// Generates the building and writes it atomically.
pub fn run(a: Args) -> Result<()> {
    let t0 = Instant::now();
    let bars = Bars::new();
    let mut started = false;
    let params = Params {
        preset: a.preset,
        seed: a.seed,
        floors: a.floors,
    };
    let building = generate(&params, &mut |p| {
        if !started {
            bars.start("storeys", p.total);
            started = true;
        }
        bars.inc(1);
    })
    .with_context(|| format!("generating the {} preset", a.preset))?;
    bars.finish();
    let mut glb = building.glb;
    if a.textured {
        glb = portico_generator::with_textures(&glb).context("adding textures")?;
    }
    if a.untagged {
        glb = portico_generator::without_tags(&glb).context("removing the tags")?;
    }
    let obj = a
        .output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    if obj {
        let model = portico_data::import::gltf::import_slice(&glb, None, &Default::default())
            .map_err(|e| anyhow::anyhow!("reading the generated building back: {e}"))?;
        let frame = SourceFrame {
            unit: a.units.unwrap_or(LengthUnit::Metre),
            up: a.up.unwrap_or(UpAxis::Y),
            ..SourceFrame::metres_y_up()
        };
        portico_data::export::write_obj(&model, &frame, &a.output)?;
        eprintln!(
            "wrote OBJ in {}, {} up",
            frame.unit.name(),
            frame.up.symbol().to_ascii_uppercase()
        );
    } else {
        if a.units.is_some() || a.up.is_some() {
            anyhow::bail!(
                "--units and --up apply to an .obj output; a GLB is metres and Y up by its specification"
            );
        }
        write_atomically(&a.output, &glb)?;
    }
    let s = &building.stats;
    eprintln!(
        "wrote {} ({:.1} MB) in {:.2} s: {} storeys, {} rooms, {} instances of {} definitions, {} triangles at the highest LOD",
        a.output.display(),
        std::fs::metadata(&a.output).map_or(0, |m| m.len()) as f64 / 1e6,
        t0.elapsed().as_secs_f64(),
        s.storeys,
        s.rooms,
        s.instances,
        s.definitions,
        s.triangles_highest,
    );
    Ok(())
}

/// Writes through a temporary file in the same directory and renames it into place.
fn write_atomically(path: &std::path::Path, bytes: &[u8]) -> Result<()> {
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir)
        .with_context(|| format!("{}: cannot create a file there", dir.display()))?;
    // A temporary file is private (0600); a model is meant to be read by other tools and users
    // (a web server, a viewer), so it is world-readable like any file a generator writes.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))
            .with_context(|| format!("{}: cannot set its permissions", path.display()))?;
    }
    tmp.write_all(bytes)
        .and_then(|_| tmp.as_file().sync_all())
        .with_context(|| format!("{}: write failed", path.display()))?;
    tmp.persist(path)
        .with_context(|| format!("{}: cannot rename into place", path.display()))?;
    Ok(())
}
