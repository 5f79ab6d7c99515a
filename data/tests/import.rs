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

/// The corpus models that must be refused, each with the words its one-line error must hold;
/// every other model in the corpus must import.
const REFUSED: &[(&str, &str)] = &[
    ("OBJ/point_cloud.obj", "contains no triangle meshes"),
    // Points, lines, line loops and line strips only (glTF modes 0-3): nothing to draw.
    (
        "glTF2/glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_00.gltf",
        "contains no triangle meshes",
    ),
    (
        "glTF2/glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_01.gltf",
        "contains no triangle meshes",
    ),
    (
        "glTF2/glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_02.gltf",
        "contains no triangle meshes",
    ),
    (
        "glTF2/glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_03.gltf",
        "contains no triangle meshes",
    ),
    (
        "glTF2/glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_07.gltf",
        "contains no triangle meshes",
    ),
    (
        "glTF2/glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_08.gltf",
        "contains no triangle meshes",
    ),
    (
        "glTF2/glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_09.gltf",
        "contains no triangle meshes",
    ),
    (
        "glTF2/glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_10.gltf",
        "contains no triangle meshes",
    ),
    ("OBJ/testpoints.obj", "contains no triangle meshes"),
    // A polyline: tobj made a triangle of its three points.
    ("OBJ/testline.obj", "contains no triangle meshes"),
    ("invalid/empty.obj", "contains no triangle meshes"),
    (
        "invalid/malformed.obj",
        "line 23: '12': vertex index 12 is out of range",
    ),
    (
        "glTF/BoxTextured-glTF-Binary/BoxTextured.glb",
        "binary glTF 1.0 is not supported",
    ),
    (
        "glTF/BoxTextured-glTF-Embedded/BoxTextured.gltf",
        "glTF 1.0 is not supported",
    ),
    (
        "glTF/BoxTextured-glTF-MaterialsCommon/BoxTextured.gltf",
        "glTF 1.0 is not supported",
    ),
    (
        "glTF/BoxTextured-glTF/BoxTextured.gltf",
        "glTF 1.0 is not supported",
    ),
    (
        "glTF/CesiumMilkTruck/CesiumMilkTruck.gltf",
        "asset.version is missing (glTF 1.0?)",
    ),
    (
        "glTF/IncorrectVertexArrays/Cube_v1.gltf",
        "glTF 1.0 is not supported",
    ),
    ("glTF/TwoBoxes/TwoBoxes.gltf", "glTF 1.0 is not supported"),
    (
        "glTF2/BoxTextured-glTF-techniqueWebGL/BoxTextured.gltf",
        "required extension KHR_technique_webgl is not supported",
    ),
    (
        "glTF2/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb",
        "accessor 2 (POSITION): element 0 is not a finite number",
    ),
    (
        "glTF2/IncorrectVertexArrays/Cube.gltf",
        "primitive 0: 35 vertices without indices is not a whole number of triangles",
    ),
    (
        "glTF2/IndexOutOfRange/AllIndicesOutOfRange.gltf",
        "accessor 0 (indices): index 65535 is out of range for 24 vertices",
    ),
    (
        "glTF2/IndexOutOfRange/IndexOutOfRange.gltf",
        "accessor 0 (indices): index 255 is out of range for 24 vertices",
    ),
    ("glTF2/MissingBin/BoxTextured.gltf", "buffer 0: "),
    (
        "glTF2/RecursiveNodes/RecursiveNodes.gltf",
        "scene root node 0 is also another node's child",
    ),
    (
        "glTF2/SchemaFailures/sceneWrongType.gltf",
        "line 6 column 20",
    ),
    (
        "glTF2/TestNoRootNode/NoScene.gltf",
        "invalid glTF: scene: Index out of bounds",
    ),
    (
        "glTF2/TestNoRootNode/SceneWithoutNodes.gltf",
        "missing field `nodes`",
    ),
    (
        "glTF2/draco/2CylinderEngine.gltf",
        "Draco (KHR_draco_mesh_compression) are not supported",
    ),
    ("glTF2/wrongTypes/badArray.gltf", "line 44 column 26"),
    ("glTF2/wrongTypes/badNumber.gltf", "line 132 column 27"),
    ("glTF2/wrongTypes/badObject.gltf", "line 125 column 52"),
    ("glTF2/wrongTypes/badString.gltf", "line 12 column 14"),
    ("glTF2/wrongTypes/badUint.gltf", "line 128 column 31"),
];

#[test]
fn every_corpus_model_imports_except_the_pinned_refusals() {
    let Some(dir) = corpus() else { return };
    let mut files = Vec::new();
    models_under(&dir, &mut files);
    assert!(files.len() >= 78, "only {} models found", files.len());
    let mut imported = 0;
    for f in &files {
        let rel = f.strip_prefix(&dir).unwrap().to_string_lossy().into_owned();
        let refusal = REFUSED.iter().find(|(r, _)| *r == rel).map(|(_, why)| *why);
        match (std::panic::catch_unwind(|| import_file(f)), refusal) {
            (Err(_), _) => panic!("{rel} made the importer panic"),
            (Ok(Ok(m)), None) => {
                imported += 1;
                for d in &m.defs {
                    for l in &d.lods {
                        l.validate().unwrap_or_else(|e| panic!("{rel}: {e}"));
                    }
                }
            }
            (Ok(Ok(_)), Some(why)) => panic!("{rel} imported, but must be refused with '{why}'"),
            (Ok(Err(e)), None) => panic!("{rel} must import: {e}"),
            (Ok(Err(e)), Some(why)) => {
                let msg = e.to_string();
                assert!(
                    msg.contains(&f.display().to_string()),
                    "the error does not name the file: {msg}"
                );
                assert!(msg.contains(why), "{rel}: expected '{why}' in: {msg}");
                assert!(!msg.contains('\n'), "error is not one line: {msg}");
            }
        }
    }
    assert_eq!(imported, files.len() - REFUSED.len());
}

/// The OBJ files real exporters write that strict readers refuse: a material with an empty
/// name, numbers like `3.1+e2`, a Latin-1 material name, UTF-16 with a byte-order mark.
#[test]
fn quirky_obj_files_import_with_warnings() {
    let Some(dir) = corpus() else { return };
    for (rel, warning) in [
        ("OBJ/empty_mat.obj", "line 233: 'usemtl' without a name"),
        ("OBJ/number_formats.obj", "line 11: '3.1+e2' read as 3.1"),
        ("OBJ/regr01.obj", "read as Latin-1"),
        ("OBJ/box_UTF16BE.obj", "read as UTF-16BE"),
    ] {
        let m = import_file(&dir.join(rel)).unwrap_or_else(|e| panic!("{e}"));
        assert!(
            m.warnings.iter().any(|w| w.contains(warning)),
            "{rel}: {:?}",
            m.warnings
        );
        assert!(!m.instances.is_empty());
    }
    // The Latin-1 name still finds its material.
    let m = import_file(&dir.join("OBJ/regr01.obj")).unwrap();
    let t = m
        .materials
        .iter()
        .position(|mat| mat.name == "Terraindæk")
        .expect("the Latin-1 material");
    assert!(m.instances.iter().any(|i| i.material == t as u32));
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
        ("invalid/empty.obj", "contains no triangle meshes"),
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
