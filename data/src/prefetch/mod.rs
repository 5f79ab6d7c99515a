//! Predictive prefetch (Funkhouser §5.2): from one observer's position, speed and view, the
//! segments it will need in the next N frames, in the order it will need them.
//!
//! - [`range`]: the observer range and the range cells (§5.2.1, Dijkstra in frames-to-enter).
//! - [`lookahead`]: the lookahead objects and each one's maximum LOD (§5.2.2).
//! - [`predicted`]: the lookahead as what is seen from the eye's predicted positions.
//! - [`shared`]: one need list for every observer in a cell looking the same way, cached.
//! - [`swept`]: the predicted lookahead of every observer in the same place, for [`shared`].
//! - this module: the read set — stab lists of the range cells first, then the geometry of what
//!   the observer sees right now, then the rest, each ordered by LOD (coarsest first) and by
//!   when it can become visible, cut at the read budget but never before the coarsest LOD of
//!   everything visible from the eye cell — and the release hints (§5.2.3).
//!
//! The algorithm is pure: the server answers `/v1/prefetch` and drives `/v1/stream` with it, and
//! the load tester's oracle and baselines call it directly.

pub mod lookahead;
pub mod predicted;
pub mod range;
pub mod shared;
pub mod sight;
pub mod swept;

use crate::Database;
use crate::cells::{CellGraph, StabList};
use crate::error::Result;
use crate::format::SegmentKind;
use crate::geometry::Aabb;
use crate::texture::TexelFormat;
use portico_protocol::{
    LookaheadCull, NeedItem, NeedKind, Observer, PROTOCOL_VERSION, Policy, PrefetchResponse,
};
use range::ObserverRange;
use std::collections::HashSet;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// Most release hints in one answer: a client that holds more than the lookahead needs is told
/// about the rest in later answers, so one request with a huge held set cannot make a huge
/// answer.
pub const MAX_RELEASE_HINTS: usize = 4096;

/// How long one answer may compute: the loops check it and stop with
/// [`crate::DataError::Deadline`], so no request can hold a worker long; and whether whoever
/// asked for it is still waiting ([`Budget::cancelled_by`]: a request whose client went away,
/// a stream session that ended), so no work goes on for nobody.
#[derive(Debug, Clone)]
pub struct Budget {
    start: Instant,
    deadline: Option<Instant>,
    cancelled: Option<Arc<std::sync::atomic::AtomicBool>>,
}

impl Budget {
    /// No limit (the load tester's oracle and baselines, tests).
    pub fn unlimited() -> Budget {
        Budget {
            start: Instant::now(),
            deadline: None,
            cancelled: None,
        }
    }

    /// Stops at `deadline`.
    pub fn until(deadline: Instant) -> Budget {
        Budget {
            start: Instant::now(),
            deadline: Some(deadline),
            cancelled: None,
        }
    }

    /// Also stops as soon as `flag` is set (by whoever stopped waiting for the answer).
    pub fn cancelled_by(mut self, flag: Arc<std::sync::atomic::AtomicBool>) -> Budget {
        self.cancelled = Some(flag);
        self
    }

    /// An error once the deadline has passed or the computation was cancelled.
    pub fn check(&self) -> Result<()> {
        let cancelled = self
            .cancelled
            .as_ref()
            .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed));
        match self.deadline {
            _ if cancelled => Err(crate::DataError::Deadline(self.start.elapsed())),
            Some(d) if Instant::now() >= d => Err(crate::DataError::Deadline(self.start.elapsed())),
            _ => Ok(()),
        }
    }

    /// Whether [`Budget::check`] would fail now.
    pub fn spent(&self) -> bool {
        self.check().is_err()
    }

    /// Time spent since the budget was made.
    pub fn elapsed(&self) -> Duration {
        self.start.elapsed()
    }
}

/// A database opened for prefetch answers: the cell graph decoded once, stab lists decoded on
/// first use and kept (lock-free reads afterwards), segment sizes at hand.
pub struct Prefetcher {
    db: Arc<Database>,
    graph: Option<CellGraph>,
    stabs: Vec<OnceLock<Arc<StabList>>>,
    bounds: Vec<Aabb>,
    /// Per segment: the bytes it occupies in a client's cache ([`crate::format::Header::cache_charges`]),
    /// for a client holding textures as RGBA8 (`[0]`) and block-compressed (`[1]`).
    decoded: [Vec<u64>; 2],
    shared: shared::SharedAnswers,
    sight: sight::RegionSight,
}

impl std::fmt::Debug for Prefetcher {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Prefetcher").field("db", &self.db).finish()
    }
}

/// One geometry candidate before ordering.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    /// The object is in the observer's view right now (eye-to-object visibility).
    now: bool,
    /// The instance.
    object: u32,
    level: u32,
    frames: u32,
    seq: u32,
    item: NeedItem,
}

impl Prefetcher {
    /// Decodes the cell graph (if the database has cells).
    pub fn new(db: Arc<Database>) -> Result<Prefetcher> {
        let graph = db.cell_graph()?;
        let n = graph.as_ref().map_or(0, |g| g.cells.len());
        let bounds = db.header().instances.iter().map(|i| i.bounds).collect();
        let wire: Vec<u64> = db.segments().iter().map(|e| e.length).collect();
        let decoded = [TexelFormat::Rgba8, TexelFormat::Block]
            .map(|texels| db.header().cache_charges(&wire, texels));
        Ok(Prefetcher {
            db,
            graph,
            stabs: (0..n).map(|_| OnceLock::new()).collect(),
            bounds,
            decoded,
            shared: shared::SharedAnswers::new(shared::DEFAULT_CACHE_BYTES),
            sight: sight::RegionSight::default(),
        })
    }

    /// The database.
    pub fn database(&self) -> &Arc<Database> {
        &self.db
    }

    /// The cell graph, if any.
    pub fn graph(&self) -> Option<&CellGraph> {
        self.graph.as_ref()
    }

    /// A cell's stab list, decoded once.
    pub fn stab(&self, cell: u32) -> Result<Arc<StabList>> {
        let Some(slot) = self.stabs.get(cell as usize) else {
            return Ok(Arc::new(StabList::default()));
        };
        if let Some(s) = slot.get() {
            return Ok(s.clone());
        }
        let decoded = Arc::new(self.db.stab_list(cell)?);
        Ok(slot.get_or_init(|| decoded).clone())
    }

    /// The segment holding a cell's stab list.
    pub fn stab_segment(&self, cell: u32) -> Option<u32> {
        self.db.header().cells.as_ref()?.stab_segment(cell)
    }

    /// What segment `id` costs the client's cache ([`crate::format::Header::cache_charges`]).
    fn cache_charge(&self, id: u32, block_textures: bool) -> u64 {
        self.decoded[usize::from(block_textures)]
            .get(id as usize)
            .copied()
            .unwrap_or(0)
    }

    fn segment_bytes(&self, id: u32) -> u64 {
        self.db.segments().get(id as usize).map_or(0, |e| e.length)
    }

    /// Answers one prefetch request: `held` is the set of segments the client already has.
    pub fn answer(
        &self,
        obs: &Observer,
        policy: &Policy,
        held: &HashSet<u32>,
    ) -> Result<PrefetchResponse> {
        self.answer_within(obs, policy, held, &Budget::unlimited())
    }

    /// [`Prefetcher::answer`], stopped with [`crate::DataError::Deadline`] if it runs past
    /// `budget` (checked per range cell, per stab-list entry and every 1,024 objects).
    pub fn answer_within(
        &self,
        obs: &Observer,
        policy: &Policy,
        held: &HashSet<u32>,
        budget: &Budget,
    ) -> Result<PrefetchResponse> {
        let t0 = std::time::Instant::now();
        let mut resp = self
            .need_list_within(obs, policy, budget)?
            .cut(held, policy.read_bytes);
        resp.micros = t0.elapsed().as_micros().min(u32::MAX as u128) as u32;
        Ok(resp)
    }

    /// The need list of one observer (before the cut by what the client holds), stopped with
    /// [`crate::DataError::Deadline`] past `budget`.
    pub fn need_list_within(
        &self,
        obs: &Observer,
        policy: &Policy,
        budget: &Budget,
    ) -> Result<NeedList> {
        let range = ObserverRange::new(obs, policy);
        let (ranged, stab_items, cands, lookahead_cells) = match &self.graph {
            Some(g) => {
                let now = self.visible_now(g, obs)?;
                let predicted = match policy.lookahead_cull {
                    LookaheadCull::Predicted => {
                        self.lookahead_predicted(g, &range, &now, obs, policy, budget)?
                    }
                    _ => None,
                };
                match predicted {
                    Some(p) => p,
                    None => {
                        self.lookahead_with_cells(g, &range, &now, obs.half_fov_y, policy, budget)?
                    }
                }
            }
            None => (
                1,
                Vec::new(),
                self.lookahead_without_cells(&range, obs, policy, budget)?,
                1,
            ),
        };
        budget.check()?;
        let mut list = NeedList::ordered(stab_items, cands);
        list.range_cells = ranged;
        list.lookahead_cells = lookahead_cells;
        self.fit_cache(&mut list, policy.cache_bytes, policy.block_textures);
        Ok(list)
    }

    /// Sets [`NeedList::fit`] for a cache of `cache_bytes`. When the first geometry item falls
    /// past it, that item becomes mandatory: a cache too small for anything still gets the
    /// first object it would draw (and nothing else past the fit).
    fn fit_cache(&self, list: &mut NeedList, cache_bytes: u64, block_textures: bool) {
        let decoded = &self.decoded[usize::from(block_textures)];
        let mut used = 0u64;
        list.fit = list
            .items
            .iter()
            .position(|i| {
                used += decoded.get(i.segment as usize).copied().unwrap_or(i.bytes);
                used > cache_bytes
            })
            .unwrap_or(list.items.len());
        let first_geometry = list.items.iter().position(|i| i.kind == NeedKind::Geometry);
        if let Some(i) = first_geometry.filter(|&i| i >= list.fit) {
            list.must[i] = true;
        }
    }

    /// Appends the textured boxes of the clusters above the lookahead objects (the objects in
    /// view first, then by frames until visible): a cluster's impostor comes before any
    /// object's geometry, so the coarse view of a whole wing arrives before its furniture
    /// (Maciel & Shirley 1995). Clusters around the eye are left out: no box can stand in for
    /// them. `eyes` is where the eye may be (a point, or a shared range's cell): a cluster is
    /// left out only when it holds all of it.
    fn with_textures(
        &self,
        mut items: Vec<NeedItem>,
        cands: &[Candidate],
        eyes: &Aabb,
    ) -> Vec<NeedItem> {
        let Some(h) = &self.db.header().hierarchy else {
            return items;
        };
        let mut order: Vec<&Candidate> = cands.iter().filter(|c| c.level == 0).collect();
        order.sort_by_key(|c| (!c.now, c.frames, c.seq));
        let mut seen = HashSet::new();
        for c in order {
            let mut node = h
                .instance_parent
                .get(c.object as usize)
                .copied()
                .unwrap_or(u32::MAX);
            while let Some(n) = h.nodes.get(node as usize) {
                if !seen.insert(node) {
                    break;
                }
                let around_eye = n.bounds.contains_box(eyes);
                if n.texture != u32::MAX && !around_eye {
                    let bytes = self.segment_bytes(n.texture);
                    items.push(need(n.texture, NeedKind::Texture, 0, bytes, c.frames));
                }
                node = n.parent;
            }
        }
        items
    }

    /// Whether a segment id names a geometry segment (the client checks pushed ids with it).
    pub fn is_geometry(&self, id: u32) -> bool {
        self.db
            .segments()
            .get(id as usize)
            .is_some_and(|e| SegmentKind::from_u16(e.kind) == Some(SegmentKind::Geometry))
    }
}

fn need(segment: u32, kind: NeedKind, lod: u8, bytes: u64, frames: u32) -> NeedItem {
    NeedItem {
        segment,
        kind,
        lod,
        bytes,
        frames,
    }
}

/// The lookahead set in need order, each segment once (§5.2.3's order): stab lists first, then
/// the geometry of the objects in the observer's view right now, then the rest; each group by
/// LOD (coarsest first) and frames-until-visible. It does not depend on what the client holds,
/// so one list serves every client that shares its observer range ([`shared`]).
///
/// Funkhouser orders the whole read set by LOD, then frames: with a cold cache that reads the
/// coarsest LOD of every object seen from anywhere in the range cells (hundreds) before the
/// next LOD of the one in front of the observer. Reading the view's objects first keeps his
/// guarantee and serves the current frame first (measured in docs/performance.md: fewer LODs skipped
/// while the cache warms up, the same once it is warm).
#[derive(Debug, Clone, Default)]
pub struct NeedList {
    /// Every segment of the lookahead set, in need order.
    pub items: Vec<NeedItem>,
    /// Per item: read whatever the budget (a stab list, or the coarsest LOD of an object
    /// visible from the eye cell: Funkhouser's read set is not complete until everything
    /// visible now is resident or being read; or the first geometry item when even that falls
    /// past [`NeedList::fit`]).
    pub must: Vec<bool>,
    /// The items' segments, for membership tests.
    pub segments: HashSet<u32>,
    /// Range cells found.
    pub range_cells: u32,
    /// Cells whose objects entered the lookahead.
    pub lookahead_cells: u32,
    /// Objects in the lookahead set.
    pub lookahead_objects: u32,
    /// Wire bytes of the whole lookahead set.
    pub lookahead_bytes: u64,
    /// The items before this fit the client's cache together (decoded sizes, from the top of
    /// the list); a session pushes no further but for mandatory items, so what it pushes is
    /// never more than the client can keep (pushing past it would only be evicted and asked
    /// for again).
    pub fit: usize,
}

impl NeedList {
    /// Orders stab items and candidates (see the type's documentation).
    fn ordered(stabs: Vec<NeedItem>, mut cands: Vec<Candidate>) -> NeedList {
        cands.sort_unstable_by_key(|c| (!c.now, c.level, c.frames, c.seq));
        let mut list = NeedList::default();
        // Stab lists are as mandatory as the coarsest LODs; impostor atlases come before the
        // geometry but within the budget.
        let ordered = stabs
            .into_iter()
            .map(|s| (s.kind == NeedKind::Stab, s))
            .chain(cands.iter().map(|c| (c.level == 0, c.item)));
        for (coarsest, item) in ordered {
            if item.kind == NeedKind::Geometry && coarsest {
                list.lookahead_objects += 1;
            }
            if !list.segments.insert(item.segment) {
                continue; // a definition's LOD shared by several instances
            }
            list.lookahead_bytes += item.bytes;
            list.must.push(coarsest && item.frames == 0);
            list.items.push(item);
        }
        list
    }

    /// Approximate heap bytes (the shared cache's accounting).
    pub fn heap_bytes(&self) -> usize {
        self.items.len() * (std::mem::size_of::<NeedItem>() + 1 + 16)
    }

    /// The read set for a client holding `held`, cut at `budget` bytes (§5.2.3): everything
    /// mandatory, then items in order while they fit the read budget and, with what comes
    /// before them, the client's cache ([`NeedList::fit`]: reading past it would only evict
    /// what the next frames draw, to be read again); and release hints for what it holds
    /// outside the lookahead.
    pub fn cut(&self, held: &HashSet<u32>, budget: u64) -> PrefetchResponse {
        let mut items = Vec::new();
        let mut used = 0u64;
        let mut truncated = false;
        for (i, (item, &must)) in self.items.iter().zip(&self.must).enumerate() {
            if held.contains(&item.segment) || (i >= self.fit && !must) {
                continue;
            }
            if must || (!truncated && used + item.bytes <= budget) {
                used += item.bytes;
                items.push(*item);
            } else {
                truncated = true;
            }
        }
        let mut evict: Vec<u32> = held
            .iter()
            .copied()
            .filter(|s| !self.segments.contains(s))
            .collect();
        evict.sort_unstable();
        evict.truncate(MAX_RELEASE_HINTS);
        PrefetchResponse {
            version: PROTOCOL_VERSION,
            items,
            evict,
            range_cells: self.range_cells,
            lookahead_cells: self.lookahead_cells,
            lookahead_objects: self.lookahead_objects,
            lookahead_bytes: self.lookahead_bytes,
            truncated,
            micros: 0,
        }
    }
}
