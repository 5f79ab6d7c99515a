//! `portico path --db FILE.portico --kind tour|spin|revisit -o path.json`: standard observer
//! paths through the cells of any model, for walks, load tests and benchmarks.

use anyhow::{Context, Result};
use portico_data::Database;
use portico_data::path::{PathKind, generate};
use std::path::PathBuf;

/// Which standard path.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum Kind {
    /// Walk between random rooms.
    Tour,
    /// Turn on the spot in the roomiest cell.
    Spin,
    /// A tour out and back the same way.
    Revisit,
}

impl From<Kind> for PathKind {
    fn from(k: Kind) -> PathKind {
        match k {
            Kind::Tour => PathKind::Tour,
            Kind::Spin => PathKind::Spin,
            Kind::Revisit => PathKind::Revisit,
        }
    }
}

/// How `walk`, `loadtest` and `bench` get their observer path: a file from `portico path`, or
/// a standard path generated from the model's cells.
#[derive(clap::Args, Clone)]
pub struct PathArgs {
    /// A path JSON file (from `portico path`).
    #[arg(long, conflicts_with = "path_kind")]
    pub path: Option<PathBuf>,
    /// Or generate a standard path from the model's cells.
    #[arg(long, value_enum)]
    pub path_kind: Option<Kind>,
    /// Legs of a generated tour.
    #[arg(long, default_value_t = 4)]
    pub legs: usize,
    /// Seed of a generated path.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

impl PathArgs {
    /// The path file, checked; or, without one, a generated path through the cell graph that
    /// `graph` fetches (from a server or a database).
    pub fn load(
        &self,
        graph: impl FnOnce() -> Result<portico_data::cells::CellGraph>,
    ) -> Result<portico_data::path::CameraPath> {
        if let Some(f) = &self.path {
            let text = std::fs::read(f).with_context(|| format!("reading {}", f.display()))?;
            let p: portico_data::path::CameraPath = serde_json::from_slice(&text)
                .with_context(|| format!("{}: not a path JSON", f.display()))?;
            p.validate()
                .map_err(anyhow::Error::msg)
                .with_context(|| f.display().to_string())?;
            return Ok(p);
        }
        let kind = self.path_kind.map_or(PathKind::Tour, Into::into);
        generate(
            &graph()?,
            kind,
            self.legs,
            self.seed,
            1.5,
            90f32.to_radians(),
        )
        .context("the model has no live cells to walk through")
    }
}

/// Arguments of `portico path`.
#[derive(clap::Args)]
pub struct Args {
    /// The display database.
    #[arg(long)]
    db: PathBuf,
    /// Path kind.
    #[arg(long, value_enum, default_value = "tour")]
    kind: Kind,
    /// Legs of a tour (random rooms visited).
    #[arg(long, default_value_t = 6)]
    legs: usize,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Walking speed, m/s.
    #[arg(long, default_value_t = 1.5)]
    speed: f32,
    /// Turning speed, degrees/s.
    #[arg(long, default_value_t = 90.0)]
    turn: f32,
    /// Output JSON file.
    #[arg(short, long)]
    output: PathBuf,
}

/// Generates the path and writes it as JSON.
pub fn run(a: Args) -> Result<()> {
    let db = Database::open(&a.db)?;
    let graph = db.cell_graph()?.with_context(|| {
        format!(
            "{}: built without cells (--no-cells); paths follow the cells",
            a.db.display()
        )
    })?;
    let path = generate(
        &graph,
        a.kind.into(),
        a.legs,
        a.seed,
        a.speed,
        a.turn.to_radians(),
    )
    .with_context(|| format!("{}: no live cells to walk through", a.db.display()))?;
    std::fs::write(&a.output, serde_json::to_vec_pretty(&path)?)
        .with_context(|| format!("writing {}", a.output.display()))?;
    eprintln!(
        "{} path: {} keyframes, {:.1} s → {}",
        path.kind,
        path.keyframes.len(),
        path.duration(),
        a.output.display()
    );
    Ok(())
}
