//! The client's side of the paged manifest ([`portico_protocol::CoreManifest`],
//! [`portico_protocol::Page`]): the IO stage fetches (pull) or is pushed (push) each cell's
//! page with the cell's stab list, checks it against the core, learns its segment rows, and
//! hands its instance records and its part of the cell graph to the frame loop with the stab
//! list (Funkhouser §5.2: the client only needs what the cells of its observer range see).
//!
//! A stab list is never handed on before its cell's page was taken (it would name instances the
//! frame loop cannot place), and a segment whose row no page has brought waits for the pages on
//! their way, then fails and is asked for (or pushed) again.

use crate::io::Catalogue;
use portico_data::cells::paged::GraphCore;
use portico_data::format::{CellPage, Header, take_rows};
use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Mutex, RwLock};
use std::time::Duration;
use tokio::time::Instant;

/// How long a fetched segment waits for the pages on their way to bring its row before it
/// fails and is asked for again.
pub const ROW_WAIT: Duration = Duration::from_secs(3);

/// A page checked and taken into the segment table, for the frame loop.
pub type TakenPage = Arc<CellPage>;

/// What the IO stage knows of the pages.
pub struct PageBook {
    /// The core header (no instance table): pages are checked against it.
    core: Header,
    /// Instances in the whole model.
    instances: u32,
    /// The cell graph's frame: the pages' parts of the graph are checked against it.
    graph: Option<GraphCore>,
    /// The cell of each stab list segment.
    cells: HashMap<u32, u32>,
    state: Mutex<BookState>,
}

#[derive(Default)]
struct BookState {
    /// Cells whose page is on its way (asked for over HTTP).
    asked: HashSet<u32>,
    /// Cells whose page was taken.
    taken: HashSet<u32>,
    /// Pages taken, not yet handed to the frame loop, by their stab list's segment.
    pending: HashMap<u32, TakenPage>,
}

impl PageBook {
    /// A book for a client that started from a core manifest of `instances` instances (checked
    /// with [`portico_data::format::check_core`]).
    pub fn new(core: Header, instances: u32, graph: Option<GraphCore>) -> PageBook {
        let cells = core
            .cells
            .as_ref()
            .map(|c| c.stab_cells())
            .unwrap_or_default();
        PageBook {
            core,
            instances,
            graph,
            cells,
            state: Mutex::default(),
        }
    }

    fn state(&self) -> std::sync::MutexGuard<'_, BookState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The cell of stab list segment `id`, if it is one.
    pub fn cell_of(&self, id: u32) -> Option<u32> {
        self.cells.get(&id).copied()
    }

    /// The cell of stab list segment `id` when its page has been neither taken nor asked for;
    /// it counts as asked from now on ([`PageBook::release`] if the asking fails).
    pub fn claim(&self, id: u32) -> Option<u32> {
        let cell = self.cell_of(id)?;
        let mut st = self.state();
        (!st.taken.contains(&cell) && st.asked.insert(cell)).then_some(cell)
    }

    /// Forgets that `cell`'s page was asked for (the request failed).
    pub fn release(&self, cell: u32) {
        self.state().asked.remove(&cell);
    }

    /// Checks a page against the core (its instances, rows and part of the graph: the cell
    /// asked for, when `asked` says which) and takes its rows (and its LODs' decoded sizes) into
    /// `catalogue`; the page waits for its stab list ([`PageBook::handed`]).
    ///
    /// # Errors
    /// One line: the page is not the one asked for, or does not fit the model
    /// ([`Header::check_page`], [`GraphCore::check_part`]); nothing is taken then.
    pub fn take(
        &self,
        catalogue: &RwLock<Catalogue>,
        page: CellPage,
        asked: Option<u32>,
    ) -> anyhow::Result<()> {
        if let Some(c) = asked.filter(|&c| c != page.cell) {
            anyhow::bail!("page of cell {c}: the server sent cell {}'s", page.cell);
        }
        let mut cat = catalogue.write().unwrap_or_else(|e| e.into_inner());
        self.core
            .check_page(self.instances, cat.segments.len(), &page)
            .map_err(anyhow::Error::msg)?;
        match &self.graph {
            Some(g) => g.check_part(&page.graph),
            None if page.graph.cells.is_empty() && page.graph.portals.is_empty() => Ok(()),
            None => Err("the model has no cells, the page has some".to_string()),
        }
        .map_err(|e| anyhow::anyhow!("page of cell {}: {e}", page.cell))?;
        take_rows(&mut cat.segments, &page);
        for (_, inst) in &page.instances {
            for l in self.core.lods_of(inst) {
                let size = portico_data::geometry::plain_size(l.vertices, l.triangles, l.uv);
                cat.decoded.insert(l.segment, size);
            }
        }
        drop(cat);
        let mut st = self.state();
        st.asked.remove(&page.cell);
        st.taken.insert(page.cell);
        st.pending.insert(page.stab.0, Arc::new(page));
        Ok(())
    }

    /// A pushed page ([`portico_protocol::FRAME_PAGE`]'s payload): inflated, decoded, taken.
    ///
    /// # Errors
    /// One line: it does not inflate or decode, or does not fit the model.
    pub fn take_frame(&self, catalogue: &RwLock<Catalogue>, deflated: &[u8]) -> anyhow::Result<()> {
        let page = portico_protocol::inflate_page(deflated)
            .map_err(|e| anyhow::anyhow!("a pushed page: {e}"))?;
        self.take(catalogue, page, None)
    }

    /// The page that came for stab list segment `id`, once: it goes to the frame loop with the
    /// stab list.
    pub fn handed(&self, id: u32) -> Option<TakenPage> {
        self.state().pending.remove(&id)
    }

    /// Whether segment `id` can be checked and handed on now: its row is known and, for a stab
    /// list, its cell's page was taken.
    fn ready_now(&self, catalogue: &RwLock<Catalogue>, id: u32) -> bool {
        let row = catalogue
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .segments
            .get(id as usize)
            .is_some_and(|r| r.kind != 0);
        row && self
            .cell_of(id)
            .is_none_or(|c| self.state().taken.contains(&c))
    }

    /// Waits until segment `id` can be checked and handed on (its row is known and, for a stab
    /// list, its cell's page was taken) while pages are on their way, until `deadline` at most;
    /// whether it can.
    pub async fn ready(&self, catalogue: &RwLock<Catalogue>, id: u32, deadline: Instant) -> bool {
        loop {
            if self.ready_now(catalogue, id) {
                return true;
            }
            if self.state().asked.is_empty() || Instant::now() >= deadline {
                return false;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    }
}
