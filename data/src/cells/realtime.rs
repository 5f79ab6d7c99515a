//! Real-time visibility for one observer (Funkhouser §4.1.2), shared by client and server.
//!
//! - Eye-to-cell: a depth-first search from the eye's cell through portals, narrowing a wedge
//!   of planes through the eye: each portal is clipped to the current wedge and the planes
//!   through the eye and the clipped polygon's edges become the wedge beyond it.
//! - Eye-to-object: the objects of the precomputed cell-to-object set (the eye cell's stab list)
//!   in each reached cell whose boxes touch that cell's wedge.
//! - Frustum-to-cell / frustum-to-object: plain view-frustum culling, for comparison (the FTC
//!   and FTO rows of Table 4.1).

pub use super::cone::{Cone, cone_meets};
use super::polytope::{Plane, clip_polygon};
use super::{CellGraph, StabList, touches};
use crate::geometry::Aabb;
use glam::{DVec3, Vec3};

/// A view frustum as inward-facing halfspaces (`normal · x <= d` keeps the inside).
#[derive(Debug, Clone, PartialEq)]
pub struct Frustum {
    /// The eye.
    pub eye: Vec3,
    /// Side planes (through the eye).
    pub planes: Vec<Plane>,
}

impl Frustum {
    /// A symmetric perspective frustum (no near/far planes: walls do the far culling).
    pub fn new(eye: Vec3, dir: Vec3, up: Vec3, half_fov_x: f32, half_fov_y: f32) -> Frustum {
        let f = dir.normalize_or_zero();
        let r = f.cross(up).normalize_or_zero();
        let u = r.cross(f);
        let side = |axis: Vec3, half: f32, sign: f32| {
            // Outward normal of the plane tilted `half` from the forward direction.
            let n = axis * sign * half.cos() - f * half.sin();
            Plane::through(eye, n)
        };
        Frustum {
            eye,
            planes: vec![
                side(r, half_fov_x, 1.0),
                side(r, half_fov_x, -1.0),
                side(u, half_fov_y, 1.0),
                side(u, half_fov_y, -1.0),
            ],
        }
    }

    /// A frustum that sees everything (an observer looking in every direction).
    pub fn all_around(eye: Vec3) -> Frustum {
        Frustum {
            eye,
            planes: Vec::new(),
        }
    }

    /// Whether a box touches the frustum (conservative plane-by-plane test: a large box beside
    /// or behind the eye that meets each plane's inside but not the frustum passes).
    pub fn touches(&self, b: &Aabb) -> bool {
        self.planes.iter().all(|p| p.touches_box(b))
    }

    /// Whether a box meets the frustum, without [`Frustum::touches`]'s false positives
    /// ([`cone_meets`]).
    pub fn meets(&self, b: &Aabb) -> bool {
        cone_meets(self.eye, &self.planes, b)
    }
}

/// A cell reached from the eye and the wedge through which it is seen.
#[derive(Debug, Clone, PartialEq)]
pub struct Reached {
    /// The cell.
    pub cell: u32,
    /// The wedge (planes through the eye) bounding what of the cell is visible.
    pub wedge: Vec<Plane>,
}

/// Most portal sequences one eye-to-cell search follows. The search is exponential in the worst
/// case (an open grid of cells, where every cell sees every other through many sequences); past
/// this bound it stops and falls back to [`frustum_reached`], so one frame or one prefetch
/// request costs at most this many portal clips and this much memory, on any model.
pub const MAX_EYE_SEQUENCES: usize = 20_000;

/// Eye-to-cell visibility. Empty when the eye is outside every live cell. For a grid of open
/// cells (a model without walls) portals cull nothing, and for a search past
/// [`MAX_EYE_SEQUENCES`] they cost too much: both use [`frustum_reached`] instead.
pub fn eye_to_cell(graph: &CellGraph, view: &Frustum) -> Vec<Reached> {
    eye_to_cell_bounded(graph, view, MAX_EYE_SEQUENCES)
}

/// [`eye_to_cell`] with its bound on portal sequences given: past `max_sequences` the search
/// answers [`frustum_reached`].
pub fn eye_to_cell_bounded(
    graph: &CellGraph,
    view: &Frustum,
    max_sequences: usize,
) -> Vec<Reached> {
    let Some(start) = graph
        .locate(view.eye)
        .filter(|&c| graph.cells[c as usize].live)
    else {
        return Vec::new();
    };
    if graph.grid_fallback {
        return frustum_reached(graph, view, start);
    }
    let mut out = vec![Reached {
        cell: start,
        wedge: view.planes.clone(),
    }];
    let mut stack = vec![(start, view.planes.clone(), vec![start])];
    let mut followed = 0usize;
    while let Some((cell, wedge, path)) = stack.pop() {
        followed += 1;
        if followed > max_sequences {
            return frustum_reached(graph, view, start);
        }
        for &p in &graph.cells[cell as usize].portals {
            let portal = &graph.portals[p as usize];
            let next = portal.other(cell);
            if path.contains(&next) {
                continue;
            }
            let mut poly = portal.corners().to_vec();
            for pl in &wedge {
                poly = clip_polygon(&poly, pl);
                if poly.len() < 3 {
                    break;
                }
            }
            if poly.len() < 3 || polygon_area(&poly) < 1e-8 {
                continue;
            }
            let mut narrowed = wedge_through(view.eye, &poly);
            if narrowed.is_empty() {
                // The eye lies in the portal's plane. Standing in the opening it sees the
                // whole next cell through the current wedge; beside the opening it sees nothing
                // through it, and the wedge may stay wide (conservative either way).
                if !touches(
                    &portal.rect,
                    &Aabb {
                        min: view.eye.into(),
                        max: view.eye.into(),
                    },
                ) {
                    continue;
                }
                narrowed = wedge.clone();
            }
            out.push(Reached {
                cell: next,
                wedge: narrowed.clone(),
            });
            let mut next_path = path.clone();
            next_path.push(next);
            stack.push((next, narrowed, next_path));
        }
    }
    out
}

/// The cells connected to `start` through portals by a chain of cells that all touch the view
/// frustum, each seen through the whole frustum: every sightline from the eye inside the
/// frustum passes only through such cells, so this is conservative, and it costs one visit per
/// cell and portal.
pub fn frustum_reached(graph: &CellGraph, view: &Frustum, start: u32) -> Vec<Reached> {
    let mut seen = vec![false; graph.cells.len()];
    seen[start as usize] = true;
    let mut queue = std::collections::VecDeque::from([start]);
    let mut out = Vec::new();
    while let Some(cell) = queue.pop_front() {
        out.push(Reached {
            cell,
            wedge: view.planes.clone(),
        });
        for &p in &graph.cells[cell as usize].portals {
            let next = graph.portals[p as usize].other(cell);
            let c = &graph.cells[next as usize];
            if !seen[next as usize] && c.live && view.touches(&c.bounds) {
                seen[next as usize] = true;
                queue.push_back(next);
            }
        }
    }
    out
}

/// Eye-to-object visibility: objects of the eye cell's stab list inside the wedges.
pub fn eye_to_object(reached: &[Reached], stab: &StabList, objects: &[Aabb]) -> Vec<u32> {
    let mut out = Vec::new();
    for r in reached {
        let Some(entry) = stab.entry(r.cell) else {
            continue;
        };
        out.extend(entry.objects.iter().copied().filter(|&o| {
            let b = &objects[o as usize];
            r.wedge.iter().all(|p| p.touches_box(b))
        }));
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// [`eye_to_object`] without the plane-by-plane test's false positives: each object's box must
/// meet a wedge it is seen through ([`cone_meets`], the wedges' apex at `eye`). A subset of
/// [`eye_to_object`] that keeps every object some sightline inside a wedge reaches; what a
/// conservative test from a box of eyes keeps holds it ([`super::region`]).
pub fn eye_to_object_exact(
    reached: &[Reached],
    stab: &StabList,
    objects: &[Aabb],
    eye: Vec3,
) -> Vec<u32> {
    let mut out = Vec::new();
    for r in reached {
        let Some(entry) = stab.entry(r.cell) else {
            continue;
        };
        let cone = Cone::new(eye, &r.wedge);
        out.extend(
            entry
                .objects
                .iter()
                .copied()
                .filter(|&o| cone.meets(&objects[o as usize])),
        );
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// Eye-to-object visibility while the eye cell's stab list has not arrived: every object that
/// touches a reached cell inside the wedge it is seen through. A superset of [`eye_to_object`]
/// (a stab list only lists, per reached cell, objects touching it that some sightline reaches),
/// so just as conservative, only looser; it needs nothing but the cell graph (a client that
/// started from the paged manifest knows only the cells and objects of the pages it holds).
/// Linear in the objects: for the few frames a stab list is late.
pub fn eye_to_object_unlisted(
    graph: &CellGraph,
    reached: &[Reached],
    objects: &[Aabb],
) -> Vec<u32> {
    (0..objects.len() as u32)
        .filter(|&o| {
            let b = &objects[o as usize];
            reached.iter().any(|r| {
                touches(&graph.cells[r.cell as usize].bounds, b)
                    && r.wedge.iter().all(|p| p.touches_box(b))
            })
        })
        .collect()
}

/// Cells touching the view frustum (Table 4.1's FTC).
pub fn frustum_to_cell(graph: &CellGraph, view: &Frustum) -> Vec<u32> {
    (0..graph.cells.len() as u32)
        .filter(|&c| graph.cells[c as usize].live && view.touches(&graph.cells[c as usize].bounds))
        .collect()
}

/// Objects touching the view frustum (Table 4.1's FTO).
pub fn frustum_to_object(objects: &[Aabb], view: &Frustum) -> Vec<u32> {
    (0..objects.len() as u32)
        .filter(|&o| view.touches(&objects[o as usize]))
        .collect()
}

/// The planes through the eye and each edge of a convex polygon, oriented to keep the polygon
/// (and what lies behind it) inside.
///
/// Computed in `f64`: a portal clipped down to a sliver a millimetre across, seen from metres
/// away, gives edge planes whose `f32` normals (a cross product of two nearly parallel vectors)
/// are off by about a millimetre at the portal; the wedge then no longer closes around the
/// sliver and lets through cells no sightline reaches.
fn wedge_through(eye: Vec3, poly: &[Vec3]) -> Vec<Plane> {
    let e = eye.as_dvec3();
    let pts: Vec<DVec3> = poly.iter().map(|p| p.as_dvec3() - e).collect();
    let centroid = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
    let mut planes = Vec::with_capacity(pts.len());
    let mut edge_on = true;
    for i in 0..pts.len() {
        let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
        // (a − eye) × (b − a): the edge vector itself, not a difference of two long ones.
        let n = a.cross(b - a);
        if n.length_squared() < 1e-24 {
            continue;
        }
        let mut n = n.normalize();
        let side = n.dot(centroid);
        if side > 0.0 {
            n = -n;
        }
        edge_on &= side.abs() < 1e-6;
        planes.push(Plane::through(eye, n.as_vec3()));
    }
    // An eye in the polygon's plane sees it edge-on: every edge plane holds the centroid.
    if edge_on {
        return Vec::new();
    }
    planes
}

fn polygon_area(poly: &[Vec3]) -> f32 {
    let mut n = Vec3::ZERO;
    for i in 1..poly.len().saturating_sub(1) {
        n += (poly[i] - poly[0]).cross(poly[i + 1] - poly[0]);
    }
    n.length() * 0.5
}

/// One row of a Funkhouser Table 4.1-style comparison: (mean, max) per view.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CullRow {
    /// The culling method.
    pub method: String,
    /// Cells kept (mean, max).
    pub cells: (f64, u64),
    /// Objects kept (mean, max).
    pub objects: (f64, u64),
    /// Polygons of the kept objects at their highest LOD (mean, max).
    pub polygons: (f64, u64),
}

/// What one method kept in one view: cells, and the objects.
type Kept = (u64, Vec<u32>);

/// Compares no culling, frustum culling (FTC/FTO), cell-to-object visibility of the eye's cell
/// (CTO), CTO within the frustum, and eye-to-cell/eye-to-object (ETC/ETO) over a set of views.
/// `stabs` are the stab lists of every cell; `polygons` the highest-LOD triangles per object.
pub fn compare_culling(
    graph: &CellGraph,
    stabs: &[StabList],
    objects: &[Aabb],
    polygons: &[u64],
    views: &[Frustum],
) -> Vec<CullRow> {
    let live: Vec<u32> = (0..graph.cells.len() as u32)
        .filter(|&c| graph.cells[c as usize].live)
        .collect();
    let all: Vec<u32> = (0..objects.len() as u32).collect();
    let mut rows: Vec<(&str, Vec<Kept>)> = vec![
        ("none", Vec::new()),
        ("frustum (FTC, FTO)", Vec::new()),
        ("cell-to-object (CTO)", Vec::new()),
        ("CTO within frustum", Vec::new()),
        ("eye-to-object (ETC, ETO)", Vec::new()),
    ];
    for view in views {
        let Some(eye_cell) = graph.locate(view.eye) else {
            continue;
        };
        let stab = &stabs[eye_cell as usize];
        let cto = stab.objects();
        let fto = frustum_to_object(objects, view);
        let cto_f: Vec<u32> = cto
            .iter()
            .copied()
            .filter(|&o| view.touches(&objects[o as usize]))
            .collect();
        let reached = eye_to_cell(graph, view);
        let eto = eye_to_object(&reached, stab, objects);
        let stab_cells = stab.entries.len() as u64;
        let cto_f_cells = stab
            .entries
            .iter()
            .filter(|e| view.touches(&e.region))
            .count() as u64;
        rows[0].1.push((live.len() as u64, all.clone()));
        rows[1]
            .1
            .push((frustum_to_cell(graph, view).len() as u64, fto));
        rows[2].1.push((stab_cells, cto));
        rows[3].1.push((cto_f_cells, cto_f));
        rows[4].1.push((reached.len() as u64, eto));
    }
    rows.into_iter()
        .map(|(name, per_view)| {
            let mm = |f: &dyn Fn(&Kept) -> u64| -> (f64, u64) {
                let v: Vec<u64> = per_view.iter().map(f).collect();
                (
                    v.iter().sum::<u64>() as f64 / v.len().max(1) as f64,
                    v.iter().copied().max().unwrap_or(0),
                )
            };
            CullRow {
                method: name.to_string(),
                cells: mm(&|(c, _)| *c),
                objects: mm(&|(_, o)| o.len() as u64),
                polygons: mm(&|(_, o)| o.iter().map(|&i| polygons[i as usize]).sum()),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A portal clipped down to a sliver 1 × 2 mm, seen from 7 m: the case a property test found
    /// in the generated building (an eye in an upper-floor doorway reaching a ground-floor
    /// doorway through the stair opening). The wedge must stay a narrow cone around the sliver;
    /// with `f32` cross products it let through a direction 40° away.
    #[test]
    fn a_wedge_through_a_distant_sliver_stays_narrow() {
        let eye = Vec3::new(10.718031, 5.8371763, 5.1726604);
        let sliver = [
            Vec3::new(7.5, 3.65, 11.926362),
            Vec3::new(7.5, 3.65, 11.928691),
            Vec3::new(7.5011096, 3.65, 11.926362),
        ];
        let wedge = wedge_through(eye, &sliver);
        assert_eq!(wedge.len(), 3);
        let centroid = sliver.iter().copied().sum::<Vec3>() / 3.0;
        let inside = |p: Vec3| wedge.iter().all(|pl| pl.eval(p) <= 0.0);
        // The sliver itself and the line beyond it are inside...
        assert!(inside(eye + (centroid - eye) * 1.5));
        // ...a corner of the ground-floor doorway the old wedge reached is not.
        assert!(!inside(Vec3::new(8.5, 0.15, 9.7)));
        // Nor is anything a few millimetres beside the sliver, 7 m further on.
        let beyond = eye + (centroid - eye) * 2.0;
        assert!(!inside(beyond + Vec3::new(0.0, 0.0, 0.02)));
        assert!(!inside(beyond - Vec3::new(0.02, 0.0, 0.0)));
    }

    #[test]
    fn an_eye_in_the_polygon_plane_gets_no_wedge() {
        let square = [
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
        ];
        assert!(wedge_through(Vec3::new(1.0, 0.5, 3.0), &square).is_empty());
        assert_eq!(wedge_through(Vec3::new(0.0, 0.5, 0.5), &square).len(), 4);
    }
}
