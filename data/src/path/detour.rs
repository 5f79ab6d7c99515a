//! A person walks round the furniture. The tour's points are joined by straight steps, each
//! inside one cell; a step that would pass through an object standing in the cell (a shelf, a
//! desk, a door leaf open against a wall) is planned again on a grid over the cell's floor:
//! A* (Hart, Nilsson & Raphael 1968) round the objects that reach between the knees and the
//! top of the head, the walker's body radius about them, then pulled straight (each corner
//! kept only where the straight line past it would hit an object). The cells are convex and
//! every corner is kept inside its cell, so every detour stays in it. A step that cannot go
//! round (a cell full of one object, as a stairwell's flight is) takes the way with the least
//! length inside objects (walking through an object costs 50 times walking round it); a
//! search too long for its cell leaves the step straight.
//!
//! All lengths in metres.

use crate::cells::CellGraph;
use crate::geometry::Aabb;
use crate::person::EYE_HEIGHT;
use glam::Vec3;
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};

/// Grid spacing over a cell's floor.
pub const GRID_M: f32 = 0.2;
/// How far the walker's body keeps from an object (half a person's shoulder width).
pub const BODY_RADIUS_M: f32 = 0.25;
/// Objects lower than this above the floor are stepped over (rugs, skirting).
pub const STEP_OVER_M: f32 = 0.2;
/// Cells with more grid nodes than this are not planned (their steps stay straight).
const MAX_NODES: usize = 250_000;
/// A search that has expanded this many nodes gives up (the step stays straight).
const MAX_EXPANSIONS: usize = 50_000;

/// `points` (consecutive ones sharing a cell of `graph`) with the steps that pass through
/// `objects` replaced by ways round them. Points are kept; detours are inserted between them.
/// Each cell's grid is made once, at each floor it is walked on.
pub fn round_objects(graph: &CellGraph, objects: &[Aabb], points: &[Vec3]) -> Vec<Vec3> {
    let mut grids: HashMap<(u32, i32), Option<Grid>> = HashMap::new();
    let mut out: Vec<Vec3> = points.first().copied().into_iter().collect();
    for w in points.windows(2) {
        let (a, b) = (w[0], w[1]);
        if let Some(cell) = step_cell(graph, a, b) {
            let floor = a.y.min(b.y) - EYE_HEIGHT;
            let grid = grids
                .entry((cell, (floor * 10.0).round() as i32))
                .or_insert_with(|| Grid::new(&graph.cells[cell as usize].bounds, objects, floor));
            if let Some(grid) = grid
                && !grid.clear(a, b)
            {
                out.extend(grid.way(a, b));
            }
        }
        out.push(b);
    }
    out
}

/// The cell holding the whole step from `a` to `b` on one floor, if there is one (a step
/// through a portal or up a stair's hole has none: it is left straight).
fn step_cell(graph: &CellGraph, a: Vec3, b: Vec3) -> Option<u32> {
    let cell = graph.locate((a + b) * 0.5)?;
    let c = &graph.cells[cell as usize].bounds;
    let inside = |p: Vec3| (0..3).all(|k| p[k] >= c.min[k] - 1e-3 && p[k] <= c.max[k] + 1e-3);
    (inside(a) && inside(b) && (a.y - b.y).abs() <= 0.5).then_some(cell)
}

/// The free and blocked nodes of one cell's floor for a walker standing on one floor.
struct Grid {
    /// The cell's box: nodes lie inside it.
    cell: Aabb,
    nx: usize,
    nz: usize,
    blocked: Vec<bool>,
}

impl Grid {
    /// The grid of the cell `c` for a walker whose feet are at height `floor`, if any object
    /// reaches into the walker's body there.
    fn new(c: &Aabb, objects: &[Aabb], floor: f32) -> Option<Grid> {
        let (low, high) = (floor + STEP_OVER_M, floor + EYE_HEIGHT + 0.2);
        let r = BODY_RADIUS_M;
        let solid: Vec<&Aabb> = objects
            .iter()
            .filter(|o| o.min[1] < high && o.max[1] > low)
            .filter(|o| {
                o.min[0] - r < c.max[0]
                    && o.max[0] + r > c.min[0]
                    && o.min[2] - r < c.max[2]
                    && o.max[2] + r > c.min[2]
            })
            .collect();
        if solid.is_empty() {
            return None;
        }
        let nx = ((c.max[0] - c.min[0]) / GRID_M).ceil().max(1.0) as usize;
        let nz = ((c.max[2] - c.min[2]) / GRID_M).ceil().max(1.0) as usize;
        if nx.checked_mul(nz).is_none_or(|n| n > MAX_NODES) {
            return None;
        }
        let mut blocked = vec![false; nx * nz];
        for o in solid {
            let span = |k: usize, n: usize| {
                let lo = ((o.min[k] - r - c.min[k]) / GRID_M).floor().max(0.0) as usize;
                let hi = ((o.max[k] + r - c.min[k]) / GRID_M).ceil().max(0.0) as usize;
                lo..hi.min(n)
            };
            for i in span(0, nx) {
                for j in span(2, nz) {
                    blocked[j * nx + i] = true;
                }
            }
        }
        Some(Grid {
            cell: *c,
            nx,
            nz,
            blocked,
        })
    }

    fn node(&self, p: Vec3) -> usize {
        let c = &self.cell;
        let i = (((p.x - c.min[0]) / GRID_M).max(0.0) as usize).min(self.nx - 1);
        let j = (((p.z - c.min[2]) / GRID_M).max(0.0) as usize).min(self.nz - 1);
        j * self.nx + i
    }

    /// The middle of node `n` at height `y`, kept 5 cm inside the cell (the last row and
    /// column of nodes may overhang it).
    fn centre(&self, n: usize, y: f32) -> Vec3 {
        let c = &self.cell;
        let (i, j) = (n % self.nx, n / self.nx);
        let inside = |k: usize, v: f32| {
            let m = (0.25 * (c.max[k] - c.min[k])).min(0.05);
            v.clamp(c.min[k] + m, c.max[k] - m)
        };
        Vec3::new(
            inside(0, c.min[0] + (i as f32 + 0.5) * GRID_M),
            y,
            inside(2, c.min[2] + (j as f32 + 0.5) * GRID_M),
        )
    }

    /// Whether the straight step from `a` to `b` crosses no blocked node, other than those
    /// where it starts or ends (a point itself may stand close to an object).
    fn clear(&self, a: Vec3, b: Vec3) -> bool {
        let (na, nb) = (self.node(a), self.node(b));
        let steps = (a.distance(b) / (0.25 * GRID_M)).ceil().max(1.0) as usize;
        (0..=steps).all(|s| {
            let n = self.node(a.lerp(b, s as f32 / steps as f32));
            !self.blocked[n] || n == na || n == nb
        })
    }

    /// The corners of a way from `a` to `b` round the blocked nodes (not `a` and `b`
    /// themselves): A* over the 8-connected grid, blocked nodes costing 50 times their
    /// length, then pulled straight.
    fn way(&self, a: Vec3, b: Vec3) -> Vec<Vec3> {
        let (start, goal) = (self.node(a), self.node(b));
        let n = self.nx * self.nz;
        let mut cost = vec![f32::INFINITY; n];
        let mut came = vec![usize::MAX; n];
        let at = |n: usize| ((n % self.nx) as f32, (n / self.nx) as f32);
        let (gx, gz) = at(goal);
        let guess = |n: usize| {
            let (x, z) = at(n);
            let (dx, dz) = ((x - gx).abs(), (z - gz).abs());
            dx.max(dz) + (std::f32::consts::SQRT_2 - 1.0) * dx.min(dz)
        };
        let key = |f: f32| Reverse((f * 1000.0) as u64);
        let mut open = BinaryHeap::from([(key(guess(start)), start)]);
        cost[start] = 0.0;
        let mut expanded = 0;
        while let Some((_, cur)) = open.pop() {
            if cur == goal {
                break;
            }
            expanded += 1;
            if expanded > MAX_EXPANSIONS {
                return Vec::new();
            }
            let (x, z) = (cur % self.nx, cur / self.nx);
            for (dx, dz) in [
                (-1, 0),
                (1, 0),
                (0, -1),
                (0, 1),
                (-1, -1),
                (-1, 1),
                (1, -1),
                (1, 1),
            ] {
                let (x2, z2) = (x as i64 + dx, z as i64 + dz);
                if x2 < 0 || z2 < 0 || x2 >= self.nx as i64 || z2 >= self.nz as i64 {
                    continue;
                }
                let next = z2 as usize * self.nx + x2 as usize;
                let length = if dx != 0 && dz != 0 {
                    std::f32::consts::SQRT_2
                } else {
                    1.0
                };
                let weight = if self.blocked[next] { 50.0 } else { 1.0 };
                let c = cost[cur] + length * weight;
                if c < cost[next] {
                    cost[next] = c;
                    came[next] = cur;
                    open.push((key(c + guess(next)), next));
                }
            }
        }
        if came[goal] == usize::MAX {
            return Vec::new();
        }
        let mut nodes = vec![goal];
        while let Some(&last) = nodes.last()
            && last != start
        {
            nodes.push(came[last]);
        }
        nodes.reverse();
        // Pull the way straight: from each kept point, on to the furthest node in a clear
        // line from it.
        let y = |i: usize| a.y + (b.y - a.y) * i as f32 / (nodes.len() - 1).max(1) as f32;
        let mut corners = Vec::new();
        let mut from = a;
        let mut i = 0;
        while i + 1 < nodes.len() {
            let mut j = nodes.len() - 1;
            let target = |j: usize| {
                if j == nodes.len() - 1 {
                    b
                } else {
                    self.centre(nodes[j], y(j))
                }
            };
            while j > i + 1 && !self.clear(from, target(j)) {
                j -= 1;
            }
            if j == nodes.len() - 1 {
                break;
            }
            from = target(j);
            corners.push(from);
            i = j;
        }
        corners
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph_of_one_room() -> CellGraph {
        let b = Aabb {
            min: [0.0, 0.0, 0.0],
            max: [6.0, 3.0, 6.0],
        };
        CellGraph {
            bounds: b,
            cells: vec![crate::cells::Cell {
                bounds: b,
                live: true,
                portals: vec![],
            }],
            portals: vec![],
            tree: vec![crate::cells::KdNode::Leaf(0)],
            grid_fallback: false,
        }
    }

    fn crosses(p: &[Vec3], o: &Aabb) -> bool {
        p.windows(2).any(|w| {
            (0..=100).any(|s| {
                let q = w[0].lerp(w[1], s as f32 / 100.0);
                q.x > o.min[0] && q.x < o.max[0] && q.z > o.min[2] && q.z < o.max[2]
            })
        })
    }

    #[test]
    fn a_step_through_a_shelf_goes_round_it() {
        let g = graph_of_one_room();
        let shelf = Aabb {
            min: [2.5, 0.0, 1.0],
            max: [3.5, 2.0, 5.0],
        };
        let (a, b) = (Vec3::new(1.0, 1.6, 3.0), Vec3::new(5.0, 1.6, 3.0));
        let p = round_objects(&g, &[shelf], &[a, b]);
        assert!(p.len() > 2, "{p:?}");
        assert_eq!((p[0], p[p.len() - 1]), (a, b));
        assert!(!crosses(&p, &shelf), "{p:?}");
        // Every corner keeps the body's radius from it (to within a grid step).
        let m = BODY_RADIUS_M - GRID_M;
        let near = Aabb {
            min: [shelf.min[0] - m, 0.0, shelf.min[2] - m],
            max: [shelf.max[0] + m, 2.0, shelf.max[2] + m],
        };
        assert!(p.iter().all(|&q| !crosses(&[q, q], &near)), "{p:?}");
        assert!(p.iter().all(|q| (q.y - 1.6).abs() < 1e-5));
    }

    #[test]
    fn clear_steps_low_objects_and_high_ones_are_left_straight() {
        let g = graph_of_one_room();
        let rug = Aabb {
            min: [1.0, 0.0, 1.0],
            max: [5.0, 0.02, 5.0],
        };
        let lamp = Aabb {
            min: [2.0, 2.5, 2.0],
            max: [4.0, 3.0, 4.0],
        };
        let pts = [Vec3::new(1.0, 1.6, 3.0), Vec3::new(5.0, 1.6, 3.0)];
        assert_eq!(round_objects(&g, &[rug, lamp], &pts), pts.to_vec());
        let aside = Aabb {
            min: [2.5, 0.0, 4.5],
            max: [3.5, 2.0, 5.5],
        };
        assert_eq!(round_objects(&g, &[aside], &pts), pts.to_vec());
    }
}
