//! The IO stage's read schedule (Funkhouser §5.2.3 and Ch. 6): the lookahead runs once per
//! frame on the latest observer, and the IO process reads continuously from the top of the
//! latest read set — never finishing a stale list while the observer walks on.
//!
//! [`Schedule`] is the bookkeeping, shared by every front end; the native shell's driver
//! (`portico_native::drive`) runs it over HTTP for the walk and the load tester's simulated
//! clients. Every need list replaces the one before; segments in flight are never asked for
//! twice, and a failed segment is retried after [`RETRY_AFTER`] if a later list still wants it.

use std::collections::{HashMap, HashSet};
use std::time::Duration;
use web_time::Instant;

/// How long a failed segment rests before a need list may ask for it again.
pub const RETRY_AFTER: Duration = Duration::from_millis(500);
/// Most segments one read request carries: one round trip brings several segments (a link's
/// latency, not its bandwidth, limits many small reads), while the most urgent still come first.
pub const BATCH_ITEMS: usize = 16;
/// Most bytes one read request carries (a single bigger segment goes alone).
pub const BATCH_BYTES: u64 = 256 << 10;

/// The bookkeeping of one client's reads.
#[derive(Debug, Default)]
pub struct Schedule {
    wants: Vec<u32>,
    cursor: usize,
    /// When each wanted segment was first listed (since it was last out of every list).
    listed: HashMap<u32, Instant>,
    /// Delivered, with the event sequence number, until the frame loop has taken it.
    delivered: HashMap<u32, u64>,
    /// Delivered and taken by the frame loop, with the number of the first prefetch request
    /// whose held set includes it: an answer to an earlier request may still list it.
    taken: HashMap<u32, u64>,
    /// Prefetch requests sent so far.
    asks: u64,
    inflight: HashSet<u32>,
    /// Failed, with the time it may be asked for again.
    failed: HashMap<u32, Instant>,
    /// Most bytes in flight or delivered and not yet taken (`None`: no limit).
    window: Option<u64>,
    /// Bytes of each segment in flight or delivered and not yet taken, and their sum.
    outstanding: HashMap<u32, u64>,
    outstanding_bytes: u64,
    /// Most wire bytes in flight ([`Schedule::set_wire_cap`]; `None`: no limit).
    wire_cap: Option<u64>,
    /// Wire bytes of each segment in flight, and their sum.
    wire: HashMap<u32, u64>,
    wire_bytes: u64,
}

impl Schedule {
    /// A schedule that keeps at most `window` bytes in flight or delivered and not yet taken
    /// (one segment alone may exceed it): what the IO stage holds outside the cache stays
    /// bounded however small the cache is.
    pub fn with_window(window: u64) -> Schedule {
        Schedule {
            window: Some(window),
            ..Schedule::default()
        }
    }

    /// Bytes in flight or delivered and not yet taken.
    pub fn outstanding_bytes(&self) -> u64 {
        self.outstanding_bytes
    }

    /// Keeps at most `cap` bytes on the wire in flight from now on (one segment alone may
    /// exceed it): [`crate::pacing::LinkMeter::cap`], so that what a new need list makes
    /// urgent does not queue behind more read-ahead than the link delivers within its horizon.
    /// `None` lifts the limit.
    pub fn set_wire_cap(&mut self, cap: Option<u64>) {
        self.wire_cap = cap;
    }

    /// Wire bytes in flight.
    pub fn wire_bytes(&self) -> u64 {
        self.wire_bytes
    }

    fn settle(&mut self, id: u32) {
        if let Some(b) = self.outstanding.remove(&id) {
            self.outstanding_bytes -= b;
        }
    }

    /// A new need list, most urgent first, replacing the last one.
    pub fn refresh(&mut self, wants: Vec<u32>, at: Instant) {
        self.failed.retain(|_, t| *t > at);
        let now: HashSet<u32> = wants.iter().copied().collect();
        let inflight = &self.inflight;
        self.listed
            .retain(|id, _| now.contains(id) || inflight.contains(id));
        for &id in &wants {
            self.listed.entry(id).or_insert(at);
        }
        self.wants = wants;
        self.cursor = 0;
    }

    /// The frame loop has taken every event up to `consumed` (the `consumed`-th included):
    /// what it took is in the held set it publishes from now on. With `answers` (the server
    /// makes the lists), a taken segment stays known until an answer to a request that listed
    /// it as held arrives, so an answer computed earlier cannot make it fetched twice.
    pub fn acknowledge(&mut self, consumed: u64, answers: bool) {
        let next_ask = self.asks + 1;
        let taken = &mut self.taken;
        let mut settled = Vec::new();
        self.delivered.retain(|&id, s| {
            if *s > consumed {
                return true;
            }
            if answers {
                taken.insert(id, next_ask);
            }
            settled.push(id);
            false
        });
        for id in settled {
            self.settle(id);
        }
    }

    /// A prefetch request is being sent; returns its number.
    pub fn asked(&mut self) -> u64 {
        self.asks += 1;
        self.asks
    }

    /// The answer to request `ask` arrived: segments taken before it was sent are in its held
    /// set, so the server has left them out.
    pub fn answered(&mut self, ask: u64) {
        self.taken.retain(|_, first| *first > ask);
    }

    /// Segments the server must not list again: delivered but not yet taken, or in flight.
    pub fn pending(&self) -> impl Iterator<Item = u32> + '_ {
        self.delivered.keys().chain(&self.inflight).copied()
    }

    /// The next wanted segment not on its way, delivered or resting after a failure (the list
    /// moves past what it skips).
    pub fn peek(&mut self, now: Instant) -> Option<u32> {
        while let Some(&id) = self.wants.get(self.cursor) {
            let resting = self.failed.get(&id).is_some_and(|&t| now < t);
            let busy = self.inflight.contains(&id)
                || self.delivered.contains_key(&id)
                || self.taken.contains_key(&id);
            if !(busy || resting) {
                return Some(id);
            }
            self.cursor += 1;
        }
        None
    }

    /// Marks the segment [`Schedule::peek`] gave as in flight.
    pub fn take(&mut self, id: u32) {
        if self.wants.get(self.cursor) == Some(&id) {
            self.cursor += 1;
        }
        self.inflight.insert(id);
    }

    /// [`Schedule::peek`] then [`Schedule::take`].
    pub fn next(&mut self, now: Instant) -> Option<u32> {
        let id = self.peek(now)?;
        self.take(id);
        Some(id)
    }

    /// A fetch ended; `Ok(seq)` is the sequence number of its delivery. Returns when the segment
    /// was first listed.
    pub fn finished(&mut self, id: u32, outcome: Result<u64, ()>, now: Instant) -> Instant {
        self.inflight.remove(&id);
        if let Some(b) = self.wire.remove(&id) {
            self.wire_bytes -= b;
        }
        match outcome {
            Ok(seq) => {
                self.failed.remove(&id);
                self.delivered.insert(id, seq);
            }
            Err(()) => {
                self.failed.insert(id, now + RETRY_AFTER);
                self.settle(id);
            }
        }
        self.listed.remove(&id).unwrap_or(now)
    }

    /// The next read request: the most urgent wanted segments, up to [`BATCH_ITEMS`] and
    /// [`BATCH_BYTES`] (at least one) and within the window and the wire cap (a segment alone
    /// when nothing is outstanding, or nothing is on the wire); `bytes` gives a segment's size.
    pub fn next_batch(&mut self, now: Instant, bytes: impl Fn(u32) -> u64) -> Vec<u32> {
        self.next_batch_sized(now, &bytes, &bytes)
    }

    /// [`Schedule::next_batch`] where a segment's bytes on the wire (`wire`: what a request
    /// carries, bounded by [`BATCH_BYTES`]) differ from what it occupies once decoded (`held`:
    /// what the window counts) — a compressed geometry segment.
    pub fn next_batch_sized(
        &mut self,
        now: Instant,
        wire: &impl Fn(u32) -> u64,
        held: &impl Fn(u32) -> u64,
    ) -> Vec<u32> {
        let mut ids = Vec::new();
        let (mut total, mut total_held) = (0u64, 0u64);
        while ids.len() < BATCH_ITEMS {
            let Some(id) = self.peek(now) else { break };
            let (b, h) = (wire(id), held(id));
            if !ids.is_empty() && total + b > BATCH_BYTES {
                break;
            }
            let alone = ids.is_empty() && self.outstanding_bytes == 0;
            if self
                .window
                .is_some_and(|w| self.outstanding_bytes + total_held + h > w && !alone)
            {
                break;
            }
            // A segment larger than the cap goes alone on an empty wire. (Letting it start
            // while the wire is merely under the cap measured worse: the textured soda's first
            // complete frame at 10 Mbit/s came at frame 14 instead of 6.)
            let first_on_wire = ids.is_empty() && self.wire_bytes == 0;
            if self
                .wire_cap
                .is_some_and(|c| self.wire_bytes + total + b > c && !first_on_wire)
            {
                break;
            }
            self.take(id);
            total += b;
            total_held += h;
            ids.push(id);
        }
        for &id in &ids {
            let b = held(id);
            self.outstanding.insert(id, b);
            self.outstanding_bytes += b;
            let w = wire(id);
            self.wire.insert(id, w);
            self.wire_bytes += w;
        }
        ids
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_skip_what_is_on_its_way_and_keep_first_listing_times() {
        let t0 = Instant::now();
        let t1 = t0 + Duration::from_millis(50);
        let mut s = Schedule::default();
        s.refresh(vec![1, 2, 3], t0);
        assert_eq!(s.next(t0), Some(1));
        s.refresh(vec![1, 2, 4], t1);
        // 1 is in flight: not asked again; 2 keeps its first listing; 4 is new.
        assert_eq!(s.next(t1), Some(2));
        assert_eq!(s.next(t1), Some(4));
        assert_eq!(s.next(t1), None);
        assert_eq!(s.finished(2, Ok(1), t1), t0);
        assert_eq!(s.finished(4, Ok(2), t1), t1);
        // Delivered and not yet taken: still pending for the server.
        let mut pending: Vec<u32> = s.pending().collect();
        pending.sort();
        assert_eq!(pending, vec![1, 2, 4]);
        s.acknowledge(2, false);
        assert_eq!(s.pending().collect::<Vec<_>>(), vec![1]);
    }

    #[test]
    fn an_answer_older_than_a_delivery_cannot_make_it_fetched_twice() {
        let t0 = Instant::now();
        let mut s = Schedule::default();
        let first = s.asked();
        s.refresh(vec![5], t0);
        assert_eq!(s.next(t0), Some(5));
        s.finished(5, Ok(1), t0);
        // Request 2 goes out while 5 is still untaken; the frame loop then takes it.
        let second = s.asked();
        s.acknowledge(1, true);
        // The answer to request 2 (computed before 5 was held) lists 5 again: not fetched.
        s.answered(second);
        s.refresh(vec![5], t0);
        assert_eq!(s.next(t0), None, "taken after request {second} was sent");
        // Request 3 holds it: from its answer on, 5 is the cache's business again.
        let third = s.asked();
        s.answered(third);
        s.refresh(vec![5], t0);
        assert_eq!(s.next(t0), Some(5), "evicted and wanted again");
        let _ = first;
    }

    #[test]
    fn the_window_bounds_what_is_in_flight_or_waiting_to_be_taken() {
        let t0 = Instant::now();
        let size = |id: u32| u64::from(id) * 10;
        let mut s = Schedule::with_window(100);
        s.refresh(vec![3, 4, 5, 9, 2], t0);
        // 30 + 40 fit, + 50 would not.
        assert_eq!(s.next_batch(t0, size), vec![3, 4]);
        assert_eq!(s.outstanding_bytes(), 70);
        assert!(s.next_batch(t0, size).is_empty(), "50 more would pass 100");
        // Delivered but not taken still counts; taken, it is the cache's.
        s.finished(3, Ok(1), t0);
        assert!(s.next_batch(t0, size).is_empty());
        s.acknowledge(1, false);
        assert_eq!(s.outstanding_bytes(), 40);
        assert_eq!(s.next_batch(t0, size), vec![5]);
        // A failure frees its bytes at once.
        s.finished(4, Err(()), t0);
        s.finished(5, Ok(2), t0);
        s.acknowledge(2, false);
        assert_eq!(s.outstanding_bytes(), 0);
        // A segment bigger than the window goes alone when nothing is outstanding.
        assert_eq!(s.next_batch(t0, |_| 500), vec![9]);
        assert!(s.next_batch(t0, size).is_empty());
        // Without a window, batches are bounded by BATCH_ITEMS and BATCH_BYTES only.
        let mut u = Schedule::default();
        u.refresh(vec![3, 4, 5, 9, 2], t0);
        assert_eq!(u.next_batch(t0, size), vec![3, 4, 5, 9, 2]);
    }

    /// Compressed segments: a request is sized by what it carries on the wire, the window by
    /// what the segments will occupy decoded.
    #[test]
    fn batches_count_wire_bytes_and_the_window_counts_decoded_bytes() {
        let t0 = Instant::now();
        let ids: Vec<u32> = (1..=10).collect();
        // Decoded 4x the wire size: the window (1000) holds two, not eight.
        let mut s = Schedule::with_window(1000);
        s.refresh(ids.clone(), t0);
        assert_eq!(s.next_batch_sized(t0, &|_| 100, &|_| 400), vec![1, 2]);
        assert_eq!(s.outstanding_bytes(), 800);
        // Without a window, BATCH_BYTES bounds the wire bytes: 100 KiB each, two per request,
        // however little they hold decoded...
        let mut u = Schedule::default();
        u.refresh(ids.clone(), t0);
        assert_eq!(u.next_batch_sized(t0, &|_| 100 << 10, &|_| 1), vec![1, 2]);
        // ...and small on the wire, many fit though they are large decoded.
        let mut v = Schedule::default();
        v.refresh(ids, t0);
        let n = v.next_batch_sized(t0, &|_| 1 << 10, &|_| 100 << 10).len();
        assert_eq!(n, BATCH_ITEMS.min(10));
    }

    #[test]
    fn the_wire_cap_bounds_what_is_in_flight_on_the_link() {
        let t0 = Instant::now();
        let size = |id: u32| u64::from(id) * 10;
        let mut s = Schedule::default();
        s.set_wire_cap(Some(100));
        s.refresh(vec![3, 4, 5, 9, 2], t0);
        assert_eq!(s.next_batch(t0, size), vec![3, 4]);
        assert_eq!(s.wire_bytes(), 70);
        assert!(s.next_batch(t0, size).is_empty(), "50 more would pass 100");
        // Delivered is off the wire, though not yet taken (the window's business).
        s.finished(3, Ok(1), t0);
        assert_eq!(s.wire_bytes(), 40);
        assert_eq!(s.next_batch(t0, size), vec![5]);
        s.finished(4, Err(()), t0);
        s.finished(5, Ok(2), t0);
        assert_eq!(s.wire_bytes(), 0);
        // Nothing on the wire: a segment larger than the cap goes alone.
        assert_eq!(s.next_batch(t0, |_| 500), vec![9]);
        assert!(s.next_batch(t0, size).is_empty());
        s.finished(9, Ok(3), t0);
        assert_eq!(s.wire_bytes(), 0);
        s.set_wire_cap(None);
        assert_eq!(s.next_batch(t0, size), vec![2]);
    }

    #[test]
    fn a_failed_segment_rests_before_it_is_asked_again() {
        let t0 = Instant::now();
        let mut s = Schedule::default();
        s.refresh(vec![7], t0);
        assert_eq!(s.next(t0), Some(7));
        s.finished(7, Err(()), t0);
        s.refresh(vec![7], t0);
        assert_eq!(s.next(t0), None, "resting");
        s.refresh(vec![7], t0);
        assert_eq!(s.next(t0 + RETRY_AFTER), Some(7), "asked again");
    }
}
