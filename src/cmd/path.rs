//! `portico path --db FILE.portico --kind tour|spin|revisit|orbit|flythrough -o path.json`:
//! standard observer paths for any model (tours through its rooms, or around and through a
//! model without rooms), for walks, load tests and benchmarks.

use crate::cmd::values;
use anyhow::{Context, Result};
use portico_data::Database;
use portico_data::cells::CellGraph;
use portico_data::geometry::Aabb;
use portico_data::path::{CameraPath, PathKind, standard};
use portico_data::person;
use portico_native::net::Remote;
use std::path::PathBuf;

/// Which standard path.
#[derive(Clone, Copy, clap::ValueEnum)]
pub enum Kind {
    /// Walk between random rooms (a model without rooms: an orbit, then a fly-through).
    Tour,
    /// Turn on the spot in the roomiest cell (a model without rooms: an orbit).
    Spin,
    /// A tour out and back the same way.
    Revisit,
    /// Once around the model, looking at it from outside.
    Orbit,
    /// Straight through the model along its longer side.
    Flythrough,
}

impl From<Kind> for PathKind {
    fn from(k: Kind) -> PathKind {
        match k {
            Kind::Tour => PathKind::Tour,
            Kind::Spin => PathKind::Spin,
            Kind::Revisit => PathKind::Revisit,
            Kind::Orbit => PathKind::Orbit,
            Kind::Flythrough => PathKind::Flythrough,
        }
    }
}

/// What a standard path is made from: the model's cells (when built) and its objects' boxes.
pub struct Scene {
    /// The cell graph, if the model has cells.
    pub graph: Option<CellGraph>,
    /// The model's bounds.
    pub bounds: Aabb,
    /// Every instance's bounds.
    pub objects: Vec<Aabb>,
}

impl Scene {
    /// The scene of a display database.
    pub fn of_database(db: &Database) -> Result<Scene> {
        let h = db.header();
        Ok(Scene {
            graph: db.cell_graph()?,
            bounds: h.bounds,
            objects: h.instances.iter().map(|i| i.bounds).collect(),
        })
    }

    /// The scene a server serves (its manifest, and its cells when it has them).
    pub fn of_server(remote: &Remote) -> Result<Scene> {
        let (m, graph) = portico_native::net::model_blocking(remote)?;
        Ok(Scene {
            graph,
            bounds: m.header.bounds,
            objects: m.header.instances.iter().map(|i| i.bounds).collect(),
        })
    }
}

/// How `walk`, `loadtest` and `bench` get their observer path: a file from `portico path`, or
/// a standard path generated from the model.
#[derive(clap::Args, Clone)]
pub struct PathArgs {
    /// A path JSON file (from `portico path`).
    #[arg(long, conflicts_with = "path_kind")]
    pub path: Option<PathBuf>,
    /// Or generate a standard path from the model.
    #[arg(long, value_enum)]
    pub path_kind: Option<Kind>,
    /// Legs of a generated tour.
    #[arg(long, default_value_t = values::LEGS)]
    pub legs: usize,
    /// Seed of a generated path.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

impl PathArgs {
    /// The path file, checked; or, without one, a standard path for the scene that `scene`
    /// fetches (from a server or a database).
    pub fn load(&self, scene: impl FnOnce() -> Result<Scene>) -> Result<CameraPath> {
        if let Some(f) = &self.path {
            let text = std::fs::read(f).with_context(|| format!("reading {}", f.display()))?;
            let p: CameraPath = serde_json::from_slice(&text)
                .with_context(|| format!("{}: not a path JSON", f.display()))?;
            p.validate()
                .map_err(anyhow::Error::msg)
                .with_context(|| f.display().to_string())?;
            return Ok(p);
        }
        let kind = self.path_kind.map_or(PathKind::Tour, Into::into);
        let s = scene()?;
        standard(
            s.graph.as_ref(),
            &s.bounds,
            &s.objects,
            kind,
            self.legs,
            self.seed,
            person::WALK_SPEED,
            person::TURN_DEGREES.to_radians(),
        )
        .context("the model is empty: there is no path to make")
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
    #[arg(long, default_value_t = values::LEGS)]
    legs: usize,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Walking speed, m/s.
    #[arg(long, default_value_t = person::WALK_SPEED)]
    speed: f32,
    /// Turning speed, degrees/s.
    #[arg(long, default_value_t = person::TURN_DEGREES)]
    turn: f32,
    /// Output path JSON file.
    #[arg(
        short = 'o',
        long = "out",
        visible_alias = "output",
        value_name = "FILE"
    )]
    output: PathBuf,
}

/// Generates the path and writes it as JSON.
pub fn run(a: Args) -> Result<()> {
    let db = Database::open(&a.db)?;
    let scene = Scene::of_database(&db)?;
    let path = standard(
        scene.graph.as_ref(),
        &scene.bounds,
        &scene.objects,
        a.kind.into(),
        a.legs,
        a.seed,
        a.speed,
        a.turn.to_radians(),
    )
    .with_context(|| format!("{}: the model is empty", a.db.display()))?;
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
