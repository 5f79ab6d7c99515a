//! The client's side of the paged manifest ([`portico_protocol::CoreManifest`],
//! [`portico_protocol::Page`]): the IO stage fetches (pull) or is pushed (push) each cell's
//! page with the cell's stab list, checks it against the core, learns its segment rows, and
//! hands its instance records to the frame loop with the stab list (Funkhouser §5.2: the
//! client only needs what the cells of its observer range see).

use crate::io::Catalogue;
use portico_data::format::{Header, InstanceRecord, take_rows};
use portico_protocol::Page;
use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Mutex, RwLock};
use std::time::Duration;

/// How long a fetched segment waits for the page that brings its row (one sent with another
/// batch, still on its way) before it fails and is asked for again.
pub const ROW_WAIT: Duration = Duration::from_secs(3);

/// A page checked and taken into the segment table, for the frame loop.
pub type TakenPage = Arc<Page<InstanceRecord>>;

/// What the IO stage knows of the pages.
pub struct PageBook {
    /// The core header (no instance table): pages are checked against it.
    core: Header,
    /// Instances in the whole model.
    instances: u32,
    /// The cell of each stab list segment.
    cells: HashMap<u32, u32>,
    state: Mutex<BookState>,
}

#[derive(Default)]
struct BookState {
    /// Cells whose page was asked for or came.
    asked: HashSet<u32>,
    /// Pages taken, not yet handed to the frame loop, by their stab list's segment.
    pending: HashMap<u32, TakenPage>,
}

impl PageBook {
    /// A book for a client that started from a core manifest of `instances` instances.
    pub fn new(core: Header, instances: u32) -> PageBook {
        let cells = core
            .cells
            .iter()
            .flat_map(|c| c.stab_segments.iter().enumerate())
            .filter(|(_, s)| **s != u32::MAX)
            .map(|(cell, &s)| (s, cell as u32))
            .collect();
        PageBook {
            core,
            instances,
            cells,
            state: Mutex::default(),
        }
    }

    fn state(&self) -> std::sync::MutexGuard<'_, BookState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The cell of stab list segment `id` when its page has not been asked for yet; it counts
    /// as asked from now on ([`PageBook::release`] if the asking fails).
    pub fn claim(&self, id: u32) -> Option<u32> {
        let cell = *self.cells.get(&id)?;
        self.state().asked.insert(cell).then_some(cell)
    }

    /// Forgets that `cell`'s page was asked for (the request failed).
    pub fn release(&self, cell: u32) {
        self.state().asked.remove(&cell);
    }

    /// Checks a page against the core and takes its rows (and its LODs' decoded sizes) into
    /// `catalogue`; the page waits for its stab list ([`PageBook::handed`]).
    ///
    /// # Errors
    /// The page does not fit the model ([`Header::check_page`]); nothing is taken then.
    pub fn take(
        &self,
        catalogue: &RwLock<Catalogue>,
        page: Page<InstanceRecord>,
    ) -> anyhow::Result<()> {
        let mut cat = catalogue.write().unwrap_or_else(|e| e.into_inner());
        self.core
            .check_page(self.instances, cat.segments.len(), &page)
            .map_err(anyhow::Error::msg)?;
        take_rows(&mut cat.segments, &page);
        for (_, inst) in &page.instances {
            for l in self.core.lods_of(inst) {
                let size = portico_data::geometry::plain_size(l.vertices, l.triangles, l.uv);
                cat.decoded.insert(l.segment, size);
            }
        }
        drop(cat);
        let mut st = self.state();
        st.asked.insert(page.cell);
        st.pending.insert(page.stab.0, Arc::new(page));
        Ok(())
    }

    /// A pushed page ([`portico_protocol::FRAME_PAGE`]'s payload): inflated, decoded, taken.
    ///
    /// # Errors
    /// It does not inflate or decode, or does not fit the model.
    pub fn take_frame(&self, catalogue: &RwLock<Catalogue>, deflated: &[u8]) -> anyhow::Result<()> {
        let page = portico_protocol::inflate_page(deflated)?;
        self.take(catalogue, page)
    }

    /// The page that came for stab list segment `id`, once: it goes to the frame loop with the
    /// stab list.
    pub fn handed(&self, id: u32) -> Option<TakenPage> {
        self.state().pending.remove(&id)
    }
}

/// Waits until the catalogue knows segment `id`'s row (a page on its way brings it), at most
/// [`ROW_WAIT`]; whether it does.
pub async fn row_known(catalogue: &RwLock<Catalogue>, id: u32) -> bool {
    let known = || {
        catalogue
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .segments
            .get(id as usize)
            .is_some_and(|r| r.kind != 0)
    };
    let until = tokio::time::Instant::now() + ROW_WAIT;
    while !known() {
        if tokio::time::Instant::now() >= until {
            return false;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    true
}
