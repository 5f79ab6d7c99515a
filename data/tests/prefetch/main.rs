//! Funkhouser §5.2 prefetch on the generated tiny building: the read set contains everything
//! visible now, respects its budget and order, and the range behaves as the policies say.

use glam::Vec3;
use portico_data::build::BuildOptions;
use portico_data::cells::realtime::{Frustum, eye_to_cell, eye_to_object, eye_to_object_exact};
use portico_data::prefetch::Prefetcher;
use portico_protocol::{Granularity, LookaheadCull, NeedKind, Observer, Policy, RangeCull};
use std::collections::HashSet;
use std::sync::OnceLock;

#[path = "../common/mod.rs"]
mod common;
mod lookahead;

fn prefetcher(no_cells: bool) -> &'static Prefetcher {
    static WITH: OnceLock<Prefetcher> = OnceLock::new();
    static WITHOUT: OnceLock<Prefetcher> = OnceLock::new();
    let slot = if no_cells { &WITHOUT } else { &WITH };
    slot.get_or_init(|| tiny(no_cells, None))
}

/// The tiny building (seed 5, two storeys) built into a temporary directory, with or without
/// cells, its clusters painted by `painter` if given.
fn tiny(
    no_cells: bool,
    painter: Option<&mut dyn portico_data::hierarchy::ImpostorPainter>,
) -> Prefetcher {
    let opts = BuildOptions {
        no_cells,
        ..BuildOptions::default()
    };
    tiny_with(&opts, painter)
}

/// [`tiny`] with any build options.
fn tiny_with(
    opts: &BuildOptions,
    painter: Option<&mut dyn portico_data::hierarchy::ImpostorPainter>,
) -> Prefetcher {
    common::tiny_prefetcher(opts, painter)
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
        out.push(common::observer(mid, dir));
    }
    out
}

/// The coarsest-LOD segment of every object the observer sees now (eye-to-object visibility,
/// Funkhouser §4.2, each box tested against its wedge exactly: a big box beside the eye that
/// only the plane-by-plane test passes no sightline reaches, and the predicted lookahead leaves
/// it out), with the object's id; the prefetcher must have cells.
fn coarsest_visible_now(p: &Prefetcher, obs: &Observer) -> Vec<(u32, u32)> {
    let header = p.database().header();
    let objects: Vec<_> = header.instances.iter().map(|i| i.bounds).collect();
    let g = p.graph().unwrap();
    let view = Frustum::new(
        obs.eye.into(),
        obs.dir.into(),
        Vec3::Y,
        obs.half_fov_x,
        obs.half_fov_y,
    );
    let stab = p.stab(g.locate(obs.eye.into()).unwrap()).unwrap();
    eye_to_object_exact(&eye_to_cell(g, &view), &stab, &objects, obs.eye.into())
        .into_iter()
        .map(|o| {
            let lods = header.lods_of(&header.instances[o as usize]);
            (o, lods.last().unwrap().segment)
        })
        .collect()
}

#[test]
fn the_read_set_holds_the_coarsest_lod_of_everything_visible_now_even_with_no_budget() {
    let p = prefetcher(false);
    let policy = Policy {
        read_bytes: 0,
        ..Policy::default()
    };
    let mut seen = 0;
    for obs in observers(p) {
        let r = p.answer(&obs, &policy, &HashSet::new()).unwrap();
        let got: HashSet<u32> = r.items.iter().map(|i| i.segment).collect();
        for (o, coarsest) in coarsest_visible_now(p, &obs) {
            assert!(got.contains(&coarsest), "visible object {o} missing");
            seen += 1;
        }
        let cell = p.graph().unwrap().locate(obs.eye.into()).unwrap();
        assert!(
            got.contains(&p.stab_segment(cell).unwrap()),
            "eye cell's stab list"
        );
    }
    assert!(seen > 0, "no observer saw anything");
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
    // Within the budget, except for what is mandatory: the stab lists and coarsest LODs needed
    // now (frame 0). Finer LODs of what is in view now are not mandatory.
    let level = levels(p);
    let mandatory = |i: &&portico_protocol::NeedItem| {
        i.frames == 0 && (i.kind == NeedKind::Stab || level.get(&i.segment) == Some(&0))
    };
    let optional: u64 = r
        .items
        .iter()
        .filter(|i| !mandatory(i))
        .map(|i| i.bytes)
        .sum();
    assert!(optional <= policy.read_bytes, "{optional}");
    assert!(
        r.items.iter().any(|i| !mandatory(&i) && i.frames == 0),
        "no optional item needed now: the check above is weaker than it looks"
    );
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
    let segments = |r: &portico_protocol::PrefetchResponse| -> HashSet<u32> {
        r.items.iter().map(|i| i.segment).collect()
    };
    let mut grew = 0;
    for obs in observers(p).into_iter().take(6) {
        let mut last = (0, HashSet::new());
        for depth in [1, 4, 16, 64] {
            let policy = Policy {
                depth_frames: depth,
                range_cull: RangeCull::Any,
                lookahead_cull: LookaheadCull::Any,
                cache_bytes: u64::MAX,
                read_bytes: u64::MAX,
                ..Policy::default()
            };
            let r = p.answer(&obs, &policy, &HashSet::new()).unwrap();
            assert!(
                r.range_cells >= last.0,
                "depth {depth}: {} < {}",
                r.range_cells,
                last.0
            );
            let set = segments(&r);
            assert!(set.is_superset(&last.1), "depth {depth} lost segments");
            grew += usize::from(set.len() > last.1.len() && depth > 1);
            last = (r.range_cells, set);
            let dir = Policy {
                range_cull: RangeCull::Direction,
                ..policy
            };
            let rd = p.answer(&obs, &dir, &HashSet::new()).unwrap();
            assert!(rd.range_cells <= r.range_cells);
            assert!(
                segments(&rd).is_subset(&last.1),
                "depth {depth}: the direction cull read what `any` did not"
            );
        }
    }
    assert!(grew > 0, "a deeper lookahead never added anything");
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

/// The tiny building with textured cluster boxes.
fn with_impostors() -> &'static Prefetcher {
    static P: OnceLock<Prefetcher> = OnceLock::new();
    P.get_or_init(|| tiny(false, Some(&mut common::FakePainter)))
}

/// Maciel & Shirley's textured boxes come before any geometry, once each, never for a cluster
/// that holds the eye, the view's first; without `impostors` none is listed.
#[test]
fn cluster_textures_come_first_once_each_and_never_around_the_eye() {
    let p = with_impostors();
    let h = p
        .database()
        .header()
        .hierarchy
        .clone()
        .expect("a hierarchy");
    let policy = Policy {
        impostors: true,
        read_bytes: 1 << 30,
        range_cull: RangeCull::Any,
        ..Policy::default()
    };
    let mut listed = 0;
    for obs in observers(p) {
        let r = p.answer(&obs, &policy, &HashSet::new()).unwrap();
        let kinds: Vec<NeedKind> = r.items.iter().map(|i| i.kind).collect();
        let first_geo = kinds.iter().position(|k| *k == NeedKind::Geometry);
        let textures: Vec<&portico_protocol::NeedItem> = r
            .items
            .iter()
            .filter(|i| i.kind == NeedKind::Texture)
            .collect();
        listed += textures.len();
        if let Some(g) = first_geo {
            assert!(
                kinds[g..].iter().all(|k| *k == NeedKind::Geometry),
                "a texture after geometry"
            );
        }
        let unique: HashSet<u32> = textures.iter().map(|t| t.segment).collect();
        assert_eq!(unique.len(), textures.len(), "a texture listed twice");
        let eye = Vec3::from(obs.eye);
        let around = |b: &portico_data::geometry::Aabb| {
            (0..3).all(|k| b.min[k] <= eye[k] && eye[k] <= b.max[k])
        };
        // What the view needs first comes first: frames until visible never decrease.
        assert!(
            textures.windows(2).all(|w| w[0].frames <= w[1].frames),
            "textures out of need order"
        );
        for t in &textures {
            let node = h
                .nodes
                .iter()
                .find(|n| n.texture == t.segment)
                .expect("a cluster's texture");
            assert!(!around(&node.bounds), "the box of a cluster around the eye");
            // The clusters above a listed one are listed too (a coarser view of the same place),
            // unless they hold the eye or have no texture.
            if let Some(parent) = h.nodes.get(node.parent as usize)
                && parent.texture != u32::MAX
                && !around(&parent.bounds)
            {
                assert!(
                    unique.contains(&parent.texture),
                    "a cluster listed without its parent"
                );
            }
            assert_eq!(t.bytes, p.database().segments()[t.segment as usize].length);
            assert!(!p.is_geometry(t.segment));
        }
        let plain = Policy {
            impostors: false,
            ..policy
        };
        let r = p.answer(&obs, &plain, &HashSet::new()).unwrap();
        assert!(r.items.iter().all(|i| i.kind != NeedKind::Texture));
    }
    assert!(listed > 0, "no observer was sent a single texture");
}

/// The deadline: an answer that cannot finish in time is an error, not a late answer.
#[test]
fn a_budget_past_its_deadline_stops_the_answer() {
    use portico_data::prefetch::Budget;
    use std::time::{Duration, Instant};
    let p = prefetcher(false);
    let obs = observers(p)[0];
    let past = Budget::until(Instant::now() - Duration::from_millis(1));
    assert!(past.check().is_err());
    let e = p
        .answer_within(&obs, &Policy::default(), &HashSet::new(), &past)
        .unwrap_err();
    assert!(matches!(e, portico_data::DataError::Deadline(_)), "{e}");
    let later = Budget::until(Instant::now() + Duration::from_secs(60));
    assert!(later.check().is_ok());
    assert!(
        p.answer_within(&obs, &Policy::default(), &HashSet::new(), &later)
            .is_ok()
    );
    assert!(Budget::unlimited().check().is_ok());
    std::thread::sleep(Duration::from_millis(5));
    assert!(later.elapsed() >= Duration::from_millis(5));
}

/// Sizes, kinds and the statistics of an answer are the database's: every item's bytes are its
/// segment's, stab lists are stab-list segments, the lookahead bytes are the distinct segments'
/// sum, and a cut at the read budget is a prefix of the uncut answer (nothing after the cut).
#[test]
fn answers_carry_the_segments_sizes_and_cut_as_a_prefix() {
    let p = prefetcher(false);
    let db = p.database();
    let g = p.graph().unwrap();
    let unlimited = Policy {
        read_bytes: 1 << 30,
        range_cull: RangeCull::Any,
        ..Policy::default()
    };
    for obs in observers(p) {
        let full = p.answer(&obs, &unlimited, &HashSet::new()).unwrap();
        let mut sum = 0;
        for i in &full.items {
            assert_eq!(i.bytes, db.segments()[i.segment as usize].length);
            assert_eq!(i.kind == NeedKind::Geometry, p.is_geometry(i.segment));
            sum += i.bytes;
        }
        // Nothing held and no cut: the read set is the lookahead set.
        assert_eq!(full.lookahead_bytes, sum);
        assert!(full.lookahead_objects > 0);
        let eye_cell = g.locate(Vec3::from(obs.eye)).unwrap();
        let stab = p.stab_segment(eye_cell).expect("the eye cell's stab list");
        assert!(
            full.items
                .iter()
                .any(|i| i.segment == stab && i.kind == NeedKind::Stab)
        );
        // Cut just short of each of the first optional items in turn: what is read is the full
        // order up to the cut, plus only mandatory items after it — never a later, smaller
        // item that would still fit.
        for item in full.items.iter().filter(|i| i.frames > 0).take(12) {
            // Everything before it counts against the read budget, mandatory items included.
            let before: u64 = full
                .items
                .iter()
                .take_while(|i| i.segment != item.segment)
                .map(|i| i.bytes)
                .sum();
            let cut = Policy {
                read_bytes: before + item.bytes - 1,
                ..unlimited
            };
            let part = p.answer(&obs, &cut, &HashSet::new()).unwrap();
            let part_ids: HashSet<u32> = part.items.iter().map(|i| i.segment).collect();
            assert!(
                !part_ids.contains(&item.segment),
                "the item at the cut was read"
            );
            assert!(part.truncated);
            let at = full
                .items
                .iter()
                .position(|i| i.segment == item.segment)
                .unwrap();
            for (k, i) in full.items.iter().enumerate() {
                let read = part_ids.contains(&i.segment);
                if k < at {
                    assert!(read, "an item before the cut was not read");
                } else if i.frames > 0 {
                    assert!(!read, "an optional item after the cut was read");
                }
            }
            assert_eq!(part.lookahead_bytes, full.lookahead_bytes);
            assert_eq!(part.lookahead_objects, full.lookahead_objects);
        }
    }
    assert!(format!("{p:?}").starts_with("Prefetcher"));
    assert_eq!(p.stab_segment(u32::MAX), None);
    assert!(!p.is_geometry(u32::MAX));
}
