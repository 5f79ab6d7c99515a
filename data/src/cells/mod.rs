//! Cells, portals and visibility (Funkhouser §3.2 and §4.1; Teller's cells-and-portals).
//!
//! - [`occluders`]: the axis-aligned occluder boxes of a model (tagged walls, floors, ceilings,
//!   or large box-shaped slabs found automatically in untagged models); [`cover`] for walls
//!   and slabs of any triangulation.
//! - [`subdivide`]: a k-D tree split along the major occluder faces (§3.2.1); a coarse grid when a
//!   model has no usable occluders.
//! - [`portals`]: the open rectangles on shared cell boundaries, hence the adjacency graph.
//! - [`sightline`] and [`stab`]: cell-to-cell and cell-to-object visibility by depth-first search
//!   through portal sequences (§3.2.2), stored as stab lists.
//! - [`realtime`]: eye-to-cell and eye-to-object culling by narrowing the view frustum through
//!   portals (§4.1.2), and plain frustum culling for comparison.
//! - [`paged`]: the graph cut along the stab lists for the paged manifest (a frame in the core,
//!   each cell's reach in its page) and grown back on the client.
//! - [`guard`]: rays from every live cell at build time; what they see that a stab list lacks
//!   is added to it, with a warning.
//! - [`verify`]: a ray-casting checker for false negatives and overestimation, against the
//!   objects' real triangles ([`sight`]) or the occluder boxes.

pub mod cone;
pub mod cover;
#[cfg(feature = "native")]
pub mod guard;
pub mod occluders;
pub mod paged;
pub mod polytope;
pub mod portals;
pub mod realtime;
pub mod region;
#[cfg(feature = "native")]
pub mod sight;
pub mod sightline;
pub mod solid;
#[cfg(feature = "native")]
pub mod stab;
pub mod subdivide;
#[cfg(feature = "native")]
pub mod verify;

use crate::geometry::Aabb;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// A leaf cell of the subdivision.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cell {
    /// The cell's box.
    pub bounds: Aabb,
    /// Whether an observer can be inside it (false for dead space inside walls and slabs).
    pub live: bool,
    /// Indices into [`CellGraph::portals`] of the portals on its boundary.
    pub portals: Vec<u32>,
}

/// An open axis-aligned rectangle shared by two cells.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Portal {
    /// Axis of the portal's normal (0 = x, 1 = y, 2 = z).
    pub axis: u8,
    /// The rectangle (zero extent along `axis`).
    pub rect: Aabb,
    /// The cell on the low side and the cell on the high side of the plane.
    pub cells: [u32; 2],
}

impl Portal {
    /// The cell on the other side from `cell`.
    pub fn other(&self, cell: u32) -> u32 {
        if self.cells[0] == cell {
            self.cells[1]
        } else {
            self.cells[0]
        }
    }

    /// +1 when going from `from` through the portal moves along +axis, else -1.
    pub fn direction_from(&self, from: u32) -> f32 {
        if self.cells[0] == from { 1.0 } else { -1.0 }
    }

    /// The plane coordinate along `axis`.
    pub fn plane(&self) -> f32 {
        self.rect.min[self.axis as usize]
    }

    /// The four corners, in cyclic order.
    pub fn corners(&self) -> [Vec3; 4] {
        let a = self.axis as usize;
        let (u, v) = ((a + 1) % 3, (a + 2) % 3);
        let (lo, hi) = (self.rect.min, self.rect.max);
        let corner = |x: f32, y: f32| {
            let mut p = Vec3::ZERO;
            p[a] = lo[a];
            p[u] = x;
            p[v] = y;
            p
        };
        [
            corner(lo[u], lo[v]),
            corner(hi[u], lo[v]),
            corner(hi[u], hi[v]),
            corner(lo[u], hi[v]),
        ]
    }
}

/// A node of the k-D tree over the cells.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum KdNode {
    /// A leaf: the cell index.
    Leaf(u32),
    /// An inner node: points with `p[axis] < at` go to `lo`, the others to `hi` (node indices).
    Split {
        /// Split axis.
        axis: u8,
        /// Split coordinate.
        at: f32,
        /// Low child.
        lo: u32,
        /// High child.
        hi: u32,
    },
}

/// The compact cell graph a client needs for its own culling (`/v1/cells`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellGraph {
    /// Box of the whole subdivision (the model's bounds plus a margin of outside space).
    pub bounds: Aabb,
    /// Leaf cells.
    pub cells: Vec<Cell>,
    /// Portals.
    pub portals: Vec<Portal>,
    /// The k-D tree; node 0 is the root.
    pub tree: Vec<KdNode>,
    /// True when the model had no usable occluders and a grid of open cells was used.
    pub grid_fallback: bool,
}

impl CellGraph {
    /// The cell containing `p`, if `p` is inside the subdivision. A graph grown from pages
    /// ([`CellGraph::sparse`]) has no k-D tree: the live cells it knows are looked through.
    pub fn locate(&self, p: Vec3) -> Option<u32> {
        let b = &self.bounds;
        if (0..3).any(|i| p[i] < b.min[i] || p[i] > b.max[i]) {
            return None;
        }
        if self.tree.is_empty() {
            let inside = |b: &Aabb| (0..3).all(|i| b.min[i] <= p[i] && p[i] <= b.max[i]);
            return self
                .cells
                .iter()
                .position(|c| c.live && inside(&c.bounds))
                .map(|c| c as u32);
        }
        let mut node = 0usize;
        loop {
            match *self.tree.get(node)? {
                KdNode::Leaf(c) => return Some(c),
                KdNode::Split { axis, at, lo, hi } => {
                    node = if p[axis as usize] < at { lo } else { hi } as usize;
                }
            }
        }
    }

    /// Cells whose closed box intersects `query` (k-D traversal).
    pub fn cells_touching(&self, query: &Aabb) -> Vec<u32> {
        let mut out = Vec::new();
        let mut stack = vec![0u32];
        while let Some(n) = stack.pop() {
            match self.tree.get(n as usize) {
                Some(KdNode::Leaf(c)) if touches(&self.cells[*c as usize].bounds, query) => {
                    out.push(*c);
                }
                Some(KdNode::Leaf(_)) => {}
                Some(KdNode::Split { axis, at, lo, hi }) => {
                    let a = *axis as usize;
                    if query.min[a] <= *at + polytope::EPS {
                        stack.push(*lo);
                    }
                    if query.max[a] >= *at - polytope::EPS {
                        stack.push(*hi);
                    }
                }
                None => {}
            }
        }
        out
    }

    /// Number of cells an observer can be in.
    pub fn live_cells(&self) -> usize {
        self.cells.iter().filter(|c| c.live).count()
    }

    /// Checks every cross-reference (tree nodes and children, leaf cells, portal cells and
    /// axes, cells' portal lists) and that every box is finite, so that no traversal of a graph
    /// read from a file can index out of range or loop.
    pub fn validate(&self) -> Result<(), String> {
        let (cells, portals, nodes) = (self.cells.len(), self.portals.len(), self.tree.len());
        let finite = |b: &Aabb| b.min.iter().chain(&b.max).all(|x| x.is_finite());
        if !finite(&self.bounds) {
            return Err("the bounds are not finite".into());
        }
        if nodes == 0 {
            return Err("the k-D tree is empty".into());
        }
        for (i, n) in self.tree.iter().enumerate() {
            match *n {
                KdNode::Leaf(c) if c as usize >= cells => {
                    return Err(format!("tree node {i} names cell {c} of {cells}"));
                }
                // Children come after their parent: no cycles.
                KdNode::Split { axis, at, lo, hi } => {
                    if axis > 2 || !at.is_finite() {
                        return Err(format!("tree node {i} splits on axis {axis} at {at}"));
                    }
                    for child in [lo, hi] {
                        if child as usize >= nodes || child as usize <= i {
                            return Err(format!("tree node {i} has child {child} of {nodes}"));
                        }
                    }
                }
                _ => {}
            }
        }
        for (i, p) in self.portals.iter().enumerate() {
            if p.axis > 2 || p.cells.iter().any(|&c| c as usize >= cells) || !finite(&p.rect) {
                return Err(format!("portal {i} is malformed"));
            }
        }
        for (i, c) in self.cells.iter().enumerate() {
            if !finite(&c.bounds) || c.portals.iter().any(|&p| p as usize >= portals) {
                return Err(format!("cell {i} is malformed"));
            }
        }
        Ok(())
    }
}

/// Closed-box intersection (touching faces count).
pub fn touches(a: &Aabb, b: &Aabb) -> bool {
    (0..3).all(|i| a.min[i] <= b.max[i] + polytope::EPS && b.min[i] <= a.max[i] + polytope::EPS)
}

/// One reached cell of a source cell's stab list (Funkhouser Fig. 3.22).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StabEntry {
    /// The reached cell.
    pub cell: u32,
    /// A box bounding the part of the reached cell visible from the source (the halfspaces
    /// `min <= x <= max`): a superset of the union of the visible regions over all portal
    /// sequences that reach it.
    pub region: Aabb,
    /// Objects (instance indices) in the reached cell visible from the source, sorted.
    pub objects: Vec<u32>,
}

/// Everything precomputed for one source cell: its incident objects and its stab list.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct StabList {
    /// Objects completely inside the cell.
    pub inside: Vec<u32>,
    /// Objects partially inside the cell.
    pub partial: Vec<u32>,
    /// Reached cells, the source itself first.
    pub entries: Vec<StabEntry>,
    /// True when the search hit its work limit and fell back to every connected cell
    /// (still conservative, just less tight).
    pub fallback: bool,
}

impl StabList {
    /// The cell-to-cell visibility: every reached cell.
    pub fn cells(&self) -> impl Iterator<Item = u32> + '_ {
        self.entries.iter().map(|e| e.cell)
    }

    /// The cell-to-object visibility: sorted, deduplicated instance indices.
    pub fn objects(&self) -> Vec<u32> {
        let mut all: Vec<u32> = self
            .entries
            .iter()
            .flat_map(|e| e.objects.iter().copied())
            .collect();
        all.sort_unstable();
        all.dedup();
        all
    }

    /// The entry for a reached cell.
    pub fn entry(&self, cell: u32) -> Option<&StabEntry> {
        self.entries.iter().find(|e| e.cell == cell)
    }

    /// Checks that every cell and object it names exists (`cells`, `objects` counts) and that
    /// its regions are finite.
    pub fn validate(&self, cells: usize, objects: usize) -> Result<(), String> {
        let obj_ok = |o: &u32| (*o as usize) < objects;
        if !self.inside.iter().chain(&self.partial).all(obj_ok) {
            return Err("an incident object does not exist".into());
        }
        for e in &self.entries {
            if e.cell as usize >= cells || !e.objects.iter().all(obj_ok) {
                return Err(format!(
                    "the entry for cell {} names what does not exist",
                    e.cell
                ));
            }
            if !e
                .region
                .min
                .iter()
                .chain(&e.region.max)
                .all(|x| !x.is_nan())
            {
                return Err(format!("the entry for cell {} has a NaN region", e.cell));
            }
        }
        Ok(())
    }
}

/// Funkhouser Table 3.2: mean and maximum statistics over the live cells.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CellStats {
    /// Leaf cells.
    pub cells: u64,
    /// Cells an observer can be in.
    pub live_cells: u64,
    /// Portals.
    pub portals: u64,
    /// Occluder boxes used.
    pub occluder_boxes: u64,
    /// Whether the grid fallback was used.
    pub grid_fallback: bool,
    /// Source cells whose search fell back to every connected cell.
    pub search_fallbacks: u64,
    /// (mean, max) portals per live cell.
    pub portals_per_cell: (f64, u64),
    /// (mean, max) objects completely inside.
    pub objects_inside: (f64, u64),
    /// (mean, max) objects partially inside.
    pub objects_partial: (f64, u64),
    /// (mean, max) cells visible.
    pub cells_visible: (f64, u64),
    /// (mean, max) objects visible.
    pub objects_visible: (f64, u64),
}

#[cfg(feature = "native")]
/// The result of the whole precomputation.
#[derive(Debug, Clone)]
pub struct Precomputed {
    /// The cell graph.
    pub graph: CellGraph,
    /// One stab list per cell (empty for dead cells).
    pub stabs: Vec<StabList>,
    /// Table 3.2 statistics.
    pub stats: CellStats,
    /// Seconds spent on the subdivision (with portals and incidence). Not stored in the file,
    /// which must not depend on timing.
    pub subdivision_seconds: f64,
    /// Seconds spent on the visibility precomputation.
    pub visibility_seconds: f64,
}

#[cfg(feature = "native")]
/// Runs subdivision, portals, incidence and visibility for a model's occluder boxes and object
/// bounds. `on_cell` is called once per source cell done (for a progress bar).
pub fn precompute(
    bounds: &Aabb,
    occluders: &occluders::Occluders,
    objects: &[Aabb],
    on_stage: &(dyn Fn(&str, u64) + Sync),
    on_cell: &(dyn Fn() + Sync),
) -> Precomputed {
    let t0 = std::time::Instant::now();
    let core = core_of(bounds, objects);
    let mut graph = subdivide::subdivide_around(
        bounds,
        &core,
        &occluders.faces,
        &occluders.solids,
        &occluders.rooms,
    );
    portals::find_portals_around(
        &mut graph,
        &core,
        &occluders.faces,
        &occluders.solids,
        objects,
    );
    let incidence = stab::incidence(&graph, objects);
    let subdivision_seconds = t0.elapsed().as_secs_f64();
    let t1 = std::time::Instant::now();
    on_stage("visibility", graph.cells.len() as u64);
    let stabs = stab::all_stab_lists(&graph, objects, incidence, on_cell);
    let stats = stats(&graph, &stabs, occluders.faces.len());
    Precomputed {
        graph,
        stabs,
        stats,
        subdivision_seconds,
        visibility_seconds: t1.elapsed().as_secs_f64(),
    }
}

/// A surrounding's footprint is at least this many times the rest's along both horizontal
/// axes.
pub const SURROUNDING_SCALE: f32 = 3.0;
/// Most objects taken as surroundings of one model.
pub const MAX_SURROUNDINGS: usize = 4;

/// The objects that frame a building rather than belong to it (index = object): ground
/// planes, site terrain, a horizon plane, a sky dome. Each is one of the few objects whose
/// footprint is at least [`SURROUNDING_SCALE`] times the rest's along both horizontal axes,
/// and is flat or terrain-like (at most a quarter as high as it is wide) or encloses the rest
/// on every axis (a dome). Such an object must not set the space the building is subdivided
/// in: a 60 m ground under a 10 m house would make the whole house one cell.
pub fn surroundings(objects: &[Aabb]) -> Vec<bool> {
    let mut out = vec![false; objects.len()];
    let mut order: Vec<usize> = (0..objects.len()).collect();
    let footprint = |b: &Aabb| {
        let s = b.size();
        s.x.max(0.0) * s.z.max(0.0)
    };
    order.sort_by(|&a, &b| footprint(&objects[b]).total_cmp(&footprint(&objects[a])));
    for &big in order.iter().take(MAX_SURROUNDINGS) {
        let rest = objects
            .iter()
            .enumerate()
            .filter(|&(i, _)| i != big && !out[i])
            .fold(Aabb::EMPTY, |acc, (_, b)| acc.union(b));
        if rest.is_empty() {
            break;
        }
        let (b, r) = (objects[big].size(), rest.size());
        let wide = [0, 2]
            .iter()
            .all(|&k| b[k] >= SURROUNDING_SCALE * r[k].max(crate::cells::subdivide::MIN_THICKNESS));
        let flat = b.y <= 0.25 * b.x.min(b.z);
        let encloses =
            (0..3).all(|k| objects[big].min[k] < rest.min[k] && objects[big].max[k] > rest.max[k]);
        if !(wide && (flat || encloses)) {
            break;
        }
        out[big] = true;
    }
    out
}

#[cfg(feature = "native")]
/// The part of `bounds` the building occupies: the bulk ([`crate::bulk`]) of the objects that
/// are not its [`surroundings`]; `bounds` itself when there are neither strays nor
/// surroundings.
fn core_of(bounds: &Aabb, objects: &[Aabb]) -> Aabb {
    let around = surroundings(objects);
    let boxes: Vec<crate::bulk::DBox> = objects
        .iter()
        .zip(&around)
        .filter(|(_, a)| !**a)
        .map(|(o, _)| crate::bulk::DBox {
            min: Vec3::from(o.min).as_dvec3(),
            max: Vec3::from(o.max).as_dvec3(),
        })
        .collect();
    let b = crate::bulk::bulk(&boxes);
    if (b.strays.is_empty() && !around.contains(&true)) || b.bounds.is_empty() {
        return *bounds;
    }
    Aabb {
        min: std::array::from_fn(|k| (b.bounds.min[k] as f32).max(bounds.min[k])),
        max: std::array::from_fn(|k| (b.bounds.max[k] as f32).min(bounds.max[k])),
    }
}

#[cfg(feature = "native")]
/// Table 3.2's statistics of a graph and its stab lists (again after the build's guard
/// ([`guard`]) added to them).
pub fn stats(graph: &CellGraph, stabs: &[StabList], occluder_boxes: usize) -> CellStats {
    let live: Vec<usize> = (0..graph.cells.len())
        .filter(|&i| graph.cells[i].live)
        .collect();
    let mean_max = |f: &dyn Fn(usize) -> u64| -> (f64, u64) {
        let vals: Vec<u64> = live.iter().map(|&i| f(i)).collect();
        let n = vals.len().max(1) as f64;
        (
            vals.iter().sum::<u64>() as f64 / n,
            vals.iter().copied().max().unwrap_or(0),
        )
    };
    CellStats {
        cells: graph.cells.len() as u64,
        live_cells: live.len() as u64,
        portals: graph.portals.len() as u64,
        occluder_boxes: occluder_boxes as u64,
        grid_fallback: graph.grid_fallback,
        search_fallbacks: stabs.iter().filter(|s| s.fallback).count() as u64,
        portals_per_cell: mean_max(&|i| graph.cells[i].portals.len() as u64),
        objects_inside: mean_max(&|i| stabs[i].inside.len() as u64),
        objects_partial: mean_max(&|i| stabs[i].partial.len() as u64),
        cells_visible: mean_max(&|i| stabs[i].entries.len() as u64),
        objects_visible: mean_max(&|i| stabs[i].objects().len() as u64),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bx(min: [f32; 3], max: [f32; 3]) -> Aabb {
        Aabb { min, max }
    }

    #[test]
    fn ground_planes_and_domes_surround_a_building_and_its_own_slabs_do_not() {
        let house = vec![
            bx([0.0, -0.2, 0.0], [10.0, 0.0, 8.0]), // floor slab
            bx([0.0, 0.0, 0.0], [10.0, 3.0, 0.2]),  // a wall
            bx([0.0, 3.0, 0.0], [10.0, 3.2, 8.0]),  // roof
            bx([2.0, 0.0, 2.0], [3.0, 1.0, 3.0]),   // a table
        ];
        assert_eq!(surroundings(&house), vec![false; 4]);
        let mut site = house.clone();
        site.push(bx([-25.0, -0.21, -26.0], [35.0, -0.21, 34.0])); // 60 m ground
        site.push(bx([-500.0, -500.0, -500.0], [500.0, 500.0, 500.0])); // sky dome
        assert_eq!(
            surroundings(&site),
            vec![false, false, false, false, true, true]
        );
        // A tall tower on a plinth twice its width is a building, not a site.
        let tower = vec![
            bx([0.0, 0.0, 0.0], [20.0, 1.0, 20.0]),
            bx([5.0, 1.0, 5.0], [15.0, 100.0, 15.0]),
        ];
        assert_eq!(surroundings(&tower), vec![false, false]);
    }
}
