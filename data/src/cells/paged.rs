//! The cell graph cut into pages, beside the instance table ([`crate::format::Header::page`]):
//! the core manifest carries the graph's frame ([`GraphCore`]: its box and counts), and each
//! cell's page the cells its stab list reaches with their portals ([`GraphPart`]). The portal
//! traversal from an eye in a cell only ever enters cells of that cell's stab list (its
//! cell-to-cell visibility bounds every eye inside it: Funkhouser §3.2.3, §4.1.2), so a client
//! holding the page of its eye cell reaches the cells it would with the whole graph. (Where the
//! traversal gives up for the frustum — a grid model, or too many portal sequences — it finds
//! only the cells it knows.)

use super::{Cell, CellGraph, Portal, StabList};
use crate::geometry::Aabb;
use serde::{Deserialize, Serialize};

/// The cell graph less its cells, portals and k-D tree: what the core manifest carries.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GraphCore {
    /// [`CellGraph::bounds`].
    pub bounds: Aabb,
    /// How many cells.
    pub cells: u32,
    /// How many portals.
    pub portals: u32,
    /// [`CellGraph::grid_fallback`].
    pub grid_fallback: bool,
}

/// The part of the cell graph one cell's page carries: every cell its stab list reaches (the
/// cell itself among them) and every portal on their boundaries, by index.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct GraphPart {
    /// Cells, ascending.
    pub cells: Vec<(u32, Cell)>,
    /// Portals, ascending.
    pub portals: Vec<(u32, Portal)>,
}

impl GraphCore {
    /// Checks a page's part against the graph's counts as [`CellGraph::validate`] checks the
    /// whole: indices in range, boxes finite, axes 0–2, and every portal a cell of the part
    /// lists is in the part (so no traversal meets a portal it does not know).
    ///
    /// # Errors
    /// One line naming the cell or portal at fault.
    pub fn check_part(&self, part: &GraphPart) -> Result<(), String> {
        let (cells, portals) = (self.cells as usize, self.portals as usize);
        let finite = |b: &Aabb| b.min.iter().chain(&b.max).all(|x| x.is_finite());
        let known: std::collections::HashSet<u32> = part.portals.iter().map(|(i, _)| *i).collect();
        for (i, p) in &part.portals {
            if *i as usize >= portals
                || p.axis > 2
                || p.cells.iter().any(|&c| c as usize >= cells)
                || !finite(&p.rect)
            {
                return Err(format!("portal {i} is malformed"));
            }
        }
        for (i, c) in &part.cells {
            if *i as usize >= cells || !finite(&c.bounds) {
                return Err(format!("cell {i} is malformed"));
            }
            if let Some(p) = c.portals.iter().find(|p| !known.contains(p)) {
                return Err(format!("cell {i} lists portal {p}, which the page lacks"));
            }
        }
        Ok(())
    }
}

impl CellGraph {
    /// The graph's frame for the core manifest.
    pub fn core(&self) -> GraphCore {
        GraphCore {
            bounds: self.bounds,
            cells: self.cells.len() as u32,
            portals: self.portals.len() as u32,
            grid_fallback: self.grid_fallback,
        }
    }

    /// The part of the graph the page of a cell with stab list `stab` carries.
    pub fn part(&self, stab: &StabList) -> GraphPart {
        let mut cells: Vec<u32> = stab.cells().collect();
        cells.sort_unstable();
        cells.dedup();
        cells.retain(|&c| (c as usize) < self.cells.len());
        let mut portals: Vec<u32> = cells
            .iter()
            .flat_map(|&c| self.cells[c as usize].portals.iter().copied())
            .filter(|&p| (p as usize) < self.portals.len())
            .collect();
        portals.sort_unstable();
        portals.dedup();
        GraphPart {
            cells: cells
                .into_iter()
                .map(|c| (c, self.cells[c as usize].clone()))
                .collect(),
            portals: portals
                .into_iter()
                .map(|p| (p, self.portals[p as usize]))
                .collect(),
        }
    }

    /// A graph to grow from pages: `core`'s frame, every cell a placeholder (dead, no box, no
    /// portals), every portal one that joins nothing, and no k-D tree ([`CellGraph::locate`]
    /// then looks through the live cells).
    pub fn sparse(core: &GraphCore) -> CellGraph {
        CellGraph {
            bounds: core.bounds,
            cells: vec![
                Cell {
                    bounds: Aabb::EMPTY,
                    live: false,
                    portals: Vec::new(),
                };
                core.cells as usize
            ],
            portals: vec![
                Portal {
                    axis: 0,
                    rect: Aabb::EMPTY,
                    cells: [u32::MAX; 2],
                };
                core.portals as usize
            ],
            tree: Vec::new(),
            grid_fallback: core.grid_fallback,
        }
    }

    /// Takes a checked part ([`GraphCore::check_part`]) into a sparse graph.
    pub fn take_part(&mut self, part: &GraphPart) {
        for (i, c) in &part.cells {
            if let Some(slot) = self.cells.get_mut(*i as usize) {
                *slot = c.clone();
            }
        }
        for (i, p) in &part.portals {
            if let Some(slot) = self.portals.get_mut(*i as usize) {
                *slot = *p;
            }
        }
    }
}
