//! The lookahead/IO stage in a page (Funkhouser Ch. 6 and §5.2.3), on the page's one thread.
//! What it brings waits in an inbox until the next frame takes it, so a frame never waits for
//! the network. Two transports:
//!
//! - **push** (the default): one `/v1/stream` session ([`crate::stream`]); the observer goes
//!   every frame, the server pushes in need order what the cache lacks;
//! - **pull** (the fallback, and `?transport=pull`): the native client's read [`Schedule`] over
//!   HTTP — one prefetch request in flight at a time (a newer observer waits for its answer)
//!   and up to [`PARALLEL`] segment batches from the top of the latest list: what the last
//!   frame lacked, then the latest answer's items.
//!
//! A stream that does not open within [`OPEN_WAIT`], or closes (a server restart), hands over
//! to pull at once and is tried again after [`RETRY`].

use crate::net::{Remote, Stale};
use crate::stream::{Pushed, Stream};
use portico_client::deadline::{Link, ReadPlan};
use portico_client::pacing::LinkMeter;
use portico_client::schedule::Schedule;
use portico_protocol::{Observer, PROTOCOL_VERSION, Policy, PrefetchRequest, PrefetchResponse};
use std::cell::RefCell;
use std::collections::{HashMap, HashSet, VecDeque};
use std::rc::Rc;
use std::time::Duration;
use web_time::Instant;

/// Segment batches in flight at once (as the native client).
pub const PARALLEL: usize = 8;
/// How long a stream may take to open before pull takes over.
pub const OPEN_WAIT: Duration = Duration::from_secs(2);
/// How long after a stream failed another is tried.
pub const RETRY: Duration = Duration::from_secs(5);
/// How long pull waits after a failed prefetch request before it asks again (a server that is
/// down is not asked sixty times a second).
pub const BACKOFF: Duration = Duration::from_millis(500);
/// Most pushed bytes taken into the cache in one frame: the rest waits for the next frames, so
/// a burst of pushes never makes one long frame.
pub const PUSHED_PER_FRAME: u64 = 4 << 20;

/// What a finished request left in the inbox.
enum Done {
    Answer(u64, Instant, anyhow::Result<PrefetchResponse>),
    Batch(
        Vec<u32>,
        Instant,
        anyhow::Result<Vec<(u32, anyhow::Result<Vec<u8>>)>>,
    ),
}

/// What the frame loop gets from the IO stage.
pub enum Arrival {
    /// A segment, its bytes checked against the manifest, and when a need list first asked for
    /// it.
    Segment(u32, Vec<u8>, Instant),
    /// The server's eviction hints of its latest answer (§5.2.3).
    Release(Vec<u32>),
    /// A request failed; a later list may ask again.
    Failed(String),
    /// The server serves another file now: the stage has stopped.
    Stale(String),
}

/// Each segment's size and checksum (the manifest's table) and what it occupies decoded.
pub struct Catalogue {
    /// The manifest's segment table, by id.
    pub segments: Vec<portico_protocol::SegmentInfo>,
    /// Geometry segments by their decoded size.
    pub decoded: HashMap<u32, u64>,
}

/// The IO stage: the schedule, the requests in flight and their inbox.
pub struct Io {
    remote: Rc<Remote>,
    catalogue: Rc<Catalogue>,
    policy: Policy,
    schedule: Schedule,
    inbox: Rc<RefCell<VecDeque<Done>>>,
    asking: bool,
    batches: usize,
    /// Events handed to the frame loop so far (the schedule's sequence numbers).
    seq: u64,
    stopped: bool,
    /// Whether to push (else pull only), the session, when it was opened, and when the next
    /// one may be.
    push: bool,
    stream: Option<(Stream, Instant)>,
    retry_at: Option<Instant>,
    /// Stream sessions opened so far.
    pub sessions: u64,
    /// No prefetch request before this (after a failure).
    ask_after: Option<Instant>,
    /// Whether the stream carried the segments at the last frame.
    was_pushing: bool,
    /// The latest answer and what the latest frame lacked: the frame's first, then what of
    /// the answer cannot wait for the next one (as `portico_native::drive`).
    plan: ReadPlan,
    /// The link as the reads measure it: what stays on the wire, and the deadlines.
    meter: LinkMeter,
}

impl Io {
    /// A stage reading from `remote` under `policy`, keeping at most `window` bytes in flight
    /// or delivered and not yet taken.
    /// With `push`, segments come over `/v1/stream` while it works.
    pub fn new(
        remote: Rc<Remote>,
        catalogue: Catalogue,
        policy: Policy,
        window: u64,
        push: bool,
    ) -> Io {
        Io {
            push,
            stream: None,
            retry_at: None,
            sessions: 0,
            ask_after: None,
            was_pushing: false,
            plan: ReadPlan::default(),
            meter: LinkMeter::default(),
            remote,
            catalogue: Rc::new(catalogue),
            policy,
            schedule: Schedule::with_window(window),
            inbox: Rc::new(RefCell::new(VecDeque::new())),
            asking: false,
            batches: 0,
            seq: 0,
            stopped: false,
        }
    }

    /// Takes what the finished requests brought: answers become the read list, segments are
    /// checked against the manifest. Everything returned counts as taken by the frame loop.
    pub fn take(&mut self) -> Vec<Arrival> {
        let mut out = Vec::new();
        let now = Instant::now();
        let done: Vec<Done> = self.inbox.borrow_mut().drain(..).collect();
        for d in done {
            match d {
                Done::Answer(ask, at, answer) => {
                    self.asking = false;
                    match answer {
                        Ok(resp) => {
                            self.schedule.answered(ask);
                            self.plan.answered(resp.items, at);
                            self.refresh(now);
                            out.push(Arrival::Release(resp.evict));
                        }
                        Err(e) => {
                            self.ask_after = Some(now + BACKOFF);
                            out.push(self.failure(e));
                        }
                    }
                }
                Done::Batch(ids, sent, got) => {
                    self.batches -= 1;
                    let wire: u64 = got.as_ref().map_or(0, |items| {
                        items
                            .iter()
                            .filter_map(|(_, b)| b.as_ref().ok())
                            .map(|b| b.len() as u64)
                            .sum()
                    });
                    self.meter.finished(sent, now, wire);
                    let items = match got {
                        Ok(items) => items,
                        Err(e) => {
                            for &id in &ids {
                                self.schedule.finished(id, Err(()), now);
                            }
                            out.push(self.failure(e));
                            continue;
                        }
                    };
                    let mut answered = HashSet::new();
                    for (id, item) in items {
                        answered.insert(id);
                        let checked = item.and_then(|b| {
                            portico_protocol::verify_segment(
                                self.catalogue.segments.get(id as usize),
                                id,
                                &b,
                            )
                            .map(|()| b)
                            .map_err(anyhow::Error::msg)
                        });
                        match checked {
                            Ok(bytes) => {
                                self.seq += 1;
                                let listed = self.schedule.finished(id, Ok(self.seq), now);
                                out.push(Arrival::Segment(id, bytes, listed));
                            }
                            Err(e) => {
                                self.schedule.finished(id, Err(()), now);
                                out.push(Arrival::Failed(format!("{e:#}")));
                            }
                        }
                    }
                    for id in ids.into_iter().filter(|id| !answered.contains(id)) {
                        self.schedule.finished(id, Err(()), now);
                    }
                }
            }
        }
        // The frame loop takes every arrival at once.
        self.schedule.acknowledge(self.seq, true);
        self.take_pushed(&mut out);
        out
    }

    /// What the stream pushed, checked like pulled segments; a closed stream hands over to
    /// pull.
    fn take_pushed(&mut self, out: &mut Vec<Arrival>) {
        let Some((stream, _)) = &self.stream else {
            return;
        };
        let now = Instant::now();
        for p in stream.take(PUSHED_PER_FRAME) {
            match p {
                Pushed::Segment(id, bytes) => {
                    let info = self.catalogue.segments.get(id as usize);
                    match portico_protocol::verify_segment(info, id, &bytes) {
                        Ok(()) => out.push(Arrival::Segment(id, bytes, now)),
                        Err(e) => out.push(Arrival::Failed(e)),
                    }
                }
                Pushed::Error(e) => out.push(Arrival::Failed(e)),
            }
        }
        if let Some(why) = stream.closed() {
            if stream.stale() {
                out.push(Arrival::Stale(why));
                self.stream = None;
                self.stopped = true;
                return;
            }
            out.push(Arrival::Failed(format!("{why}; pulling over HTTP")));
            self.stream = None;
            self.retry_at = Some(now + RETRY);
        }
    }

    /// Which transport brings segments now: `stream` or `pull`.
    pub fn transport(&self) -> &'static str {
        match &self.stream {
            Some((s, _)) if s.is_open() => "stream",
            _ => "pull",
        }
    }

    /// What geometry segment `id` occupies decoded, by its LOD record (bytes).
    pub fn decoded_size(&self, id: u32) -> Option<u64> {
        self.catalogue.decoded.get(&id).copied()
    }

    /// Segments the cache released (the stream's server forgets it sent them).
    pub fn evicted(&self, ids: Vec<u32>) {
        if let Some((s, _)) = &self.stream {
            s.evicted(ids);
        }
    }

    /// Keeps a stream session going when pushing; `true` while it carries the segments (or
    /// may still open), so pull stays idle.
    /// `held`: what the cache holds, asked for only when a session opens (it tells the server).
    fn pushing(&mut self, observer: Observer, held: impl FnOnce() -> Vec<u32>) -> bool {
        if !self.push {
            return false;
        }
        let now = Instant::now();
        if self.stream.is_none() && self.retry_at.is_none_or(|t| now >= t) {
            let db = self.remote.database();
            let base = self.remote.base();
            match Stream::open(
                base,
                db.as_deref(),
                self.remote.token(),
                self.policy,
                &held(),
            ) {
                Ok(s) => {
                    self.stream = Some((s, now));
                    self.sessions += 1;
                }
                Err(_) => self.retry_at = Some(now + RETRY),
            }
        }
        let pushing = match &self.stream {
            Some((s, _)) if s.is_open() => {
                s.observe(observer);
                true
            }
            Some((_, since)) if now.duration_since(*since) < OPEN_WAIT => true,
            // Not open in time: pull, and try another session later.
            Some(_) => {
                self.stream = None;
                self.retry_at = Some(now + RETRY);
                false
            }
            None => false,
        };
        if pushing && !self.was_pushing {
            // The stream takes over: what pull still meant to read is the stream's now.
            self.schedule.refresh(Vec::new(), now);
            self.plan.clear();
        }
        self.was_pushing = pushing;
        pushing
    }

    /// The read list from the plan at `now`.
    fn refresh(&mut self, now: Instant) {
        let link = Link {
            rate: self.meter.rate(),
            rtt_s: self.meter.rtt_s(),
            in_flight: self.schedule.wire_bytes(),
        };
        let list = self
            .plan
            .list(now, f64::from(self.policy.frame_time_s), link);
        self.schedule.refresh(list, now);
    }

    fn failure(&mut self, e: anyhow::Error) -> Arrival {
        if e.downcast_ref::<Stale>().is_some() {
            self.stopped = true;
            return Arrival::Stale(format!("{e:#}"));
        }
        Arrival::Failed(format!("{e:#}"))
    }

    /// After a frame: asks the server about `observer` unless an answer is pending, and keeps
    /// up to [`PARALLEL`] batches in flight from the top of the latest read list, no more on
    /// the wire than the measured link delivers within two frames past its round trip. `held`:
    /// the segments resident in the cache; `lacking`: what the frame lacked, read first, and
    /// alone while the frame was `incomplete` ([`ReadPlan`]).
    pub fn pump(
        &mut self,
        observer: Observer,
        held: impl Iterator<Item = u32>,
        lacking: Vec<u32>,
        incomplete: bool,
    ) {
        if self.stopped {
            return;
        }
        // Listed once at most: for a session that opens, or for the prefetch request.
        let mut held = Some(held);
        let mut listed: Option<Vec<u32>> = None;
        let pushing = self.pushing(observer, || {
            let v: Vec<u32> = held.take().into_iter().flatten().collect();
            listed = Some(v.clone());
            v
        });
        if pushing {
            return;
        }
        let held = listed.unwrap_or_else(|| held.take().into_iter().flatten().collect());
        // Every frame: deadlines come nearer as the answer ages.
        self.plan.frame(lacking, incomplete);
        self.refresh(Instant::now());
        let frame_s = f64::from(self.policy.frame_time_s);
        self.schedule
            .set_wire_cap(Some(self.meter.cap(2.0 * frame_s)));
        if !self.asking && self.ask_after.is_none_or(|t| Instant::now() >= t) {
            self.asking = true;
            self.ask_after = None;
            let held: HashSet<u32> = held.into_iter().chain(self.schedule.pending()).collect();
            let number = self.schedule.asked();
            let req = PrefetchRequest {
                version: PROTOCOL_VERSION,
                observer,
                policy: self.policy,
                held: portico_protocol::encode_held(held),
            };
            let (remote, inbox) = (self.remote.clone(), self.inbox.clone());
            wasm_bindgen_futures::spawn_local(async move {
                let at = Instant::now();
                let answer = remote.prefetch(&req).await;
                inbox
                    .borrow_mut()
                    .push_back(Done::Answer(number, at, answer));
            });
        }
        let catalogue = self.catalogue.clone();
        let wire = |id: u32| catalogue.segments.get(id as usize).map_or(0, |s| s.bytes);
        let held = |id: u32| {
            catalogue
                .decoded
                .get(&id)
                .map_or(wire(id), |&d| d.max(wire(id)))
        };
        while self.batches < PARALLEL {
            let ids = self.schedule.next_batch_sized(Instant::now(), &wire, &held);
            if ids.is_empty() {
                break;
            }
            self.batches += 1;
            let sent = Instant::now();
            self.meter.started(sent);
            let (remote, inbox) = (self.remote.clone(), self.inbox.clone());
            wasm_bindgen_futures::spawn_local(async move {
                let got = remote.batch(&ids).await;
                inbox.borrow_mut().push_back(Done::Batch(ids, sent, got));
            });
        }
    }
}
