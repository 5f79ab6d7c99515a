//! One read request of a page's pull: the batch, and beside it the pages of the stab lists it
//! carries when the page started from the core manifest (as the native IO thread does). Each
//! segment is checked against its row once the pages on their way have brought it
//! ([`portico_client::engine::pages::Readiness`]), waiting at most
//! [`portico_client::engine::pages::ROW_WAIT`].

use crate::net::Remote;
use portico_client::engine::catalogue::Catalogue;
use portico_client::engine::pages::{Pages, ROW_WAIT, Readiness};
use std::cell::RefCell;
use std::collections::HashMap;
use std::rc::Rc;
use wasm_bindgen_futures::JsFuture;
use web_time::Instant;

/// What a read request needs of the IO stage.
pub struct Read {
    /// The server.
    pub remote: Rc<Remote>,
    /// The segment table (pages add rows to it).
    pub catalogue: Rc<RefCell<Catalogue>>,
    /// Started from the core manifest: the pages.
    pub pages: Option<Rc<RefCell<Pages>>>,
}

impl Read {
    /// Reads `ids` (and the pages their stab lists need): each segment checked against its row,
    /// or why not; the whole request may fail too.
    pub async fn batch(
        &self,
        ids: Vec<u32>,
    ) -> anyhow::Result<Vec<(u32, Result<Vec<u8>, String>)>> {
        let cells: Vec<(u32, u32)> = match &self.pages {
            Some(p) => {
                let mut p = p.borrow_mut();
                ids.iter()
                    .filter_map(|&s| p.claim(s).map(|c| (s, c)))
                    .collect()
            }
            None => Vec::new(),
        };
        let pages = futures_util::future::join_all(cells.iter().map(|&(_, c)| self.remote.page(c)));
        let (got, pages) = futures_util::future::join(self.remote.batch(&ids), pages).await;
        // A stab list whose page failed fails too (both are asked again).
        let mut failed: HashMap<u32, String> = HashMap::new();
        if let Some(book) = &self.pages {
            for (&(seg, cell), page) in cells.iter().zip(pages) {
                let taken = page.map_err(|e| format!("{e:#}")).and_then(|page| {
                    let mut cat = self.catalogue.borrow_mut();
                    book.borrow_mut().take(&mut cat, page, Some(cell))
                });
                if let Err(e) = taken {
                    book.borrow_mut().release(cell);
                    failed.insert(seg, e);
                }
            }
        }
        // One deadline for the whole request, as the native IO thread has.
        let until = Instant::now() + ROW_WAIT;
        let mut out = Vec::new();
        for (id, item) in got? {
            let item = match (failed.remove(&id), item) {
                (Some(e), _) => Err(e),
                (None, Err(e)) => Err(format!("{e:#}")),
                (None, Ok(bytes)) => {
                    self.ready(id, until).await;
                    let checked = self.catalogue.borrow().verify(id, &bytes);
                    checked.map(|()| bytes)
                }
            };
            out.push((id, item));
        }
        Ok(out)
    }

    /// Waits while pages on their way may bring segment `id`'s row, until `until` at most.
    async fn ready(&self, id: u32, until: Instant) {
        let Some(pages) = &self.pages else { return };
        while pages.borrow().readiness(&self.catalogue.borrow(), id) == Readiness::Waiting
            && Instant::now() < until
        {
            sleep_ms(5).await;
        }
    }
}

/// Resolves after `ms` milliseconds (the page's timer).
async fn sleep_ms(ms: i32) {
    let promise = js_sys::Promise::new(&mut |resolve, _| {
        if let Some(w) = web_sys::window() {
            let _ = w.set_timeout_with_callback_and_timeout_and_arguments_0(&resolve, ms);
        }
    });
    let _ = JsFuture::from(promise).await;
}
