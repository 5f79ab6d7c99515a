//! The IO stage's read schedule and its driver (Funkhouser §5.2.3 and Ch. 6): the lookahead
//! runs once per frame on the latest observer, and the IO process reads continuously from the
//! top of the latest read set — never finishing a stale list while the observer walks on.
//!
//! [`drive`] is shared by the real client ([`crate::io`]) and the load tester's simulated
//! clients ([`crate::loadtest::sim`]); what differs is the [`Fetcher`] (HTTP and a GPU upload,
//! or HTTP through an emulated link) and where the need list comes from:
//! - from the server: each published frame state becomes a `POST /v1/prefetch` (one at a time;
//!   a newer state waits for the answer in flight), and the answer's items become the list;
//! - from the client itself ([`Ask::wants`]): demand fetch and the oracle of the load tester.
//!
//! Every need list replaces the one before; segments in flight are never asked for twice, and
//! a failed segment is retried after [`RETRY_AFTER`] if a later list still wants it.

use portico_protocol::{Observer, PROTOCOL_VERSION, Policy, PrefetchRequest, PrefetchResponse};
use std::collections::{HashMap, HashSet};
use std::future::Future;
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tokio::task::{JoinHandle, JoinSet};
use tokio::time::Instant;

/// How long a failed segment rests before a need list may ask for it again.
pub const RETRY_AFTER: Duration = Duration::from_millis(500);
/// Most segments one read request carries: one round trip brings several segments (a link's
/// latency, not its bandwidth, limits many small reads), while the most urgent still come first.
pub const BATCH_ITEMS: usize = 16;
/// Most bytes one read request carries (a single bigger segment goes alone).
pub const BATCH_BYTES: u64 = 256 << 10;

/// What the frame loop publishes after each frame.
#[derive(Debug, Clone)]
pub struct Ask {
    /// The observer, for the server's lookahead.
    pub observer: Observer,
    /// Segments resident in the cache.
    pub held: Vec<u32>,
    /// How many events the frame loop has taken from the queue so far.
    pub consumed: u64,
    /// The client's own need list, most urgent first (demand fetch, oracle); `None` asks the
    /// server's lookahead instead.
    pub wants: Option<Vec<u32>>,
    /// When the frame loop published this.
    pub at: Instant,
}

/// What the driver hands the frame loop.
#[derive(Debug)]
pub enum Event<B> {
    /// A prefetch answer (its items are already scheduled; its eviction hints are for the
    /// cache).
    Answer(Box<PrefetchResponse>),
    /// A segment arrived.
    Segment {
        /// Segment id.
        id: u32,
        /// What the fetcher made of it.
        body: B,
        /// Bytes on the wire.
        bytes: u64,
        /// When a need list first asked for it.
        listed_at: Instant,
    },
    /// A request failed (the walk goes on; a later list may ask again).
    Failed(String),
    /// The server no longer serves the database this client reads (rebuilt and reloaded): the
    /// IO stage has stopped, rather than fetch another file's segments by the old ids. The walk
    /// goes on with what it holds.
    Stale(String),
}

/// How the driver talks to the server.
pub trait Fetcher: Clone + Send + Sync + 'static {
    /// A fetched segment, ready for the cache.
    type Body: Send + 'static;
    /// `POST /v1/prefetch`.
    fn prefetch(
        &self,
        req: PrefetchRequest,
    ) -> impl Future<Output = anyhow::Result<PrefetchResponse>> + Send + 'static;
    /// `GET /v1/batch`: the segments, each checked and decoded (or why not), with its size on
    /// the wire; the whole request may fail too.
    fn batch(
        &self,
        ids: Vec<u32>,
    ) -> impl Future<Output = anyhow::Result<Items<Self::Body>>> + Send + 'static;
    /// A segment's size in bytes (from the manifest), to size the batches.
    fn bytes(&self, id: u32) -> u64;
}

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
}

impl Schedule {
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
        self.delivered.retain(|&id, s| {
            if *s > consumed {
                return true;
            }
            if answers {
                taken.insert(id, next_ask);
            }
            false
        });
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
        match outcome {
            Ok(seq) => {
                self.failed.remove(&id);
                self.delivered.insert(id, seq);
            }
            Err(()) => {
                self.failed.insert(id, now + RETRY_AFTER);
            }
        }
        self.listed.remove(&id).unwrap_or(now)
    }
}

/// Runs the IO stage until the frame loop goes away: keeps `parallel` segment fetches busy from
/// the latest need list and sends what happens on `tx`.
pub async fn drive<F: Fetcher>(
    fetcher: F,
    policy: Policy,
    parallel: usize,
    mut state: watch::Receiver<Option<Ask>>,
    tx: mpsc::Sender<Event<F::Body>>,
) {
    let mut s = Schedule::default();
    let mut seq = 0u64;
    let mut fetches: JoinSet<Fetched<F::Body>> = JoinSet::new();
    // What each read request in flight asked for (a task that panics must not strand them).
    let mut batches: HashMap<tokio::task::Id, Vec<u32>> = HashMap::new();
    let mut asking: Option<JoinHandle<Answered>> = None;
    // A frame state the server has not yet been asked about.
    let mut unasked: Option<Ask> = None;
    loop {
        if asking.is_none()
            && let Some(ask) = unasked.take()
        {
            asking = Some(ask_server(&fetcher, &mut s, policy, ask));
        }
        while fetches.len() < parallel.max(1) {
            let ids = next_batch(&mut s, &fetcher);
            if ids.is_empty() {
                break;
            }
            let f = fetcher.clone();
            let asked = ids.clone();
            let task = fetches.spawn(async move {
                let got = f.batch(ids.clone()).await;
                (ids, got)
            });
            batches.insert(task.id(), asked);
        }
        let event = tokio::select! {
            changed = state.changed() => {
                if changed.is_err() {
                    break;
                }
                let Some(ask) = state.borrow_and_update().clone() else { continue };
                s.acknowledge(ask.consumed, ask.wants.is_none());
                match ask.wants {
                    Some(ref wants) => s.refresh(wants.clone(), ask.at),
                    None => unasked = Some(ask),
                }
                continue;
            }
            answered = async { asking.as_mut().expect("guarded").await }, if asking.is_some() => {
                asking = None;
                match answered {
                    Ok((ask, at, Ok(resp))) => {
                        s.answered(ask);
                        s.refresh(resp.items.iter().map(|i| i.segment).collect(), at);
                        Event::Answer(Box::new(resp))
                    }
                    Ok((_, _, Err(e))) if e.downcast_ref::<crate::net::Stale>().is_some() => {
                        let _ = tx.send(Event::Stale(format!("{e:#}"))).await;
                        break;
                    }
                    Ok((_, _, Err(e))) => Event::Failed(format!("{e:#}")),
                    Err(e) => Event::Failed(format!("prefetch task: {e}")),
                }
            }
            Some(done) = fetches.join_next_with_id(), if !fetches.is_empty() => {
                let (ids, got) = match done {
                    Ok((task, (ids, got))) => {
                        batches.remove(&task);
                        (ids, got)
                    }
                    // The task panicked (a decoder or the GPU upload): its segments failed.
                    Err(e) => {
                        let ids = batches.remove(&e.id()).unwrap_or_default();
                        (ids, Err(anyhow::anyhow!("read task: {e}")))
                    }
                };
                if let Err(e) = &got
                    && e.downcast_ref::<crate::net::Stale>().is_some()
                {
                    let _ = tx.send(Event::Stale(format!("{e:#}"))).await;
                    break;
                }
                if deliver(&mut s, ids, got, &mut seq, &tx).await.is_err() {
                    break;
                }
                continue;
            }
        };
        seq += 1;
        if tx.send(event).await.is_err() {
            break;
        }
    }
    fetches.abort_all();
    if let Some(a) = asking {
        a.abort();
    }
}

/// What one read request brings: each segment (id, then its body and size on the wire, or why
/// not).
pub type Items<B> = Vec<(u32, anyhow::Result<(B, u64)>)>;
/// A finished read request: the ids asked for and what came of them.
type Fetched<B> = (Vec<u32>, anyhow::Result<Items<B>>);

/// The next read request: the most urgent wanted segments, up to [`BATCH_ITEMS`] and
/// [`BATCH_BYTES`] (at least one).
fn next_batch<F: Fetcher>(s: &mut Schedule, fetcher: &F) -> Vec<u32> {
    let now = Instant::now();
    let mut ids = Vec::new();
    let mut bytes = 0u64;
    while ids.len() < BATCH_ITEMS {
        let Some(id) = s.peek(now) else { break };
        let b = fetcher.bytes(id);
        if !ids.is_empty() && bytes + b > BATCH_BYTES {
            break;
        }
        s.take(id);
        bytes += b;
        ids.push(id);
    }
    ids
}

/// Hands one finished read request's segments to the frame loop, one event each (one event
/// for a request that failed as a whole). `Err` when the frame loop is gone.
async fn deliver<B>(
    s: &mut Schedule,
    ids: Vec<u32>,
    got: anyhow::Result<Items<B>>,
    seq: &mut u64,
    tx: &mpsc::Sender<Event<B>>,
) -> Result<(), ()> {
    let now = Instant::now();
    let items = match got {
        Ok(items) => items,
        Err(e) => {
            for id in ids {
                s.finished(id, Err(()), now);
            }
            *seq += 1;
            return tx
                .send(Event::Failed(format!("{e:#}")))
                .await
                .map_err(|_| ());
        }
    };
    let mut answered = HashSet::new();
    for (id, item) in items {
        answered.insert(id);
        let event = match item {
            Ok((body, bytes)) => {
                let listed_at = s.finished(id, Ok(*seq + 1), now);
                Event::Segment {
                    id,
                    body,
                    bytes,
                    listed_at,
                }
            }
            Err(e) => {
                s.finished(id, Err(()), now);
                Event::Failed(format!("{e:#}"))
            }
        };
        *seq += 1;
        tx.send(event).await.map_err(|_| ())?;
    }
    for id in ids.into_iter().filter(|id| !answered.contains(id)) {
        s.finished(id, Err(()), now);
    }
    Ok(())
}
/// A finished prefetch request: its number, when it was asked, and the answer.
type Answered = (u64, Instant, anyhow::Result<PrefetchResponse>);

/// Starts one `POST /v1/prefetch` for a frame state.
fn ask_server<F: Fetcher>(
    fetcher: &F,
    s: &mut Schedule,
    policy: Policy,
    ask: Ask,
) -> JoinHandle<Answered> {
    let held: HashSet<u32> = ask.held.iter().copied().chain(s.pending()).collect();
    let number = s.asked();
    let req = PrefetchRequest {
        version: PROTOCOL_VERSION,
        observer: ask.observer,
        policy,
        held: portico_protocol::encode_held(held),
    };
    let f = fetcher.clone();
    tokio::spawn(async move {
        let at = Instant::now();
        (number, at, f.prefetch(req).await)
    })
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
