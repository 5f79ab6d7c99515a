//! The lookahead's sizes, LOD caps, range cells and cache bound (Funkhouser §5.2.1–5.2.2).

use super::*;

/// §5.2.2's size: the disc of an object's bounding sphere on the screen, in pixels.
#[test]
fn projected_pixels_are_the_bounding_discs_area_capped_at_the_screen() {
    use portico_data::prefetch::lookahead::projected_pixels;
    let policy = Policy {
        screen: [640, 480],
        ..Policy::default()
    };
    // A box whose bounding sphere has radius 1 m, seen with tan(half fov) = 1: 240 px per
    // metre at 1 m, so 24 px of radius at 10 m.
    let side = 2.0 / 3f32.sqrt();
    let b = portico_data::geometry::Aabb {
        min: [0.0; 3],
        max: [side; 3],
    };
    let quarter = std::f32::consts::FRAC_PI_4;
    let px = projected_pixels(&b, 10.0, &policy, quarter);
    let want = std::f32::consts::PI * 24.0 * 24.0;
    assert!((px - want).abs() < want * 1e-3, "{px} vs {want}");
    // Twice as far, a quarter of the area; inside the sphere, the whole screen.
    let far = projected_pixels(&b, 20.0, &policy, quarter);
    assert!((far * 4.0 - px).abs() < px * 1e-3, "{far}");
    assert_eq!(projected_pixels(&b, 0.5, &policy, quarter), 640.0 * 480.0);
    // Just outside the sphere the disc (π·237.6² px) is still under the screen: not capped.
    let near = projected_pixels(&b, 1.01, &policy, quarter);
    assert!(near < 640.0 * 480.0 && near > 170_000.0, "{near}");
    // A wider view shows the same box smaller.
    assert!(projected_pixels(&b, 10.0, &policy, 1.0) < px);
}

fn lods(triangles: &[u32]) -> Vec<portico_data::format::LodRecord> {
    triangles
        .iter()
        .enumerate()
        .map(|(i, &t)| portico_data::format::LodRecord {
            segment: i as u32,
            triangles: t,
            vertices: t,
            error: 0.0,
            uv: false,
        })
        .collect()
}

/// The static size threshold caps an object's LOD (Funkhouser §4.2.4, §5.2.2): the finest LOD
/// whose average triangle covers at least the threshold, else the coarsest.
#[test]
fn the_size_threshold_picks_the_finest_lod_with_triangles_big_enough() {
    use portico_data::prefetch::lookahead::max_lod;
    let l = lods(&[1000, 100, 12]);
    // 10,000 pixels: 10 px per triangle at LOD 0, 100 at LOD 1, 833 at LOD 2.
    assert_eq!(max_lod(&l, 10_000.0, 10.0), 0);
    assert_eq!(max_lod(&l, 10_000.0, 10.5), 1);
    assert_eq!(max_lod(&l, 10_000.0, 100.0), 1);
    assert_eq!(max_lod(&l, 10_000.0, 101.0), 2);
    assert_eq!(
        max_lod(&l, 10_000.0, 1e6),
        2,
        "none is big enough: the coarsest"
    );
    assert_eq!(max_lod(&l, 10_000.0, 0.0), 0);
    assert_eq!(max_lod(&[], 10.0, 1.0), 0);
}

/// Over the observer range, the nearest point decides: near objects may need their finest LOD,
/// far ones only a coarse one, and an object the range reaches into its finest.
#[test]
fn the_nearest_point_of_the_range_sets_each_objects_lod_cap() {
    use portico_data::prefetch::lookahead::max_lod_in_range;
    use portico_data::prefetch::range::ObserverRange;
    let policy = Policy {
        screen: [640, 480],
        size_threshold_px: 64.0,
        frame_time_s: 0.05,
        depth_frames: 20,
        ..Policy::default()
    };
    let obs = Observer {
        eye: [0.0, 1.5, 0.0],
        dir: [1.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        velocity: [0.0; 3],
        half_fov_x: 0.6,
        half_fov_y: 0.45,
        max_speed: 2.0,
        max_turn: 1.0,
        turn: [0.0; 3],
    };
    let range = ObserverRange::new(&obs, &policy);
    // 2 m/s for 20 frames of 50 ms: the observer may come 2 m closer.
    assert!((range.radius - 2.0).abs() < 1e-3, "{}", range.radius);
    let l = lods(&[20_000, 2_000, 200, 12]);
    let at = |x: f32| portico_data::geometry::Aabb {
        min: [x, 1.0, -0.5],
        max: [x + 1.0, 2.0, 0.5],
    };
    let caps: Vec<usize> = [2.5, 5.0, 40.0, 400.0]
        .iter()
        .map(|&x| max_lod_in_range(&l, &at(x), &range, &policy, obs.half_fov_y))
        .collect();
    // Within reach the object may fill the screen: 307,200 px over 20,000 triangles is 15 px
    // each, under the 64 px threshold; LOD 1's 2,000 give 154 px each.
    assert_eq!(
        caps[0], 1,
        "within reach: the finest the full screen allows"
    );
    let fine = Policy {
        size_threshold_px: 10.0,
        ..policy
    };
    assert_eq!(
        max_lod_in_range(&l, &at(2.5), &range, &fine, obs.half_fov_y),
        0
    );
    assert!(
        caps.windows(2).all(|w| w[0] <= w[1]),
        "farther never finer: {caps:?}"
    );
    assert_eq!(caps[3], 3, "far away: the coarsest");
    // 3 m away at the nearest: a 143 px disc, 64,600 px; LOD 2 gives 323 px a triangle.
    assert_eq!(caps[1], 2, "{caps:?}");
}

/// Dijkstra over the portals in frames-to-enter (§5.2.1): the eye's cell first at 0, frames
/// never decreasing, never past the depth, live cells only, never before the observer could
/// reach the cell, and every neighbour reachable in time included.
#[test]
fn range_cells_are_the_cells_reachable_in_time_nearest_first() {
    use portico_data::prefetch::range::{ObserverRange, range_cells, start_cell};
    let p = prefetcher(false);
    let g = p.graph().unwrap();
    for obs in observers(p) {
        let policy = Policy {
            frame_time_s: 0.05,
            depth_frames: 40,
            ..Policy::default()
        };
        let r = ObserverRange::new(&obs, &policy);
        let cells = range_cells(g, &r, RangeCull::Any);
        let start = start_cell(g, Vec3::from(obs.eye)).unwrap();
        assert_eq!(cells[0], (start, 0));
        assert!(
            cells.windows(2).all(|w| w[0].1 <= w[1].1),
            "frames decrease"
        );
        let listed: std::collections::HashMap<u32, u32> = cells.iter().copied().collect();
        assert_eq!(listed.len(), cells.len(), "a cell twice");
        for &(c, f) in &cells {
            assert!(g.cells[c as usize].live);
            assert!(f <= r.depth);
            assert!(f >= r.frames_to(&g.cells[c as usize].bounds).min(r.depth));
        }
        // Every live neighbour of a range cell whose portal can be reached in time is in.
        for &(c, f) in &cells {
            for &pi in &g.cells[c as usize].portals {
                let portal = &g.portals[pi as usize];
                let next = portal.other(c);
                let t = f.max(r.frames_to(&portal.rect));
                if g.cells[next as usize].live && t <= r.depth {
                    assert!(listed.get(&next).is_some_and(|&n| n <= t), "cell {next}");
                }
            }
        }
        // The culls only remove cells; a standing observer has only the cells around its eye.
        for cull in [RangeCull::Plane, RangeCull::Frustum, RangeCull::Direction] {
            let some = range_cells(g, &r, cull);
            assert!(some.iter().all(|c| listed.contains_key(&c.0)), "{cull:?}");
            assert_eq!(some[0], (start, 0));
        }
        let still = ObserverRange::new(
            &Observer {
                max_speed: 0.0,
                ..obs
            },
            &policy,
        );
        assert!(
            range_cells(g, &still, RangeCull::Any)
                .iter()
                .all(|c| c.1 == 0)
        );
    }
}

/// §5.2.2 condition 2: the lookahead stops once it claims more than the client's cache, but
/// never before everything visible now is in; a smaller cache never gets a bigger lookahead.
#[test]
fn the_lookahead_stops_at_the_cache_size_but_keeps_the_view() {
    for no_cells in [false, true] {
        let p = prefetcher(no_cells);
        let mut stopped = 0;
        for obs in observers(prefetcher(false)) {
            let mut sizes = Vec::new();
            for cache in [1u64, 64 << 10, 1 << 20, 1 << 30] {
                let policy = cache_bound(cache);
                let r = p.answer(&obs, &policy, &HashSet::new()).unwrap();
                assert!(
                    r.items.iter().any(|i| i.kind == NeedKind::Geometry),
                    "nothing at all for a {cache}-byte cache"
                );
                if !no_cells {
                    let got: HashSet<u32> = r.items.iter().map(|i| i.segment).collect();
                    for (o, coarsest) in coarsest_visible_now(p, &obs) {
                        assert!(
                            got.contains(&coarsest),
                            "a {cache}-byte cache lost visible object {o}"
                        );
                    }
                }
                sizes.push(r.lookahead_bytes);
            }
            assert!(
                sizes.windows(2).all(|w| w[0] <= w[1]),
                "no_cells {no_cells}: {sizes:?}"
            );
            stopped += usize::from(sizes[0] < sizes[3]);
        }
        assert!(
            stopped > 0,
            "no_cells {no_cells}: the cache never stopped a lookahead"
        );
    }
}

/// A policy whose lookahead only the cache stops: any range, 64 frames deep, no read cap.
fn cache_bound(cache: u64) -> Policy {
    Policy {
        cache_bytes: cache,
        read_bytes: 1 << 30,
        range_cull: RangeCull::Any,
        depth_frames: 64,
        ..Policy::default()
    }
}

/// The lookahead claims what segments occupy decoded: a compressed database reads ahead exactly
/// what the plain one does (its segments weigh a third on the wire, but not in the cache).
#[test]
fn compression_does_not_stretch_the_lookahead_past_the_cache() {
    let plain = prefetcher(false);
    let opts = BuildOptions {
        compress: true,
        ..BuildOptions::default()
    };
    let packed = tiny_with(&opts, None);
    let (mut compared, mut cut) = (0, 0);
    for obs in observers(plain) {
        let mut sizes = Vec::new();
        for cache in [64u64 << 10, 1 << 20] {
            let policy = cache_bound(cache);
            let ids = |p: &Prefetcher| -> Vec<u32> {
                let r = p.answer(&obs, &policy, &HashSet::new()).unwrap();
                let mut v: Vec<u32> = r.items.iter().map(|i| i.segment).collect();
                v.sort_unstable();
                v
            };
            let got = ids(&packed);
            assert_eq!(ids(plain), got, "cache {cache}");
            sizes.push(got.len());
            compared += 1;
        }
        // The small cache must have cut this lookahead short, or the comparison proves little.
        cut += usize::from(sizes[0] < sizes[1]);
    }
    assert!(
        compared > 10 && cut > 0,
        "{compared} answers compared, {cut} cut by the cache"
    );
}
