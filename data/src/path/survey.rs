//! Standard paths for models without rooms: an object, a machine, a site with no walls (the
//! cells are one box or an open grid, and a tour between rooms has nowhere to go). The observer
//! circles the model at a distance that fits it in view ([`orbit`]), then flies straight through
//! it along the line that passes through the least solid ([`flythrough`]).

use super::{CameraPath, Keyframe};
use crate::geometry::Aabb;
use glam::Vec3;

/// Vertical half field of view the orbit distance is chosen for (radians): a 60° view.
const HALF_FOV: f32 = 0.52;
/// Seconds per orbit, at most and at least (a small object is not circled in one second, a
/// campus not in ten minutes).
pub const ORBIT_SECONDS: (f32, f32) = (12.0, 60.0);

/// One turn around the model's bounds, looking at their centre from a little above, at a
/// distance that keeps the whole model in view; `speed` in m/s sets the pace within
/// [`ORBIT_SECONDS`].
pub fn orbit(bounds: &Aabb, speed: f32) -> CameraPath {
    let c = bounds.center();
    let radius = (bounds.size().length() * 0.5).max(0.5);
    let distance = radius / HALF_FOV.sin() * 1.1;
    let height = c.y + radius * 0.35;
    let period = (std::f32::consts::TAU * distance / speed.max(0.01))
        .clamp(ORBIT_SECONDS.0, ORBIT_SECONDS.1);
    let steps = 48;
    let keyframes = (0..=steps)
        .map(|i| {
            let a = std::f32::consts::TAU * i as f32 / steps as f32;
            let eye = Vec3::new(c.x + distance * a.cos(), height, c.z + distance * a.sin());
            Keyframe {
                t: period * i as f32 / steps as f32,
                eye: eye.into(),
                dir: (c - eye).normalize().into(),
            }
        })
        .collect();
    CameraPath {
        kind: "orbit".into(),
        keyframes,
    }
}

/// A straight flight through the model from outside to outside, along its longer horizontal
/// axis, on the line (of a 9 × 9 grid across the bounds) that passes through the least of the
/// objects' boxes, looking along the flight; at `speed` m/s (at least a tenth of the model's
/// length per second).
pub fn flythrough(bounds: &Aabb, objects: &[Aabb], speed: f32) -> CameraPath {
    let size = bounds.size();
    let along = if size.x >= size.z { 0 } else { 2 };
    let across = 2 - along;
    let margin = (size[along] * 0.25).max(1.0);
    let (start, end) = (bounds.min[along] - margin, bounds.max[along] + margin);
    let samples = 64;
    let point = |u: f32, v: f32, t: f32| {
        let mut p = Vec3::ZERO;
        p[along] = start + (end - start) * t;
        p[1] = bounds.min[1] + size.y * u;
        p[across] = bounds.min[across] + size[across] * v;
        p
    };
    let inside = |p: Vec3| {
        objects
            .iter()
            .any(|o| (0..3).all(|k| o.min[k] < p[k] && p[k] < o.max[k]))
    };
    let mut best = (usize::MAX, 0.5f32, 0.5f32);
    for i in 1..10 {
        for j in 1..10 {
            let (u, v) = (i as f32 / 10.0, j as f32 / 10.0);
            let solid = (0..=samples)
                .filter(|&k| inside(point(u, v, k as f32 / samples as f32)))
                .count();
            // Least solid first; among equals, nearest the middle, a little below it.
            let key = |u: f32, v: f32| (u - 0.4).abs() + (v - 0.5).abs();
            if solid < best.0 || (solid == best.0 && key(u, v) < key(best.1, best.2)) {
                best = (solid, u, v);
            }
        }
    }
    let (a, b) = (point(best.1, best.2, 0.0), point(best.1, best.2, 1.0));
    let speed = speed.max((end - start) / 10.0).max(0.01);
    let dir: [f32; 3] = (b - a).normalize().into();
    CameraPath {
        kind: "flythrough".into(),
        keyframes: vec![
            Keyframe {
                t: 0.0,
                eye: a.into(),
                dir,
            },
            Keyframe {
                t: (b - a).length() / speed,
                eye: b.into(),
                dir,
            },
        ],
    }
}

/// `first` then `second`, the second shifted in time to start when the first ends, with a turn
/// of `turn_s` seconds between them.
pub fn then(first: CameraPath, second: CameraPath, turn_s: f32) -> CameraPath {
    let offset = first.duration() + turn_s;
    let mut keyframes = first.keyframes;
    keyframes.extend(second.keyframes.into_iter().map(|mut k| {
        k.t += offset;
        k
    }));
    CameraPath {
        kind: format!("{}+{}", first.kind, second.kind),
        keyframes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bx(min: [f32; 3], max: [f32; 3]) -> Aabb {
        Aabb { min, max }
    }

    #[test]
    fn the_orbit_keeps_the_model_in_view_from_outside() {
        let b = bx([0.0, 0.0, 0.0], [4.0, 2.0, 6.0]);
        let p = orbit(&b, 1.5);
        assert!(p.validate().is_ok());
        assert!((ORBIT_SECONDS.0..=ORBIT_SECONDS.1).contains(&p.duration()));
        let r = b.size().length() * 0.5;
        for k in &p.keyframes {
            let eye = Vec3::from(k.eye);
            let to_centre = b.center() - eye;
            // Outside the bounds, looking at the centre, far enough for the bounding sphere to
            // fit the view.
            assert!((0..3).any(|i| eye[i] < b.min[i] || eye[i] > b.max[i]));
            assert!(Vec3::from(k.dir).dot(to_centre.normalize()) > 0.999);
            assert!((r / to_centre.length()).asin() <= HALF_FOV + 1e-3);
        }
    }

    #[test]
    fn the_flythrough_avoids_solid_objects() {
        // A block filling the lower half: the flight passes above it.
        let b = bx([0.0, 0.0, 0.0], [10.0, 4.0, 4.0]);
        let block = bx([2.0, 0.0, 0.0], [8.0, 2.5, 4.0]);
        let p = flythrough(&b, &[block], 1.5);
        assert!(p.validate().is_ok());
        for t in 0..=100 {
            let (eye, _) = p.sample(p.duration() * t as f32 / 100.0);
            assert!(
                !(eye.y < 2.5 && eye.x > 2.0 && eye.x < 8.0),
                "inside the block at {eye}"
            );
        }
        let (a, z) = (
            Vec3::from(p.keyframes[0].eye),
            Vec3::from(p.keyframes[1].eye),
        );
        assert!(
            a.x < 0.0 && z.x > 10.0,
            "from outside to outside: {a} → {z}"
        );
    }
}
