//! Predictive prefetch (Funkhouser §5.2): from one observer's position, speed and view, the
//! segments it will need in the next N frames, in the order it will need them.
//!
//! - [`range`]: the observer range and the range cells (§5.2.1, Dijkstra in frames-to-enter).
//! - [`lookahead`]: the lookahead objects and each one's maximum LOD (§5.2.2).
//! - this module: the read set — stab lists of the range cells first, then the geometry of what
//!   the observer sees right now, then the rest, each ordered by LOD (coarsest first) and by
//!   when it can become visible, cut at the read budget but never before the coarsest LOD of
//!   everything visible from the eye cell — and the release hints (§5.2.3).
//!
//! The algorithm is pure: the server answers `/v1/prefetch` and drives `/v1/stream` with it, and
//! the load tester's oracle and baselines call it directly.

pub mod lookahead;
pub mod range;

use crate::Database;
use crate::cells::realtime::{Frustum, eye_to_cell, eye_to_object};
use crate::cells::{CellGraph, StabList};
use crate::error::Result;
use crate::format::SegmentKind;
use crate::geometry::Aabb;
use portico_protocol::{
    Granularity, NeedItem, NeedKind, Observer, PROTOCOL_VERSION, Policy, PrefetchResponse,
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
/// [`crate::DataError::Deadline`], so no request can hold a worker long.
#[derive(Debug, Clone, Copy)]
pub struct Budget {
    start: Instant,
    deadline: Option<Instant>,
}

impl Budget {
    /// No limit (the load tester's oracle and baselines, tests).
    pub fn unlimited() -> Budget {
        Budget {
            start: Instant::now(),
            deadline: None,
        }
    }

    /// Stops at `deadline`.
    pub fn until(deadline: Instant) -> Budget {
        Budget {
            start: Instant::now(),
            deadline: Some(deadline),
        }
    }

    /// An error once the deadline has passed.
    pub fn check(&self) -> Result<()> {
        match self.deadline {
            Some(d) if Instant::now() >= d => Err(crate::DataError::Deadline(self.start.elapsed())),
            _ => Ok(()),
        }
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
        Ok(Prefetcher {
            db,
            graph,
            stabs: (0..n).map(|_| OnceLock::new()).collect(),
            bounds,
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
        let c = self.db.header().cells.as_ref()?;
        c.stab_segments
            .get(cell as usize)
            .copied()
            .filter(|&s| s != u32::MAX)
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
        let range = ObserverRange::new(obs, policy);
        let (ranged, stab_items, cands, lookahead_cells) = match &self.graph {
            Some(g) => self.lookahead_with_cells(g, &range, obs, policy, budget)?,
            None => (
                1,
                Vec::new(),
                self.lookahead_without_cells(&range, obs, policy, budget)?,
                1,
            ),
        };
        budget.check()?;
        let mut resp = read_set(stab_items, cands, held, policy.read_bytes);
        resp.range_cells = ranged;
        resp.lookahead_cells = lookahead_cells;
        resp.micros = t0.elapsed().as_micros().min(u32::MAX as u128) as u32;
        Ok(resp)
    }

    /// Range cells → visible cells → objects → LOD candidates.
    #[allow(clippy::type_complexity)]
    fn lookahead_with_cells(
        &self,
        graph: &CellGraph,
        range: &ObserverRange,
        obs: &Observer,
        policy: &Policy,
        budget: &Budget,
    ) -> Result<(u32, Vec<NeedItem>, Vec<Candidate>, u32)> {
        let ranged = range::range_cells(graph, range, policy.range_cull);
        budget.check()?;
        let now = self.visible_now(graph, obs)?;
        let mut stab_items = Vec::new();
        let mut seen_obj = vec![false; self.db.header().instances.len()];
        let mut seen_cell = vec![false; graph.cells.len()];
        let mut cands = Vec::new();
        let mut claimed = 0u64;
        let mut lookahead_cells = 0u32;
        'outer: for &(cell, frames) in &ranged {
            if let Some(seg) = self.stab_segment(cell) {
                stab_items.push(need(
                    seg,
                    NeedKind::Stab,
                    0,
                    self.segment_bytes(seg),
                    frames,
                ));
            }
            let stab = self.stab(cell)?;
            for entry in &stab.entries {
                budget.check()?;
                if !range.lookahead_keeps(policy.lookahead_cull, &entry.region) {
                    continue;
                }
                if !std::mem::replace(&mut seen_cell[entry.cell as usize], true) {
                    lookahead_cells += 1;
                }
                let objects = match policy.granularity {
                    Granularity::Object => entry.objects.clone(),
                    Granularity::Cell => {
                        let s = self.stab(entry.cell)?;
                        s.inside.iter().chain(&s.partial).copied().collect()
                    }
                };
                for o in objects {
                    if std::mem::replace(&mut seen_obj[o as usize], true) {
                        continue;
                    }
                    let first = cands.len();
                    claimed += self.add_object(o, frames, range, obs, policy, &mut cands);
                    if now.contains(&o) {
                        cands[first..].iter_mut().for_each(|c| c.now = true);
                    }
                }
                // §5.2.2 condition 2: memory is claimed, and everything visible now is in.
                if frames > 0 && claimed > policy.cache_bytes {
                    break 'outer;
                }
            }
        }
        let stab_items = if policy.impostors {
            self.with_textures(stab_items, &cands, glam::Vec3::from(obs.eye))
        } else {
            stab_items
        };
        Ok((ranged.len() as u32, stab_items, cands, lookahead_cells))
    }

    /// Appends the textured boxes of the clusters above the lookahead objects (the objects in
    /// view first, then by frames until visible): a cluster's impostor comes before any
    /// object's geometry, so the coarse view of a whole wing arrives before its furniture
    /// (DESIGN §6). Clusters around the eye are left out: no box can stand in for them.
    fn with_textures(
        &self,
        mut items: Vec<NeedItem>,
        cands: &[Candidate],
        eye: glam::Vec3,
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
                let around_eye =
                    (0..3).all(|k| n.bounds.min[k] <= eye[k] && eye[k] <= n.bounds.max[k]);
                if n.texture != u32::MAX && !around_eye {
                    let bytes = self.segment_bytes(n.texture);
                    items.push(need(n.texture, NeedKind::Texture, 0, bytes, c.frames));
                }
                node = n.parent;
            }
        }
        items
    }

    /// The objects in the observer's view right now: eye-to-object visibility from the eye
    /// cell's stab list through the portals (§4.1.2), as the client culls. Empty outside every
    /// live cell.
    fn visible_now(&self, graph: &CellGraph, obs: &Observer) -> Result<HashSet<u32>> {
        let eye = glam::Vec3::from(obs.eye);
        let Some(cell) = graph.locate(eye).filter(|&c| graph.cells[c as usize].live) else {
            return Ok(HashSet::new());
        };
        let dir = glam::Vec3::from(obs.dir)
            .try_normalize()
            .unwrap_or(glam::Vec3::NEG_Z);
        let mut up = glam::Vec3::from(obs.up)
            .try_normalize()
            .unwrap_or(glam::Vec3::Y);
        if up.cross(dir).length_squared() < 1e-6 {
            up = if dir.y.abs() < 0.9 {
                glam::Vec3::Y
            } else {
                glam::Vec3::X
            };
        }
        let (hx, hy) = (
            obs.half_fov_x.clamp(0.01, 1.55),
            obs.half_fov_y.clamp(0.01, 1.55),
        );
        let view = Frustum::new(eye, dir, up, hx, hy);
        let reached = eye_to_cell(graph, &view);
        let stab = self.stab(cell)?;
        Ok(eye_to_object(&reached, &stab, &self.bounds)
            .into_iter()
            .collect())
    }

    /// Without cells every object is a lookahead object, needed when the observer can reach it.
    fn lookahead_without_cells(
        &self,
        range: &ObserverRange,
        obs: &Observer,
        policy: &Policy,
        budget: &Budget,
    ) -> Result<Vec<Candidate>> {
        let mut cands = Vec::new();
        let mut claimed = 0u64;
        let mut order: Vec<(u32, u32)> = self
            .db
            .header()
            .instances
            .iter()
            .enumerate()
            .map(|(i, inst)| (range.frames_to(&inst.bounds), i as u32))
            .collect();
        order.sort_unstable();
        for (i, (frames, o)) in order.into_iter().enumerate() {
            if i % 1024 == 0 {
                budget.check()?;
            }
            if frames > 0 && claimed > policy.cache_bytes {
                break;
            }
            claimed += self.add_object(o, frames.min(range.depth), range, obs, policy, &mut cands);
        }
        Ok(cands)
    }

    /// Adds the LODs of one object from the coarsest up to its maximum; returns their bytes.
    fn add_object(
        &self,
        o: u32,
        frames: u32,
        range: &ObserverRange,
        obs: &Observer,
        policy: &Policy,
        cands: &mut Vec<Candidate>,
    ) -> u64 {
        let header = self.db.header();
        let Some(inst) = header.instances.get(o as usize) else {
            return 0;
        };
        let lods = header.lods_of(inst);
        let max = lookahead::max_lod_in_range(lods, &inst.bounds, range, policy, obs.half_fov_y);
        let mut bytes = 0;
        for (i, l) in lods.iter().enumerate().skip(max) {
            let b = self.segment_bytes(l.segment);
            bytes += b;
            cands.push(Candidate {
                now: false,
                object: o,
                level: (lods.len() - 1 - i) as u32,
                frames,
                seq: cands.len() as u32,
                item: need(l.segment, NeedKind::Geometry, i as u8, b, frames),
            });
        }
        bytes
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

/// Orders the lookahead set into the read set and cuts it at `budget` bytes (§5.2.3): stab lists
/// first, then the geometry of the objects in the observer's view right now, then the rest;
/// each group by LOD (coarsest first) and frames-until-visible. The coarsest LOD of everything
/// visible from the eye cell (and its stab list) is always included, budget or not:
/// Funkhouser's read set is not complete until everything visible now is resident or being read.
///
/// Funkhouser orders the whole read set by LOD, then frames: with a cold cache that reads the
/// coarsest LOD of every object seen from anywhere in the range cells (hundreds) before the
/// next LOD of the one in front of the observer. Reading the view's objects first keeps his
/// guarantee and serves the current frame first (measured in the README: fewer LODs skipped
/// while the cache warms up, the same once it is warm).
fn read_set(
    stabs: Vec<NeedItem>,
    mut cands: Vec<Candidate>,
    held: &HashSet<u32>,
    budget: u64,
) -> PrefetchResponse {
    cands.sort_unstable_by_key(|c| (!c.now, c.level, c.frames, c.seq));
    let mut lookahead_segments = HashSet::new();
    let mut lookahead_bytes = 0u64;
    let mut objects = 0u32;
    let mut items = Vec::new();
    let mut used = 0u64;
    let mut truncated = false;
    // Stab lists are as mandatory as the coarsest LODs; impostor atlases come before the
    // geometry but within the budget.
    let ordered = stabs
        .into_iter()
        .map(|s| (s.kind == NeedKind::Stab, s))
        .chain(cands.iter().map(|c| (c.level == 0, c.item)));
    for (coarsest, item) in ordered {
        if item.kind == NeedKind::Geometry && coarsest {
            objects += 1;
        }
        if !lookahead_segments.insert(item.segment) {
            continue; // a definition's LOD shared by several instances
        }
        lookahead_bytes += item.bytes;
        if held.contains(&item.segment) {
            continue;
        }
        let must = coarsest && item.frames == 0;
        if must || (!truncated && used + item.bytes <= budget) {
            used += item.bytes;
            items.push(item);
        } else {
            truncated = true;
        }
    }
    let mut evict: Vec<u32> = held
        .iter()
        .copied()
        .filter(|s| !lookahead_segments.contains(s))
        .collect();
    evict.sort_unstable();
    evict.truncate(MAX_RELEASE_HINTS);
    PrefetchResponse {
        version: PROTOCOL_VERSION,
        items,
        evict,
        range_cells: 0,
        lookahead_cells: 0,
        lookahead_objects: objects,
        lookahead_bytes,
        truncated,
        micros: 0,
    }
}
