//! What a cell's part of a swept region may see, kept for every place that shares it.
//!
//! A place's list ([`super::swept`]) asks, for each cell its walk may reach, which objects an
//! eye in the cell's part of the last swept region may see (region-to-cell visibility, then
//! region-to-object: [`crate::cells::region`]). That region depends only on the place's cube,
//! velocity bucket and speed band (and the lookahead's depth), not on its view or turn, so the places a walker passes
//! through while it turns its head ask the same question of the same box again. The answer is
//! a pure function of the cell and the box (whatever policy made the box), kept here (least
//! recently used dropped first past [`SIGHT_CACHE_IDS`] object ids, each answer counted
//! [`ENTRY_IDS`] more for its key and node); a search stopped by its deadline is not kept.

use lru::LruCache;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};

/// Object ids the cache holds at most (4 bytes each: 16 MiB).
pub const SIGHT_CACHE_IDS: usize = 4 << 20;

/// What an answer costs beyond its ids (its key, `Arc` and LRU node: about 128 bytes), in ids:
/// an empty answer is not free.
pub const ENTRY_IDS: usize = 32;

/// A cell and the exact bits of the box of eyes in it.
pub(super) type SightKey = (u32, [u32; 6]);

/// The answers kept, least recently used first out, and the object ids they hold.
type Kept = (LruCache<SightKey, Arc<[u32]>>, usize);

/// The cache (see the module).
pub struct RegionSight {
    cache: Mutex<Kept>,
    /// Questions answered from the cache.
    pub hits: AtomicU64,
    /// Questions searched.
    pub misses: AtomicU64,
}

impl Default for RegionSight {
    fn default() -> Self {
        RegionSight {
            cache: Mutex::new((LruCache::unbounded(), 0)),
            hits: AtomicU64::new(0),
            misses: AtomicU64::new(0),
        }
    }
}

/// The key of `cell` and the box `eyes` (its corners' bits: equal boxes only).
pub(super) fn sight_key(cell: u32, eyes: &crate::geometry::Aabb) -> SightKey {
    let (a, b) = (eyes.min, eyes.max);
    (cell, [a[0], a[1], a[2], b[0], b[1], b[2]].map(f32::to_bits))
}

impl RegionSight {
    /// What `key`'s box may see, from the cache or from `search` (kept when it succeeds).
    pub(super) fn get_or<E>(
        &self,
        key: SightKey,
        search: impl FnOnce() -> Result<Vec<u32>, E>,
    ) -> Result<Arc<[u32]>, E> {
        if let Some(hit) = self.lock().0.get(&key).cloned() {
            self.hits.fetch_add(1, Relaxed);
            return Ok(hit);
        }
        self.misses.fetch_add(1, Relaxed);
        let seen: Arc<[u32]> = search()?.into();
        let mut g = self.lock();
        if let Some(old) = g.0.put(key, seen.clone()) {
            g.1 -= old.len() + ENTRY_IDS;
        }
        g.1 += seen.len() + ENTRY_IDS;
        while g.1 > SIGHT_CACHE_IDS {
            let Some((_, l)) = g.0.pop_lru() else { break };
            g.1 -= l.len() + ENTRY_IDS;
        }
        Ok(seen)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Kept> {
        self.cache.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Aabb;

    #[test]
    fn a_box_is_searched_once_and_a_failed_search_is_not_kept() {
        let s = RegionSight::default();
        let b = Aabb {
            min: [0.0; 3],
            max: [1.0, 2.0, 3.0],
        };
        let mut searched = 0;
        for _ in 0..3 {
            let got = s.get_or::<()>(sight_key(4, &b), || {
                searched += 1;
                Ok(vec![1, 2, 3])
            });
            assert_eq!(&*got.unwrap(), &[1, 2, 3]);
        }
        assert_eq!(searched, 1);
        // Another cell, or a box a hair larger: another question.
        let wider = Aabb {
            max: [1.0, 2.0, 3.000_001],
            ..b
        };
        assert_ne!(sight_key(4, &b), sight_key(5, &b));
        assert_ne!(sight_key(4, &b), sight_key(4, &wider));
        assert!(s.get_or(sight_key(4, &wider), || Err("deadline")).is_err());
        let again = s
            .get_or::<()>(sight_key(4, &wider), || Ok(vec![9]))
            .unwrap();
        assert_eq!(&*again, &[9]);
        assert_eq!(s.hits.load(Relaxed), 2);
        assert_eq!(s.misses.load(Relaxed), 3);
    }

    #[test]
    fn empty_answers_count_too() {
        // Answers with no objects still take memory: past the bound, the oldest go.
        let s = RegionSight::default();
        let n = SIGHT_CACHE_IDS / ENTRY_IDS + 100;
        for i in 0..n {
            let b = Aabb {
                min: [i as f32; 3],
                max: [i as f32 + 1.0; 3],
            };
            s.get_or::<()>(sight_key(0, &b), || Ok(Vec::new())).unwrap();
        }
        let (kept, ids) = {
            let g = s.lock();
            (g.0.len(), g.1)
        };
        assert!(kept <= SIGHT_CACHE_IDS / ENTRY_IDS, "{kept} kept");
        assert!(ids <= SIGHT_CACHE_IDS);
    }
}
