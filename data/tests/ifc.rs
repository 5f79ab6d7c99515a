//! IFC import against a real building: the FZK-Haus of Debian's `assimp-testmodels` (installed
//! by `.ci/run`), a two-storey house from the Karlsruhe Institute of Technology exported by
//! ArchiCAD 14 as IFC 2x3: 13 walls, 4 slabs, 5 doors, 11 windows, 7 spaces on 2 storeys.

use glam::{Mat4, Vec3};
use portico_data::cells::occluders::{occluder_boxes, transform_box};
use portico_data::cells::precompute;
use portico_data::geometry::Aabb;
use portico_data::import::{import_bytes, import_file};
use portico_data::model::Model;
use portico_data::path::{PathKind, generate};
use std::collections::BTreeMap;
use std::path::PathBuf;

const HAUS: &str = "/usr/share/assimp/models/IFC/AC14-FZK-Haus.ifc";

/// The house, or `None` (skip) when the corpus is not installed outside CI.
fn haus() -> Option<Model> {
    let p = PathBuf::from(HAUS);
    if !p.exists() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{HAUS} missing: .ci/run installs assimp-testmodels"
        );
        eprintln!("skipping: {HAUS} not installed (apt-get install assimp-testmodels)");
        return None;
    }
    Some(import_file(&p).expect("FZK-Haus imports"))
}

fn classes(m: &Model) -> BTreeMap<String, usize> {
    let mut out = BTreeMap::new();
    for i in &m.instances {
        *out.entry(i.tags["ifc_class"].clone()).or_default() += 1;
    }
    out
}

fn world_box(m: &Model, i: usize) -> Aabb {
    let inst = &m.instances[i];
    m.defs[inst.def as usize].lods[0]
        .bounds()
        .transformed(&inst.transform)
}

#[test]
fn the_house_imports_with_its_classes_storeys_spaces_and_colours() {
    let Some(m) = haus() else { return };
    let c = classes(&m);
    assert_eq!(c["IfcWallStandardCase"], 13, "{c:?}");
    assert_eq!(c["IfcSlab"], 4, "{c:?}");
    assert_eq!(c["IfcDoor"], 5, "{c:?}");
    assert_eq!(c["IfcWindow"], 11, "{c:?}");
    assert!(
        !c.contains_key("IfcOpeningElement") && !c.contains_key("IfcSpace"),
        "{c:?}"
    );
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    // Walls and slabs occlude; nothing else does.
    for i in &m.instances {
        let structural =
            i.tags["ifc_class"].starts_with("IfcWall") || i.tags["ifc_class"] == "IfcSlab";
        assert_eq!(i.occluder, structural, "{}", i.name);
    }
    // Storeys by name, from the containment and aggregation relations.
    let door = m
        .instances
        .iter()
        .find(|i| i.name == "Haustuer")
        .expect("the front door");
    assert_eq!(door.tags["storey"], "0. Erdgeschoss");
    assert!(door.tags["guid"].len() == 22, "{:?}", door.tags);
    // The seven rooms, Y up: the ground floor from 0 to 2.5 m, the attic above 2.7 m.
    let mut names: Vec<&str> = m.spaces.iter().map(|s| s.name.as_str()).collect();
    names.sort();
    assert_eq!(
        names,
        [
            "Bad",
            "Buero",
            "Flur",
            "Galerie",
            "Küche",
            "Schlafzimmer",
            "Wohnen"
        ]
    );
    let galerie = m.spaces.iter().find(|s| s.name == "Galerie").unwrap();
    assert_eq!(galerie.storey.as_deref(), Some("1. Dachgeschoss"));
    assert!(
        (galerie.bounds.min[1] - 2.7).abs() < 1e-3,
        "{:?}",
        galerie.bounds
    );
    // The house is 12 m × 10 m on the ground (x and z), about 6.3 m high (y).
    let walls = (0..m.instances.len())
        .filter(|&i| m.instances[i].tags["ifc_class"] == "IfcWallStandardCase")
        .fold(Aabb::EMPTY, |b, i| b.union(&world_box(&m, i)));
    let s = walls.size();
    assert!(
        (s.x - 12.0).abs() < 0.01 && (s.z - 10.0).abs() < 0.01 && s.y > 6.0,
        "{walls:?}"
    );
    // Colours from the file's surface styles, not one flat grey: the windows' glass is
    // see-through and the doors are not the walls' colour.
    let colour = |name: &str| {
        let i = m.instances.iter().find(|i| i.name == name).unwrap();
        m.defs[i.def as usize].lods[0].vertices[0].color
    };
    assert_ne!(colour("Haustuer"), colour("Wand-Ext-ERDG-1"));
    let glass = m
        .instances
        .iter()
        .filter(|i| i.tags["ifc_class"] == "IfcWindow")
        .any(|i| {
            m.defs[i.def as usize].lods[0]
                .vertices
                .iter()
                .any(|v| v.color[3] < 255)
        });
    assert!(glass, "no window has a transparent part");
}

#[test]
fn the_cells_are_the_rooms_and_the_doors_join_them() {
    let Some(m) = haus() else { return };
    let mut occ = occluder_boxes(
        m.instances
            .iter()
            .map(|i| (&m.defs[i.def as usize].lods[0], i.transform, i.occluder)),
    );
    occ.rooms = m
        .spaces
        .iter()
        .filter_map(|s| transform_box(&s.bounds, &Mat4::IDENTITY))
        .collect();
    let objects: Vec<Aabb> = (0..m.instances.len()).map(|i| world_box(&m, i)).collect();
    let p = precompute(&m.bounds(), &occ, &objects, &|_, _| {}, &|| {});
    let g = &p.graph;
    let inside =
        |b: &Aabb, q: Vec3| (0..3).all(|k| b.min[k] - 1e-3 <= q[k] && q[k] <= b.max[k] + 1e-3);
    // Every room is covered by live cells lying inside it (the walls around it are solid);
    // "covered" against the room's box, which for the hall (an L whose notch is a wall) is
    // 7 % more than the room.
    for s in &m.spaces {
        let cells: Vec<&Aabb> = g
            .cells
            .iter()
            .filter(|c| c.live && inside(&s.bounds, c.bounds.center()))
            .map(|c| &c.bounds)
            .collect();
        let volume = |b: &Aabb| {
            let z = b.size();
            z.x * z.y * z.z
        };
        let covered: f32 = cells.iter().map(|b| volume(b)).sum();
        assert!(
            covered >= 0.9 * volume(&s.bounds),
            "{}: {covered} of {}",
            s.name,
            volume(&s.bounds)
        );
        for b in cells {
            assert!(
                inside(&s.bounds, b.min.into()) && inside(&s.bounds, b.max.into()),
                "{}: {b:?}",
                s.name
            );
        }
    }
    // Each ground-floor room but the hall is one cell.
    for name in ["Bad", "Buero", "Küche", "Schlafzimmer", "Wohnen"] {
        let s = m.spaces.iter().find(|s| s.name == name).unwrap();
        let n = g
            .cells
            .iter()
            .filter(|c| c.live && inside(&s.bounds, c.bounds.center()))
            .count();
        assert_eq!(n, 1, "{name}");
    }
    // Each door stands in an opening cell between two rooms (or a room and the outside):
    // live, with portals on both sides.
    for (i, inst) in m.instances.iter().enumerate() {
        if inst.tags["ifc_class"] != "IfcDoor" {
            continue;
        }
        let c = g
            .locate(world_box(&m, i).center())
            .expect("the door is inside the model");
        let cell = &g.cells[c as usize];
        assert!(
            cell.live && cell.portals.len() >= 2,
            "{}: {cell:?}",
            inst.name
        );
    }
    // And the rooms do not all see each other: the bathroom does not see the bedroom's
    // objects, a wall and a corridor apart... but it sees its own.
    let bad = g.locate(Vec3::new(5.7, 1.2, -7.8)).unwrap();
    let seen = p.stabs[bad as usize].objects();
    let named = |n: &str| m.instances.iter().position(|i| i.name == n).unwrap() as u32;
    assert!(seen.contains(&named("Badewanne")));
    assert!(
        !seen.contains(&named("Doppelbett")),
        "the bath sees the bed"
    );

    // A tour walks: it stays inside the house (through doors and up the stair's hole, never
    // out of a window), visits every room, and keeps the eye at standing height.
    let tour = generate(g, PathKind::Tour, 40, 1, 1.4, 1.0).expect("a tour");
    let house = Aabb {
        min: [0.0, 0.0, -10.0],
        max: [12.0, 6.5, 0.0],
    };
    for k in &tour.keyframes {
        assert!(
            inside(&house, k.eye.into()),
            "the tour leaves the house at {:?}",
            k.eye
        );
        // In a room, the eye is at standing height above that room's floor.
        let c = g.locate(k.eye.into()).expect("the eye is in a cell");
        let b = &g.cells[c as usize].bounds;
        let s = b.size();
        if s.x >= 1.0 && s.z >= 1.0 && s.y >= 2.0 {
            let above = k.eye[1] - b.min[1];
            assert!(
                (1.4..=1.8).contains(&above),
                "the eye at {:?} is {above} m above its room's floor",
                k.eye
            );
        }
    }
    for s in &m.spaces {
        let visited = tour
            .keyframes
            .iter()
            .any(|k| inside(&s.bounds, k.eye.into()));
        assert!(visited, "the tour never enters {}", s.name);
    }
}

#[test]
fn a_truncated_file_builds_what_it_holds_and_says_it_is_truncated() {
    let Some(_) = haus() else { return };
    let bytes = std::fs::read(HAUS).unwrap();
    let m = import_bytes(&bytes[..200_000], "ifc").expect("the first products import");
    assert!(!m.instances.is_empty());
    assert!(
        m.warnings.iter().any(|w| w.contains("truncated")),
        "{:?}",
        m.warnings
    );
}

#[test]
fn a_file_that_is_not_ifc_is_one_clear_error() {
    let e = import_bytes(b"solid cube\nendsolid\n", "ifc").unwrap_err();
    assert!(e.contains("not an IFC file"), "{e}");
    let e = import_bytes(
        b"ISO-10303-21;\nHEADER;\nENDSEC;\nDATA;\nENDSEC;\nEND-ISO-10303-21;\n",
        "ifc",
    )
    .unwrap_err();
    assert!(e.contains("no building elements"), "{e}");
}
