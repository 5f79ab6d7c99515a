//! `portico`: one command line over the Portico crates. Each subcommand lives in
//! `cmd/` and stays thin: parse arguments, call the library, report.

#![forbid(unsafe_code)]

mod cmd;
mod progress;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Streaming walkthroughs of huge 3D buildings.
#[derive(Parser)]
#[command(name = "portico", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate a furnished building as glTF (GLB).
    Generate(cmd::generate::Args),
    /// Build a display database (.portico) from OBJ / glTF / GLB / IFC models.
    Build(cmd::build::Args),
    /// Print statistics of a display database.
    Inspect(cmd::inspect::Args),
    /// Write a display database as OGC 3D Tiles (tileset.json and binary glTF tiles).
    #[command(name = "export-3dtiles")]
    Export3dTiles(cmd::export3dtiles::Args),
    /// Check the stored visibility against the occluders by casting random rays.
    Verify(cmd::verify::Args),
    /// Compare visibility culling methods over random views (Funkhouser Table 4.1).
    Cull(cmd::cull::Args),
    /// Serve a display database (or a model, built first and cached) over HTTP and WebSocket.
    Serve(cmd::serve::Args),
    /// Make a standard observer path (tour, spin, revisit) through a model's cells.
    Path(cmd::path::Args),
    /// Walk a path through a served model with the headless wgpu client.
    Walk(cmd::walk::Args),
    /// Simulate many clients against a server and measure the prefetch policy.
    Loadtest(cmd::loadtest::Args),
    /// Measure frame rate and image fidelity of the detail elision algorithms.
    Bench(cmd::bench::Args),
    /// Generate, build, serve, walk and report on a demo building in one command.
    Demo(cmd::demo::Args),
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Generate(a) => cmd::generate::run(a),
        Command::Build(a) => cmd::build::run(a),
        Command::Inspect(a) => cmd::inspect::run(a),
        Command::Export3dTiles(a) => cmd::export3dtiles::run(a),
        Command::Verify(a) => cmd::verify::run(a),
        Command::Cull(a) => cmd::cull::run(a),
        Command::Serve(a) => cmd::serve::run(a),
        Command::Path(a) => cmd::path::run(a),
        Command::Walk(a) => cmd::walk::run(a),
        Command::Loadtest(a) => cmd::loadtest::run(a),
        Command::Bench(a) => cmd::bench::run(a),
        Command::Demo(a) => cmd::demo::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // One line: the whole cause chain joined with ": ".
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
