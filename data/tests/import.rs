//! Importers against real files: the glTF and OBJ models of Debian's `assimp-testmodels`
//! (installed by `.ci/run`), good and deliberately broken, plus hand-made broken files.

use portico_data::Database;
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::import::import_file;
use std::path::{Path, PathBuf};

const ASSIMP: &str = "/usr/share/assimp/models";

/// The corpus directory, or `None` (skip) when it is not installed outside CI.
fn corpus() -> Option<PathBuf> {
    let dir = PathBuf::from(ASSIMP);
    if dir.is_dir() {
        return Some(dir);
    }
    assert!(
        std::env::var_os("CI").is_none(),
        "{ASSIMP} missing: .ci/run installs assimp-testmodels"
    );
    eprintln!("skipping: {ASSIMP} not installed (apt-get install assimp-testmodels)");
    None
}

fn models_under(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            models_under(&p, out);
        } else if matches!(
            p.extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .as_deref(),
            Some("obj" | "gltf" | "glb")
        ) {
            out.push(p);
        }
    }
}

#[test]
fn every_corpus_model_imports_or_fails_cleanly() {
    let Some(dir) = corpus() else { return };
    let mut files = Vec::new();
    models_under(&dir, &mut files);
    assert!(files.len() > 50, "only {} models found", files.len());
    let mut ok = 0;
    for f in &files {
        let r = std::panic::catch_unwind(|| import_file(f));
        match r {
            Err(_) => panic!("{} made the importer panic", f.display()),
            Ok(Ok(m)) => {
                ok += 1;
                for d in &m.defs {
                    for l in &d.lods {
                        l.validate()
                            .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
                    }
                }
            }
            Ok(Err(e)) => {
                let msg = e.to_string();
                assert!(
                    msg.contains(&f.display().to_string()),
                    "error does not name the file: {msg}"
                );
                assert!(!msg.contains('\n'), "error is not one line: {msg}");
            }
        }
    }
    assert!(ok >= 30, "only {ok} of {} models imported", files.len());
}

#[test]
fn real_models_build_and_round_trip() {
    let Some(dir) = corpus() else { return };
    let tmp = tempfile::tempdir().unwrap();
    for (rel, min_tris) in [
        (
            "glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb",
            100_000,
        ),
        ("glTF2/BoxTextured-glTF/BoxTextured.gltf", 12),
        ("OBJ/WusonOBJ.obj", 3_000),
        ("OBJ/spider.obj", 1_000),
    ] {
        let src = dir.join(rel);
        let model = import_file(&src).unwrap_or_else(|e| panic!("{e}"));
        let out = tmp.path().join("m.portico");
        build(model, &out, &BuildOptions::default(), &Quiet).unwrap_or_else(|e| panic!("{e}"));
        let db = Database::open(&out).unwrap();
        db.verify_all().unwrap();
        let h = db.header();
        let highest: u64 = h
            .instances
            .iter()
            .map(|i| h.lods_of(i)[0].triangles as u64)
            .sum();
        assert!(highest >= min_tris, "{rel}: {highest} triangles");
        // Every object big enough got automatic LODs that halve.
        for o in &h.objects {
            for w in o.lods.windows(2) {
                assert!(
                    w[1].triangles * 2 <= w[0].triangles,
                    "{rel}: {} -> {}",
                    w[0].triangles,
                    w[1].triangles
                );
            }
            if o.lods[0].triangles > 200 {
                assert!(
                    o.lods.len() >= 3,
                    "{rel}: object with {} triangles has {} LODs",
                    o.lods[0].triangles,
                    o.lods.len()
                );
            }
        }
    }
}

#[test]
fn the_engine_shares_meshes_between_nodes() {
    let Some(dir) = corpus() else { return };
    let m =
        import_file(&dir.join("glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb")).unwrap();
    assert!(
        m.instances.len() > m.defs.len(),
        "{} instances of {} definitions",
        m.instances.len(),
        m.defs.len()
    );
}

#[test]
fn broken_corpus_files_name_the_problem() {
    let Some(dir) = corpus() else { return };
    for (rel, needle) in [
        ("glTF2/IndexOutOfRange/IndexOutOfRange.gltf", "out of range"),
        (
            "glTF2/IndexOutOfRange/AllIndicesOutOfRange.gltf",
            "out of range",
        ),
        ("glTF2/MissingBin/BoxTextured.gltf", "buffer"),
        ("invalid/empty.obj", ""),
    ] {
        let e = import_file(&dir.join(rel)).expect_err(rel).to_string();
        assert!(e.contains(rel) && e.contains(needle), "{rel}: {e}");
    }
}

#[test]
fn hand_made_broken_files() {
    let tmp = tempfile::tempdir().unwrap();
    let obj = tmp.path().join("broken.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    let e = import_file(&obj).unwrap_err().to_string();
    assert!(e.contains("broken.obj"), "{e}");

    let junk = tmp.path().join("junk.glb");
    std::fs::write(&junk, b"definitely not a glb").unwrap();
    let e = import_file(&junk).unwrap_err().to_string();
    assert!(e.contains("junk.glb") && e.contains("glTF"), "{e}");

    let e = import_file(&tmp.path().join("absent.gltf"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("absent.gltf") && e.contains("no such file"),
        "{e}"
    );

    let fbx = tmp.path().join("model.fbx");
    std::fs::write(&fbx, b"Kaydara FBX Binary").unwrap();
    let e = import_file(&fbx).unwrap_err().to_string();
    assert!(e.contains("unsupported"), "{e}");
}
