//! Any unit, any up axis, and IFC as modellers write it (`tests/cases/units/`,
//! `tests/cases/ifc/`, described in their READMEs): the same house in centimetres or Z up walks
//! like the one in metres, a door's clearance is not drawn, mapped chairs are instances, and a
//! product whose parts carry its shape is not reported as lacking one.

use glam::{DMat4, DVec3, Vec3};
use portico_data::Database;
use portico_data::build::{BuildOptions, BuildReport, Quiet, build};
use portico_data::frame::{FrameSource, LengthUnit, SourceFrame, UpAxis};
use portico_data::geometry::Aabb;
use portico_data::import::frame::{FrameOptions, Piece, evidence, pieces_of};
use portico_data::import::{import_file, import_file_with};
use portico_data::model::Model;
use portico_data::path::{CameraPath, PathKind, standard};
use portico_data::person::{EYE_HEIGHT, TURN_DEGREES, WALK_SPEED};
use std::path::{Path, PathBuf};

mod common;

fn case(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/cases")
        .join(name)
}

struct Built {
    model: Model,
    report: BuildReport,
    db: Database,
    _dir: tempfile::TempDir,
}

fn build_model(model: Model) -> Built {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("case.portico");
    let opts = BuildOptions {
        no_hierarchy: true,
        ..BuildOptions::default()
    };
    let report = build(model.clone(), &out, &opts, &Quiet).unwrap();
    Built {
        model,
        report,
        db: Database::open(&out).unwrap(),
        _dir: dir,
    }
}

impl Built {
    fn counts(&self) -> (u64, u64, u64) {
        let c = self.report.cells.as_ref().unwrap();
        (c.cells, c.live_cells, c.portals)
    }

    /// The standard tour, as `portico path` makes it (4 legs, seed 1, at a person's pace).
    fn tour(&self) -> CameraPath {
        let graph = self.db.cell_graph().unwrap().expect("cells");
        let objects: Vec<Aabb> = self
            .db
            .header()
            .instances
            .iter()
            .map(|i| i.bounds)
            .collect();
        standard(
            Some(&graph),
            &self.db.header().bounds,
            &objects,
            PathKind::Tour,
            4,
            1,
            WALK_SPEED,
            TURN_DEGREES.to_radians(),
        )
        .unwrap()
    }
}

/// Seconds and metres of a path.
fn extent(p: &CameraPath) -> (f32, f32) {
    let len = p
        .keyframes
        .windows(2)
        .map(|w| Vec3::from(w[0].eye).distance(Vec3::from(w[1].eye)))
        .sum();
    (p.keyframes.last().unwrap().t, len)
}

fn within(a: f32, b: f32, share: f32) -> bool {
    (a - b).abs() <= share * b.abs().max(1e-6)
}

#[test]
fn the_house_in_centimetres_or_z_up_walks_like_the_house_in_metres() {
    let reference = build_model(import_file(&case("units/house-m.obj")).unwrap());
    let (secs, metres) = extent(&reference.tour());
    // At a person's pace in metres: 28 s when the tour turned in the middle of each room, 65 s
    // now that it walks round them; in centimetres read as metres it lasted 657 s.
    assert!(
        (20.0..120.0).contains(&secs),
        "the reference tour: {secs} s"
    );
    let frame = &reference.model.frames[0];
    assert_eq!((frame.unit, frame.up), (LengthUnit::Metre, UpAxis::Y));
    for (name, unit, up) in [
        ("units/house-cm.obj", LengthUnit::Centimetre, UpAxis::Y),
        ("units/house-z-up.obj", LengthUnit::Metre, UpAxis::Z),
    ] {
        let b = build_model(import_file(&case(name)).unwrap());
        let f = &b.model.frames[0];
        assert_eq!((f.unit, f.up), (unit, up), "{name}: {}", f.describe());
        assert_eq!(
            (f.unit_source, f.up_source),
            (FrameSource::Found, FrameSource::Found)
        );
        assert!(
            b.model.warnings.is_empty(),
            "{name}: {:?}",
            b.model.warnings
        );
        assert_eq!(
            b.counts(),
            reference.counts(),
            "{name}: cells, live cells, portals"
        );
        let (lo, hi) = (b.model.bounds(), reference.model.bounds());
        assert!(
            Vec3::from(lo.min).distance(Vec3::from(hi.min)) < 1e-3
                && Vec3::from(lo.max).distance(Vec3::from(hi.max)) < 1e-3,
            "{name}: bounds {lo:?} against {hi:?}"
        );
        let tour = b.tour();
        let (s, m) = extent(&tour);
        assert!(
            within(s, secs, 0.02) && within(m, metres, 0.02),
            "{name}: {s} s, {m} m"
        );
        // The eye is 1.6 m above the floor (its top is at 0) all the way.
        assert!(
            tour.keyframes
                .iter()
                .all(|k| (k.eye[1] - EYE_HEIGHT).abs() < 1e-3),
            "{name}: eye heights"
        );
        // The header keeps the frame, as `inspect` reports it.
        assert_eq!(b.db.header().frames, b.model.frames);
    }
    // The test can fail: read as metres, the centimetre house is walked 1.6 cm above its floor
    // for many times as long (the fault of the case).
    let given = FrameOptions {
        units: Some(LengthUnit::Metre),
        up: Some(UpAxis::Y),
    };
    let wrong = build_model(import_file_with(&case("units/house-cm.obj"), &given).unwrap());
    assert_eq!(wrong.model.frames[0].unit_source, FrameSource::Given);
    assert!(
        wrong
            .model
            .warnings
            .iter()
            .any(|w| w.contains("is --units cm meant")),
        "{:?}",
        wrong.model.warnings
    );
    let (s, _) = extent(&wrong.tour());
    assert!(
        s > 10.0 * secs,
        "the centimetre house read as metres: {s} s"
    );
}

#[test]
fn the_options_override_what_the_geometry_says() {
    let given = FrameOptions {
        units: Some(LengthUnit::Millimetre),
        up: None,
    };
    let m = import_file_with(&case("units/house-z-up.obj"), &given).unwrap();
    let f = &m.frames[0];
    assert_eq!(
        (f.unit, f.unit_source),
        (LengthUnit::Millimetre, FrameSource::Given)
    );
    assert_eq!((f.up, f.up_source), (UpAxis::Z, FrameSource::Found));
    let s = m.bounds().size();
    assert!(
        (s[1] - 0.0034).abs() < 1e-5,
        "3.4 units tall in millimetres: {s}"
    );
}

/// The connected parts of every instance of a model, placed by `to_file` after its own
/// transform.
fn model_pieces(m: &Model, to_file: &DMat4) -> Vec<Piece> {
    m.instances
        .iter()
        .flat_map(|i| {
            let mesh = &m.defs[i.def as usize].lods[0];
            let p: Vec<DVec3> = mesh
                .vertices
                .iter()
                .map(|v| Vec3::from(v.position).as_dvec3())
                .collect();
            pieces_of(&p, &mesh.indices, &(*to_file * i.transform.as_dmat4()))
        })
        .collect()
}

#[test]
fn generated_buildings_in_every_unit_and_up_axis_are_found() {
    let dir = tempfile::tempdir().unwrap();
    // Two storeys to twenty: a tower's repeated floors must not turn it on its side.
    for (seed, floors) in [(5, 2), (11, 3), (7, 20)] {
        let glb = common::tiny_glb(dir.path(), seed, floors);
        let model = import_file(&glb).unwrap();
        for unit in LengthUnit::ALL {
            for up in [UpAxis::Y, UpAxis::Z] {
                let frame = SourceFrame {
                    unit,
                    up,
                    ..SourceFrame::metres_y_up()
                };
                let ev = evidence(&model_pieces(&model, &frame.to_metres_y_up().inverse()));
                assert_eq!(
                    (ev.up, ev.unit),
                    (Some(up), Some(unit)),
                    "seed {seed}, {floors} storeys, in {unit:?} with {up:?} up: {ev:?}"
                );
            }
        }
    }
}

#[test]
fn a_generated_building_written_as_obj_in_centimetres_z_up_comes_back_in_metres_y_up() {
    let dir = tempfile::tempdir().unwrap();
    let glb = common::tiny_glb(dir.path(), 5, 2);
    let model = import_file(&glb).unwrap();
    let obj = dir.path().join("tiny.obj");
    let frame = SourceFrame {
        unit: LengthUnit::Centimetre,
        up: UpAxis::Z,
        ..SourceFrame::metres_y_up()
    };
    portico_data::export::write_obj(&model, &frame, &obj).unwrap();
    let back = import_file(&obj).unwrap();
    let f = &back.frames[0];
    assert_eq!(
        (f.unit, f.up),
        (LengthUnit::Centimetre, UpAxis::Z),
        "{}",
        f.describe()
    );
    let (a, b) = (model.bounds(), back.bounds());
    assert!(
        Vec3::from(a.min).distance(Vec3::from(b.min)) < 1e-3
            && Vec3::from(a.max).distance(Vec3::from(b.max)) < 1e-3,
        "{a:?} against {b:?}"
    );
}

/// The world box of the instance of IFC class `class`.
fn box_of(m: &Model, class: &str) -> Aabb {
    let i = m
        .instances
        .iter()
        .find(|i| {
            i.tags
                .get("ifc_class")
                .is_some_and(|c| c.eq_ignore_ascii_case(class))
        })
        .unwrap_or_else(|| panic!("no {class}"));
    m.defs[i.def as usize].lods[0]
        .bounds()
        .transformed(&i.transform)
}

#[test]
fn a_doors_clearance_is_not_drawn() {
    let body = import_file(&case("ifc/door-body-only.ifc")).unwrap();
    let both = import_file(&case("ifc/door-with-clearance.ifc")).unwrap();
    let (a, b) = (box_of(&body, "IfcDoor"), box_of(&both, "IfcDoor"));
    assert!(
        (b.min[0] - 4.97).abs() < 1e-4 && (b.max[0] - 5.03).abs() < 1e-4,
        "{b:?}"
    );
    assert_eq!(a, b);
    let f = &both.frames[0];
    assert_eq!(
        (f.unit, f.up, f.up_source),
        (LengthUnit::Metre, UpAxis::Z, FrameSource::Format)
    );
    assert!(both.warnings.is_empty(), "{:?}", both.warnings);
}

/// Instances, definitions and the built file's bytes.
fn sizes(model: Model) -> (usize, usize, u64) {
    let (i, d) = (model.instances.len(), model.defs.len());
    let b = build_model(model);
    (i, d, b.report.written.file_bytes)
}

#[test]
fn mapped_chairs_are_instances_of_one_definition() {
    let mapped = import_file(&case("visibility/hall-600-mapped-chairs.ifc")).unwrap();
    let chairs: Vec<_> = mapped
        .instances
        .iter()
        .filter(|i| {
            i.tags
                .get("ifc_class")
                .is_some_and(|c| c.eq_ignore_ascii_case("IfcFurniture"))
        })
        .collect();
    assert_eq!(chairs.len(), 600);
    assert!(
        chairs.iter().all(|c| c.def == chairs[0].def),
        "one definition for all chairs"
    );
    // The last chair, placed by its shared definition's transform, stands on the floor.
    let far = chairs.last().unwrap();
    let placed = mapped.defs[far.def as usize].lods[0]
        .bounds()
        .transformed(&far.transform);
    assert!(
        placed.min[1].abs() < 1e-3,
        "chairs stand on the floor: {placed:?}"
    );
    let (inst, defs, bytes) = sizes(mapped);
    let (g_inst, g_defs, g_bytes) =
        sizes(import_file(&case("ifc/hall-600-chairs-instanced.glb")).unwrap());
    assert_eq!(inst, g_inst, "instances");
    assert!(
        defs <= g_defs,
        "{defs} definitions against the GLB's {g_defs}"
    );
    assert!(
        bytes <= 2 * g_bytes,
        "{bytes} bytes against the GLB's {g_bytes}"
    );
}

/// `door-body-only.ifc` with `extra` entities added before its end.
fn door_with(extra: &str) -> Model {
    let text = std::fs::read_to_string(case("ifc/door-body-only.ifc")).unwrap();
    let at = text.rfind("ENDSEC;").unwrap();
    let edited = format!("{}{extra}\n{}", &text[..at], &text[at..]);
    let dir = tempfile::tempdir().unwrap();
    let path: &Path = &dir.path().join("door.ifc");
    std::fs::write(path, edited).unwrap();
    import_file(path).unwrap()
}

#[test]
fn products_whose_parts_carry_the_shape_are_not_reported_as_left_out() {
    // A roof assembly of the two slabs (its own body empty: its parts carry the shape), and a
    // proxy with no shape at all: nothing is lost.
    let m = door_with(
        "#903=IFCSHAPEREPRESENTATION(#10,'Body','SweptSolid',());\n\
         #904=IFCPRODUCTDEFINITIONSHAPE($,$,(#903));\n\
         #900=IFCELEMENTASSEMBLY('AAAAAAAAAAAAAAAAAAAA9Z',$,'Roof',$,$,#143,#904,$,.NOTDEFINED.,.NOTDEFINED.);\n\
         #901=IFCRELAGGREGATES('AAAAAAAAAAAAAAAAAAAA9Y',$,$,$,#900,(#33,#44));\n\
         #902=IFCBUILDINGELEMENTPROXY('AAAAAAAAAAAAAAAAAAAA9X',$,'Marker',$,$,$,$,$,$);\n\
         #907=IFCSHAPEREPRESENTATION(#11,'Clearance','SweptSolid',(#138));\n\
         #908=IFCPRODUCTDEFINITIONSHAPE($,$,(#907));\n\
         #909=IFCBUILDINGELEMENTPROXY('AAAAAAAAAAAAAAAAAAAA9V',$,'Swing',$,$,#143,#908,$,$);",
    );
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    // A product whose only shape is a clearance draws nothing.
    assert!(
        m.instances.iter().all(|i| i.name != "Swing"),
        "the clearance is drawn"
    );
    // A body that meshes to nothing is still named: its shape was lost.
    let m = door_with(
        "#903=IFCSHAPEREPRESENTATION(#10,'Body','SweptSolid',());\n\
         #904=IFCPRODUCTDEFINITIONSHAPE($,$,(#903));\n\
         #905=IFCBUILDINGELEMENTPROXY('AAAAAAAAAAAAAAAAAAAA9W',$,'Empty',$,$,#143,#904,$,$);",
    );
    assert!(
        m.warnings
            .iter()
            .any(|w| w.contains("#905") && w.contains("left out")),
        "{:?}",
        m.warnings
    );
}

/// The tiny building as a GLB whose one root node scales it by `scale` and turns it Z up, as
/// a glTF exported from a Z-up tool in other units lies.
fn tiny_glb_lying(dir: &Path, scale: f64) -> PathBuf {
    let glb = std::fs::read(common::tiny_glb(dir, 5, 2)).unwrap();
    let g = gltf::Glb::from_slice(&glb).unwrap();
    let mut json: serde_json::Value = serde_json::from_slice(&g.json).unwrap();
    let scene = json["scene"].as_u64().unwrap_or(0) as usize;
    let roots = json["scenes"][scene]["nodes"].clone();
    let nodes = json["nodes"].as_array_mut().unwrap();
    // Y up to Z up is a quarter turn about X; its quaternion is (sin 45°, 0, 0, cos 45°).
    let h = std::f64::consts::FRAC_1_SQRT_2;
    nodes.push(serde_json::json!({
        "name": "exporter root",
        "children": roots,
        "rotation": [h, 0.0, 0.0, h],
        "scale": [scale, scale, scale],
    }));
    let root = nodes.len() - 1;
    json["scenes"][scene]["nodes"] = serde_json::json!([root]);
    let mut text = serde_json::to_vec(&json).unwrap();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let out = gltf::Glb {
        header: g.header,
        json: text.into(),
        bin: g.bin,
    };
    let path = dir.join("lying.glb");
    std::fs::write(&path, out.to_vec().unwrap()).unwrap();
    path
}

#[test]
fn a_gltf_that_is_not_metres_y_up_is_named_and_the_options_set_it_right() {
    let dir = tempfile::tempdir().unwrap();
    let upright = import_file(&common::tiny_glb(dir.path(), 5, 2)).unwrap();
    assert!(upright.warnings.is_empty(), "{:?}", upright.warnings);
    let lying = tiny_glb_lying(dir.path(), 100.0);
    // The format says metres and Y up: kept, but the warning names both options.
    let m = import_file(&lying).unwrap();
    let f = &m.frames[0];
    assert_eq!(
        (f.unit, f.up, f.up_source),
        (LengthUnit::Metre, UpAxis::Y, FrameSource::Format)
    );
    assert!(
        m.warnings.iter().any(|w| w.contains("--up z")),
        "{:?}",
        m.warnings
    );
    assert!(
        m.warnings.iter().any(|w| w.contains("--units cm")),
        "{:?}",
        m.warnings
    );
    // Given, the building stands where it stood.
    let given = FrameOptions {
        units: Some(LengthUnit::Centimetre),
        up: Some(UpAxis::Z),
    };
    let m = import_file_with(&lying, &given).unwrap();
    let (a, b) = (upright.bounds(), m.bounds());
    assert!(
        Vec3::from(a.min).distance(Vec3::from(b.min)) < 1e-3
            && Vec3::from(a.max).distance(Vec3::from(b.max)) < 1e-3,
        "{a:?} against {b:?}"
    );
}
