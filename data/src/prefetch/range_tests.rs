//! The observer range's geometry, case by case.

use super::*;

fn bx(min: [f32; 3], max: [f32; 3]) -> Aabb {
    Aabb { min, max }
}

fn observer(dir: [f32; 3], max_speed: f32, half_fov: f32) -> Observer {
    Observer {
        eye: [0.0; 3],
        dir,
        up: [0.0, 1.0, 0.0],
        velocity: [0.0; 3],
        half_fov_x: half_fov,
        half_fov_y: half_fov,
        max_speed,
        max_turn: 0.0,
        turn: [0.0; 3],
    }
}

/// 1 m/s, 100 ms frames, 20 frames: 0.1 m a frame, a 2 m range.
fn range(dir: [f32; 3], half_fov: f32) -> ObserverRange {
    let policy = Policy {
        frame_time_s: 0.1,
        depth_frames: 20,
        ..Policy::default()
    };
    ObserverRange::new(&observer(dir, 1.0, half_fov), &policy)
}

#[test]
fn distance_to_a_box_is_euclidean_and_zero_inside() {
    let b = bx([0.0; 3], [1.0; 3]);
    assert_eq!(distance_to_box(Vec3::splat(0.5), &b), 0.0);
    assert!((distance_to_box(Vec3::new(3.0, 0.5, 0.5), &b) - 2.0).abs() < 1e-6);
    assert!((distance_to_box(Vec3::new(-2.0, 0.5, 0.5), &b) - 2.0).abs() < 1e-6);
    assert!((distance_to_box(Vec3::splat(2.0), &b) - 3f32.sqrt()).abs() < 1e-6);
}

#[test]
fn the_range_is_speed_times_frames_and_frames_to_reach_round_up() {
    let r = range([1.0, 0.0, 0.0], 0.5);
    assert!((r.step - 0.1).abs() < 1e-6 && (r.radius - 2.0).abs() < 1e-5);
    assert_eq!(r.depth, 20);
    assert_eq!(r.frames_to(&bx([-1.0; 3], [1.0; 3])), 0, "inside");
    assert_eq!(r.frames_to(&bx([1.0, -1.0, -1.0], [2.0, 1.0, 1.0])), 10);
    assert_eq!(
        r.frames_to(&bx([1.05, -1.0, -1.0], [2.0, 1.0, 1.0])),
        11,
        "10.5 → 11"
    );
    let still = ObserverRange::new(&observer([1.0, 0.0, 0.0], 0.0, 0.5), &Policy::default());
    assert_eq!(
        still.frames_to(&bx([1.0, -1.0, -1.0], [2.0, 1.0, 1.0])),
        u32::MAX
    );
}

#[test]
fn in_front_counts_everything_the_range_can_reach_behind_the_eye() {
    for (axis, sign) in [
        (0, 1.0f32),
        (0, -1.0),
        (1, 1.0),
        (1, -1.0),
        (2, 1.0),
        (2, -1.0),
    ] {
        let mut dir = [0.0; 3];
        dir[axis] = sign;
        let r = range(dir, 0.5);
        // A slab across the axis at distance `at` (signed along the view direction).
        let slab_at = |at: f32| {
            let (mut min, mut max) = ([-1.0f32; 3], [1.0f32; 3]);
            let (a, b) = (at * sign, (at + 0.5) * sign);
            min[axis] = a.min(b);
            max[axis] = a.max(b);
            bx(min, max)
        };
        assert!(r.in_front(&slab_at(5.0)), "ahead, axis {axis} sign {sign}");
        assert!(
            r.in_front(&slab_at(-2.4)),
            "1.9 m behind, within the 2 m range"
        );
        assert!(!r.in_front(&slab_at(-3.0)), "2.5 m behind, out of reach");
        assert!(!r.range_keeps(RangeCull::Plane, &slab_at(-3.0)));
        assert!(r.range_keeps(RangeCull::Any, &slab_at(-3.0)));
        assert!(!r.lookahead_keeps(LookaheadCull::Plane, &slab_at(-3.0)));
        assert!(r.lookahead_keeps(LookaheadCull::Any, &slab_at(-3.0)));
    }
}

#[test]
fn the_frustum_and_the_ray_keep_what_lies_ahead() {
    let r = range([1.0, 0.0, 0.0], 0.4);
    assert!(r.frustum.is_some());
    let ahead = bx([10.0, -0.5, -0.5], [11.0, 0.5, 0.5]);
    let aside = bx([10.0, -0.5, 30.0], [11.0, 0.5, 31.0]);
    let behind = bx([-11.0, -0.5, -0.5], [-10.0, 0.5, 0.5]);
    assert!(r.in_frustum(&ahead) && !r.in_frustum(&aside) && !r.in_frustum(&behind));
    assert!(r.on_ray(&ahead) && !r.on_ray(&aside) && !r.on_ray(&behind));
    let beside_the_ray = bx([10.0, -0.5, 2.0], [11.0, 0.5, 3.0]);
    assert!(r.in_frustum(&beside_the_ray) && !r.on_ray(&beside_the_ray));
    for (cull, keeps) in [
        (RangeCull::Any, [true, true, true]),
        (RangeCull::Plane, [true, true, false]),
        (RangeCull::Frustum, [true, false, false]),
        (RangeCull::Direction, [true, false, false]),
    ] {
        let got = [ahead, aside, behind].map(|b| r.range_keeps(cull, &b));
        assert_eq!(got, keeps, "{cull:?}");
    }
    assert!(r.lookahead_keeps(LookaheadCull::Frustum, &beside_the_ray));
    assert!(!r.lookahead_keeps(LookaheadCull::Frustum, &aside));
    // A view too wide for a frustum falls back to the plane.
    let wide = range([1.0, 0.0, 0.0], 1.6);
    assert!(wide.frustum.is_none());
    assert!(wide.in_frustum(&aside) && !wide.in_frustum(&behind));
}
