//! Display database round trips and corruption handling (a truncated, corrupt or
//! foreign file gives a clear error naming the problem, never a panic).

use glam::{Mat4, Vec3};
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::format::{FORMAT_VERSION, PROLOGUE_SIZE, SegmentEntry};
use portico_data::geometry::{Aabb, GeometryView, Mesh, Vertex};
use portico_data::lod::box_mesh;
use portico_data::model::{Instance, Material, Model, ObjectDef};
use portico_data::{DataError, Database};
use proptest::prelude::*;
use std::path::Path;

/// A UV sphere: enough triangles for several automatic LODs.
fn sphere(n: u32, color: [f32; 4]) -> Mesh {
    let mut m = Mesh::default();
    for i in 0..=n {
        let th = std::f32::consts::PI * i as f32 / n as f32;
        for j in 0..=2 * n {
            let ph = std::f32::consts::PI * j as f32 / n as f32;
            let p = Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
            m.vertices.push(Vertex::new(p.into(), p.into(), color));
        }
    }
    let w = 2 * n + 1;
    for i in 0..n {
        for j in 0..2 * n {
            let (a, b) = (i * w + j, (i + 1) * w + j);
            m.indices.extend([a, b, a + 1, a + 1, b, b + 1]);
        }
    }
    m
}

/// Two definitions (a sphere, a wall box), five instances.
fn model() -> Model {
    let wall = box_mesh(
        &Aabb {
            min: [0.0, 0.0, 0.0],
            max: [4.0, 3.0, 0.2],
        },
        [0.9, 0.9, 0.8, 1.0],
    );
    let mut instances: Vec<Instance> = (0..4)
        .map(|i| Instance {
            name: format!("ball{i}"),
            def: 0,
            transform: Mat4::from_translation(Vec3::new(i as f32 * 3.0, 1.0, 2.0)),
            material: 1,
            occluder: false,
            tags: [("kind".to_string(), "furniture".to_string())].into(),
        })
        .collect();
    instances.push(Instance {
        name: "wall".into(),
        def: 1,
        transform: Mat4::IDENTITY,
        material: 0,
        occluder: true,
        tags: Default::default(),
    });
    Model {
        materials: vec![
            Material::default(),
            Material {
                name: "red".into(),
                base_color: [1.0, 0.0, 0.0, 1.0],
                // Every material field goes through the file (format 6 added the last four).
                emissive: [0.1, 0.2, 0.3],
                unlit: true,
                double_sided: false,
                texture_role: portico_data::model::TextureRole::Emissive,
                ..Material::default()
            },
        ],
        defs: vec![
            ObjectDef {
                name: "ball".into(),
                lods: vec![sphere(24, [1.0, 0.0, 0.0, 1.0])],
                material: 1,
            },
            ObjectDef {
                name: "wall".into(),
                lods: vec![wall],
                material: 0,
            },
        ],
        instances,
        sources: vec!["test.glb".into()],
        ..Model::default()
    }
}

fn built(dir: &Path, flatten: bool) -> std::path::PathBuf {
    let path = dir.join(if flatten {
        "flat.portico"
    } else {
        "shared.portico"
    });
    build(
        model(),
        &path,
        &BuildOptions {
            flatten,
            ..BuildOptions::default()
        },
        &Quiet,
    )
    .expect("build");
    path
}

#[test]
fn round_trip_preserves_instancing_lods_and_every_segment() {
    let dir = tempfile::tempdir().unwrap();
    let path = built(dir.path(), false);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o644, "a server running as another user can read it");
    }
    let db = Database::open(&path).expect("open");
    db.verify_all().expect("checksums");
    let h = db.header();
    assert_eq!(h.materials, model().materials);
    assert_eq!(h.objects.len(), 2);
    assert_eq!(h.instances.len(), 5);
    assert!(
        h.instances[..4]
            .iter()
            .all(|i| i.object == 0 && i.lods.is_none())
    );
    assert!(h.instances[4].occluder && !h.instances[0].occluder);
    assert_eq!(h.instances[0].tag("kind"), Some("furniture"));
    let ball = &h.objects[0];
    assert!(ball.lods.len() >= 4, "ball has {} LODs", ball.lods.len());
    assert_eq!(ball.lods[0].triangles, 2 * 24 * 48);
    for w in ball.lods.windows(2) {
        assert!(w[1].triangles * 2 <= w[0].triangles);
    }
    // Every LOD's bytes decode to a mesh with the recorded counts, every segment is aligned.
    for lod in h.objects.iter().flat_map(|o| &o.lods) {
        let bytes = db.geometry(lod).expect("geometry");
        let view = GeometryView::parse(&bytes).unwrap();
        assert_eq!(view.header.vertex_count, lod.vertices);
        assert_eq!(view.to_mesh().triangle_count() as u32, lod.triangles);
    }
    assert!(db.segments().iter().all(|s| s.offset % 64 == 0));
    // Instances of one definition share its segments.
    assert_eq!(h.lods_of(&h.instances[0]), h.lods_of(&h.instances[3]));
}

#[test]
fn flatten_gives_each_instance_its_own_baked_world_geometry() {
    let dir = tempfile::tempdir().unwrap();
    let shared = Database::open(&built(dir.path(), false)).unwrap();
    let flat = Database::open(&built(dir.path(), true)).unwrap();
    flat.verify_all().unwrap();
    let h = flat.header();
    assert!(h.flattened);
    let own: Vec<_> = h
        .instances
        .iter()
        .map(|i| i.lods.clone().expect("own LODs"))
        .collect();
    assert_ne!(own[0][0].segment, own[1][0].segment);
    assert!(flat.file_len() > shared.file_len());
    // Instance 2 sits at x = 6: its flattened vertices are in world space.
    let bytes = flat.geometry(&own[2][0]).unwrap();
    let mesh = GeometryView::parse(&bytes).unwrap().to_mesh();
    let c = mesh.bounds().center();
    assert!((c - Vec3::new(6.0, 1.0, 2.0)).length() < 1e-3, "{c}");
    // Baked lighting makes two copies of one definition differ in colour.
    let other = GeometryView::parse(&flat.geometry(&own[0][0]).unwrap())
        .unwrap()
        .to_mesh();
    let colors = |m: &Mesh| m.vertices.iter().map(|v| v.color).collect::<Vec<_>>();
    assert!(
        colors(&mesh) != colors(&other),
        "baked colours of two instances are identical"
    );
    assert_eq!(h.bounds, shared.header().bounds);
}

fn open_bytes(bytes: Vec<u8>) -> Result<Database, DataError> {
    Database::from_bytes(Path::new("x.portico"), bytes.into())
}

/// The byte ranges a checksum covers in a good file: the prologue, the header, the segment
/// index and every segment.
fn covered_ranges(good: &[u8]) -> Vec<std::ops::Range<u64>> {
    let db = open_bytes(good.to_vec()).expect("a good file");
    let p = *db.prologue();
    let entry = std::mem::size_of::<SegmentEntry>() as u64;
    let mut ranges = vec![
        0..PROLOGUE_SIZE as u64,
        p.header_offset..p.header_offset + p.header_len,
        p.index_offset..p.index_offset + p.index_count * entry,
    ];
    ranges.extend(db.segments().iter().map(|s| s.offset..s.offset + s.length));
    ranges
}

/// The prologue's padding lies outside its checksum: a flip there is refused too (the property
/// test below found one that went unnoticed).
#[test]
fn a_flip_in_the_prologue_padding_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut v = std::fs::read(built(dir.path(), false)).unwrap();
    v[PROLOGUE_SIZE - 1] ^= 1;
    let Err(e) = open_bytes(v) else {
        panic!("a damaged prologue was accepted")
    };
    let e = e.to_string();
    assert!(e.contains("prologue padding"), "{e}");
}

/// A flip in the header or in the segment index is caught by its own checksum, named in the
/// error (not by whatever decoding happens to trip over next).
#[test]
fn header_and_index_flips_are_caught_by_their_checksums() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read(built(dir.path(), false)).unwrap();
    let p = *open_bytes(good.clone()).unwrap().prologue();
    let entry = std::mem::size_of::<SegmentEntry>() as u64;
    let cases = [
        (p.header_offset, p.header_len, "header checksum mismatch"),
        (
            p.index_offset,
            p.index_count * entry,
            "segment index checksum mismatch",
        ),
    ];
    for (offset, len, message) in cases {
        assert!(len > 8, "{message}: an empty range");
        for at in [offset, offset + len / 2, offset + len - 1] {
            let mut v = good.clone();
            v[at as usize] ^= 0x10;
            match open_bytes(v) {
                Ok(_) => panic!("a flip at byte {at} went unnoticed ({message})"),
                Err(e) => assert!(e.to_string().contains(message), "byte {at}: {e}"),
            }
        }
    }
}

#[test]
fn truncated_corrupt_and_foreign_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read(built(dir.path(), false)).unwrap();

    let e = open_bytes(good[..good.len() - 1].to_vec()).unwrap_err();
    assert!(matches!(e, DataError::Truncated { .. }), "{e}");
    let e = open_bytes(good[..100].to_vec()).unwrap_err();
    assert!(matches!(e, DataError::Truncated { .. }), "{e}");
    let e = open_bytes(b"glTF\x02\0\0\0 not ours".to_vec()).unwrap_err();
    assert!(matches!(e, DataError::NotPortico { .. }), "{e}");
    assert_eq!(
        e.to_string(),
        "x.portico: not a Portico display database but a GLB model: build one with \
         `portico build x.portico -o x.portico`"
    );
    let e = open_bytes(b"# exported\nmtllib a.mtl\nv 0 0 0\n".to_vec()).unwrap_err();
    assert!(e.to_string().contains("but an OBJ model"), "{e}");
    let e = open_bytes(b"{\"asset\":{\"version\":\"2.0\"}}".to_vec()).unwrap_err();
    assert!(e.to_string().contains("but a glTF model"), "{e}");
    let e = open_bytes(b"PK\x03\x04 a zip".to_vec()).unwrap_err();
    assert!(
        e.to_string()
            .ends_with("(bad magic bytes): make one with `portico build MODEL -o FILE.portico`"),
        "{e}"
    );

    let mut v = good.clone();
    v[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    assert!(matches!(
        open_bytes(v).unwrap_err(),
        DataError::Version { .. }
    ));

    // A flipped bit in the prologue, the header, or the index.
    for at in [20, good.len() - 10] {
        let mut v = good.clone();
        v[at] ^= 0x40;
        let e = open_bytes(v).unwrap_err();
        assert!(matches!(e, DataError::Corrupt { .. }), "flip at {at}: {e}");
    }
    // A flipped bit in a segment payload is caught when the segment is read.
    let first = Database::from_bytes(Path::new("x"), good.clone().into())
        .unwrap()
        .segments()[0];
    let mut v = good.clone();
    v[first.offset as usize + 40] ^= 1;
    let db = open_bytes(v).expect("header still fine");
    let e = db.verify_all().unwrap_err();
    assert!(e.to_string().contains("segment 0 checksum mismatch"), "{e}");
    assert!(db.segment(9999).is_err());
}

#[test]
fn missing_file_names_the_path() {
    let e = Database::open(Path::new("/nonexistent/dir/a.portico")).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/dir/a.portico"), "{e}");
}

#[test]
fn a_failed_build_leaves_no_file_behind() {
    let dir = tempfile::tempdir().unwrap();
    let mut m = model();
    m.instances[0].def = 99; // dangling reference: the writer refuses the header
    let out = dir.path().join("bad.portico");
    let r = std::panic::catch_unwind(|| build(m, &out, &BuildOptions::default(), &Quiet));
    // Either an error or (if indexing panicked) a panic: both must leave no file.
    assert!(r.is_err() || r.unwrap().is_err());
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Any byte flipped anywhere in the file gives an error, or a database that still verifies
    /// only if the flip hit padding; it never panics. Covered bytes are those of the prologue,
    /// the header, the segment index and the segments, located in the *unflipped* file.
    #[test]
    fn any_single_byte_flip_is_detected_or_harmless(pos in 0usize..1_000_000, bit in 0u8..8) {
        let dir = tempfile::tempdir().unwrap();
        let good = std::fs::read(built(dir.path(), false)).unwrap();
        let pos = pos % good.len();
        let covered = covered_ranges(&good).iter().any(|r| r.contains(&(pos as u64)));
        let mut v = good.clone();
        v[pos] ^= 1 << bit;
        if let Ok(db) = open_bytes(v)
            && db.verify_all().is_ok() {
                prop_assert!(!covered, "a flip of bit {} at byte {} went unnoticed", bit, pos);
            }
    }

    /// Any prefix of the file is rejected without panicking.
    #[test]
    fn every_truncation_is_rejected(cut in 0usize..1_000_000) {
        let dir = tempfile::tempdir().unwrap();
        let good = std::fs::read(built(dir.path(), false)).unwrap();
        let cut = cut % good.len();
        prop_assert!(open_bytes(good[..cut].to_vec()).is_err());
    }

    /// Random meshes survive encode → write → read unchanged.
    #[test]
    fn random_meshes_round_trip(n in 3usize..300, seed in any::<u64>()) {
        let mut x = seed | 1;
        let mut rnd = || { x ^= x << 13; x ^= x >> 7; x ^= x << 17; (x % 1000) as f32 / 100.0 };
        let vertices: Vec<Vertex> = (0..n).map(|_| Vertex::new([rnd(), rnd(), rnd()], [0.0, 1.0, 0.0], [0.5, 0.5, 0.5, 1.0])).collect();
        let indices: Vec<u32> = (0..(n / 3) * 3).map(|i| ((i * 7 + seed as usize) % n) as u32).collect();
        let mesh = Mesh { vertices, indices, uvs: Vec::new() };
        let bytes = portico_data::geometry::encode_geometry(&mesh);
        prop_assert_eq!(GeometryView::parse(&bytes).unwrap().to_mesh(), mesh);
    }
}
