//! The client's side of the paged manifest ([`portico_protocol::CoreManifest`],
//! [`portico_protocol::Page`]), without IO: each cell's page comes with the cell's stab list
//! (fetched beside it over pull, pushed before it over push); it is checked against the core,
//! its segment rows go into the [`Catalogue`], and its instance records and its part of the
//! cell graph wait to go to the frame loop with the stab list (Funkhouser §5.2: the client only
//! needs what the cells of its observer range see).
//!
//! A stab list is never handed on before its cell's page was taken (it would name instances the
//! frame loop cannot place), and a segment whose row no page has brought waits while pages are
//! on their way ([`Readiness::Waiting`]), then fails and is asked for again (pull); a pushed one
//! is given back at once in a page (the server pushes pages before the stab lists that need
//! them) and after the same wait natively.

use super::catalogue::Catalogue;
use portico_data::cells::paged::GraphCore;
use portico_data::format::{CellPage, Header};
use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::time::Duration;

/// How long a segment whose row is not known waits for the pages on their way before it fails
/// and is asked for again.
pub const ROW_WAIT: Duration = Duration::from_secs(3);

/// A page checked and taken into the catalogue, for the frame loop.
pub type TakenPage = Arc<CellPage>;

/// Whether a segment can be checked and handed on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Readiness {
    /// Its row is known and, for a stab list, its cell's page was taken.
    Ready,
    /// Not yet, but pages are on their way that may bring it.
    Waiting,
    /// Not, and no page on its way can change that: it fails (and is asked for again).
    Never,
}

/// What the client knows of the pages.
#[derive(Debug)]
pub struct Pages {
    /// The core header (no instance table): pages are checked against it.
    core: Header,
    /// Instances in the whole model.
    instances: u32,
    /// The cell graph's frame: the pages' parts of the graph are checked against it.
    graph: Option<GraphCore>,
    /// The cell of each stab list segment.
    cells: HashMap<u32, u32>,
    /// Cells whose page is on its way (asked for over HTTP).
    asked: HashSet<u32>,
    /// Cells whose page was taken.
    taken: HashSet<u32>,
    /// Pages taken, not yet handed to the frame loop, by their stab list's segment.
    pending: HashMap<u32, TakenPage>,
}

impl Pages {
    /// The pages of a model whose core manifest has header `core` (no instance table),
    /// `instances` instances and the cell graph frame `graph` (checked with
    /// [`portico_data::format::check_core`]).
    pub fn new(core: Header, instances: u32, graph: Option<GraphCore>) -> Pages {
        let cells = core
            .cells
            .as_ref()
            .map(|c| c.stab_cells())
            .unwrap_or_default();
        Pages {
            core,
            instances,
            graph,
            cells,
            asked: HashSet::new(),
            taken: HashSet::new(),
            pending: HashMap::new(),
        }
    }

    /// The cell of stab list segment `id`, if it is one.
    pub fn cell_of(&self, id: u32) -> Option<u32> {
        self.cells.get(&id).copied()
    }

    /// The cell of stab list segment `id` when its page has been neither taken nor asked for;
    /// it counts as asked from now on ([`Pages::release`] if the asking fails).
    pub fn claim(&mut self, id: u32) -> Option<u32> {
        let cell = self.cell_of(id)?;
        (!self.taken.contains(&cell) && self.asked.insert(cell)).then_some(cell)
    }

    /// Forgets that `cell`'s page was asked for (the request failed).
    pub fn release(&mut self, cell: u32) {
        self.asked.remove(&cell);
    }

    /// Checks a page against the core (its instances, rows and part of the graph: the cell
    /// asked for, when `asked` says which) and takes its rows (and its LODs' decoded sizes) into
    /// `catalogue`; the page waits for its stab list ([`Pages::handed`]).
    ///
    /// # Errors
    /// One line: the page is not the one asked for, or does not fit the model
    /// ([`Header::check_page`], [`GraphCore::check_part`]); nothing is taken then.
    pub fn take(
        &mut self,
        catalogue: &mut Catalogue,
        page: CellPage,
        asked: Option<u32>,
    ) -> Result<(), String> {
        if let Some(c) = asked.filter(|&c| c != page.cell) {
            return Err(format!(
                "page of cell {c}: the server sent cell {}'s",
                page.cell
            ));
        }
        self.core
            .check_page(self.instances, catalogue.segments.len(), &page)?;
        match &self.graph {
            Some(g) => g.check_part(&page.graph),
            None if page.graph.cells.is_empty() && page.graph.portals.is_empty() => Ok(()),
            None => Err("the model has no cells, the page has some".to_string()),
        }
        .map_err(|e| format!("page of cell {}: {e}", page.cell))?;
        catalogue.take_page(&self.core, &page);
        self.asked.remove(&page.cell);
        self.taken.insert(page.cell);
        self.pending.insert(page.stab.0, Arc::new(page));
        Ok(())
    }

    /// A pushed page ([`portico_protocol::FRAME_PAGE`]'s payload): inflated, decoded, taken.
    ///
    /// # Errors
    /// One line: it does not inflate or decode, or does not fit the model.
    pub fn take_frame(&mut self, catalogue: &mut Catalogue, deflated: &[u8]) -> Result<(), String> {
        let page =
            portico_protocol::inflate_page(deflated).map_err(|e| format!("a pushed page: {e}"))?;
        self.take(catalogue, page, None)
    }

    /// The page that came for stab list segment `id`, once: it goes to the frame loop with the
    /// stab list.
    pub fn handed(&mut self, id: u32) -> Option<TakenPage> {
        self.pending.remove(&id)
    }

    /// Whether segment `id` can be checked and handed on now.
    pub fn readiness(&self, catalogue: &Catalogue, id: u32) -> Readiness {
        let page_taken = self.cell_of(id).is_none_or(|c| self.taken.contains(&c));
        if catalogue.known(id) && page_taken {
            Readiness::Ready
        } else if self.asked.is_empty() {
            Readiness::Never
        } else {
            Readiness::Waiting
        }
    }
}

#[cfg(test)]
mod tests;
