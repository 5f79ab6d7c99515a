//! Visibility on real buildings: the cases in `tests/cases/visibility/` (its README says what
//! each was and what is right), the build's visibility guard, and a property test that the
//! precompute alone is conservative on walls and slabs of any triangulation with holes of any
//! shape (Funkhouser §4.1: every visible object in the set).

use glam::{Mat4, Vec3};
use portico_data::Database;
use portico_data::build::{BuildOptions, BuildReport, Quiet, build};
use portico_data::cells::guard::guard;
use portico_data::cells::occluders::occluder_boxes;
use portico_data::cells::sight::Triangles;
use portico_data::cells::verify::verify_against_triangles;
use portico_data::cells::{CellGraph, StabList, precompute};
use portico_data::geometry::{Aabb, Mesh, Vertex};
use portico_data::import::import_file;
use portico_data::model::{Instance, Material, Model, ObjectDef};
use portico_data::path::{PathKind, standard};
use portico_data::texture::AlphaMode;
use proptest::prelude::*;
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};
use std::path::{Path, PathBuf};

#[path = "../common/mod.rs"]
mod common;
mod walls;
use walls::in_convex;

fn case(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/cases")
        .join(name)
}

/// A case built as `portico build --no-hierarchy` does, with its cells read back.
struct Built {
    report: BuildReport,
    graph: CellGraph,
    stabs: Vec<StabList>,
    db: Database,
    model: Model,
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
    let db = Database::open(&out).unwrap();
    let graph = db.cell_graph().unwrap().expect("cells");
    let stabs = (0..graph.cells.len() as u32)
        .map(|c| db.stab_list(c).unwrap())
        .collect();
    Built {
        report,
        graph,
        stabs,
        db,
        model,
        _dir: dir,
    }
}

fn build_case(name: &str) -> Built {
    build_model(import_file(&case(name)).unwrap_or_else(|e| panic!("{name}: {e}")))
}

impl Built {
    /// (cells, live cells, portals).
    fn counts(&self) -> (u64, u64, u64) {
        let c = self.report.cells.as_ref().unwrap();
        (c.cells, c.live_cells, c.portals)
    }

    /// Live cells inside `inside` and portals between two of them: the building's own cells,
    /// whatever lies around it.
    fn counts_in(&self, inside: &Aabb) -> (usize, usize) {
        let within = |b: &Aabb| {
            (0..3).all(|a| inside.min[a] - 1e-3 <= b.min[a] && b.max[a] <= inside.max[a] + 1e-3)
        };
        let cells: Vec<u32> = (0..self.graph.cells.len() as u32)
            .filter(|&c| {
                self.graph.cells[c as usize].live && within(&self.graph.cells[c as usize].bounds)
            })
            .collect();
        let portals = self
            .graph
            .portals
            .iter()
            .filter(|p| p.cells.iter().all(|c| cells.contains(c)))
            .count();
        (cells.len(), portals)
    }

    /// Whether the live cells outside `inside` list `object`, and at least one of them does.
    fn seen_around(&self, inside: &Aabb, object: u32) -> bool {
        let outside: Vec<usize> = (0..self.graph.cells.len())
            .filter(|&c| {
                let b = &self.graph.cells[c].bounds;
                self.graph.cells[c].live
                    && (0..3).any(|a| {
                        b.max[a] <= inside.min[a] + 1e-3 || b.min[a] >= inside.max[a] - 1e-3
                    })
            })
            .collect();
        !outside.is_empty()
            && outside
                .iter()
                .all(|&c| self.stabs[c].objects().contains(&object))
    }

    /// The guard repaired nothing: the precompute alone was conservative.
    fn unrepaired(&self) -> bool {
        self.report.guard.as_ref().unwrap().repaired.is_empty()
    }

    /// False negatives of `portico verify --rays N` against the objects' own triangles.
    fn false_negatives(&self, rays: u64) -> u64 {
        let scene = Triangles::of_database(&self.db).unwrap();
        verify_against_triangles(&self.graph, &self.stabs, &scene, rays, 7).false_negatives
    }

    fn instance(&self, name: &str) -> u32 {
        self.model
            .instances
            .iter()
            .position(|i| i.name == name)
            .unwrap_or_else(|| panic!("no instance {name}")) as u32
    }

    /// The standard tour's kind and whether every keyframe's eye is inside `inside`.
    fn tour_inside(&self, inside: &Aabb) -> (String, bool) {
        let objects: Vec<Aabb> = self
            .db
            .header()
            .instances
            .iter()
            .map(|i| i.bounds)
            .collect();
        let p = standard(
            Some(&self.graph),
            &self.db.header().bounds,
            &objects,
            PathKind::Tour,
            6,
            1,
            1.5,
            1.0,
        )
        .unwrap();
        let all = p.keyframes.iter().all(|k| {
            (0..3).all(|a| inside.min[a] - 1e-3 <= k.eye[a] && k.eye[a] <= inside.max[a] + 1e-3)
        });
        (p.kind, all && !p.keyframes.is_empty())
    }
}

/// The two-room house's box: (0, −0.2, 0)–(10, 3.2, 8) m.
fn house_box() -> Aabb {
    Aabb {
        min: [0.0, -0.2, 0.0],
        max: [10.0, 3.2, 8.0],
    }
}

#[test]
fn a_skylight_cut_into_a_roof_is_seen_from_the_rooms_below() {
    let b = build_case("visibility/roof-skylight.ifc");
    assert_eq!(b.false_negatives(20_000), 0);
    // The hole is a cell and a portal to the layer above the roof, as with the boxes control.
    let control = build_case("visibility/roof-skylight-boxes.gltf");
    assert_eq!(control.counts(), (17, 5, 4));
    assert_eq!(control.false_negatives(20_000), 0);
    assert_eq!(b.counts(), (17, 5, 4));
    // Both rooms list the skylight, and the precompute found it (the guard repaired nothing).
    let skylight = b.instance("Skylight");
    // IFC is Z up: its y becomes −z.
    for room in [Vec3::new(2.5, 1.5, -2.5), Vec3::new(7.5, 1.5, -2.5)] {
        let c = b.graph.locate(room).unwrap();
        assert!(
            b.stabs[c as usize].objects().contains(&skylight),
            "cell {c}"
        );
    }
    assert!(b.unrepaired());
}

#[test]
fn a_house_on_a_ground_plane_keeps_its_own_cells_and_is_toured_inside() {
    let b = build_case("visibility/house-on-ground-60m.obj");
    assert_eq!(b.counts_in(&house_box()), (3, 2));
    // The ground lies in the live cells around the house: an observer out there sees it.
    assert!(b.seen_around(&house_box(), b.instance("ground")));
    assert_eq!(b.false_negatives(20_000), 0);
    assert!(b.unrepaired());
    assert_eq!(b.tour_inside(&house_box()), ("tour".into(), true));
}

/// The house of `import/house.obj` on a 400 × 400 m hilly terrain, 5 m between its vertices,
/// flat around the house and up to about 12 m high at the edges: the shared case
/// `house-on-terrain-400m.obj` (1.1 MB, so made here rather than stored) has the same grid,
/// extent and heights.
fn house_on_terrain(dir: &Path) -> PathBuf {
    let mut obj = std::fs::read_to_string(case("import/house.obj")).unwrap();
    let base = obj.lines().filter(|l| l.starts_with("v ")).count();
    obj.push_str("\no ground\n");
    let n = 81;
    for j in 0..n {
        for i in 0..n {
            let (x, z) = (-195.0 + 5.0 * i as f32, -196.0 + 5.0 * j as f32);
            let d = ((x - 5.0).powi(2) + (z - 4.0).powi(2)).sqrt();
            let hills = 6.0 * (1.0 - (-(d / 80.0).powi(2)).exp()) * (2.0 + (x / 40.0).sin());
            obj.push_str(&format!("v {x} {} {z}\n", hills - 0.21));
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let v = |a: usize, b: usize| base + 1 + b * n + a;
            let (a, b, c, d) = (v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1));
            obj.push_str(&format!("f {a} {d} {c}\nf {a} {c} {b}\n"));
        }
    }
    let path = dir.join("house-on-terrain.obj");
    std::fs::write(&path, obj).unwrap();
    path
}

#[test]
fn a_house_on_hilly_terrain_keeps_its_own_cells_and_is_toured_inside() {
    let dir = tempfile::tempdir().unwrap();
    let m = import_file(&house_on_terrain(dir.path())).unwrap();
    let ground = m.instances.iter().position(|i| i.name == "ground").unwrap();
    let boxes = common::object_boxes(&m);
    assert!(boxes[ground].size().y > 10.0, "{:?}", boxes[ground]);
    let around = portico_data::cells::surroundings(&boxes);
    assert_eq!(
        around.iter().positions(),
        vec![ground],
        "only the terrain surrounds the house"
    );
    let b = build_model(m);
    assert_eq!(b.counts_in(&house_box()), (3, 2));
    assert!(b.seen_around(&house_box(), ground as u32));
    assert_eq!(b.false_negatives(5_000), 0);
    assert!(b.unrepaired());
    assert_eq!(b.tour_inside(&house_box()), ("tour".into(), true));
}

/// Positions of the `true`s.
trait Positions {
    fn positions(self) -> Vec<usize>;
}

impl<'a, I: Iterator<Item = &'a bool>> Positions for I {
    fn positions(self) -> Vec<usize> {
        self.enumerate()
            .filter(|(_, b)| **b)
            .map(|(i, _)| i)
            .collect()
    }
}

#[test]
fn walls_exported_as_proxies_occlude_like_walls() {
    let b = build_case("visibility/outer-walls-as-proxies.ifc");
    assert_eq!(b.counts(), (12, 3, 2));
    assert_eq!(b.false_negatives(20_000), 0);
    assert!(b.unrepaired());
}

#[test]
fn a_closed_hall_is_a_live_cell_and_the_tour_walks_inside_it() {
    let b = build_case("visibility/hall-600-mapped-chairs.ifc");
    let c = b.report.cells.as_ref().unwrap();
    assert_eq!(c.live_cells, 1, "{c:?}");
    let hall = b.graph.cells.iter().find(|c| c.live).unwrap().bounds;
    let s = hall.size();
    assert!(s.x > 25.0 && s.z > 15.0, "{hall:?}");
    // Every chair is listed: the hall sees all of them.
    let live = b.graph.cells.iter().position(|c| c.live).unwrap();
    assert_eq!(
        b.stabs[live].objects().len(),
        b.model.instances.len(),
        "objects in the hall's list"
    );
    assert!(b.unrepaired());
    let (kind, inside) = b.tour_inside(&hall);
    assert_eq!((kind.as_str(), inside), ("tour", true));
}

/// The house's model as triangles for the guard: each instance's finest mesh, placed.
fn scene_of(m: &Model) -> Triangles {
    let shapes = m
        .defs
        .iter()
        .map(|d| {
            let p = &d.lods[0].vertices;
            d.lods[0]
                .indices
                .chunks_exact(3)
                .map(|t| [t[0], t[1], t[2]].map(|i| Vec3::from(p[i as usize].position)))
                .collect()
        })
        .collect();
    let bounds = common::object_boxes(m);
    Triangles::instanced(
        bounds,
        shapes,
        m.instances.iter().map(|i| (i.def, i.transform)).collect(),
    )
}

#[test]
fn the_build_guard_finds_and_repairs_a_planted_false_negative() {
    let m = import_file(&case("import/house.obj")).unwrap();
    let occ = occluder_boxes(
        m.instances
            .iter()
            .map(|i| (&m.defs[i.def as usize].lods[0], i.transform, i.occluder)),
    );
    let scene = scene_of(&m);
    let objects = scene.bounds().to_vec();
    let mut p = precompute(&m.bounds(), &occ, &objects, &|_, _| {}, &|| {});
    let clean = guard(&p.graph, &mut p.stabs, &scene, 1);
    assert!(clean.repaired.is_empty(), "{:?}", clean.repaired);
    assert!(clean.rays >= 3 * 8);
    // Plant a false negative: the table disappears from its own room's list.
    let table = m.instances.iter().position(|i| i.name == "table").unwrap() as u32;
    let room = p
        .graph
        .locate(objects[table as usize].center() + Vec3::Y)
        .unwrap();
    for e in &mut p.stabs[room as usize].entries {
        e.objects.retain(|&o| o != table);
    }
    assert!(!p.stabs[room as usize].objects().contains(&table));
    let fixed = guard(&p.graph, &mut p.stabs, &scene, 1);
    assert_eq!(fixed.repaired, vec![(room, table)]);
    // In the source cell's own entry, which the client filters by the frustum alone.
    assert_eq!(p.stabs[room as usize].entries[0].cell, room);
    assert!(p.stabs[room as usize].entries[0].objects.contains(&table));
    let r = verify_against_triangles(&p.graph, &p.stabs, &scene, 20_000, 3);
    assert_eq!(r.false_negatives, 0);
}

/// A face `w × h` (in its own u, v) with convex holes, triangulated as a CSG kernel might: a
/// constrained Delaunay triangulation of the outline and the holes' rims with `extra` points
/// inside (fans, slivers, long thin triangles), holes left out. Every `split`-th triangle
/// (none for 0) is cut in two at the middle of an edge, which leaves a T-junction where its
/// neighbour keeps that edge whole.
fn holed_face(
    w: f64,
    h: f64,
    holes: &[Vec<[f64; 2]>],
    extra: &[[f64; 2]],
    split: usize,
) -> Vec<[[f32; 2]; 3]> {
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    let mut ring = |pts: &[[f64; 2]]| {
        let hs: Vec<_> = pts
            .iter()
            .map(|p| cdt.insert(Point2::new(p[0], p[1])).unwrap())
            .collect();
        for k in 0..hs.len() {
            cdt.add_constraint(hs[k], hs[(k + 1) % hs.len()]);
        }
    };
    ring(&[[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]);
    for hole in holes {
        ring(hole);
    }
    for p in extra {
        let inside_hole = holes.iter().any(|hole| in_convex(hole, *p, 0.02));
        if !inside_hole {
            let _ = cdt.insert(Point2::new(p[0], p[1]));
        }
    }
    cdt.inner_faces()
        .map(|f| f.vertices().map(|v| [v.position().x, v.position().y]))
        .filter(|t| {
            let c = [
                (t[0][0] + t[1][0] + t[2][0]) / 3.0,
                (t[0][1] + t[1][1] + t[2][1]) / 3.0,
            ];
            !holes.iter().any(|hole| in_convex(hole, c, 0.0))
        })
        .enumerate()
        .flat_map(|(k, [a, b, c])| {
            if split > 0 && k % split == 0 {
                let m = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
                vec![[a, m, c], [m, b, c]]
            } else {
                vec![[a, b, c]]
            }
        })
        .map(|t| t.map(|p| [p[0] as f32, p[1] as f32]))
        .collect()
}
