//! Shared need lists under the predicted lookahead (the default policy): a place is the eye's
//! metre of its cell and buckets of its view, velocity and turn (`prefetch::swept`); each
//! place's list is a superset of the exact answer of every observer it serves, a crowd in one
//! place computes it once, and an observer that moves computes again only when it changes
//! place.

use glam::Vec3;
use portico_data::build::BuildOptions;
use portico_data::prefetch::swept::VOXEL_M;
use portico_data::prefetch::{Budget, Prefetcher};
use portico_protocol::{NeedKind, Observer, Policy, RangeCull};
use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::sync::OnceLock;
use std::sync::atomic::Ordering::Relaxed;

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

/// The tiny building with textured materials.
fn textured() -> &'static Prefetcher {
    static P: OnceLock<Prefetcher> = OnceLock::new();
    P.get_or_init(|| common::prefetcher_for(3, 1, true, &BuildOptions::default(), None))
}

/// Observers at several points of every live cell (corners included), looking several ways,
/// standing, walking ahead, sideways or up a stair, and turning left, right or not at all, at
/// several turn rates.
fn observers(p: &Prefetcher) -> Vec<Observer> {
    let g = p.graph().unwrap();
    let mut out = Vec::new();
    for (i, c) in g.cells.iter().enumerate().filter(|(_, c)| c.live) {
        let (lo, hi) = (Vec3::from(c.bounds.min), Vec3::from(c.bounds.max));
        for (k, t) in [0.5f32, 0.02, 0.98, 0.3].into_iter().enumerate() {
            let eye = lo + (hi - lo) * Vec3::new(t, 0.5, 1.0 - t);
            let n = i * 4 + k;
            let a = n as f32 * 0.785;
            let dir = Vec3::new(a.cos(), (k as f32 - 1.5) * 0.2, a.sin()).normalize();
            let flat = Vec3::new(dir.x, 0.0, dir.z).normalize();
            let velocity = match n % 4 {
                0 => Vec3::ZERO,
                1 => flat * 1.4,
                2 => Vec3::new(-flat.z, 0.0, flat.x) * 0.6,
                _ => (flat + Vec3::Y * 0.5) * 0.8,
            };
            let turn = [0.0, 0.7, -1.3][n % 3];
            out.push(Observer {
                eye: eye.into(),
                dir: dir.into(),
                up: [0.0, 1.0, 0.0],
                velocity: velocity.into(),
                half_fov_x: 0.6,
                half_fov_y: 0.45,
                max_speed: 1.5,
                max_turn: [0.5, 1.5, 3.0][(n / 3) % 3],
                turn: [0.0, turn, 0.0],
            });
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
    [RangeCull::Direction, RangeCull::Frustum, RangeCull::Any]
        .into_iter()
        .map(|range_cull| Policy { range_cull, ..base })
        .collect()
}

/// Checks every observer under `policy`: the shared list of its place holds its whole exact
/// answer (the cache bound is off), and what the exact answer makes mandatory the shared list
/// makes mandatory too. Returns (observers checked, exact bytes, shared bytes).
fn check_superset(p: &Prefetcher, policy: Policy) -> (usize, u64, u64) {
    let (mut checked, mut exact_bytes, mut shared_bytes) = (0, 0u64, 0u64);
    // Each mip segment's texture and index (coarsest first).
    let mips: HashMap<u32, (usize, usize)> = p
        .database()
        .header()
        .textures
        .iter()
        .enumerate()
        .flat_map(|(t, r)| {
            r.segments
                .iter()
                .enumerate()
                .flat_map(move |(k, m)| m.ids().map(move |id| (id, (t, k))))
        })
        .collect();
    for first in observers(p) {
        let Some(key) = p.share_key(&first, &policy) else {
            continue; // on a cell's face: answered exactly
        };
        // The list made for the first observer of the place, checked against its answer and
        // against those of other observers of the same place.
        let shared = p
            .shared_list(&key, &first, &policy, &Budget::unlimited())
            .unwrap();
        let served = std::iter::once(first)
            .chain(neighbours(&first))
            .filter(|o| p.share_key(o, &policy).as_ref() == Some(&key));
        for obs in served {
            let exact = p.answer(&obs, &policy, &HashSet::new()).unwrap();
            assert!(!exact.items.is_empty());
            for item in &exact.items {
                // A texture's useful mip segment depends on the object's nearest distance: the
                // shared list, from the region's nearest point, may hold a finer one of the same
                // texture instead (more texels of the same image).
                let finer_mips = item.kind == NeedKind::Mips
                    && mips.get(&item.segment).is_some_and(|&(t, k)| {
                        shared
                            .items
                            .iter()
                            .filter_map(|i| mips.get(&i.segment))
                            .any(|&(t2, k2)| t2 == t && k2 >= k)
                    });
                assert!(
                    shared.segments.contains(&item.segment) || finer_mips,
                    "{policy:?} at {:?} looking {:?} moving {:?} turning {:?}: segment {} ({:?}, \
                 LOD {}, frame {}) of the exact answer is not in the shared list",
                    obs.eye,
                    obs.dir,
                    obs.velocity,
                    obs.turn,
                    item.segment,
                    item.kind,
                    item.lod,
                    item.frames,
                );
            }
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
            for item in p.answer(&obs, &no_budget, &HashSet::new()).unwrap().items {
                assert!(
                    must.contains(&item.segment),
                    "at {:?}: segment {} ({:?}) is mandatory for the observer, not in the shared \
                 list",
                    obs.eye,
                    item.segment,
                    item.kind
                );
            }
            checked += 1;
            exact_bytes += exact.lookahead_bytes;
            shared_bytes += shared.lookahead_bytes;
        }
    }
    (checked, exact_bytes, shared_bytes)
}

/// Observers near `o`: a few centimetres to decimetres away, looking and walking a few degrees
/// off, a little faster, turning a little more or less (those in `o`'s place are served by the
/// list made for `o`).
fn neighbours(o: &Observer) -> Vec<Observer> {
    let turn = |v: [f32; 3], yaw: f32, pitch: f32| {
        let q = glam::Quat::from_rotation_y(yaw) * glam::Quat::from_rotation_x(pitch);
        <[f32; 3]>::from(q * Vec3::from(v))
    };
    let moved = |d: Vec3| Observer {
        eye: (Vec3::from(o.eye) + d).into(),
        ..*o
    };
    vec![
        moved(Vec3::new(0.2, 0.0, -0.2)),
        moved(Vec3::new(-0.15, 0.1, 0.25)),
        moved(Vec3::new(0.3, -0.05, 0.05)),
        Observer {
            dir: turn(o.dir, 0.04, 0.0),
            ..moved(Vec3::new(-0.1, 0.0, -0.1))
        },
        Observer {
            dir: turn(o.dir, -0.05, 0.03),
            velocity: turn(o.velocity, 0.06, 0.0).map(|x| x * 1.06),
            ..*o
        },
        Observer {
            turn: [o.turn[0], o.turn[1] + 0.1, o.turn[2]],
            velocity: o.velocity.map(|x| x * 0.95),
            ..moved(Vec3::new(0.05, 0.0, 0.12))
        },
        Observer {
            turn: [o.turn[0], o.turn[1] - 0.09, o.turn[2]],
            dir: turn(o.dir, 0.02, -0.02),
            ..moved(Vec3::new(-0.22, 0.02, 0.0))
        },
    ]
}

#[test]
fn a_predicted_shared_list_holds_every_served_observers_whole_answer() {
    let p = prefetcher();
    let (mut checked, mut exact_bytes, mut shared_bytes) = (0, 0u64, 0u64);
    for policy in policies() {
        let (n, e, s) = check_superset(p, policy);
        checked += n;
        exact_bytes += e;
        shared_bytes += s;
    }
    // Each observer's own place, and others of the same places.
    assert!(checked > 1000, "{checked}");
    // Conservative, not everything: within a small factor of the exact answers.
    let ratio = shared_bytes as f64 / exact_bytes as f64;
    eprintln!("shared / exact lookahead bytes: {ratio:.2} over {checked} observers");
    assert!((1.0..2.5).contains(&ratio), "{ratio}");
}

#[test]
fn with_impostors_and_textures_the_predicted_shared_list_holds_every_answer() {
    let impostors = Policy {
        impostors: true,
        ..policies()[0]
    };
    assert!(check_superset(with_impostors(), impostors).0 > 100);
    assert!(check_superset(textured(), policies()[0]).0 > 20);
}

/// The first observer of [`observers`] walking ahead, at the middle of its metre of the cell
/// (the places' cubes: `prefetch::swept::VOXEL_M`), moved by `d` metres and its view turned
/// by `yaw` radians.
fn walker(p: &Prefetcher, d: Vec3, yaw: f32) -> Observer {
    let mut o = observers(p)[1];
    let eye = (Vec3::from(o.eye) / VOXEL_M).floor() * VOXEL_M + Vec3::splat(VOXEL_M * 0.5) + d;
    o.eye = eye.into();
    o.dir = glam::Quat::from_rotation_y(yaw)
        .mul_vec3(Vec3::from(o.dir))
        .into();
    o
}

#[test]
fn a_crowd_in_one_place_computes_one_list() {
    // A prefetcher of its own: its counters are not shared with the other tests.
    let p = Prefetcher::new(prefetcher().database().clone()).unwrap();
    let policy = Policy::default();
    let key = p.share_key(&walker(&p, Vec3::ZERO, 0.0), &policy).unwrap();
    // Fifty observers a few centimetres apart, looking a degree or so apart: those in the
    // same place (most of them) share one list, computed once.
    let crowd: Vec<Observer> = (0..50)
        .map(|i| {
            let d = Vec3::new((i % 5) as f32, 0.0, (i / 5 % 5) as f32) * 0.01;
            walker(&p, d, (i % 3) as f32 * 0.005)
        })
        .filter(|o| p.share_key(o, &policy).as_ref() == Some(&key))
        .collect();
    assert!(crowd.len() >= 25, "{}", crowd.len());
    let lists: Vec<_> = crowd
        .iter()
        .map(|o| {
            p.shared_list(&key, o, &policy, &Budget::unlimited())
                .unwrap()
        })
        .collect();
    assert!(lists.iter().all(|l| Arc::ptr_eq(l, &lists[0])));
    assert_eq!(p.shared_answers().misses.load(Relaxed), 1);
    assert_eq!(
        p.shared_answers().hits.load(Relaxed),
        crowd.len() as u64 - 1
    );
    // Another metre, view, speed or turn is another place.
    let o = crowd[0];
    let moved = walker(&p, Vec3::new(1.0, 0.0, 0.0), 0.0);
    let turned = walker(&p, Vec3::ZERO, 0.6);
    let faster = Observer {
        velocity: (Vec3::from(o.velocity) * 1.5).into(),
        ..o
    };
    let turning = Observer {
        turn: [0.0, 0.9, 0.0],
        ..o
    };
    for other in [moved, turned, faster, turning] {
        assert_ne!(p.share_key(&other, &policy).as_ref(), Some(&key));
    }
}

#[test]
fn a_moving_observer_computes_again_only_when_its_place_changes() {
    let p = Prefetcher::new(prefetcher().database().clone()).unwrap();
    let policy = Policy::default();
    // A walk of 2 s at 20 updates a second, turning slowly: a session's stream computes (or
    // takes from the cache) a list only when the place changes.
    let first = walker(&p, Vec3::ZERO, 0.0);
    let v = Vec3::from(first.velocity);
    let mut places = Vec::new();
    let mut lists = 0;
    for i in 0..40 {
        let t = i as f32 * 0.05;
        let o = walker(&p, v * t * 0.5, t * 0.2);
        let Some(key) = p.share_key(&o, &policy) else {
            continue;
        };
        if places.last() != Some(&key.place) {
            places.push(key.place);
            p.shared_list(&key, &o, &policy, &Budget::unlimited())
                .unwrap();
            lists += 1;
        }
    }
    let computed = p.shared_answers().misses.load(Relaxed);
    assert!(places.len() >= 3, "the walk stayed in one place");
    assert!(places.len() <= 20, "{} places in 40 updates", places.len());
    assert_eq!(computed as usize, lists);
    // The same walk again (another session on the same tour) computes nothing.
    let before = p.shared_answers().misses.load(Relaxed);
    for i in 0..40 {
        let t = i as f32 * 0.05;
        let o = walker(&p, v * t * 0.5, t * 0.2);
        if let Some(key) = p.share_key(&o, &policy) {
            p.shared_list(&key, &o, &policy, &Budget::unlimited())
                .unwrap();
        }
    }
    assert_eq!(p.shared_answers().misses.load(Relaxed), before);
}
