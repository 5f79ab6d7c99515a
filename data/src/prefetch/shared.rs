//! Shared prefetch answers: one need list for every observer in the same cell looking the same
//! way, computed once and kept in a cache bounded by memory.
//!
//! Funkhouser's lookahead (§5.2.2) depends on where the observer stands and where it looks.
//! Fix only its eye cell and a direction bucket ([`direction_bucket`]), and
//! [`super::range::ObserverRange::for_cell`] makes one observer range that holds the range of
//! every observer in the cell whose view lies in the bucket, so the need list computed from it
//! is a superset of each one's (conservative, like the cells; up to the cache bound where the
//! lookahead stops). What differs per client is only what it already holds:
//! [`super::NeedList::cut`] takes that difference in one pass over the list.
//!
//! The predicted lookahead depends on more (the observer's velocity and turn), and on where in
//! the cell the eye is: its places are finer ([`super::swept`]), and their lists are made from
//! the regions every observer of the place may be in, so the same holds.
//!
//! So a server answers a crowd on one tour with a handful of computations, and a stream
//! session computes nothing while its observer stays in its cell and bucket.

use super::range::ObserverRange;
use super::swept::{Motion, VIEW_AZIMUTH, VIEW_ELEVATION};
use super::{Budget, NeedList, Prefetcher};
use crate::cells::CellGraph;
use crate::cells::realtime::Frustum;
use crate::error::Result;
use glam::Vec3;
use portico_protocol::{LookaheadCull, Observer, Policy};
use std::collections::{HashMap, HashSet};
use std::f32::consts::PI;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex};

/// Azimuth sectors of the direction buckets (15° each).
pub const AZIMUTH_BUCKETS: u32 = 24;
/// Elevation bands of the direction buckets (20° each, from straight down to straight up).
pub const ELEVATION_BUCKETS: u32 = 9;
/// Radians any direction in a bucket may be from the bucket's centre: half a sector plus half a
/// band (the great-circle angle is at most the elevation step plus the azimuth step).
pub const BUCKET_SPREAD: f32 = PI / AZIMUTH_BUCKETS as f32 + PI / (2.0 * ELEVATION_BUCKETS as f32);
/// Default memory for cached need lists (bytes): a list on flattened `mega` is about 1 MB, and
/// a crowd on a tour keeps a few hundred places warm.
pub const DEFAULT_CACHE_BYTES: usize = 256 << 20;

/// The bucket of a view direction (y up) and the bucket's centre direction (unit).
pub fn direction_bucket(dir: Vec3) -> (u16, Vec3) {
    direction_bucket_in(dir, AZIMUTH_BUCKETS, ELEVATION_BUCKETS)
}

/// The bucket of a direction (y up) among `azimuth` sectors by `elevation` bands, and the
/// bucket's centre direction (unit). Every direction is within half a sector plus half a band
/// of its centre (`PI / azimuth + PI / (2 * elevation)` radians).
pub fn direction_bucket_in(dir: Vec3, azimuth: u32, elevation: u32) -> (u16, Vec3) {
    let d = dir.try_normalize().unwrap_or(Vec3::NEG_Z);
    let az = d.z.atan2(d.x).rem_euclid(2.0 * PI);
    let el = d.y.clamp(-1.0, 1.0).asin() + PI / 2.0; // 0..π
    let a = ((az / (2.0 * PI) * azimuth as f32) as u32).min(azimuth - 1);
    let e = ((el / PI * elevation as f32) as u32).min(elevation - 1);
    let (ca, ce) = (
        (a as f32 + 0.5) * 2.0 * PI / azimuth as f32,
        (e as f32 + 0.5) * PI / elevation as f32 - PI / 2.0,
    );
    let centre = Vec3::new(ce.cos() * ca.cos(), ce.sin(), ce.cos() * ca.sin());
    ((e * azimuth + a) as u16, centre)
}

/// Where an observer stands for sharing: the eye cell, the direction bucket, and its speed,
/// turn rate and field of view (exact bits: one client sends the same ones every frame); under
/// the predicted lookahead also the eye's cube, its velocity's and turn's buckets
/// ([`super::swept::Motion`]) and a fine direction bucket. A stream session recomputes only
/// when this changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SharePlace {
    /// The live cell the eye is in.
    pub cell: u32,
    /// [`direction_bucket`] (under the predicted lookahead: [`direction_bucket_in`] with
    /// [`super::swept::VIEW_AZIMUTH`] × [`super::swept::VIEW_ELEVATION`]).
    pub bucket: u16,
    motion: [u32; 4],
    predicted: Option<Motion>,
}

/// What a shared need list depends on: the [`SharePlace`] and the policy (its bincode bytes).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ShareKey {
    /// The observer's place.
    pub place: SharePlace,
    policy: Arc<[u8]>,
}

impl ShareKey {
    /// The key of `place` under a policy already encoded with [`encode_policy`].
    pub fn new(place: SharePlace, policy: Arc<[u8]>) -> ShareKey {
        ShareKey { place, policy }
    }
}

/// A policy's bytes for [`ShareKey::new`] (encode once per session, not per observer).
pub fn encode_policy(policy: &Policy) -> Arc<[u8]> {
    portico_protocol::to_bincode(policy)
        .unwrap_or_default()
        .into()
}

/// The cache of shared need lists, least recently used dropped first past its byte bound.
pub struct SharedAnswers {
    lists: Mutex<(lru::LruCache<ShareKey, Arc<NeedList>>, usize)>,
    capacity: AtomicUsize,
    /// One gate per list being computed: whoever else needs it waits for that computation
    /// instead of repeating it (a crowd entering a room asks for its list at once).
    computing: Mutex<HashMap<ShareKey, Arc<Mutex<()>>>>,
    /// Lookups answered from the cache.
    pub hits: AtomicU64,
    /// Lookups that computed a list.
    pub misses: AtomicU64,
}

impl SharedAnswers {
    /// A cache holding at most `capacity` bytes of need lists.
    pub fn new(capacity: usize) -> SharedAnswers {
        SharedAnswers {
            lists: Mutex::new((lru::LruCache::unbounded(), 0)),
            capacity: AtomicUsize::new(capacity),
            computing: Mutex::new(HashMap::new()),
            hits: AtomicU64::new(0),
            misses: AtomicU64::new(0),
        }
    }

    /// Changes the bound (bytes); lists past it go at the next insertion.
    pub fn set_capacity(&self, bytes: usize) {
        self.capacity.store(bytes, Relaxed);
    }

    /// Lists cached and their bytes.
    pub fn usage(&self) -> (usize, usize) {
        let g = self.lists.lock().unwrap_or_else(|e| e.into_inner());
        (g.0.len(), g.1)
    }

    fn get(&self, key: &ShareKey) -> Option<Arc<NeedList>> {
        let mut g = self.lists.lock().unwrap_or_else(|e| e.into_inner());
        g.0.get(key).cloned()
    }

    fn put(&self, key: ShareKey, list: Arc<NeedList>) {
        let capacity = self.capacity.load(Relaxed);
        let bytes = entry_bytes(&key, &list);
        let mut g = self.lists.lock().unwrap_or_else(|e| e.into_inner());
        if bytes <= capacity {
            if let Some(old) = g.0.put(key.clone(), list) {
                g.1 -= entry_bytes(&key, &old);
            }
            g.1 += bytes;
        }
        while g.1 > capacity {
            let Some((k, l)) = g.0.pop_lru() else { break };
            g.1 -= entry_bytes(&k, &l);
        }
    }
}

fn entry_bytes(key: &ShareKey, list: &NeedList) -> usize {
    list.heap_bytes() + key.policy.len() + 64
}

impl Prefetcher {
    /// Where `obs` stands for sharing under `policy`; `None` without cells or with the eye
    /// outside every live cell (and, under the predicted lookahead, for a view, velocity or
    /// turn that is not a finite number or too large to bucket), where answers are computed
    /// per observer. Cheap: a k-D descent and a few `atan2`.
    pub fn share_place(&self, obs: &Observer, policy: &Policy) -> Option<SharePlace> {
        let graph = self.graph.as_ref()?;
        // Only an eye inside its cell: the widened range holds the observers in the cell, not
        // one in a wall or outside the model (that one gets its own answer).
        let cell = graph
            .locate(Vec3::from(obs.eye))
            .filter(|&c| graph.cells[c as usize].live)?;
        let dir = Vec3::from(obs.dir);
        let (bucket, predicted) = if policy.lookahead_cull == LookaheadCull::Predicted {
            // A view that does not normalize is no direction (the observer's own answer looks
            // along -z and does not turn it): not bucketed.
            dir.try_normalize()?;
            let fine = direction_bucket_in(dir, VIEW_AZIMUTH, VIEW_ELEVATION).0;
            (fine, Some(Motion::of(obs)?))
        } else {
            (direction_bucket(dir).0, None)
        };
        Some(SharePlace {
            cell,
            bucket,
            predicted,
            motion: [
                obs.max_speed.to_bits(),
                obs.max_turn.to_bits(),
                obs.half_fov_x.to_bits(),
                obs.half_fov_y.to_bits(),
            ],
        })
    }

    /// The key of the shared need list serving `obs` under `policy` (see
    /// [`Prefetcher::share_place`]).
    pub fn share_key(&self, obs: &Observer, policy: &Policy) -> Option<ShareKey> {
        Some(ShareKey::new(
            self.share_place(obs, policy)?,
            encode_policy(policy),
        ))
    }

    /// The cached need list for `key`, if any (cheap: one lock and a hash lookup).
    pub fn shared_cached(&self, key: &ShareKey) -> Option<Arc<NeedList>> {
        let hit = self.shared.get(key);
        if hit.is_some() {
            self.shared.hits.fetch_add(1, Relaxed);
        }
        hit
    }

    /// The need list every observer with `key` shares: from the cache, or computed from the
    /// widened range of the key's cell and bucket (with `obs`'s speed, turn rate and field of
    /// view) and cached. Errors: [`crate::DataError::Deadline`] past `budget`; a damaged stab
    /// list.
    pub fn shared_list(
        &self,
        key: &ShareKey,
        obs: &Observer,
        policy: &Policy,
        budget: &Budget,
    ) -> Result<Arc<NeedList>> {
        if let Some(l) = self.shared_cached(key) {
            return Ok(l);
        }
        let gate = {
            let mut c = self
                .shared
                .computing
                .lock()
                .unwrap_or_else(|e| e.into_inner());
            c.entry(key.clone()).or_default().clone()
        };
        let done = self.compute_once(&gate, key, obs, policy, budget);
        let mut c = self
            .shared
            .computing
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        drop(gate);
        // The last one through (every holder drops its clone under this lock) clears the gate.
        if c.get(key).is_some_and(|g| Arc::strong_count(g) == 1) {
            c.remove(key);
        }
        done
    }

    /// Takes the gate's turn, waiting within `budget` (so a waiter never holds a compute slot
    /// past its deadline), then computes the list unless whoever went first already did.
    fn compute_once(
        &self,
        gate: &Mutex<()>,
        key: &ShareKey,
        obs: &Observer,
        policy: &Policy,
        budget: &Budget,
    ) -> Result<Arc<NeedList>> {
        let _turn = loop {
            match gate.try_lock() {
                Ok(g) => break g,
                Err(std::sync::TryLockError::Poisoned(p)) => break p.into_inner(),
                Err(std::sync::TryLockError::WouldBlock) => {
                    budget.check()?;
                    std::thread::sleep(std::time::Duration::from_micros(200));
                }
            }
        };
        match self.shared_cached(key) {
            Some(l) => Ok(l),
            None => self.compute_shared(key, obs, policy, budget),
        }
    }

    fn compute_shared(
        &self,
        key: &ShareKey,
        obs: &Observer,
        policy: &Policy,
        budget: &Budget,
    ) -> Result<Arc<NeedList>> {
        let Some(graph) = self.graph.as_ref() else {
            return Ok(Arc::new(NeedList::default()));
        };
        self.shared.misses.fetch_add(1, Relaxed);
        let cell = key.place.cell;
        let (ranged, stabs, cands, cells) = match &key.place.predicted {
            Some(motion) => self.lookahead_swept(graph, cell, motion, obs, policy, budget)?,
            None => {
                let bounds = graph.cells[cell as usize].bounds;
                let (_, dir) = direction_bucket(Vec3::from(obs.dir));
                let range = ObserverRange::for_cell(cell, &bounds, dir, BUCKET_SPREAD, obs, policy);
                let now = self.visible_from_cell(graph, cell, &range, obs)?;
                self.lookahead_with_cells(graph, &range, &now, obs.half_fov_y, policy, budget)?
            }
        };
        budget.check()?;
        let mut list = NeedList::ordered(stabs, cands);
        list.range_cells = ranged;
        list.lookahead_cells = cells;
        self.fit_cache(&mut list, policy.cache_bytes, policy.block_textures);
        let list = Arc::new(list);
        self.shared.put(key.clone(), list.clone());
        Ok(list)
    }

    /// The shared-answer cache (its counters and usage).
    pub fn shared_answers(&self) -> &SharedAnswers {
        &self.shared
    }

    /// What swept regions may see, kept across places ([`super::sight`]; its counters).
    pub fn region_sight(&self) -> &super::sight::RegionSight {
        &self.sight
    }

    /// What any observer of the shared range may see now: the objects the cell's stab list
    /// lists, in a view cone opened by the bucket's spread and stepped back to hold the cell
    /// (a superset of each observer's eye-to-object set, §4.1.2).
    fn visible_from_cell(
        &self,
        graph: &CellGraph,
        cell: u32,
        range: &ObserverRange,
        obs: &Observer,
    ) -> Result<HashSet<u32>> {
        if !graph.cells[cell as usize].live {
            return Ok(HashSet::new());
        }
        // The one observer's view (`visible_now`) clamps its half-angles the same way.
        let (tx, ty) = (
            obs.half_fov_x.clamp(0.01, 1.55).tan(),
            obs.half_fov_y.clamp(0.01, 1.55).tan(),
        );
        let half = (tx * tx + ty * ty).sqrt().atan() + range.spread;
        let cone = (half < PI / 2.0 - 0.02).then(|| {
            let up = if range.dir.y.abs() < 0.9 {
                Vec3::Y
            } else {
                Vec3::X
            };
            Frustum::new(
                range.eye - range.dir * (range.slack / half.sin()),
                range.dir,
                up,
                half,
                half,
            )
        });
        let stab = self.stab(cell)?;
        Ok(stab
            .entries
            .iter()
            .flat_map(|e| e.objects.iter().copied())
            .filter(|&o| {
                cone.as_ref()
                    .is_none_or(|c| c.touches(&self.bounds[o as usize]))
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_direction_is_within_the_spread_of_its_bucket_centre() {
        let mut worst = 0.0f32;
        for i in 0..4000 {
            // A spiral over the sphere.
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / 4000.0;
            let r = (1.0 - y * y).sqrt();
            let phi = i as f32 * 2.399_963;
            let d = Vec3::new(r * phi.cos(), y, r * phi.sin());
            let (b, c) = direction_bucket(d);
            assert!(u32::from(b) < AZIMUTH_BUCKETS * ELEVATION_BUCKETS);
            worst = worst.max(d.angle_between(c));
        }
        assert!(worst <= BUCKET_SPREAD, "{worst} > {BUCKET_SPREAD}");
        // The bound is not loose by more than a third (the buckets are as fine as claimed).
        assert!(worst > BUCKET_SPREAD * 0.66, "{worst}");
    }

    #[test]
    fn nearby_directions_share_a_bucket_and_opposite_ones_do_not() {
        let a = direction_bucket(Vec3::new(1.0, 0.0, 0.01)).0;
        assert_eq!(a, direction_bucket(Vec3::new(1.0, 0.01, 0.02)).0);
        assert_ne!(a, direction_bucket(Vec3::new(-1.0, 0.0, 0.0)).0);
        assert_ne!(a, direction_bucket(Vec3::new(0.0, 0.0, 1.0)).0);
    }
}
