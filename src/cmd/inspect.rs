//! `portico inspect FILE.portico [--json] [--verify]`

use anyhow::Result;
use portico_data::Database;
use portico_data::stats::stats;
use std::path::PathBuf;

/// Arguments of `portico inspect`.
#[derive(clap::Args)]
pub struct Args {
    /// The display database.
    file: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Also check every segment's checksum (reads the whole file).
    #[arg(long)]
    verify: bool,
}

/// Opens (validating the prologue, index and header) and prints statistics.
pub fn run(a: Args) -> Result<()> {
    let db = Database::open(&a.file)?;
    if a.verify {
        db.verify_all()?;
    }
    let s = stats(&db);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
    } else {
        print!("{}", s.to_text());
    }
    Ok(())
}
