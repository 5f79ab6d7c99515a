//! Shared need lists (one per eye cell and direction bucket): each is a superset of the answer
//! of every observer it serves, it is computed once and then served from the cache, and the
//! per-client cut leaves out what the client holds.

use glam::Vec3;
use portico_data::build::BuildOptions;
use portico_data::prefetch::shared::direction_bucket;
use portico_data::prefetch::{Budget, Prefetcher};
use portico_protocol::{LookaheadCull, Observer, Policy, RangeCull};
use std::collections::HashSet;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::{Arc, OnceLock};

mod common;

fn prefetcher() -> &'static Prefetcher {
    static P: OnceLock<Prefetcher> = OnceLock::new();
    P.get_or_init(|| common::tiny_prefetcher(&BuildOptions::default(), None))
}

/// The tiny building with textured cluster boxes (impostors).
fn with_impostors() -> &'static Prefetcher {
    static P: OnceLock<Prefetcher> = OnceLock::new();
    P.get_or_init(|| {
        common::tiny_prefetcher(&BuildOptions::default(), Some(&mut common::FakePainter))
    })
}

/// A walker's observer (1.5 m/s, a 69° by 52° view) at `eye` looking along `dir`.
fn observer(eye: Vec3, dir: Vec3, max_turn: f32) -> Observer {
    Observer {
        eye: eye.into(),
        dir: dir.into(),
        up: [0.0, 1.0, 0.0],
        velocity: [0.0; 3],
        half_fov_x: 0.6,
        half_fov_y: 0.45,
        max_speed: 1.5,
        max_turn,
        turn: [0.0; 3],
    }
}

/// Observers at several points of every live cell (corners included), looking in eight
/// directions, some tilted, turning at 0, 0.3 or 1 rad/s (the slower ones keep a range frustum:
/// at 1 rad/s over 16 frames it opens past a half-space).
fn observers(p: &Prefetcher) -> Vec<Observer> {
    let g = p.graph().unwrap();
    let mut out = Vec::new();
    for (i, c) in g.cells.iter().enumerate().filter(|(_, c)| c.live) {
        let (lo, hi) = (Vec3::from(c.bounds.min), Vec3::from(c.bounds.max));
        for (k, t) in [0.5f32, 0.02, 0.98, 0.3].into_iter().enumerate() {
            let at = Vec3::new(t, 0.5, 1.0 - t);
            let eye = lo + (hi - lo) * at;
            let a = (i * 4 + k) as f32 * 0.785;
            let dir = Vec3::new(a.cos(), (k as f32 - 1.5) * 0.2, a.sin()).normalize();
            out.push(observer(eye, dir, [0.0, 0.3, 1.0][(i + k) % 3]));
        }
    }
    out
}

fn policies() -> Vec<Policy> {
    let base = Policy {
        cache_bytes: u64::MAX / 4,
        read_bytes: u64::MAX / 4,
        ..Policy::default()
    };
    let mut out = Vec::new();
    for range_cull in [RangeCull::Direction, RangeCull::Frustum, RangeCull::Any] {
        for lookahead_cull in [LookaheadCull::Any, LookaheadCull::Frustum] {
            out.push(Policy {
                range_cull,
                lookahead_cull,
                ..base
            });
        }
    }
    out
}

/// Checks every observer of [`observers`] under `policy`: the shared list holds its whole
/// exact answer (the cache bound is off) and, with no read budget, its mandatory part as
/// mandatory. Returns (observers checked, exact bytes, shared bytes).
fn check_superset(p: &Prefetcher, policy: Policy) -> (usize, u64, u64) {
    let (mut checked, mut exact_bytes, mut shared_bytes) = (0, 0u64, 0u64);
    let header = p.database().header();
    for obs in observers(p) {
        let Some(key) = p.share_key(&obs, &policy) else {
            continue; // on a cell's face, outside every live cell: answered exactly
        };
        let shared = p
            .shared_list(&key, &obs, &policy, &Budget::unlimited())
            .unwrap();
        let exact = p.answer(&obs, &policy, &HashSet::new()).unwrap();
        assert!(!exact.items.is_empty());
        for item in &exact.items {
            assert!(
                shared.segments.contains(&item.segment),
                "{policy:?} at {:?} looking {:?}: segment {} ({:?}) of the exact answer is not \
                 in the shared list",
                obs.eye,
                obs.dir,
                item.segment,
                item.kind
            );
        }
        // What the observer must read now, the shared list reads now too (the eye cell's
        // coarsest LODs and stab list are mandatory in both).
        let must: HashSet<u32> = shared
            .items
            .iter()
            .zip(&shared.must)
            .filter(|(_, m)| **m)
            .map(|(i, _)| i.segment)
            .collect();
        let no_budget = Policy {
            read_bytes: 0,
            ..policy
        };
        let exact_must = p.answer(&obs, &no_budget, &HashSet::new()).unwrap();
        let cell = key.place.cell;
        let stab = p.stab(cell).unwrap();
        let here: HashSet<u32> = stab
            .entries
            .iter()
            .flat_map(|e| e.objects.clone())
            .collect();
        for item in &exact_must.items {
            let ours = here.iter().any(|&o| {
                let lods = header.lods_of(&header.instances[o as usize]);
                lods.last().unwrap().segment == item.segment
            });
            if ours || p.stab_segment(cell) == Some(item.segment) {
                assert!(
                    must.contains(&item.segment),
                    "{} not mandatory",
                    item.segment
                );
            }
        }
        checked += 1;
        exact_bytes += exact.lookahead_bytes;
        shared_bytes += shared.lookahead_bytes;
    }
    (checked, exact_bytes, shared_bytes)
}

#[test]
fn a_shared_list_holds_every_served_observers_whole_lookahead_and_its_mandatory_part() {
    let p = prefetcher();
    let (mut checked, mut exact_bytes, mut shared_bytes) = (0, 0u64, 0u64);
    for policy in policies() {
        let (n, e, s) = check_superset(p, policy);
        checked += n;
        exact_bytes += e;
        shared_bytes += s;
    }
    assert!(checked > 500, "{checked}");
    // Conservative, not everything: the widened lists stay within a small factor of the exact.
    let ratio = shared_bytes as f64 / exact_bytes as f64;
    eprintln!("shared / exact lookahead bytes: {ratio:.2} over {checked} observers");
    assert!((1.0..2.0).contains(&ratio), "{ratio}");
}

#[test]
fn with_impostors_the_shared_list_holds_every_cluster_box_an_observer_needs() {
    let p = with_impostors();
    for policy in policies().into_iter().step_by(2) {
        let impostors = Policy {
            impostors: true,
            ..policy
        };
        let (n, _, _) = check_superset(p, impostors);
        assert!(n > 100, "{n}");
    }
}

#[test]
fn an_eye_outside_every_live_cell_is_not_shared() {
    let p = prefetcher();
    let g = p.graph().unwrap();
    let far = Vec3::from(g.bounds.max) + Vec3::splat(50.0);
    let obs = Observer {
        eye: far.into(),
        ..observers(p)[0]
    };
    assert!(p.share_place(&obs, &Policy::default()).is_none());
    assert!(p.share_key(&obs, &Policy::default()).is_none());
    // It is still answered, from the nearest cell, one observer at a time.
    assert!(
        !p.answer(&obs, &Policy::default(), &HashSet::new())
            .unwrap()
            .items
            .is_empty()
    );
}

#[test]
fn one_computation_serves_everyone_in_the_cell_and_bucket() {
    let p = prefetcher();
    // The range lookahead: its places are whole cells (the predicted one's are finer:
    // `shared_predicted.rs`).
    let policy = Policy {
        lookahead_cull: LookaheadCull::Frustum,
        ..Policy::default()
    };
    let g = p.graph().unwrap();
    let (i, c) = g
        .cells
        .iter()
        .enumerate()
        .find(|(_, c)| c.live && c.bounds.max[0] - c.bounds.min[0] > 1.0)
        .unwrap();
    let (lo, hi) = (Vec3::from(c.bounds.min), Vec3::from(c.bounds.max));
    let at = |t: f32, dir: Vec3| observer(lo + (hi - lo) * Vec3::new(t, 0.5, t), dir, 1.0);
    let a = at(0.3, Vec3::new(1.0, 0.0, 0.05));
    let b = at(0.7, Vec3::new(1.0, 0.02, 0.08));
    let ka = p.share_key(&a, &policy).unwrap();
    let kb = p.share_key(&b, &policy).unwrap();
    assert_eq!(ka, kb);
    assert_eq!(ka.place.cell as usize, i);
    let hits = p.shared_answers().hits.load(Relaxed);
    let la = p
        .shared_list(&ka, &a, &policy, &Budget::unlimited())
        .unwrap();
    let lb = p
        .shared_list(&kb, &b, &policy, &Budget::unlimited())
        .unwrap();
    assert!(
        Arc::ptr_eq(&la, &lb),
        "the second observer computed its own list"
    );
    assert!(p.shared_answers().hits.load(Relaxed) > hits);
    assert!(p.shared_cached(&ka).is_some());
    // Turning past the bucket, or another policy, is another list.
    let turned = at(0.3, Vec3::new(-1.0, 0.0, 0.0));
    assert_ne!(p.share_key(&turned, &policy).unwrap(), ka);
    assert_ne!(direction_bucket(Vec3::X).0, direction_bucket(Vec3::NEG_X).0);
    let deeper = Policy {
        depth_frames: 32,
        ..policy
    };
    assert_ne!(p.share_key(&a, &deeper).unwrap(), ka);
}

#[test]
fn the_per_client_cut_leaves_out_what_it_holds_and_keeps_the_mandatory_part() {
    let p = prefetcher();
    let policy = Policy::default();
    let obs = observers(p)[0];
    let key = p.share_key(&obs, &policy).unwrap();
    let list = p
        .shared_list(&key, &obs, &policy, &Budget::unlimited())
        .unwrap();
    let all = list.cut(&HashSet::new(), u64::MAX);
    assert_eq!(all.items.len(), list.items.len());
    let held: HashSet<u32> = list.items.iter().step_by(2).map(|i| i.segment).collect();
    let rest = list.cut(&held, u64::MAX);
    assert_eq!(rest.items.len(), list.items.len() - held.len());
    assert!(rest.items.iter().all(|i| !held.contains(&i.segment)));
    let none = list.cut(&HashSet::new(), 0);
    let must = list.must.iter().filter(|m| **m).count();
    assert!(must > 0);
    assert_eq!(none.items.len(), must);
    // Held segments outside the list are release hints.
    let stray: HashSet<u32> = [u32::MAX - 1].into();
    assert_eq!(list.cut(&stray, 0).evict, vec![u32::MAX - 1]);
    // Nothing past what fits the client's cache is listed (it would evict what the next frames
    // draw, to be read again), whatever the read budget: only the mandatory part.
    assert_eq!(
        list.fit,
        list.items.len(),
        "the default cache holds this list"
    );
    let mut small = (*list).clone();
    small.fit = list.items.len() / 2;
    let cut = small.cut(&HashSet::new(), u64::MAX);
    let expected: Vec<u32> = (list.items.iter().zip(&list.must).enumerate())
        .filter(|(i, (_, m))| *i < small.fit || **m)
        .map(|(_, (item, _))| item.segment)
        .collect();
    assert!(expected.len() < list.items.len());
    assert_eq!(
        cut.items.iter().map(|i| i.segment).collect::<Vec<_>>(),
        expected
    );
}

#[test]
fn a_crowd_asking_for_one_place_at_once_computes_its_list_once() {
    // A prefetcher of its own: the counters are not shared with the other tests.
    let p = Prefetcher::new(prefetcher().database().clone()).unwrap();
    let policy = Policy::default();
    let obs = observers(&p)[5];
    let key = p.share_key(&obs, &policy).unwrap();
    let start = std::sync::Barrier::new(8);
    let lists: Vec<_> = std::thread::scope(|s| {
        let tasks: Vec<_> = (0..8)
            .map(|_| {
                s.spawn(|| {
                    start.wait();
                    p.shared_list(&key, &obs, &policy, &Budget::unlimited())
                        .unwrap()
                })
            })
            .collect();
        tasks.into_iter().map(|t| t.join().unwrap()).collect()
    });
    assert_eq!(p.shared_answers().misses.load(Relaxed), 1);
    assert!(lists.iter().all(|l| Arc::ptr_eq(l, &lists[0])));
    assert_eq!(p.shared_answers().usage().0, 1);
    // A bound below one list keeps nothing, and the next ask computes again.
    p.shared_answers().set_capacity(0);
    let other = Policy {
        depth_frames: 8,
        ..policy
    };
    let k2 = p.share_key(&obs, &other).unwrap();
    p.shared_list(&k2, &obs, &other, &Budget::unlimited())
        .unwrap();
    p.shared_list(&k2, &obs, &other, &Budget::unlimited())
        .unwrap();
    assert_eq!(p.shared_answers().misses.load(Relaxed), 3);
}
