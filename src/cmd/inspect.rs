//! `portico inspect FILE.portico [--json] [--verify]`

use anyhow::{Context, Result};
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
    let verdict = match a.verify {
        true => {
            db.verify_all().context("verify: FAILED")?;
            let bytes: u64 = db.segments().iter().map(|e| e.length).sum();
            Some(format!(
                "verify: OK, all {} segments match their checksums ({:.1} MB read)",
                db.segments().len(),
                bytes as f64 / 1e6
            ))
        }
        false => None,
    };
    let s = stats(&db);
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
        // stdout stays one JSON document; the verdict goes beside it.
        if let Some(v) = verdict {
            eprintln!("{v}");
        }
    } else {
        print!("{}", s.to_text());
        if let Some(v) = verdict {
            println!("{v}");
        }
    }
    Ok(())
}
