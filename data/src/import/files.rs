//! Files a model names (texture images, material libraries) found the way the tool that wrote
//! them would have: Windows exporters write `\` between directories and do not care about case
//! (`textures/Brick.JPG` for `Textures/brick.jpg`), so a name that is not found as written is
//! looked up with `\` read as `/` and each part matched without regard to case. Every name
//! found other than as written comes back with a warning naming both names.

use std::path::{Component, Path, PathBuf};

/// A file named by the model, found under `dir`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Found {
    /// Where it is.
    pub path: PathBuf,
    /// Set when the name had to be read differently to find it: says how (names both names).
    pub warning: Option<String>,
    /// Whether a part of the name matched only without regard to case (a format whose names
    /// are Windows paths, such as MTL, warns only of this).
    pub case_differs: bool,
}

/// Finds the file `name` (relative, `/` or `\` between parts) under `dir`: as written, else
/// with `\` read as `/`, else part by part without regard to case (ASCII and Unicode; the first
/// in name order when several differ only in case). Errors: an absolute name or one climbing
/// out of `dir` with `..` (a model reads only files beside it), or no such file, named as
/// written.
pub fn find(dir: &Path, name: &str) -> Result<Found, String> {
    let slashed = name.replace('\\', "/");
    let rel = Path::new(&slashed);
    if rel.is_absolute()
        || slashed.starts_with('/')
        || rel
            .components()
            .any(|c| matches!(c, Component::ParentDir | Component::Prefix(_)))
    {
        return Err(format!("'{name}' lies outside the model's directory"));
    }
    let exact = dir.join(name);
    if !name.contains('\\') && exact.is_file() {
        return Ok(Found {
            path: exact,
            warning: None,
            case_differs: false,
        });
    }
    let parts: Vec<&str> = rel
        .components()
        .filter_map(|c| match c {
            Component::Normal(p) => p.to_str(),
            _ => None,
        })
        .collect();
    if parts.is_empty() {
        return Err(format!("'{name}' names no file"));
    }
    let slash = dir.join(parts.join("/"));
    if slash.is_file() {
        return Ok(Found {
            path: slash,
            warning: Some(format!(
                "'{name}' read as '{}' (\\ is not a path separator here)",
                parts.join("/")
            )),
            case_differs: false,
        });
    }
    let mut path = dir.to_path_buf();
    for (i, part) in parts.iter().enumerate() {
        let last = i + 1 == parts.len();
        let direct = path.join(part);
        let fits = |p: &Path| if last { p.is_file() } else { p.is_dir() };
        if fits(&direct) {
            path = direct;
            continue;
        }
        let want = part.to_lowercase();
        let mut matches: Vec<PathBuf> = std::fs::read_dir(&path)
            .map_err(|_| format!("'{name}' not found"))?
            .filter_map(|e| e.ok())
            .filter(|e| {
                e.file_name()
                    .to_str()
                    .is_some_and(|n| n.to_lowercase() == want)
            })
            .map(|e| e.path())
            .filter(|p| fits(p))
            .collect();
        matches.sort();
        path = matches
            .into_iter()
            .next()
            .ok_or_else(|| format!("'{name}' not found in {}", dir.display()))?;
    }
    let found = path
        .strip_prefix(dir)
        .map_or_else(|_| path.display().to_string(), |p| p.display().to_string());
    Ok(Found {
        warning: Some(format!(
            "'{name}' found as '{found}' (the names differ in case{})",
            if name.contains('\\') {
                ", and \\ read as /"
            } else {
                ""
            }
        )),
        path,
        case_differs: true,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_found_as_windows_exporters_meant_them() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("Textures")).unwrap();
        std::fs::write(dir.path().join("Textures/brick.jpg"), b"x").unwrap();
        std::fs::write(dir.path().join("top.png"), b"x").unwrap();
        let d = dir.path();
        let plain = find(d, "top.png").unwrap();
        assert_eq!((plain.path, plain.warning), (d.join("top.png"), None));
        let back = find(d, "Textures\\brick.jpg").unwrap();
        assert_eq!(back.path, d.join("Textures/brick.jpg"));
        assert!(
            back.warning
                .unwrap()
                .contains("read as 'Textures/brick.jpg'")
        );
        let case = find(d, "textures/Brick.JPG").unwrap();
        assert_eq!(case.path, d.join("Textures/brick.jpg"));
        let w = case.warning.unwrap();
        assert!(
            w.contains("'textures/Brick.JPG' found as 'Textures/brick.jpg'"),
            "{w}"
        );
        assert!(
            find(d, "textures\\BRICK.jpg")
                .unwrap()
                .warning
                .unwrap()
                .contains("\\ read as /")
        );
        // A different name is still missing; nothing outside the directory is read.
        assert!(
            find(d, "Textures/brick.jpeg")
                .unwrap_err()
                .contains("not found")
        );
        assert!(find(d, "../top.png").unwrap_err().contains("outside"));
        assert!(find(d, "/etc/passwd").unwrap_err().contains("outside"));
        assert!(find(d, "..\\top.png").unwrap_err().contains("outside"));
        assert!(find(d, ".").unwrap_err().contains("names no file"));
        assert!(find(d, "").unwrap_err().contains("names no file"));
    }
}
