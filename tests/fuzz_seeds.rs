//! The fuzz targets' bodies (`fuzz/bodies/`, the same code libFuzzer runs) over every committed
//! seed (`fuzz/seeds/<target>/`; for `import`, the import cases): each must give a result or an
//! error, never a panic. A crash a fuzzer finds is added to its seeds with the fix. Fuzzing itself needs cargo-fuzz and a
//! nightly-capable compiler (fuzz/README.md); this replay runs everywhere, in CI too.

#[path = "../fuzz/bodies/http.rs"]
mod http;
#[path = "../fuzz/bodies/import.rs"]
mod import;
#[path = "../fuzz/bodies/prefetch.rs"]
mod prefetch;
#[path = "../fuzz/bodies/protocol.rs"]
mod protocol;
#[path = "../fuzz/bodies/reader.rs"]
mod reader;
#[path = "../fuzz/bodies/tiny.rs"]
mod tiny;

use std::path::Path;

/// Every file in `dir` (relative to the repository), at least `min` of them, fed to `run`;
/// what `run` returned for each, in file-name order.
fn replay<R>(dir: &str, min: usize, run: fn(&[u8]) -> R) -> Vec<R> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("entry").path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    assert!(
        files.len() >= min,
        "{}: {} seeds, expected at least {min}",
        dir.display(),
        files.len()
    );
    files
        .iter()
        .map(|f| {
            let bytes = std::fs::read(f).expect("read seed");
            std::panic::catch_unwind(|| run(&bytes))
                .unwrap_or_else(|_| panic!("the fuzz body panicked on {}", f.display()))
        })
        .collect()
}

#[test]
fn reader_seeds() {
    replay("fuzz/seeds/reader", 1, reader::run);
}

#[test]
fn protocol_seeds() {
    replay("fuzz/seeds/protocol", 4, protocol::run);
}

#[test]
fn import_seeds_are_the_import_cases() {
    replay("data/tests/cases/import", 14, import::run);
}

#[test]
fn prefetch_seeds() {
    // The valid seeds are answered (within the body's deadline), so the answers' bounds are
    // checked, not skipped.
    let answered: usize = replay("fuzz/seeds/prefetch", 3, prefetch::run).iter().sum();
    assert!(answered > 0, "no prefetch seed was answered");
}

#[test]
fn http_seeds() {
    replay("fuzz/seeds/http", 7, http::run);
}
