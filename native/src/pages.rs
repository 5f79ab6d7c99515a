//! The paged manifest on the IO thread: the client engine's IO-free [`Pages`]
//! ([`portico_client::engine::pages`]) behind a lock shared by the read tasks, and the wait of a
//! segment whose row the pages on their way may bring.

use portico_client::engine::catalogue::Catalogue;
use portico_client::engine::pages::{Pages, Readiness};
use portico_data::format::CellPage;
use std::sync::{Mutex, MutexGuard, RwLock};
use std::time::Duration;
use tokio::time::Instant;

pub use portico_client::engine::pages::{ROW_WAIT, TakenPage};

/// [`Pages`], shared by the IO thread's tasks. Locks are taken catalogue first, then pages.
pub struct PageBook {
    pages: Mutex<Pages>,
}

impl PageBook {
    /// The book of `pages`.
    pub fn new(pages: Pages) -> PageBook {
        PageBook {
            pages: Mutex::new(pages),
        }
    }

    fn lock(&self) -> MutexGuard<'_, Pages> {
        self.pages.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// [`Pages::claim`].
    pub fn claim(&self, id: u32) -> Option<u32> {
        self.lock().claim(id)
    }

    /// [`Pages::release`].
    pub fn release(&self, cell: u32) {
        self.lock().release(cell);
    }

    /// [`Pages::take`], into `catalogue`.
    ///
    /// # Errors
    /// One line: the page is not the one asked for, or does not fit the model.
    pub fn take(
        &self,
        catalogue: &RwLock<Catalogue>,
        page: CellPage,
        asked: Option<u32>,
    ) -> anyhow::Result<()> {
        let mut cat = catalogue.write().unwrap_or_else(|e| e.into_inner());
        self.lock()
            .take(&mut cat, page, asked)
            .map_err(anyhow::Error::msg)
    }

    /// [`Pages::take_frame`], into `catalogue`.
    ///
    /// # Errors
    /// One line: it does not inflate or decode, or does not fit the model.
    pub fn take_frame(&self, catalogue: &RwLock<Catalogue>, deflated: &[u8]) -> anyhow::Result<()> {
        let mut cat = catalogue.write().unwrap_or_else(|e| e.into_inner());
        self.lock()
            .take_frame(&mut cat, deflated)
            .map_err(anyhow::Error::msg)
    }

    /// [`Pages::handed`].
    pub fn handed(&self, id: u32) -> Option<TakenPage> {
        self.lock().handed(id)
    }

    /// Waits until segment `id` can be checked and handed on while pages are on their way
    /// ([`Readiness::Waiting`]), until `deadline` at most; whether it can.
    pub async fn ready(&self, catalogue: &RwLock<Catalogue>, id: u32, deadline: Instant) -> bool {
        loop {
            let now = {
                let cat = catalogue.read().unwrap_or_else(|e| e.into_inner());
                self.lock().readiness(&cat, id)
            };
            match now {
                Readiness::Ready => return true,
                Readiness::Never => return false,
                Readiness::Waiting if Instant::now() >= deadline => return false,
                Readiness::Waiting => tokio::time::sleep(Duration::from_millis(5)).await,
            }
        }
    }
}
