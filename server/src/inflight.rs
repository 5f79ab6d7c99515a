//! One computation per shared need list at a time, and nobody else holding a compute slot
//! while it runs.
//!
//! A crowd's observers share places (`portico_data::prefetch::shared`), so a crowd arriving
//! at a cold server asks for the same uncached list many times at once. The first asker leads:
//! it computes the list on a compute slot. The others wait here, on the async worker, for the
//! leader to finish, then take the list from the cache. Waiting inside a slot instead (as the
//! data crate's own gate does, which stays as a second line) left one slot of two asleep
//! whenever two observers of one place came together, so a cold crowd queued behind the
//! sleepers. A leader that fails (its deadline passed, its client left) wakes the waiters,
//! and the next of them leads.

use std::collections::HashMap;
use std::hash::Hash;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use tokio::sync::watch;

/// The lists being computed now, by key.
#[derive(Debug)]
pub struct InFlight<K> {
    computing: Computing<K>,
}

/// Each key being computed and the receiver its waiters clone.
type Computing<K> = Arc<Mutex<HashMap<K, watch::Receiver<()>>>>;

impl<K> Default for InFlight<K> {
    fn default() -> Self {
        InFlight {
            computing: Arc::default(),
        }
    }
}

/// What an asker does: take the list, or compute it (holding the [`Lead`] until it is cached
/// or has failed: the computation itself holds it, so the waiters wake as soon as it ends).
#[derive(Debug)]
pub enum Turn<K: Hash + Eq + Clone, V> {
    /// The list, from the cache.
    Ready(V),
    /// Nobody is computing it: this asker does, and the others wait until `Lead` is dropped.
    Lead(Lead<K>),
}

/// The leader's claim on a key; dropping it wakes the waiters.
#[derive(Debug)]
pub struct Lead<K: Hash + Eq + Clone> {
    computing: Computing<K>,
    key: K,
    _wake: watch::Sender<()>,
}

impl<K: Hash + Eq + Clone> Drop for Lead<K> {
    fn drop(&mut self) {
        let mut m = self.computing.lock().unwrap_or_else(|e| e.into_inner());
        m.remove(&self.key);
        // `_wake` drops after this: every waiter's `changed()` returns.
    }
}

impl<K: Hash + Eq + Clone> InFlight<K> {
    /// The list for `key` from `cached`, waiting (on the async worker, no slot held) while
    /// another asker computes it; or the lead when nobody does. `None` once `until` passes
    /// first (the asker's deadline: it is answered busy).
    pub async fn turn<V>(
        &self,
        key: &K,
        until: Instant,
        cached: impl Fn() -> Option<V>,
    ) -> Option<Turn<K, V>> {
        loop {
            if let Some(v) = cached() {
                return Some(Turn::Ready(v));
            }
            let mut wait = {
                let mut m = self.computing.lock().unwrap_or_else(|e| e.into_inner());
                match m.get(key) {
                    Some(rx) => rx.clone(),
                    None => {
                        let (tx, rx) = watch::channel(());
                        m.insert(key.clone(), rx);
                        drop(m);
                        let lead = Lead {
                            computing: self.computing.clone(),
                            key: key.clone(),
                            _wake: tx,
                        };
                        // A leader may have cached it and left between the first look and
                        // the claim: then there is nothing to compute.
                        return Some(match cached() {
                            Some(v) => Turn::Ready(v),
                            None => Turn::Lead(lead),
                        });
                    }
                }
            };
            // Returns (with an error) when the leader's claim is dropped.
            if tokio::time::timeout_at(until.into(), wait.changed())
                .await
                .is_err()
            {
                return None;
            }
        }
    }

    /// How many lists are being computed now.
    pub fn len(&self) -> usize {
        self.computing
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;
    use std::sync::atomic::{AtomicUsize, Ordering::SeqCst};
    use std::time::Duration;

    /// A cache and a count of computations, as the server's shared lists have.
    #[derive(Default)]
    struct Lists {
        inflight: InFlight<u32>,
        cache: Mutex<HashMap<u32, u64>>,
        computed: AtomicUsize,
        running: AtomicUsize,
        most_running: AtomicUsize,
    }

    impl Lists {
        /// Asks for `key`'s list; a computation takes 20 ms and fails when `fail` is set.
        async fn ask(self: &Arc<Self>, key: u32, fail: bool) -> Option<u64> {
            let until = Instant::now() + Duration::from_secs(5);
            let cached = || self.cache.lock().unwrap().get(&key).copied();
            match self.inflight.turn(&key, until, cached).await? {
                Turn::Ready(v) => Some(v),
                Turn::Lead(_lead) => {
                    let now = self.running.fetch_add(1, SeqCst) + 1;
                    self.most_running.fetch_max(now, SeqCst);
                    self.computed.fetch_add(1, SeqCst);
                    tokio::time::sleep(Duration::from_millis(20)).await;
                    self.running.fetch_sub(1, SeqCst);
                    if fail {
                        return None;
                    }
                    self.cache.lock().unwrap().insert(key, u64::from(key) * 10);
                    Some(u64::from(key) * 10)
                }
            }
        }
    }

    #[tokio::test]
    async fn a_crowd_asking_one_list_computes_it_once_and_all_get_it() {
        let l = Arc::new(Lists::default());
        let asks: Vec<_> = (0..50)
            .map(|i| {
                let l = l.clone();
                tokio::spawn(async move { l.ask(7 + (i % 2), false).await })
            })
            .collect();
        for (i, a) in asks.into_iter().enumerate() {
            assert_eq!(a.await.unwrap(), Some(u64::from(7 + (i as u32 % 2)) * 10));
        }
        // Two keys: two computations, at most two at once, and nothing left in flight.
        assert_eq!(l.computed.load(SeqCst), 2);
        assert!(l.most_running.load(SeqCst) <= 2);
        assert_eq!(l.inflight.len(), 0);
        // Cached now: no computation.
        assert_eq!(l.ask(7, false).await, Some(70));
        assert_eq!(l.computed.load(SeqCst), 2);
    }

    #[tokio::test]
    async fn a_failed_leader_hands_the_lead_to_a_waiter() {
        let l = Arc::new(Lists::default());
        let first = {
            let l = l.clone();
            tokio::spawn(async move { l.ask(3, true).await })
        };
        tokio::time::sleep(Duration::from_millis(5)).await;
        let second = {
            let l = l.clone();
            tokio::spawn(async move { l.ask(3, false).await })
        };
        assert_eq!(first.await.unwrap(), None);
        assert_eq!(second.await.unwrap(), Some(30));
        assert_eq!(l.computed.load(SeqCst), 2);
    }

    #[tokio::test]
    async fn a_claim_on_a_list_cached_meanwhile_computes_nothing() {
        // The cache is empty at the first look and full at the second (a leader cached the
        // list and left in between): the asker takes it instead of leading.
        let looks = AtomicUsize::new(0);
        let l = InFlight::<u32>::default();
        let cached = || (looks.fetch_add(1, SeqCst) > 0).then_some(5u8);
        let Some(Turn::Ready(5)) = l.turn(&1, Instant::now(), cached).await else {
            panic!("a list cached meanwhile is taken");
        };
        assert_eq!(l.len(), 0);
    }

    #[tokio::test]
    async fn a_waiter_past_its_deadline_gives_up() {
        let l = InFlight::<u32>::default();
        let Some(Turn::Lead(_lead)) = l.turn(&1, Instant::now(), || None::<u8>).await else {
            panic!("the first asker leads");
        };
        let t0 = Instant::now();
        let late = l
            .turn(&1, t0 + Duration::from_millis(30), || None::<u8>)
            .await;
        assert!(late.is_none());
        assert!(t0.elapsed() >= Duration::from_millis(30));
    }
}
