//! The one error type of the `data` crate: every variant names the file and the problem, so the
//! CLI can print it on one line (`error: building.portico: truncated: ...`).

use std::path::PathBuf;

/// Everything that can go wrong while importing, building, or reading a display database.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// The operating system refused a read, write, rename or map.
    // `error` is not a `#[source]`: the message already says it, and chained error printing
    // (`{:#}`) would say it twice.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file involved.
        path: PathBuf,
        /// What the OS said.
        error: std::io::Error,
    },
    /// The file does not start with the Portico magic bytes: it is some other kind of file
    /// (the message says which when it is a model `portico build` reads, and how to build it).
    #[error("{}: not a Portico display database{}", path.display(), not_portico_hint(path, *model))]
    NotPortico {
        /// The file involved.
        path: PathBuf,
        /// What the file looks like when it is a model `portico build` reads: "GLB", "glTF",
        /// "OBJ".
        model: Option<&'static str>,
    },
    /// The file was written by a different, incompatible version of the format.
    #[error("{}: format version {found} is not supported (this build reads version {expected}); rebuild it with `portico build`", path.display())]
    Version {
        /// The file involved.
        path: PathBuf,
        /// The version found in the prologue.
        found: u32,
        /// The version this build reads and writes.
        expected: u32,
    },
    /// The file is shorter than its prologue says: an interrupted copy or download.
    #[error("{}: truncated: the prologue records {expected} bytes but the file has {actual}", path.display())]
    Truncated {
        /// The file involved.
        path: PathBuf,
        /// Length recorded in the prologue.
        expected: u64,
        /// Length on disk.
        actual: u64,
    },
    /// A checksum or structural check failed.
    #[error("{}: corrupt: {what}", path.display())]
    Corrupt {
        /// The file involved.
        path: PathBuf,
        /// Which check failed, and where.
        what: String,
    },
    /// A model file could not be imported.
    #[error("{}: {what}", path.display())]
    Import {
        /// The model file involved.
        path: PathBuf,
        /// What was wrong with it.
        what: String,
    },
    /// A caller asked for something that does not exist (e.g. a segment id out of range).
    #[error("{0}")]
    NotFound(String),
    /// The impostor painter (the renderer used at build time) failed.
    #[error("painting impostors: {0}")]
    Impostor(String),
    /// A computation ran past its [`crate::prefetch::Budget`] and was stopped.
    #[error("stopped after {0:?}: the computation ran past its deadline")]
    Deadline(std::time::Duration),
}

impl DataError {
    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        DataError::Io {
            path: path.into(),
            error,
        }
    }

    /// A corruption error for `path`.
    pub fn corrupt(path: impl Into<PathBuf>, what: impl Into<String>) -> Self {
        DataError::Corrupt {
            path: path.into(),
            what: what.into(),
        }
    }

    /// An import error for `path`.
    pub fn import(path: impl Into<PathBuf>, what: impl Into<String>) -> Self {
        DataError::Import {
            path: path.into(),
            what: what.into(),
        }
    }
}

/// Result alias for the `data` crate.
pub type Result<T, E = DataError> = std::result::Result<T, E>;

/// The tail of [`DataError::NotPortico`]'s message: what to run instead.
fn not_portico_hint(path: &std::path::Path, model: Option<&str>) -> String {
    let stem = path
        .file_stem()
        .map_or("model".into(), |s| s.to_string_lossy().into_owned());
    match model {
        Some(kind) => format!(
            " but {} {kind} model: build one with `portico build {} -o {stem}.portico`",
            if kind.starts_with('O') { "an" } else { "a" },
            path.display()
        ),
        None => " (bad magic bytes): make one with `portico build MODEL -o FILE.portico`".into(),
    }
}

/// What a file that is not a display database looks like, from its first bytes: a model
/// `portico build` reads ("GLB", "glTF", "OBJ"), or `None`.
pub fn sniff_model(head: &[u8]) -> Option<&'static str> {
    if head.starts_with(b"glTF") {
        return Some("GLB");
    }
    let text = String::from_utf8_lossy(&head[..head.len().min(4096)]);
    let text = text.trim_start_matches('\u{feff}').trim_start();
    if text.starts_with('{') && text.contains("\"asset\"") {
        return Some("glTF");
    }
    let obj = text.lines().map(str::trim).any(|l| {
        ["v ", "vn ", "vt ", "f ", "o ", "g ", "mtllib ", "usemtl "]
            .iter()
            .any(|k| l.starts_with(k))
    });
    obj.then_some("OBJ")
}
