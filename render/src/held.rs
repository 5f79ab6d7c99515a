//! GPU memory held by the meshes and impostor boxes one renderer's device created, counted where
//! they are created and dropped — an account independent of the client's cache, which charges
//! only what it admits: what the cache holds, what waits in the IO queue and stand-ins outside
//! the cache all count here.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// The account (shared by a renderer and its uploaders).
#[derive(Debug, Clone, Default)]
pub(crate) struct Held(Arc<AtomicU64>);

impl Held {
    /// Charges `bytes` until the returned charge is dropped.
    pub(crate) fn charge(&self, bytes: u64) -> Charge {
        self.0.fetch_add(bytes, Relaxed);
        Charge {
            account: self.0.clone(),
            bytes,
        }
    }

    /// Bytes charged now.
    pub(crate) fn bytes(&self) -> u64 {
        self.0.load(Relaxed)
    }
}

/// Bytes charged to an account while this lives.
#[derive(Debug)]
pub(crate) struct Charge {
    account: Arc<AtomicU64>,
    bytes: u64,
}

impl Drop for Charge {
    fn drop(&mut self) {
        self.account.fetch_sub(self.bytes, Relaxed);
    }
}
