//! The memory-resident object cache (Funkhouser §5.2.3): segments (one LOD of one object, or a
//! cell's stab list) under a hard byte budget. Entries are ordered by when they were last in the
//! lookahead set — [`ObjectCache::touch`] moves one to the head — and the release set comes from
//! the tail, so the cache never holds more than its budget, not even for a moment: room is made
//! before anything new goes in.

use lru::LruCache;

/// Splits a client's byte budget between the cache and the IO stage: `(cache, window)`, where
/// `window` (an eighth) bounds the segments in flight or delivered and waiting to be taken
/// ([`crate::schedule::Schedule::with_window`]). They are held outside the cache, so with this
/// split the two together never exceed the budget.
pub fn split_budget(budget: u64) -> (u64, u64) {
    let window = budget / 8;
    (budget - window, window)
}

/// A byte-budgeted LRU of values keyed by segment id. `V` is a GPU mesh in the client and a
/// plain size in the load tester; dropping an evicted value frees its memory.
#[derive(Debug)]
pub struct ObjectCache<V> {
    lru: LruCache<u32, (V, u64)>,
    bytes: u64,
    budget: u64,
    peak: u64,
    evictions: u64,
}

/// An entry bigger than the whole budget cannot be cached.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TooBig {
    /// The entry's size.
    pub bytes: u64,
    /// The cache's budget.
    pub budget: u64,
}

impl<V> ObjectCache<V> {
    /// An empty cache holding at most `budget` bytes.
    pub fn new(budget: u64) -> Self {
        ObjectCache {
            lru: LruCache::unbounded(),
            bytes: 0,
            budget,
            peak: 0,
            evictions: 0,
        }
    }

    /// Whether a segment is resident (does not change the order).
    pub fn contains(&self, id: u32) -> bool {
        self.lru.contains(&id)
    }

    /// A resident value (does not change the order: order follows the lookahead set).
    pub fn get(&self, id: u32) -> Option<&V> {
        self.lru.peek(&id).map(|(v, _)| v)
    }

    /// Moves a segment to the head: it is in this frame's lookahead (or visible) set.
    pub fn touch(&mut self, id: u32) {
        self.lru.promote(&id);
    }

    /// Moves a segment to the tail: the server says it left the lookahead set, so it goes first.
    pub fn demote(&mut self, id: u32) {
        self.lru.demote(&id);
    }

    /// Inserts a segment, first releasing entries from the tail until it fits. Returns the ids
    /// released (tail first: the ones longest out of the lookahead set).
    pub fn insert(&mut self, id: u32, value: V, bytes: u64) -> Result<Vec<u32>, TooBig> {
        if bytes > self.budget {
            return Err(TooBig {
                bytes,
                budget: self.budget,
            });
        }
        if let Some((_, old)) = self.lru.pop(&id) {
            self.bytes -= old;
        }
        let mut released = Vec::new();
        while self.bytes + bytes > self.budget {
            let Some((victim, (_, b))) = self.lru.pop_lru() else {
                break;
            };
            self.bytes -= b;
            self.evictions += 1;
            released.push(victim);
        }
        self.lru.put(id, (value, bytes));
        self.bytes += bytes;
        self.peak = self.peak.max(self.bytes);
        Ok(released)
    }

    /// Releases one segment (e.g. a server eviction hint); returns whether it was resident.
    pub fn remove(&mut self, id: u32) -> bool {
        match self.lru.pop(&id) {
            Some((_, b)) => {
                self.bytes -= b;
                self.evictions += 1;
                true
            }
            None => false,
        }
    }

    /// Bytes resident now.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// The byte budget.
    pub fn budget(&self) -> u64 {
        self.budget
    }

    /// The most bytes ever resident.
    pub fn peak_bytes(&self) -> u64 {
        self.peak
    }

    /// Entries released so far.
    pub fn evictions(&self) -> u64 {
        self.evictions
    }

    /// Number of resident segments.
    pub fn len(&self) -> usize {
        self.lru.len()
    }

    /// Whether nothing is resident.
    pub fn is_empty(&self) -> bool {
        self.lru.is_empty()
    }

    /// Resident segment ids, head (most recently needed) first.
    pub fn ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.lru.iter().map(|(k, _)| *k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn never_above_budget_and_releases_the_least_recently_needed() {
        let mut c = ObjectCache::new(100);
        c.insert(1, (), 40).unwrap();
        c.insert(2, (), 40).unwrap();
        c.touch(1); // 1 is in the lookahead set again: 2 is now the tail
        assert_eq!(c.insert(3, (), 40).unwrap(), vec![2]);
        assert!(c.contains(1) && c.contains(3) && !c.contains(2));
        assert_eq!(c.bytes(), 80);
        assert_eq!(c.insert(4, (), 100).unwrap(), vec![1, 3]);
        assert_eq!(c.peak_bytes(), 100);
        assert_eq!(
            c.insert(5, (), 101),
            Err(TooBig {
                bytes: 101,
                budget: 100
            })
        );
        assert!(c.contains(4), "a refused entry releases nothing");
    }

    #[test]
    fn reinserting_replaces_and_remove_frees() {
        let mut c = ObjectCache::new(100);
        c.insert(1, "a", 30).unwrap();
        c.insert(1, "b", 50).unwrap();
        assert_eq!((c.len(), c.bytes(), c.get(1)), (1, 50, Some(&"b")));
        assert!(c.remove(1));
        assert!(!c.remove(1));
        assert_eq!(c.bytes(), 0);
    }

    #[test]
    fn random_operations_keep_the_accounting_exact() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::SmallRng::seed_from_u64(12345);
        let mut c = ObjectCache::new(1000);
        let (mut released, mut removed) = (0u64, 0u64);
        for _ in 0..10_000 {
            let id = rng.random_range(0..50u32);
            match rng.random_range(0..4) {
                0 => {
                    if let Ok(r) = c.insert(id, (), rng.random_range(0..400)) {
                        released += r.len() as u64;
                    }
                }
                1 => c.touch(id),
                2 => c.demote(id),
                _ => removed += u64::from(c.remove(id)),
            }
            assert!(c.bytes() <= c.budget());
            assert_eq!(c.len(), c.ids().count());
            assert_eq!(c.is_empty(), c.ids().next().is_none());
        }
        let sum: u64 = c.lru.iter().map(|(_, (_, b))| *b).sum();
        assert_eq!(sum, c.bytes());
        assert_eq!(c.evictions(), released + removed);
    }

    #[test]
    fn exactly_full_releases_nothing_and_counts_what_it_releases() {
        let mut c = ObjectCache::new(100);
        assert!(c.is_empty());
        c.insert(1, (), 60).unwrap();
        assert_eq!(
            c.insert(2, (), 40).unwrap(),
            Vec::<u32>::new(),
            "60 + 40 fits 100"
        );
        assert_eq!((c.bytes(), c.len(), c.evictions()), (100, 2, 0));
        assert!(!c.is_empty());
        assert_eq!(c.insert(3, (), 1).unwrap(), vec![1]);
        assert!(c.remove(2));
        assert_eq!(c.evictions(), 2, "one released to make room, one removed");
    }

    #[test]
    fn demoted_entries_go_first_and_ids_run_head_first() {
        let mut c = ObjectCache::new(100);
        for id in [1, 2, 3] {
            c.insert(id, (), 30).unwrap();
        }
        assert_eq!(c.ids().collect::<Vec<_>>(), vec![3, 2, 1]);
        // The server says 3 left the lookahead set: it is released before 1 and 2.
        c.demote(3);
        assert_eq!(c.ids().collect::<Vec<_>>(), vec![2, 1, 3]);
        assert_eq!(c.insert(4, (), 30).unwrap(), vec![3]);
        assert_eq!(c.ids().collect::<Vec<_>>(), vec![4, 2, 1]);
    }

    #[test]
    fn the_io_window_is_an_eighth_and_the_two_parts_make_the_budget() {
        assert_eq!(split_budget(64 << 20), (56 << 20, 8 << 20));
        assert_eq!(split_budget(800), (700, 100));
        assert_eq!(split_budget(7), (7, 0));
        for b in [0, 1, 9, 1000, u64::MAX] {
            let (cache, window) = split_budget(b);
            assert_eq!(cache + window, b);
        }
    }
}
