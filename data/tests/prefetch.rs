//! Funkhouser §5.2 prefetch on the generated tiny building: the read set contains everything
//! visible now, respects its budget and order, and the range behaves as the policies say.

use glam::Vec3;
use portico_data::Database;
use portico_data::build::{BuildOptions, Quiet, build};
use portico_data::cells::realtime::{Frustum, eye_to_cell, eye_to_object};
use portico_data::import::import_file;
use portico_data::prefetch::Prefetcher;
use portico_protocol::{Granularity, LookaheadCull, NeedKind, Observer, Policy, RangeCull};
use std::collections::HashSet;
use std::sync::{Arc, OnceLock};

fn prefetcher(no_cells: bool) -> &'static Prefetcher {
    static WITH: OnceLock<Prefetcher> = OnceLock::new();
    static WITHOUT: OnceLock<Prefetcher> = OnceLock::new();
    let slot = if no_cells { &WITHOUT } else { &WITH };
    slot.get_or_init(|| {
        let params = portico_generator::Params {
            preset: portico_generator::Preset::Tiny,
            seed: 5,
            floors: Some(2),
        };
        let b = portico_generator::generate(&params, &mut |_| {}).expect("generate");
        let dir = tempfile::tempdir().unwrap();
        let glb = dir.path().join("tiny.glb");
        std::fs::write(&glb, &b.glb).unwrap();
        let out = dir.path().join("tiny.portico");
        let opts = BuildOptions {
            no_cells,
            ..BuildOptions::default()
        };
        build(import_file(&glb).unwrap(), &out, &opts, &Quiet).unwrap();
        // The map stays valid after the directory is removed (the inode lives on).
        let db = Arc::new(Database::open(&out).unwrap());
        Prefetcher::new(db).unwrap()
    })
}

/// Observers standing in the middle of live cells, looking along +x, -x, +z.
fn observers(p: &Prefetcher) -> Vec<Observer> {
    let g = p.graph().unwrap();
    let mut out = Vec::new();
    for (i, c) in g
        .cells
        .iter()
        .enumerate()
        .filter(|(_, c)| c.live)
        .step_by(3)
    {
        let mid = Vec3::from(c.bounds.min).lerp(Vec3::from(c.bounds.max), 0.5);
        let dir = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]][i % 3];
        out.push(Observer {
            eye: mid.into(),
            dir,
            up: [0.0, 1.0, 0.0],
            velocity: [0.0; 3],
            half_fov_x: 0.6,
            half_fov_y: 0.45,
            max_speed: 1.5,
            max_turn: 1.0,
        });
    }
    out
}

#[test]
fn the_read_set_holds_the_coarsest_lod_of_everything_visible_now_even_with_no_budget() {
    let p = prefetcher(false);
    let db = p.database();
    let header = db.header();
    let objects: Vec<_> = header.instances.iter().map(|i| i.bounds).collect();
    let policy = Policy {
        read_bytes: 0,
        ..Policy::default()
    };
    for obs in observers(p) {
        let r = p.answer(&obs, &policy, &HashSet::new()).unwrap();
        let got: HashSet<u32> = r.items.iter().map(|i| i.segment).collect();
        let g = p.graph().unwrap();
        let view = Frustum::new(obs.eye.into(), obs.dir.into(), Vec3::Y, 0.6, 0.45);
        let cell = g.locate(obs.eye.into()).unwrap();
        let stab = p.stab(cell).unwrap();
        for o in eye_to_object(&eye_to_cell(g, &view), &stab, &objects) {
            let lods = header.lods_of(&header.instances[o as usize]);
            let coarsest = lods.last().unwrap().segment;
            assert!(got.contains(&coarsest), "visible object {o} missing");
        }
        assert!(
            got.contains(&p.stab_segment(cell).unwrap()),
            "eye cell's stab list"
        );
    }
}

#[test]
fn the_read_set_is_ordered_budgeted_and_skips_what_is_held() {
    let p = prefetcher(false);
    let policy = Policy {
        read_bytes: 64 << 10,
        range_cull: RangeCull::Any,
        ..Policy::default()
    };
    let obs = observers(p)[0];
    let r = p.answer(&obs, &policy, &HashSet::new()).unwrap();
    assert!(!r.items.is_empty());
    // Stab lists first, then geometry.
    let first_geo = r
        .items
        .iter()
        .position(|i| i.kind == NeedKind::Geometry)
        .unwrap();
    assert!(
        r.items[first_geo..]
            .iter()
            .all(|i| i.kind == NeedKind::Geometry)
    );
    // Within the budget, except for the mandatory coarsest LODs of what is visible now.
    let optional: u64 = r
        .items
        .iter()
        .filter(|i| i.frames > 0)
        .map(|i| i.bytes)
        .sum();
    assert!(optional <= policy.read_bytes, "{optional}");
    // No segment twice.
    let unique: HashSet<u32> = r.items.iter().map(|i| i.segment).collect();
    assert_eq!(unique.len(), r.items.len());
    // Holding everything that was sent: the next answer continues where this one stopped.
    let held: HashSet<u32> = unique;
    let r2 = p.answer(&obs, &policy, &held).unwrap();
    assert!(r2.items.iter().all(|i| !held.contains(&i.segment)));
    assert!(
        r2.evict.is_empty(),
        "nothing held is outside the lookahead set"
    );
    assert_eq!(r.lookahead_bytes, r2.lookahead_bytes);
}

#[test]
fn held_segments_outside_the_lookahead_set_are_eviction_hints() {
    let p = prefetcher(false);
    let policy = Policy {
        depth_frames: 1,
        ..Policy::default()
    };
    let obs = observers(p)[0];
    let r = p.answer(&obs, &policy, &HashSet::new()).unwrap();
    let needed: HashSet<u32> = r.items.iter().map(|i| i.segment).collect();
    let stranger = (0..p.database().segments().len() as u32)
        .find(|s| !needed.contains(s) && p.is_geometry(*s))
        .unwrap();
    let held: HashSet<u32> = [stranger].into();
    let r = p.answer(&obs, &policy, &held).unwrap();
    assert_eq!(r.evict, vec![stranger]);
}

#[test]
fn deeper_lookahead_never_shrinks_and_direction_cull_is_a_subset_of_any() {
    let p = prefetcher(false);
    for obs in observers(p).into_iter().take(6) {
        let mut last = 0;
        for depth in [1, 4, 16, 64] {
            let policy = Policy {
                depth_frames: depth,
                range_cull: RangeCull::Any,
                lookahead_cull: LookaheadCull::Any,
                cache_bytes: u64::MAX,
                ..Policy::default()
            };
            let r = p.answer(&obs, &policy, &HashSet::new()).unwrap();
            assert!(
                r.range_cells >= last,
                "depth {depth}: {} < {last}",
                r.range_cells
            );
            last = r.range_cells;
            let dir = Policy {
                range_cull: RangeCull::Direction,
                ..policy
            };
            let rd = p.answer(&obs, &dir, &HashSet::new()).unwrap();
            assert!(rd.range_cells <= r.range_cells);
            assert!(rd.lookahead_bytes <= r.lookahead_bytes);
        }
    }
}

#[test]
fn cell_granularity_fetches_at_least_object_granularity() {
    let p = prefetcher(false);
    for obs in observers(p).into_iter().take(6) {
        let obj = Policy {
            cache_bytes: u64::MAX,
            ..Policy::default()
        };
        let cell = Policy {
            granularity: Granularity::Cell,
            ..obj
        };
        let a = p.answer(&obs, &obj, &HashSet::new()).unwrap();
        let b = p.answer(&obs, &cell, &HashSet::new()).unwrap();
        assert!(b.lookahead_objects >= a.lookahead_objects);
    }
}

#[test]
fn a_database_without_cells_still_gets_answers_nearest_first() {
    let p = prefetcher(true);
    assert!(p.graph().is_none());
    let g = prefetcher(false).graph().unwrap();
    let c = g.cells.iter().find(|c| c.live).unwrap();
    let mid = Vec3::from(c.bounds.min).lerp(Vec3::from(c.bounds.max), 0.5);
    let obs = Observer {
        eye: mid.into(),
        ..observers(prefetcher(false))[0]
    };
    let r = p.answer(&obs, &Policy::default(), &HashSet::new()).unwrap();
    assert!(!r.items.is_empty());
    // The first thing sent is needed soonest.
    let soonest = r.items.iter().map(|i| i.frames).min();
    assert_eq!(soonest, Some(r.items[0].frames));
    assert_eq!(
        r.items[0].frames, 0,
        "the observer stands among the furniture"
    );
}

#[test]
fn an_observer_outside_the_building_is_answered_from_the_nearest_cell() {
    let p = prefetcher(false);
    let obs = Observer {
        eye: [1e4, 1e4, 1e4],
        ..observers(p)[0]
    };
    let r = p.answer(&obs, &Policy::default(), &HashSet::new()).unwrap();
    assert!(r.range_cells >= 1);
    assert!(!r.items.is_empty());
}

#[test]
fn what_the_observer_sees_now_is_read_before_the_rest_of_the_lookahead() {
    let p = prefetcher(false);
    let db = p.database();
    let header = db.header();
    let objects: Vec<_> = header.instances.iter().map(|i| i.bounds).collect();
    let policy = Policy {
        read_bytes: u64::MAX,
        range_cull: RangeCull::Any,
        ..Policy::default()
    };
    let g = p.graph().unwrap();
    let mut checked = 0;
    for obs in observers(p) {
        let view = Frustum::new(obs.eye.into(), obs.dir.into(), Vec3::Y, 0.6, 0.45);
        let cell = g.locate(obs.eye.into()).unwrap();
        let stab = p.stab(cell).unwrap();
        let in_view: HashSet<u32> = eye_to_object(&eye_to_cell(g, &view), &stab, &objects)
            .into_iter()
            .collect();
        // Segments of objects in view, and of no object out of it (definitions are shared).
        let mut seen = HashSet::new();
        let mut unseen = HashSet::new();
        for (i, inst) in header.instances.iter().enumerate() {
            let set = if in_view.contains(&(i as u32)) {
                &mut seen
            } else {
                &mut unseen
            };
            set.extend(header.lods_of(inst).iter().map(|l| l.segment));
        }
        let (seen, unseen): (HashSet<u32>, HashSet<u32>) = (
            seen.difference(&unseen).copied().collect(),
            unseen.difference(&seen).copied().collect(),
        );
        let r = p.answer(&obs, &policy, &HashSet::new()).unwrap();
        let geo: Vec<u32> = r
            .items
            .iter()
            .filter(|i| i.kind == NeedKind::Geometry)
            .map(|i| i.segment)
            .collect();
        let first_other = geo.iter().position(|s| unseen.contains(s));
        let last_seen = geo.iter().rposition(|s| seen.contains(s));
        if let (Some(first_other), Some(last_seen)) = (first_other, last_seen) {
            assert!(
                last_seen < first_other,
                "a segment of an unseen object (at {first_other}) before one in view (at {last_seen})"
            );
            checked += 1;
        }
    }
    assert!(
        checked > 0,
        "some observer sees something and has more ahead"
    );
}

/// The level of each geometry segment counted from the coarsest (0), as the read set orders
/// them: a definition's LOD table lists finest first.
fn levels(p: &Prefetcher) -> std::collections::HashMap<u32, u32> {
    let header = p.database().header();
    let mut out = std::collections::HashMap::new();
    for inst in &header.instances {
        let lods = header.lods_of(inst);
        for (i, l) in lods.iter().enumerate() {
            out.insert(l.segment, (lods.len() - 1 - i) as u32);
        }
    }
    out
}

/// The whole order of an answer (Funkhouser §5.2.2 with the current view first): stab lists
/// and atlases, then the geometry in at most two runs — what the observer sees now, then the
/// rest of the lookahead — each ordered by level (coarsest first), then frames until visible.
/// Returns the number of geometry items in the first run.
fn assert_read_order(p: &Prefetcher, obs: &Observer, policy: &Policy) -> usize {
    let level = levels(p);
    let r = p.answer(obs, policy, &HashSet::new()).unwrap();
    let first_geo = r
        .items
        .iter()
        .position(|i| i.kind == NeedKind::Geometry)
        .unwrap_or(r.items.len());
    assert!(
        r.items[first_geo..]
            .iter()
            .all(|i| i.kind == NeedKind::Geometry),
        "a stab list or atlas after geometry"
    );
    let keys: Vec<(u32, u32)> = r.items[first_geo..]
        .iter()
        .map(|i| (level[&i.segment], i.frames))
        .collect();
    let descents: Vec<usize> = (1..keys.len()).filter(|&k| keys[k] < keys[k - 1]).collect();
    assert!(
        descents.len() <= 1,
        "more than two ordered runs: descents at {descents:?} of {keys:?}"
    );
    let first_run = descents.first().copied().unwrap_or(keys.len());
    if !descents.is_empty() {
        assert!(
            keys[..first_run].iter().all(|&(_, f)| f == 0),
            "the first run holds something not visible now: {:?}",
            &keys[..first_run]
        );
    }
    first_run
}

#[test]
fn the_whole_read_order_is_now_then_level_then_frames() {
    let policy = Policy {
        read_bytes: u64::MAX,
        range_cull: RangeCull::Any,
        ..Policy::default()
    };
    let p = prefetcher(false);
    let mut two_runs = 0;
    let obs = observers(p);
    for o in &obs {
        let first = assert_read_order(p, o, &policy);
        let geometry = p
            .answer(o, &policy, &HashSet::new())
            .unwrap()
            .items
            .iter()
            .filter(|i| i.kind == NeedKind::Geometry)
            .count();
        two_runs += usize::from(first < geometry);
    }
    assert!(two_runs > 0, "no observer had both a view and a lookahead");
    // Without cells: the same order, the view found by the frustum alone.
    let q = prefetcher(true);
    for o in &obs {
        assert_read_order(q, o, &policy);
    }
}
