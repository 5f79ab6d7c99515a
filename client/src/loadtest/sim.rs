//! One simulated client (DESIGN §7): the real client's frame loop without a GPU. Each frame it
//! takes what its IO task delivered into a byte-budgeted [`ObjectCache`] (values are sizes
//! only), runs the client's visibility ([`view::visible`]) and candidates, lets the `optimize`
//! elider choose among RESIDENT LODs with the default cost model, and counts what it had to give
//! up (LODs skipped, objects skipped: Funkhouser §5.2.4). It never waits for the network.
//!
//! Its IO task fetches through the client's emulated [`Pipe`], in one of three ways:
//! - [`Mode::Prefetch`]: the real client's prefetch loop (`client/src/io.rs`): post the observer
//!   and the held set to `/v1/prefetch`, demote the eviction hints, fetch the answer's items in
//!   need order a few at a time, repeat with the latest observer (Funkhouser §5.2–5.3);
//! - [`Mode::Demand`]: no lookahead; each frame the client asks for exactly the LODs its elider
//!   wanted and did not have (and the eye cell's stab list), computed from its visible set;
//! - [`Mode::Oracle`]: knows the future path; each frame it asks for what an omniscient client
//!   would draw in the next frames, nearest in time first.

use super::link::Pipe;
use super::world::{World, cap_detail};
use crate::cache::ObjectCache;
use crate::cost::CostModel;
use crate::elision::{Algorithm, Candidate, Choice, Elider};
use crate::net::Remote;
use crate::view;
use futures_util::StreamExt;
use portico_protocol::{Observer, PROTOCOL_VERSION, Policy, PrefetchRequest, PrefetchResponse};
use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinSet;
use tokio::time::{Instant, MissedTickBehavior};

/// How a simulated client gets its data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mode {
    /// The server's prefetch answers (Funkhouser §5.2) with this policy.
    Prefetch(Policy),
    /// Fetch on demand what the elider wanted and did not have.
    Demand,
    /// Fetch what will be drawn in the next `lookahead` frames, nearest first.
    Oracle {
        /// Frames looked ahead.
        lookahead: u64,
    },
}

/// Concurrent segment fetches per client (as the real client's IO stage).
pub const PARALLEL: usize = 8;

/// One frame's counts.
#[derive(Debug, Clone, Copy, Default)]
pub struct FrameStat {
    /// Path frame shown.
    pub path_frame: usize,
    /// LOD levels given up for coarser resident ones (§5.2.4).
    pub lods_skipped: u32,
    /// Wanted objects with nothing resident to draw.
    pub objects_skipped: u32,
    /// `lods_skipped` plus, for every skipped object, the levels from the wanted one down to
    /// the coarsest (everything the frame lacked, in LOD levels).
    pub lod_deficit: u32,
    /// Objects the visibility stage passed.
    pub visible_objects: u32,
    /// LODs the elider wanted.
    pub wanted: u32,
    /// Of those, how many were resident.
    pub hits: u32,
    /// The latest prefetch answer's lookahead set size (bytes), 0 before the first one.
    pub lookahead_bytes: u64,
    /// The eye cell's stab list was not resident (frustum culling was used).
    pub fallback: bool,
    /// The eye was in no live cell (so there is no stab list to use: frustum culling).
    pub outside: bool,
}

/// Figures of one prefetch answer.
#[derive(Debug, Clone, Copy, Default)]
pub struct AnswerStat {
    /// Range cells.
    pub range_cells: u32,
    /// Lookahead objects.
    pub lookahead_objects: u32,
    /// Lookahead set bytes.
    pub lookahead_bytes: u64,
    /// Server compute time (µs).
    pub micros: u32,
    /// Segments in the read set.
    pub items: u32,
}

/// Everything one client measured.
#[derive(Debug, Clone, Default)]
pub struct ClientResult {
    /// One row per frame.
    pub rows: Vec<FrameStat>,
    /// Seconds from first listing to residency, one per arrival.
    pub latencies: Vec<f64>,
    /// Every prefetch answer.
    pub answers: Vec<AnswerStat>,
    /// Segment bytes that arrived.
    pub bytes_fetched: u64,
    /// Segments that arrived.
    pub segments_fetched: u64,
    /// Arrived bytes never drawn before their release or the end (or arrived twice).
    pub bytes_wasted: u64,
    /// Peak cache bytes.
    pub cache_peak: u64,
    /// Segments released.
    pub evictions: u64,
    /// Failed requests.
    pub failures: u64,
}

/// What the frame loop tells its IO task after each frame.
#[derive(Debug, Clone)]
struct Published {
    observer: Observer,
    held: Vec<u32>,
    wants: Vec<u32>,
    consumed: u64,
    at: Instant,
}

/// What the IO task hands the frame loop.
#[derive(Debug)]
enum Msg {
    Segment {
        id: u32,
        bytes: u64,
        listed_at: Instant,
    },
    Hints(Vec<u32>),
    Answer(AnswerStat),
    Failed(String),
}

/// What a client task needs.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The shared world.
    pub world: Arc<World>,
    /// The server.
    pub remote: Remote,
    /// The client's link.
    pub pipe: Arc<Pipe>,
    /// How it fetches.
    pub mode: Mode,
    /// First path frame.
    pub offset: usize,
    /// Frames to play.
    pub frames: u64,
    /// Cache budget (bytes).
    pub cache_bytes: u64,
    /// Frames played by all clients so far (progress).
    pub done: Arc<AtomicU64>,
}

/// Plays one client's frames in real time (one frame per `world.dt`) and returns its figures.
pub async fn client(s: Setup) -> ClientResult {
    let (state_tx, state_rx) = watch::channel(None);
    let (tx, rx) = mpsc::channel(4096);
    let io = Io {
        remote: s.remote.clone(),
        pipe: s.pipe.clone(),
        tx,
    };
    let task = match s.mode {
        Mode::Prefetch(p) => tokio::spawn(prefetch_io(io, p, state_rx)),
        Mode::Demand | Mode::Oracle { .. } => tokio::spawn(list_io(io, state_rx)),
    };
    let mut c = Client::new(&s, rx);
    let mut tick = tokio::time::interval(Duration::from_secs_f64(s.world.dt.max(1e-3)));
    tick.set_missed_tick_behavior(MissedTickBehavior::Delay);
    for f in 0..s.frames {
        tick.tick().await;
        c.take_arrivals();
        let p = (s.offset + f as usize) % s.world.path_frames();
        let (row, decided) = c.frame(p);
        c.result.rows.push(row);
        let published = c.publish(p, f, &decided);
        let _ = state_tx.send(Some(published));
        s.done.fetch_add(1, Ordering::Relaxed);
    }
    drop(state_tx);
    task.abort();
    c.finish()
}

/// The frame loop's state.
struct Client {
    world: Arc<World>,
    mode: Mode,
    frames: u64,
    rx: mpsc::Receiver<Msg>,
    cache: ObjectCache<()>,
    /// Resident segments: (bytes, drawn at least once).
    entries: HashMap<u32, (u64, bool)>,
    elider: Elider,
    cost: CostModel,
    consumed: u64,
    last_answer: Option<AnswerStat>,
    result: ClientResult,
}

impl Client {
    fn new(s: &Setup, rx: mpsc::Receiver<Msg>) -> Client {
        Client {
            world: s.world.clone(),
            mode: s.mode,
            frames: s.frames,
            rx,
            cache: ObjectCache::new(s.cache_bytes),
            entries: HashMap::new(),
            elider: Elider::new(Algorithm::Optimize, s.world.dt),
            cost: CostModel::default(),
            consumed: 0,
            last_answer: None,
            result: ClientResult::default(),
        }
    }

    /// Moves everything delivered into the cache (never above its budget) and counts it.
    fn take_arrivals(&mut self) {
        while let Ok(m) = self.rx.try_recv() {
            self.consumed += 1;
            match m {
                Msg::Segment {
                    id,
                    bytes,
                    listed_at,
                } => self.arrive(id, bytes, listed_at),
                Msg::Hints(ids) => ids.iter().for_each(|&id| self.cache.demote(id)),
                Msg::Answer(a) => {
                    self.last_answer = Some(a);
                    self.result.answers.push(a);
                }
                Msg::Failed(e) => {
                    self.result.failures += 1;
                    tracing::warn!("loadtest io: {e}");
                }
            }
        }
    }

    fn arrive(&mut self, id: u32, bytes: u64, listed_at: Instant) {
        let r = &mut self.result;
        r.latencies.push(listed_at.elapsed().as_secs_f64());
        r.bytes_fetched += bytes;
        r.segments_fetched += 1;
        if self.cache.contains(id) {
            r.bytes_wasted += bytes; // fetched twice
            return;
        }
        match self.cache.insert(id, (), bytes) {
            Ok(released) => {
                for gone in released {
                    if let Some((b, false)) = self.entries.remove(&gone) {
                        r.bytes_wasted += b;
                    }
                }
                self.entries.insert(id, (bytes, false));
            }
            Err(_) => r.bytes_wasted += bytes,
        }
    }

    /// Visibility → candidates (capped at the size threshold) → elision over resident LODs,
    /// for path frame `p`.
    fn frame(&mut self, p: usize) -> (FrameStat, Decided) {
        let w = self.world.clone();
        let cache = &self.cache;
        let stab = |c: u32| {
            w.stab_segment(c)
                .filter(|&s| cache.contains(s))
                .and_then(|_| w.stabs.get(&c).cloned())
        };
        let vis = view::visible(w.graph.as_ref(), &stab, &w.bounds, &w.frustum(p));
        let resident = |s: u32| cache.contains(s);
        let mut cands =
            view::candidates(&w.header, &vis.objects, &w.frames[p].viewpoint, &resident);
        let dropped = cap_detail(&mut cands, w.size_threshold_px);
        let decided = self.elider.choose(&cands, &self.cost, None);
        let mut row = FrameStat {
            path_frame: p,
            lods_skipped: decided.lods_skipped,
            objects_skipped: decided.objects_skipped,
            visible_objects: vis.objects.len() as u32,
            lookahead_bytes: self.last_answer.map_or(0, |a| a.lookahead_bytes),
            fallback: vis.fallback,
            outside: vis.eye_cell.is_none(),
            ..FrameStat::default()
        };
        let d = Decided {
            segments: cands
                .iter()
                .zip(&dropped)
                .map(|(c, &skip)| {
                    let lods = w.header.lods_of(&w.header.instances[c.id as usize]);
                    lods[skip..].iter().map(|l| l.segment).collect()
                })
                .collect(),
            cands,
            choices: decided.choices,
            eye_stab: vis.eye_cell.and_then(|c| w.stab_segment(c)),
        };
        let mut used = Vec::new();
        let mut touched = Vec::new();
        for (i, (c, ch)) in d.cands.iter().zip(&d.choices).enumerate() {
            count(&mut row, c, ch);
            used.extend(ch.lod.map(|l| d.segments[i][l]));
            let all = w.header.lods_of(&w.header.instances[c.id as usize]);
            touched.extend(all.iter().map(|l| l.segment).filter(|&s| resident(s)));
        }
        if !vis.fallback {
            used.extend(d.eye_stab);
        }
        // §5.2.3: what is needed now moves to the head of the cache.
        for s in touched.into_iter().chain(d.eye_stab) {
            self.cache.touch(s);
        }
        for s in used {
            if let Some(e) = self.entries.get_mut(&s) {
                e.1 = true;
            }
        }
        (row, d)
    }

    /// What the IO task gets after frame `f` (path frame `p`).
    fn publish(&mut self, p: usize, f: u64, d: &Decided) -> Published {
        let wants = match self.mode {
            Mode::Prefetch(_) => Vec::new(),
            Mode::Demand => self.demand_wants(d),
            Mode::Oracle { lookahead } => {
                let left = self.frames.saturating_sub(f);
                self.oracle_wants(p, lookahead.min(left), d)
            }
        };
        Published {
            observer: self.world.frames[p].observer,
            held: match self.mode {
                Mode::Prefetch(_) => self.cache.ids().collect(),
                _ => Vec::new(),
            },
            wants,
            consumed: self.consumed,
            at: Instant::now(),
        }
    }

    /// What this frame lacked, most urgent first: the eye cell's stab list, the coarsest LOD of
    /// every wanted object with nothing to draw (DESIGN §5: a coarse LOD of everything visible
    /// first), then every wanted LOD not resident; biggest objects on screen first.
    fn missing_now(&self, d: &Decided) -> Vec<u32> {
        let mut stand_ins = Vec::new();
        let mut wanted = Vec::new();
        for (i, (c, ch)) in d.cands.iter().zip(&d.choices).enumerate() {
            let Some(want) = ch.desired else { continue };
            let segs = &d.segments[i];
            if ch.lod.is_none()
                && let Some(&coarsest) = segs.last()
                && !self.cache.contains(coarsest)
            {
                stand_ins.push((c.pixels, coarsest));
            }
            if !self.cache.contains(segs[want]) {
                wanted.push((c.pixels, segs[want]));
            }
        }
        stand_ins.sort_by(|a, b| b.0.total_cmp(&a.0));
        wanted.sort_by(|a, b| b.0.total_cmp(&a.0));
        let stab = d.eye_stab.filter(|&s| !self.cache.contains(s));
        let all = stab
            .into_iter()
            .chain(stand_ins.into_iter().map(|x| x.1))
            .chain(wanted.into_iter().map(|x| x.1));
        unique(all)
    }

    /// Demand fetch: exactly what this frame lacked.
    fn demand_wants(&self, d: &Decided) -> Vec<u32> {
        self.missing_now(d)
    }

    /// The oracle: what this frame lacked, then what will be drawn in the next `k` frames,
    /// nearest first, up to the cache budget; what of it is resident moves to the head of the
    /// cache (nearest last, so headmost).
    fn oracle_wants(&mut self, p: usize, k: u64, d: &Decided) -> Vec<u32> {
        let w = self.world.clone();
        let n = w.path_frames();
        let mut window = Vec::new();
        let mut seen = HashSet::new();
        let mut bytes = 0u64;
        'frames: for j in 0..k.max(1) as usize {
            let Some(t) = w.truth[(p + j) % n].as_ref() else {
                continue;
            };
            for &s in &t.wants {
                if !seen.insert(s) {
                    continue;
                }
                bytes += w.bytes(s);
                if j > 0 && bytes > self.cache.budget() {
                    break 'frames;
                }
                window.push(s);
            }
        }
        for &s in window.iter().rev() {
            self.cache.touch(s);
        }
        let now = self.missing_now(d);
        let ahead = window.into_iter().filter(|&s| !self.cache.contains(s));
        unique(now.into_iter().chain(ahead))
    }

    /// Counts what was never drawn among the segments still resident.
    fn finish(mut self) -> ClientResult {
        let never: u64 = self
            .entries
            .values()
            .filter(|(_, drawn)| !drawn)
            .map(|(b, _)| b)
            .sum();
        self.result.bytes_wasted += never;
        self.result.cache_peak = self.cache.peak_bytes();
        self.result.evictions = self.cache.evictions();
        self.result
    }
}

/// One frame's elision, as the IO side needs it.
struct Decided {
    cands: Vec<Candidate>,
    choices: Vec<Choice>,
    /// Per candidate, the segments of its (capped) LODs, finest first.
    segments: Vec<Vec<u32>>,
    eye_stab: Option<u32>,
}

/// The items in their first order, each once.
fn unique(ids: impl Iterator<Item = u32>) -> Vec<u32> {
    let mut seen = HashSet::new();
    ids.filter(|&s| seen.insert(s)).collect()
}

/// Adds one candidate's choice to a frame's counts.
fn count(row: &mut FrameStat, c: &Candidate, ch: &Choice) {
    let Some(d) = ch.desired else { return };
    row.wanted += 1;
    row.hits += u32::from(c.lods.get(d).is_some_and(|l| l.resident));
    row.lod_deficit += if ch.object_skipped {
        c.lods.len().saturating_sub(d) as u32
    } else {
        ch.lods_skipped
    };
}

/// The IO task's ends of the channels.
struct Io {
    remote: Remote,
    pipe: Arc<Pipe>,
    tx: mpsc::Sender<Msg>,
}

impl Io {
    /// Sends one message; every message counts in the sequence the frame loop acknowledges.
    async fn send(&self, seq: &mut u64, m: Msg) -> Result<(), ()> {
        *seq += 1;
        self.tx.send(m).await.map_err(|_| ())
    }

    /// `GET /v1/segments/{id}` through the link; the body's length.
    async fn segment(remote: Remote, pipe: Arc<Pipe>, id: u32) -> (u32, anyhow::Result<u64>) {
        pipe.send().await;
        let got = remote.segment(id).await;
        if let Ok(b) = &got {
            pipe.deliver(b.len() as u64).await;
        }
        (id, got.map(|b| b.len() as u64))
    }

    /// `POST /v1/prefetch` through the link.
    async fn prefetch(&self, req: &PrefetchRequest) -> anyhow::Result<PrefetchResponse> {
        self.pipe.send().await;
        let resp = self.remote.prefetch(req).await?;
        let body = portico_protocol::to_bincode(&resp).map_or(0, |b| b.len() as u64);
        self.pipe.deliver(body).await;
        Ok(resp)
    }
}

/// The real client's prefetch loop (`io.rs`) through the emulated link.
async fn prefetch_io(io: Io, policy: Policy, mut state: watch::Receiver<Option<Published>>) {
    let mut delivered: HashMap<u32, u64> = HashMap::new();
    let mut seq = 0u64;
    while state.changed().await.is_ok() {
        let Some(st) = state.borrow_and_update().clone() else {
            continue;
        };
        delivered.retain(|_, s| *s >= st.consumed);
        let held: HashSet<u32> = st.held.iter().chain(delivered.keys()).copied().collect();
        let req = PrefetchRequest {
            version: PROTOCOL_VERSION,
            observer: st.observer,
            policy,
            held: portico_protocol::encode_held(held),
        };
        let t0 = Instant::now();
        let resp = match io.prefetch(&req).await {
            Ok(r) => r,
            Err(e) => {
                if io
                    .send(&mut seq, Msg::Failed(format!("{e:#}")))
                    .await
                    .is_err()
                {
                    return;
                }
                continue;
            }
        };
        let stat = AnswerStat {
            range_cells: resp.range_cells,
            lookahead_objects: resp.lookahead_objects,
            lookahead_bytes: resp.lookahead_bytes,
            micros: resp.micros,
            items: resp.items.len() as u32,
        };
        if io.send(&mut seq, Msg::Answer(stat)).await.is_err()
            || (!resp.evict.is_empty() && io.send(&mut seq, Msg::Hints(resp.evict)).await.is_err())
        {
            return;
        }
        let mut fetches = futures_util::stream::iter(resp.items)
            .map(|item| Io::segment(io.remote.clone(), io.pipe.clone(), item.segment))
            .buffered(PARALLEL);
        while let Some((id, got)) = fetches.next().await {
            let m = match got {
                Ok(bytes) => {
                    delivered.insert(id, seq);
                    Msg::Segment {
                        id,
                        bytes,
                        listed_at: t0,
                    }
                }
                Err(e) => Msg::Failed(format!("{e:#}")),
            };
            if io.send(&mut seq, m).await.is_err() {
                return;
            }
        }
    }
}

/// Demand fetch and the oracle: keep [`PARALLEL`] fetches going from the latest want list.
async fn list_io(io: Io, mut state: watch::Receiver<Option<Published>>) {
    let mut l = Lists::default();
    let mut tasks: JoinSet<(u32, anyhow::Result<u64>)> = JoinSet::new();
    let mut seq = 0u64;
    loop {
        while tasks.len() < PARALLEL {
            let Some(id) = l.next() else { break };
            l.inflight.insert(id);
            tasks.spawn(Io::segment(io.remote.clone(), io.pipe.clone(), id));
        }
        tokio::select! {
            changed = state.changed() => {
                if changed.is_err() {
                    return;
                }
                if let Some(st) = state.borrow_and_update().clone() {
                    l.refresh(st);
                }
            }
            Some(done) = tasks.join_next(), if !tasks.is_empty() => {
                let Ok((id, got)) = done else { continue };
                l.inflight.remove(&id);
                let m = match got {
                    Ok(bytes) => {
                        l.delivered.insert(id, seq);
                        let listed_at = l.listed.remove(&id).unwrap_or_else(Instant::now);
                        Msg::Segment { id, bytes, listed_at }
                    }
                    Err(e) => {
                        l.failed.insert(id);
                        Msg::Failed(format!("{e:#}"))
                    }
                };
                if io.send(&mut seq, m).await.is_err() {
                    return;
                }
            }
        }
    }
}

/// The bookkeeping of [`list_io`].
#[derive(Default)]
struct Lists {
    wants: Vec<u32>,
    cursor: usize,
    /// When each wanted segment was first listed (since it was last out of every list).
    listed: HashMap<u32, Instant>,
    /// Delivered, with the arrival sequence number, until the frame loop has taken it.
    delivered: HashMap<u32, u64>,
    inflight: HashSet<u32>,
    failed: HashSet<u32>,
}

impl Lists {
    fn refresh(&mut self, st: Published) {
        self.delivered.retain(|_, s| *s >= st.consumed);
        let now: HashSet<u32> = st.wants.iter().copied().collect();
        let inflight = &self.inflight;
        self.listed
            .retain(|id, _| now.contains(id) || inflight.contains(id));
        for &id in &st.wants {
            self.listed.entry(id).or_insert(st.at);
        }
        self.wants = st.wants;
        self.cursor = 0;
    }

    /// The next wanted segment not on its way or already delivered.
    fn next(&mut self) -> Option<u32> {
        while let Some(&id) = self.wants.get(self.cursor) {
            self.cursor += 1;
            let busy = self.inflight.contains(&id)
                || self.delivered.contains_key(&id)
                || self.failed.contains(&id);
            if !busy {
                return Some(id);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elision::LodOption;

    #[test]
    fn a_skipped_object_counts_every_level_it_lacks() {
        let lod = |resident| LodOption {
            triangles: 10,
            vertices: 10,
            error: 0.0,
            resident,
        };
        let c = Candidate::new(0, vec![lod(false), lod(false), lod(true)], 100.0);
        let mut row = FrameStat::default();
        // Wanted LOD 0, drew LOD 2: two levels skipped.
        let drawn = Choice {
            lod: Some(2),
            desired: Some(0),
            lods_skipped: 2,
            object_skipped: false,
        };
        count(&mut row, &c, &drawn);
        assert_eq!((row.wanted, row.hits, row.lod_deficit), (1, 0, 2));
        // Wanted LOD 1, nothing to draw: levels 1 and 2 are missing.
        let skipped = Choice {
            lod: None,
            desired: Some(1),
            lods_skipped: 0,
            object_skipped: true,
        };
        count(&mut row, &c, &skipped);
        assert_eq!((row.wanted, row.lod_deficit), (2, 4));
        // Not wanted: not counted.
        count(&mut row, &c, &Choice::default());
        assert_eq!(row.wanted, 2);
    }

    #[test]
    fn want_lists_skip_what_is_on_its_way_and_keep_first_listing_times() {
        let t0 = Instant::now();
        let published = |wants: Vec<u32>, consumed| Published {
            observer: crate::loadtest::world::path_frames(
                &portico_data::path::CameraPath {
                    kind: "t".into(),
                    keyframes: vec![portico_data::path::Keyframe {
                        t: 0.0,
                        eye: [0.0; 3],
                        dir: [1.0, 0.0, 0.0],
                    }],
                },
                0.05,
                10.0,
            )[0]
            .observer,
            held: Vec::new(),
            wants,
            consumed,
            at: Instant::now(),
        };
        let mut l = Lists::default();
        l.refresh(published(vec![1, 2, 3], 0));
        let first = l.listed[&2];
        assert!(first >= t0);
        assert_eq!(l.next(), Some(1));
        l.inflight.insert(1);
        l.delivered.insert(2, 0); // arrival #0, not yet taken by the frame loop
        assert_eq!(l.next(), Some(3));
        assert_eq!(l.next(), None);
        // The frame loop took arrival #0 and still wants 2 (it was evicted): fetch it again;
        // 3 left the list and forgets its time; 1 is in flight and keeps its.
        l.refresh(published(vec![2, 1], 1));
        assert_eq!(l.listed[&2], first);
        assert!(l.listed.contains_key(&1) && !l.listed.contains_key(&3));
        assert_eq!(l.next(), Some(2));
        assert_eq!(l.next(), None);
    }
}
