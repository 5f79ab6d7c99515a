//! One simulated client: the real client's frame loop without a GPU. Each frame it
//! takes what its IO task delivered into a byte-budgeted [`ObjectCache`] (values are sizes
//! only), runs the client's own frame decision ([`Decider`]: visibility, candidates, the
//! `optimize` elider over RESIDENT LODs with the default cost model), and counts what it had to
//! give up (LODs skipped, objects skipped: Funkhouser §5.2.4). It never waits for the network.
//!
//! Its IO task is the real client's ([`portico_native::drive::drive`]) fetching through the
//! client's emulated [`Pipe`], with its need list made in one of three ways:
//! - [`Mode::Prefetch`]: the server's lookahead, as the real client: over pull, post the
//!   observer and the held set to `/v1/prefetch` once per frame, demote the eviction hints,
//!   read what the frame lacked and then the latest answer's items in need order a few at a
//!   time (Funkhouser §5.2–5.3); over push, send the observer each frame and take what the
//!   server pushes ([`portico_native::stream`]);
//! - [`Mode::Demand`]: no lookahead; each frame the client asks for exactly the LODs its elider
//!   wanted and did not have (and the eye cell's stab list), computed from its visible set;
//! - [`Mode::Oracle`]: knows the future path; each frame it asks for what an omniscient client
//!   would draw in the next frames, nearest in time first.

use super::link::{Linked, Pipe};
use super::waste::{Ledger, Waste};
use super::world::World;
use crate::drawn::DrawnFrame;
use portico_client::cache::ObjectCache;
use portico_client::cost::CostModel;
use portico_client::demand::ahead_of;
use portico_client::elision::{Algorithm, Candidate, Choice};
use portico_client::engine::holdings::Holdings;
use portico_client::frame::{Decider, Resident};
use portico_client::parts::{Joined, Parts};
use portico_data::cells::StabList;
use portico_native::drive::{Ask, Event};
use portico_native::net::Remote;
use portico_native::stream::{Transport, run};
use portico_protocol::Policy;
use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use std::time::Instant;
use tokio::sync::{mpsc, watch};
use tokio::time::MissedTickBehavior;

/// How a simulated client gets its data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mode {
    /// The server's prefetch answers (Funkhouser §5.2) with this policy, pulled or pushed.
    Prefetch(Policy, Transport),
    /// Fetch on demand what the elider wanted and did not have.
    Demand,
    /// Fetch what will be drawn in the next `lookahead` frames, nearest first.
    Oracle {
        /// Frames looked ahead.
        lookahead: u64,
    },
}

/// Concurrent segment fetches per client (as the real client's IO stage).
pub const PARALLEL: usize = portico_client::defaults::PARALLEL;

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
    /// `bytes_wasted` by reason.
    pub waste: Waste,
    /// Peak cache bytes.
    pub cache_peak: u64,
    /// Segments released.
    pub evictions: u64,
    /// Failed requests.
    pub failures: u64,
    /// The first frame in which every visible object was represented (its own LOD, or with
    /// impostors a box above it), and the bytes that had arrived by then.
    pub first_complete: Option<(u64, u64)>,
    /// What each frame drew, when [`Setup::record`] asked for it.
    pub drawn: Vec<DrawnFrame>,
}

/// What the IO task hands the frame loop: segment bodies are just their sizes.
type Msg = Event<u64>;

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
    /// Record what each frame drew ([`ClientResult::drawn`]).
    pub record: bool,
}

/// Plays one client's frames in real time (one frame per `world.dt`) and returns its figures.
pub async fn client(s: Setup) -> ClientResult {
    let (state_tx, state_rx) = watch::channel(None);
    let (tx, rx) = mpsc::channel(4096);
    let link = Linked {
        remote: s.remote.clone(),
        pipe: s.pipe.clone(),
        world: s.world.clone(),
    };
    // Demand fetch and the oracle make their own lists; of the policy they use only the frame
    // time, which paces every run's reads alike.
    let (policy, transport) = match s.mode {
        Mode::Prefetch(p, t) => (p, t),
        Mode::Demand | Mode::Oracle { .. } => (
            Policy {
                frame_time_s: s.world.dt as f32,
                ..Policy::default()
            },
            Transport::Pull,
        ),
    };
    let window = portico_client::cache::split_budget(s.cache_bytes).1;
    // A push session is paced to the link's rate (the server caps an unlimited one).
    let rate = s.pipe.link().rate_bytes_per_s;
    let rate = if rate.is_finite() {
        rate as u64
    } else {
        u64::MAX / 2
    };
    let task = tokio::spawn(run(
        link, policy, transport, rate, PARALLEL, window, state_rx, tx,
    ));
    let mut c = Client::new(&s, rx);
    let mut tick = tokio::time::interval(Duration::from_secs_f64(s.world.dt.max(1e-3)));
    tick.set_missed_tick_behavior(MissedTickBehavior::Delay);
    for f in 0..s.frames {
        tick.tick().await;
        c.take_arrivals();
        let p = (s.offset + f as usize) % s.world.path_frames();
        let row = c.frame(p);
        if c.result.first_complete.is_none() && row.objects_skipped == 0 && row.visible_objects > 0
        {
            c.result.first_complete = Some((f, c.result.bytes_fetched));
        }
        c.result.rows.push(row);
        let published = c.publish(p, f);
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
    /// The real client's holdings (values are sizes only: `()` charged what they decode to).
    holdings: Holdings<()>,
    /// Resident segments: (bytes, drawn at least once).
    entries: HashMap<u32, (u64, bool)>,
    /// The frame decision (Maciel's traversal when the policy asks for impostors and the model
    /// has them, else the optimizing elider).
    decider: Decider,
    cost: CostModel,
    consumed: u64,
    last_answer: Option<AnswerStat>,
    result: ClientResult,
    record: bool,
    /// What was drawn and what arrived in vain, for [`ClientResult::waste`].
    ledger: Ledger,
    /// Texture segments cut into parts: those that came wait here for the rest.
    parts: Parts,
}

impl Client {
    fn new(s: &Setup, rx: mpsc::Receiver<Msg>) -> Client {
        Client {
            world: s.world.clone(),
            mode: s.mode,
            frames: s.frames,
            rx,
            holdings: Holdings::new(portico_client::cache::split_budget(s.cache_bytes).0),
            entries: HashMap::new(),
            decider: Decider::new(
                match s.mode {
                    Mode::Prefetch(p, _) if p.impostors && s.world.header.hierarchy.is_some() => {
                        Algorithm::Impostors
                    }
                    _ => Algorithm::Optimize,
                },
                s.world.dt,
                Some(s.world.size_threshold_px),
            ),
            cost: CostModel::default(),
            consumed: 0,
            last_answer: None,
            result: ClientResult::default(),
            record: s.record,
            ledger: Ledger::default(),
            parts: Parts::new(&s.world.header.textures),
        }
    }

    /// Moves everything delivered into the cache (never above its budget) and counts it.
    fn take_arrivals(&mut self) {
        while let Ok(m) = self.rx.try_recv() {
            self.consumed += 1;
            match m {
                Event::Segment {
                    id,
                    body: resident,
                    bytes,
                    listed_at,
                } => self.arrive(id, bytes, resident, listed_at),
                Event::Answer(resp) => {
                    resp.evict
                        .iter()
                        .for_each(|&id| self.holdings.cache.demote(id));
                    let a = AnswerStat {
                        range_cells: resp.range_cells,
                        lookahead_objects: resp.lookahead_objects,
                        lookahead_bytes: resp.lookahead_bytes,
                        micros: resp.micros,
                        items: resp.items.len() as u32,
                    };
                    self.last_answer = Some(a);
                    self.result.answers.push(a);
                }
                Event::Failed(e) | Event::Stale(e) => {
                    self.result.failures += 1;
                    tracing::warn!("loadtest io: {e}");
                }
            }
        }
    }

    /// `bytes` came over the wire; the cache is charged `resident`, what they decode to. A
    /// part of a texture segment waits for the rest, as the real client's do; the last one
    /// puts the whole under its head's id.
    fn arrive(&mut self, id: u32, bytes: u64, resident: u64, listed_at: Instant) {
        let r = &mut self.result;
        r.latencies.push(listed_at.elapsed().as_secs_f64());
        r.bytes_fetched += bytes;
        r.segments_fetched += 1;
        if self.holdings.has(self.parts.head(id)) {
            r.bytes_wasted += bytes; // fetched twice
            self.ledger.twice(bytes);
            self.holdings.piece_waits(&mut self.parts, id);
            return;
        }
        let (id, bytes, resident) = match self.parts.join(id, Vec::new()) {
            Joined::Whole(id, _) => (id, bytes, resident),
            Joined::Waiting => return,
            Joined::Complete(head, _) => {
                let wire = self.parts.group(head).map(|s| self.world.bytes(s)).sum();
                (head, wire, self.world.decoded(head))
            }
        };
        let released = self.holdings.hold(&mut self.parts, id, (), resident);
        for gone in released {
            if let Some((b, false)) = self.entries.remove(&gone) {
                r.bytes_wasted += b;
                self.ledger.unused(gone, b);
            }
        }
        if self.holdings.cache.contains(id) {
            self.entries.insert(id, (bytes, false));
        } else {
            // Larger than the whole cache: held beside it (reported held, never drawn).
            r.bytes_wasted += bytes;
            self.ledger.unused(id, bytes);
        }
    }

    /// Visibility → candidates (capped at the size threshold) → elision over resident LODs,
    /// for path frame `p`.
    fn frame(&mut self, p: usize) -> FrameStat {
        let w = self.world.clone();
        let scene = w.scene();
        let d = self.decider.decide(
            &scene,
            &w.frames[p].viewpoint,
            &Held(&self.holdings.cache, &w),
            &self.cost,
            None,
        );
        let mut row = FrameStat {
            path_frame: p,
            lods_skipped: d.frame.lods_skipped,
            objects_skipped: d.frame.objects_skipped,
            visible_objects: d.visible.objects.len() as u32,
            lookahead_bytes: self.last_answer.map_or(0, |a| a.lookahead_bytes),
            fallback: d.visible.fallback,
            outside: d.visible.eye_cell.is_none(),
            ..FrameStat::default()
        };
        for (c, ch) in d.candidates.iter().zip(&d.frame.choices) {
            count(&mut row, c, ch);
        }
        if self.record {
            self.result.drawn.push(DrawnFrame::of(&d, p));
        }
        // What was drawn (the eye's stab list too, when it was used) counts as used.
        let mut used: Vec<u32> = d.drawn.iter().map(|o| o.segment).collect();
        used.extend(d.drawn.iter().filter_map(|o| o.texture));
        if !d.visible.fallback {
            used.extend(d.eye_stab);
        }
        if let Some(h) = &w.header.hierarchy {
            used.extend(d.box_textures(h));
        }
        self.holdings.decided(&self.parts, &d, &scene);

        for s in used {
            if let Some(e) = self.entries.get_mut(&s) {
                e.1 = true;
            }
            self.ledger.drew(&w.chains, s);
        }
        row
    }

    /// What the IO task gets after frame `f` (path frame `p`).
    fn publish(&mut self, p: usize, f: u64) -> Ask {
        let (wants, lacking) = match self.mode {
            Mode::Prefetch(..) => (None, self.holdings.lacking.clone()),
            Mode::Demand => (Some(self.demand_wants()), Vec::new()),
            Mode::Oracle { lookahead } => {
                let left = self.frames.saturating_sub(f);
                (Some(self.oracle_wants(p, lookahead.min(left))), Vec::new())
            }
        };
        Ask {
            observer: self.world.frames[p].observer,
            held: self.holdings.held(&self.parts),
            consumed: self.consumed,
            wants,
            lacking,
            incomplete: self.holdings.incomplete,
            at: Instant::now(),
        }
    }

    /// Demand fetch: exactly what this frame lacked (with the missing parts of textures).
    fn demand_wants(&self) -> Vec<u32> {
        self.holdings.lacking.clone()
    }

    /// The oracle: what this frame lacked, then what will be drawn in the next `k` frames,
    /// nearest first, up to the cache budget; what of it is resident moves to the head of the
    /// cache (nearest last, so headmost).
    fn oracle_wants(&mut self, p: usize, k: u64) -> Vec<u32> {
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
                bytes += w.decoded(s);
                if j > 0 && bytes > self.holdings.cache.budget() {
                    break 'frames;
                }
                window.push(s);
            }
        }
        for &s in window.iter().rev() {
            self.holdings.cache.touch(s);
        }
        let ahead = window.into_iter().filter(|&s| !self.holdings.has(s));
        ahead_of(&self.holdings.lacking, self.parts.expand(ahead))
    }

    /// Counts what was never drawn among the segments still resident.
    fn finish(mut self) -> ClientResult {
        let mut never = 0;
        for (&s, &(b, drawn)) in &self.entries {
            if !drawn {
                never += b;
                self.ledger.unused(s, b);
            }
        }
        self.result.bytes_wasted += never;
        self.result.waste = self.ledger.waste(&self.world.chains);
        self.result.cache_peak = self.holdings.cache.peak_bytes();
        self.result.evictions = self.holdings.cache.evictions();
        self.result
    }
}

/// What the simulated client's cache holds, as the frame decision asks it: a stab list is used
/// only while its segment is in this client's cache, as the real client does.
struct Held<'a>(&'a ObjectCache<()>, &'a World);

impl Resident for Held<'_> {
    fn has(&self, id: u32) -> bool {
        self.0.contains(id)
    }

    fn stab(&self, cell: u32) -> Option<Arc<StabList>> {
        let seg = self.1.stab_segment(cell)?;
        self.0
            .contains(seg)
            .then(|| self.1.stabs.get(&cell).cloned())
            .flatten()
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use portico_client::elision::LodOption;

    #[test]
    fn a_skipped_object_counts_every_level_it_lacks() {
        let lod = |resident| LodOption::new(10, 10, 0.0, resident);
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
}
