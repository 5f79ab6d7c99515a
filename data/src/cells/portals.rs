//! Portals: the open parts of the boundaries shared by two cells (Funkhouser §3.2.1).
//!
//! For each cell and each of its three high faces, the cells on the other side are found
//! through the k-D tree; on each shared rectangle, the occluder faces lying in that plane are
//! marked opaque on the grid their edges induce, and the open grid cells are merged into
//! rectangles: the portals. The cell adjacency graph is the result. Cells wholly inside the
//! solids ([`super::solid`]), and sealed cells thinner than a person (the space inside walls
//! and slabs no solid box describes), are marked dead: no observer can get there. A sealed
//! cell a person fits in is a closed room, and live.

use super::{CellGraph, Portal, touches};
use crate::geometry::Aabb;

/// Ignore open slivers smaller than this (square metres).
const MIN_AREA: f32 = 1e-6;

/// Fills `graph.portals` and every live cell's portal list. Cells wholly inside the `solids`
/// are dead and get no portals; so do cells left without any that are thinner than a person.
pub fn find_portals(graph: &mut CellGraph, occluders: &[Aabb], solids: &[Aabb]) {
    let core = graph.bounds;
    find_portals_around(graph, &core, occluders, solids, &[]);
}

/// [`find_portals`] for a subdivision whose `core` (the building: the model less its strays
/// and surroundings) was cut out first ([`super::subdivide::subdivide_around`]). The cells
/// outside the core are the space around it (the site, a stray's surroundings): an outside
/// cell is live when a live core cell opens onto it, directly or through other outside cells,
/// or when one of the `objects` (boxes) touches it, so that the ground or a stray is in some
/// live cell's list and an observer out there sees it.
pub fn find_portals_around(
    graph: &mut CellGraph,
    core: &Aabb,
    occluders: &[Aabb],
    solids: &[Aabb],
    objects: &[Aabb],
) {
    let lookup = Buckets::new(occluders);
    let solid_lookup = Buckets::new(solids);
    let outside: Vec<bool> = graph
        .cells
        .iter()
        .map(|c| {
            (0..3).any(|a| {
                c.bounds.max[a] <= core.min[a] + 1e-5 || c.bounds.min[a] >= core.max[a] - 1e-5
            })
        })
        .collect();
    for cell in &mut graph.cells {
        cell.live = !inside_solids(&cell.bounds, &solid_lookup, solids);
    }
    let mut portals = Vec::new();
    for c in 0..graph.cells.len() {
        if !graph.cells[c].live {
            continue;
        }
        let b = graph.cells[c].bounds;
        for axis in 0..3 {
            let at = b.max[axis];
            let mut face = b;
            face.min[axis] = at;
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for n in graph.cells_touching(&face) {
                let nb = graph.cells[n as usize].bounds;
                if !graph.cells[n as usize].live || (nb.min[axis] - at).abs() > 1e-5 {
                    continue;
                }
                let mut shared = face;
                for w in [u, v] {
                    shared.min[w] = b.min[w].max(nb.min[w]);
                    shared.max[w] = b.max[w].min(nb.max[w]);
                }
                if (shared.max[u] - shared.min[u]) * (shared.max[v] - shared.min[v]) <= MIN_AREA {
                    continue;
                }
                let blockers: Vec<Aabb> = lookup
                    .near(&shared, occluders)
                    .into_iter()
                    .filter(|o| {
                        (o.min[axis] - at).abs() <= 1e-5 && (o.max[axis] - at).abs() <= 1e-5
                    })
                    .collect();
                for rect in open_rectangles(&shared, axis, &blockers) {
                    portals.push(Portal {
                        axis: axis as u8,
                        rect,
                        cells: [c as u32, n],
                    });
                }
            }
        }
    }
    // With a single cell there is nothing to connect; otherwise a core cell without any portal
    // is sealed: the inside of a wall or slab when it is thinner than a person
    // ([`SEALED_ROOM_MIN`]), else a closed room (a hall without openings), which stays live.
    let cells = graph.cells.len();
    let mut degree = vec![0usize; cells];
    for p in &portals {
        p.cells.iter().for_each(|&c| degree[c as usize] += 1);
    }
    let core_cells = outside.iter().filter(|o| !**o).count();
    for c in 0..cells {
        let thin = graph.cells[c].bounds.size().min_element() < SEALED_ROOM_MIN;
        if !outside[c] && core_cells > 1 && degree[c] == 0 && thin {
            graph.cells[c].live = false;
        }
    }
    // Outside cells: live when reached from a live core cell, or when something lies there.
    if outside.iter().any(|&o| o) {
        let mut reached: Vec<bool> = (0..cells)
            .map(|c| !outside[c] && graph.cells[c].live)
            .collect();
        for o in objects {
            for c in graph.cells_touching(o) {
                reached[c as usize] |= outside[c as usize];
            }
        }
        let mut changed = true;
        while changed {
            changed = false;
            for p in &portals {
                let [a, b] = p.cells.map(|c| c as usize);
                if reached[a] != reached[b] && graph.cells[a].live && graph.cells[b].live {
                    reached[a] = true;
                    reached[b] = true;
                    changed = true;
                }
            }
        }
        for c in 0..cells {
            if outside[c] && !reached[c] {
                graph.cells[c].live = false;
            }
        }
    }
    portals.retain(|p| p.cells.iter().all(|&c| graph.cells[c as usize].live));
    for (i, p) in portals.iter().enumerate() {
        for c in p.cells {
            graph.cells[c as usize].portals.push(i as u32);
        }
    }
    graph.portals = portals;
}

/// Whether the box lies wholly inside the union of the solids ([`super::solid::covered`]:
/// exact, so a cell with an opening anywhere in it stays live).
fn inside_solids(b: &Aabb, lookup: &Buckets, solids: &[Aabb]) -> bool {
    let near = lookup.near(b, solids);
    !near.is_empty() && super::solid::covered(b, &near)
}

/// A sealed cell (no portal to any other) narrower than this (metres) on some axis is the
/// inside of a wall or slab that no solid box describes: dead. A wider one is a closed room.
pub const SEALED_ROOM_MIN: f32 = 0.5;

/// The parts of `rect` (flat along `axis`) not covered by the blockers' projections, as
/// rectangles: grid cells between blocker edges, merged along rows, then rows merged.
pub fn open_rectangles(rect: &Aabb, axis: usize, blockers: &[Aabb]) -> Vec<Aabb> {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let cuts = |w: usize| -> Vec<f32> {
        let mut xs = vec![rect.min[w], rect.max[w]];
        for b in blockers {
            for x in [b.min[w], b.max[w]] {
                if x > rect.min[w] && x < rect.max[w] {
                    xs.push(x);
                }
            }
        }
        xs.sort_by(f32::total_cmp);
        xs.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
        xs
    };
    let (us, vs) = (cuts(u), cuts(v));
    let covered = |i: usize, j: usize| {
        let (cu, cv) = ((us[i] + us[i + 1]) * 0.5, (vs[j] + vs[j + 1]) * 0.5);
        blockers
            .iter()
            .any(|b| b.min[u] <= cu && cu <= b.max[u] && b.min[v] <= cv && cv <= b.max[v])
    };
    // Runs of open cells per row j, as (u0, u1) index pairs.
    let mut rects: Vec<(usize, usize, usize, usize)> = Vec::new(); // (i0, i1, j0, j1) exclusive
    for j in 0..vs.len() - 1 {
        let mut i = 0;
        while i < us.len() - 1 {
            if covered(i, j) {
                i += 1;
                continue;
            }
            let start = i;
            while i < us.len() - 1 && !covered(i, j) {
                i += 1;
            }
            // Extend a rectangle from the previous row with the same span, else start one.
            match rects
                .iter_mut()
                .find(|r| r.0 == start && r.1 == i && r.3 == j)
            {
                Some(r) => r.3 = j + 1,
                None => rects.push((start, i, j, j + 1)),
            }
        }
    }
    rects
        .into_iter()
        .map(|(i0, i1, j0, j1)| {
            let mut r = *rect;
            r.min[u] = us[i0];
            r.max[u] = us[i1];
            r.min[v] = vs[j0];
            r.max[v] = vs[j1];
            r
        })
        .filter(|r| (r.max[u] - r.min[u]) * (r.max[v] - r.min[v]) > MIN_AREA)
        .collect()
}

/// An R-tree over boxes, for "which boxes are near this box": its cost depends on the number of
/// boxes, never on the extent of the model (a grid over the extent would grow with a far
/// stray object).
struct Buckets {
    tree:
        rstar::RTree<rstar::primitives::GeomWithData<rstar::primitives::Rectangle<[f32; 3]>, u32>>,
}

impl Buckets {
    fn new(occluders: &[Aabb]) -> Self {
        let items = occluders
            .iter()
            .enumerate()
            .map(|(i, o)| {
                rstar::primitives::GeomWithData::new(
                    rstar::primitives::Rectangle::from_corners(o.min, o.max),
                    i as u32,
                )
            })
            .collect();
        Buckets {
            tree: rstar::RTree::bulk_load(items),
        }
    }

    fn near(&self, q: &Aabb, occluders: &[Aabb]) -> Vec<Aabb> {
        let grown = rstar::AABB::from_corners(q.min.map(|x| x - 1e-4), q.max.map(|x| x + 1e-4));
        let mut ids: Vec<u32> = self
            .tree
            .locate_in_envelope_intersecting(&grown)
            .map(|g| g.data)
            .collect();
        ids.sort_unstable();
        ids.into_iter()
            .map(|i| occluders[i as usize])
            .filter(|o| touches(o, q))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::subdivide::subdivide;

    fn bx(min: [f32; 3], max: [f32; 3]) -> Aabb {
        Aabb { min, max }
    }

    #[test]
    fn a_hole_in_the_middle_leaves_one_open_rectangle() {
        let rect = bx([0.0, 0.0, 0.0], [0.0, 3.0, 4.0]);
        let blockers = [
            bx([-0.1, 0.0, 0.0], [0.0, 3.0, 1.0]),
            bx([-0.1, 0.0, 2.0], [0.0, 3.0, 4.0]),
            bx([0.0, 2.0, 1.0], [0.2, 3.0, 2.0]),
        ];
        let open = open_rectangles(&rect, 0, &blockers);
        assert_eq!(open.len(), 1, "{open:?}");
        assert_eq!(open[0].min, [0.0, 0.0, 1.0]);
        assert_eq!(open[0].max, [0.0, 2.0, 2.0]);
    }

    #[test]
    fn two_rooms_joined_by_a_door_have_portals_only_through_it() {
        let walls = crate::cells::subdivide::tests::faces_of(&[
            bx([5.0, 0.0, 0.0], [5.2, 3.0, 1.0]),
            bx([5.0, 0.0, 2.0], [5.2, 3.0, 4.0]),
            bx([5.0, 2.0, 1.0], [5.2, 3.0, 2.0]),
        ]);
        let mut g = subdivide(&bx([0.0; 3], [10.0, 3.0, 4.0]), &walls);
        find_portals(&mut g, &walls, &[]);
        let door = g.locate(glam::Vec3::new(5.1, 1.0, 1.5)).unwrap();
        let left = g.locate(glam::Vec3::new(2.0, 1.0, 2.0)).unwrap();
        let right = g.locate(glam::Vec3::new(8.0, 1.0, 2.0)).unwrap();
        let neighbours = |c: u32| -> Vec<u32> {
            g.cells[c as usize]
                .portals
                .iter()
                .map(|&p| g.portals[p as usize].other(c))
                .collect()
        };
        assert!(neighbours(door).contains(&left) && neighbours(door).contains(&right));
        assert!(
            !neighbours(left).contains(&right),
            "the wall must separate the rooms"
        );
        let inside_wall = g.locate(glam::Vec3::new(5.1, 1.0, 3.0)).unwrap();
        assert!(
            !g.cells[inside_wall as usize].live,
            "wall interior must be dead"
        );
        assert!(g.cells[door as usize].live);
        for p in &g.portals {
            assert!(g.cells[p.cells[0] as usize].live && g.cells[p.cells[1] as usize].live);
        }
    }
}
