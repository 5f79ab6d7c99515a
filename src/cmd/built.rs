//! `portico serve MODEL`: the display database built from a model file, kept in a cache and
//! rebuilt only when the model, or a file beside it, changes.
//!
//! The cache is `.portico/` in the model's folder (`house.glb` → `.portico/house.glb.portico`)
//! when that folder is writable, else the user's cache folder (`$XDG_CACHE_HOME/portico`, or
//! `~/.cache/portico`) under a name carrying the hash of the model's full path. Beside the
//! database, a stamp says what it was built from: Portico's version and file format, the model's
//! bytes (hashed) and the size and time of every file in its folder and the folders below it
//! (textures, `.bin` buffers, material libraries: whichever the model reads). A build that ends
//! with a different stamp, or a database that does not open, is built again.

use crate::cmd::build::build_files;
use anyhow::{Context, Result};
use portico_data::build::BuildOptions;
use portico_data::import::frame::FrameOptions;
use std::io::Write;
use std::path::{Path, PathBuf};

/// File extensions `portico serve` builds before serving (what `portico build` imports).
pub const MODEL_EXTENSIONS: [&str; 4] = ["glb", "gltf", "obj", "ifc"];

/// Files below the model's folder looked at for the stamp, at most: a model in a more crowded
/// folder (a home folder, Downloads) is stamped by its own bytes alone.
const STAMP_FILES: usize = 4096;
/// Folder levels below the model's looked at for the stamp.
const STAMP_DEPTH: usize = 2;

/// Whether `path` names a model file (by its extension) rather than a display database.
pub fn is_model(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| MODEL_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// The display database for `model`: the cached build when its stamp still holds, else built
/// now (with `portico build`'s defaults: compressed, cells, visibility, impostors) and stamped.
/// Says which on standard error. Errors: the model cannot be read or does not build; no cache
/// folder can be written.
pub fn database_for(model: &Path) -> Result<PathBuf> {
    let model = std::fs::canonicalize(model)
        .with_context(|| format!("{}: no such model file", model.display()))?;
    let db = cache_path(&model)?;
    let stamp_path = stamp_path(&db);
    let want = stamp(&model)?;
    let had = std::fs::read_to_string(&stamp_path).ok();
    let why = match had {
        None => "no cached build",
        Some(s) if s != want => "the model or a file beside it changed since the cached build",
        Some(_) => match portico_data::Database::open(&db) {
            Ok(_) => {
                eprintln!(
                    "{}: unchanged, serving its build in {}",
                    model.display(),
                    db.display()
                );
                return Ok(db);
            }
            Err(_) => "the cached build does not open",
        },
    };
    eprintln!(
        "{}: {why}; building it into {}",
        model.display(),
        db.display()
    );
    // The stamp goes first: a stale one would only cost a rebuild, a missing database too.
    let _ = std::fs::remove_file(&stamp_path);
    build_files(
        std::slice::from_ref(&model),
        &db,
        &FrameOptions::default(),
        &BuildOptions::default(),
        false,
    )?;
    let mut f = tempfile::NamedTempFile::new_in(db.parent().unwrap_or(Path::new(".")))
        .context("writing the build's stamp")?;
    f.write_all(want.as_bytes())?;
    f.persist(&stamp_path)
        .with_context(|| format!("writing {}", stamp_path.display()))?;
    Ok(db)
}

/// The stamp file of cached database `db`.
fn stamp_path(db: &Path) -> PathBuf {
    let mut s = db.as_os_str().to_os_string();
    s.push(".stamp");
    PathBuf::from(s)
}

/// Where the build of `model` (a full path) is cached (see the module); the folder is made.
fn cache_path(model: &Path) -> Result<PathBuf> {
    let name = model
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "model".into());
    let beside = model.parent().map(|d| d.join(".portico"));
    if let Some(dir) = beside.filter(|d| writable(d)) {
        return Ok(dir.join(format!("{name}.portico")));
    }
    let home = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .context("no cache folder: the model's folder is read-only and HOME is not set")?;
    let dir = home.join("portico");
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let key = xxhash_rust::xxh3::xxh3_64(model.as_os_str().as_encoded_bytes());
    Ok(dir.join(format!("{name}-{key:016x}.portico")))
}

/// Whether folder `dir` exists or can be made, and a file can be written in it.
fn writable(dir: &Path) -> bool {
    std::fs::create_dir_all(dir).is_ok() && tempfile::NamedTempFile::new_in(dir).is_ok()
}

/// What a build of `model` depends on (see the module), as text.
fn stamp(model: &Path) -> Result<String> {
    let reading = || format!("reading {}", model.display());
    let mut file = std::io::BufReader::new(std::fs::File::open(model).with_context(reading)?);
    let mut hash = xxhash_rust::xxh3::Xxh3::new();
    let mut len = 0u64;
    loop {
        let chunk = std::io::BufRead::fill_buf(&mut file).with_context(reading)?;
        if chunk.is_empty() {
            break;
        }
        hash.update(chunk);
        let n = chunk.len();
        len += n as u64;
        std::io::BufRead::consume(&mut file, n);
    }
    let mut out = format!(
        "portico {} format {}\nmodel {len} bytes, xxh3 {:016x}\n",
        env!("CARGO_PKG_VERSION"),
        portico_data::format::FORMAT_VERSION,
        hash.digest()
    );
    let Some(dir) = model.parent() else {
        return Ok(out);
    };
    let mut files = Vec::new();
    list(dir, dir, 0, &mut files);
    if files.len() > STAMP_FILES {
        out.push_str("the folder: too many files to stamp\n");
        return Ok(out);
    }
    files.sort();
    for (rel, len, modified) in files {
        out.push_str(&format!("{rel} {len} {modified}\n"));
    }
    Ok(out)
}

/// Files below `dir` (relative to `root`, with size and modification time in nanoseconds),
/// down to [`STAMP_DEPTH`] levels, leaving out hidden ones (the cache among them).
fn list(root: &Path, dir: &Path, depth: usize, out: &mut Vec<(String, u64, u128)>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        if out.len() > STAMP_FILES {
            return;
        }
        if e.file_name().to_string_lossy().starts_with('.') {
            continue;
        }
        let Ok(meta) = e.metadata() else { continue };
        let path = e.path();
        if meta.is_dir() {
            if depth < STAMP_DEPTH {
                list(root, &path, depth + 1, out);
            }
        } else if meta.is_file() {
            let modified = meta
                .modified()
                .ok()
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                .map_or(0, |d| d.as_nanos());
            let rel = path.strip_prefix(root).unwrap_or(&path);
            out.push((rel.to_string_lossy().into_owned(), meta.len(), modified));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn models_are_told_from_databases_by_their_extension() {
        for m in ["a.glb", "b.GLTF", "c.obj", "d.Ifc"] {
            assert!(is_model(Path::new(m)), "{m}");
        }
        for d in ["a.portico", "b", "c.txt"] {
            assert!(!is_model(Path::new(d)), "{d}");
        }
    }

    #[test]
    fn the_stamp_changes_with_the_model_and_the_files_beside_it() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("m.obj");
        std::fs::write(&model, "v 0 0 0\n").unwrap();
        let a = stamp(&model).unwrap();
        assert_eq!(a, stamp(&model).unwrap(), "the same files, the same stamp");
        std::fs::write(&model, "v 0 0 1\n").unwrap();
        let b = stamp(&model).unwrap();
        assert_ne!(a, b, "the model's bytes");
        std::fs::create_dir(dir.path().join("tex")).unwrap();
        std::fs::write(dir.path().join("tex/wall.png"), "x").unwrap();
        let c = stamp(&model).unwrap();
        assert_ne!(b, c, "a texture below the model's folder");
        std::fs::create_dir(dir.path().join(".portico")).unwrap();
        std::fs::write(dir.path().join(".portico/m.obj.portico"), "db").unwrap();
        assert_eq!(c, stamp(&model).unwrap(), "the cache itself does not count");
    }
}
