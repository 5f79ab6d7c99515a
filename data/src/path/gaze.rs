//! Where a walking person looks: ahead along the way they are going, not at the wall beside
//! them. A person's gaze leads their steps — eyes and head turn towards a new direction about a
//! second before the body does (Grasso et al. 1998, "Eye-head coordination for the steering of
//! locomotion in humans: an anticipatory synergy") — so the view is aimed at the point of the
//! path [`LOOK_AHEAD_M`] ahead of the eye, as a pure-pursuit tracker aims at its look-ahead
//! point (Coulter 1992, "Implementation of the Pure Pursuit Path Tracking Algorithm", §2).
//! Turning faster than the person's turn rate slows the walk instead of snapping the view, and
//! a sharp turn ([`SHARP_TURN_DEGREES`], as at the end of a dead end) is walked up to and made
//! on the spot.
//!
//! All lengths in metres, times in seconds, angles in radians unless named in degrees.

use super::{CameraPath, Keyframe};
use glam::Vec3;

/// How far ahead along the path the eye looks (2 s at a walking pace of 1.5 m/s).
pub const LOOK_AHEAD_M: f32 = 3.0;
/// Path length between keyframes where the path runs straight.
pub const STEP_M: f32 = 0.5;
/// A turn of the path sharper than this is made standing, once the corner is reached.
pub const SHARP_TURN_DEGREES: f32 = 100.0;
/// The view is tilted up or down at most this much (climbing a stair, the eye looks ahead, not
/// at the ceiling).
pub const MAX_PITCH_DEGREES: f32 = 25.0;

/// Keyframes walking `points` at `speed` m/s, looking ahead along them, turning at most `turn`
/// rad/s. The eye passes through every point (consecutive points are joined by straight
/// lines, so the eye stays where the points say it may walk). `speed` and `turn` must be
/// positive.
pub fn walk(kind: &str, points: &[Vec3], speed: f32, turn: f32) -> CameraPath {
    let line = Polyline::new(points);
    let sharp = line.sharp_corners(SHARP_TURN_DEGREES.to_radians());
    // Every corner, and a sample every STEP_M between them (not within a twentieth of a step
    // of a corner, which is kept exactly).
    let near_corner = |s: f32| {
        let i = line.at.partition_point(|&c| c < s);
        [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|j| line.at.get(j))
            .any(|&c| (c - s).abs() < 0.05 * STEP_M)
    };
    let steps = (line.len() / STEP_M).floor() as usize;
    let mut samples: Vec<f32> = line.at.clone();
    samples.extend(
        (1..=steps)
            .map(|i| i as f32 * STEP_M)
            .filter(|&s| !near_corner(s)),
    );
    samples.sort_by(f32::total_cmp);

    let mut keyframes: Vec<Keyframe> = Vec::with_capacity(samples.len() + sharp.len());
    let mut t = 0.0f32;
    let mut dir = line.first_heading().unwrap_or(Vec3::NEG_Z);
    let mut last_eye = line.point(0.0);
    for &s in &samples {
        let eye = line.point(s);
        let walked = eye.distance(last_eye) / speed;
        last_eye = eye;
        // Look at the point ahead, but not round a sharp corner before reaching it.
        let at_sharp = sharp.iter().any(|&c| (c - s).abs() < 1e-3);
        let horizon = sharp
            .iter()
            .copied()
            .find(|&c| c > s + 1e-3)
            .unwrap_or(f32::INFINITY);
        let wanted = aim(eye, line.point((s + LOOK_AHEAD_M).min(horizon)), dir);
        if keyframes.is_empty() {
            // Start looking ahead.
        } else if at_sharp {
            // Arrive looking as before, then turn standing.
            t += walked;
            keyframes.push(Keyframe {
                t,
                eye: eye.into(),
                dir: dir.into(),
            });
            t += dir.angle_between(wanted) / turn;
        } else {
            // Walking on: the step takes at least as long as its turn.
            t += walked.max(dir.angle_between(wanted) / turn);
        }
        dir = wanted;
        keyframes.push(Keyframe {
            t,
            eye: eye.into(),
            dir: dir.into(),
        });
    }
    CameraPath {
        kind: kind.into(),
        keyframes,
    }
}

/// The unit view direction from `eye` towards `target`: its heading, tilted at most
/// [`MAX_PITCH_DEGREES`]. Where the target is (nearly) straight above, below or at the eye,
/// the heading of `before` is kept.
fn aim(eye: Vec3, target: Vec3, before: Vec3) -> Vec3 {
    let d = target - eye;
    let flat = Vec3::new(d.x, 0.0, d.z);
    let heading = if flat.length() > 0.2 {
        flat.normalize()
    } else {
        Vec3::new(before.x, 0.0, before.z)
            .try_normalize()
            .unwrap_or(Vec3::NEG_Z)
    };
    if d.length() < 0.2 {
        return heading;
    }
    let max = MAX_PITCH_DEGREES.to_radians();
    let pitch = d.y.atan2(flat.length()).clamp(-max, max);
    (heading * pitch.cos() + Vec3::Y * pitch.sin()).normalize()
}

/// A path of straight pieces, measured along its length.
struct Polyline {
    /// Its corners, without repeats.
    points: Vec<Vec3>,
    /// Length along the path to each corner (the first is 0).
    at: Vec<f32>,
}

impl Polyline {
    fn new(points: &[Vec3]) -> Polyline {
        let mut kept: Vec<Vec3> = Vec::with_capacity(points.len());
        for &p in points {
            if kept.last().is_none_or(|l| l.distance(p) > 1e-3) {
                kept.push(p);
            }
        }
        if kept.is_empty() {
            kept.push(Vec3::ZERO);
        }
        let mut at = vec![0.0];
        for w in kept.windows(2) {
            at.push(at[at.len() - 1] + w[0].distance(w[1]));
        }
        Polyline { points: kept, at }
    }

    fn len(&self) -> f32 {
        self.at[self.at.len() - 1]
    }

    /// The point `s` metres along (clamped to the path).
    fn point(&self, s: f32) -> Vec3 {
        let i = self.at.partition_point(|&a| a <= s);
        if i == 0 {
            return self.points[0];
        }
        if i >= self.points.len() {
            return self.points[self.points.len() - 1];
        }
        let (a, b) = (self.at[i - 1], self.at[i]);
        let f = ((s - a) / (b - a).max(1e-6)).clamp(0.0, 1.0);
        self.points[i - 1].lerp(self.points[i], f)
    }

    /// The heading of the first piece that is not straight up or down.
    fn first_heading(&self) -> Option<Vec3> {
        self.points.windows(2).find_map(|w| flat(w[1] - w[0]))
    }

    /// Lengths along the path of the corners where its heading turns by more than `angle`
    /// (pieces straight up or down, through a stair's hole, carry the heading over).
    fn sharp_corners(&self, angle: f32) -> Vec<f32> {
        let mut corners = Vec::new();
        let mut heading: Option<Vec3> = None;
        for (i, w) in self.points.windows(2).enumerate() {
            let Some(h) = flat(w[1] - w[0]) else {
                continue;
            };
            if heading.is_some_and(|before| before.angle_between(h) > angle) {
                corners.push(self.at[i]);
            }
            heading = Some(h);
        }
        corners
    }
}

/// The horizontal unit direction of `d`, unless it is (nearly) vertical.
fn flat(d: Vec3) -> Option<Vec3> {
    let f = Vec3::new(d.x, 0.0, d.z);
    (f.length() > 0.05).then(|| f.normalize())
}

/// Keyframes along `points` at `speed` m/s, looking along the horizontal direction of travel,
/// pausing at corners long enough to turn at `turn` rad/s: the benchmarks' tour
/// ([`super::generate`]), on which their figures were measured.
pub fn along_travel(kind: &str, points: &[Vec3], speed: f32, turn: f32) -> CameraPath {
    let mut keyframes = Vec::new();
    let mut t = 0.0f32;
    let mut dir = Vec3::X;
    for w in points.windows(2) {
        let step = w[1] - w[0];
        let flat = Vec3::new(step.x, 0.0, step.z);
        let new_dir = if flat.length() > 1e-3 {
            flat.normalize()
        } else {
            dir
        };
        if keyframes.is_empty() {
            dir = new_dir;
        }
        // Turn on the spot, then walk.
        let angle = dir.angle_between(new_dir);
        if angle > 1e-3 || keyframes.is_empty() {
            keyframes.push(Keyframe {
                t,
                eye: w[0].into(),
                dir: dir.into(),
            });
            t += angle / turn;
            dir = new_dir;
        }
        keyframes.push(Keyframe {
            t,
            eye: w[0].into(),
            dir: dir.into(),
        });
        t += step.length() / speed;
    }
    if let Some(last) = points.last() {
        keyframes.push(Keyframe {
            t,
            eye: (*last).into(),
            dir: dir.into(),
        });
    }
    CameraPath {
        kind: kind.into(),
        keyframes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn angle_at(p: &CameraPath, t: f32, towards: Vec3) -> f32 {
        p.sample(t).1.angle_between(towards).to_degrees()
    }

    #[test]
    fn the_view_turns_into_a_corner_before_the_eye_reaches_it() {
        // 6 m along X, then 6 m along Z: a right-angled corner, not a sharp one.
        let pts = [
            Vec3::ZERO,
            Vec3::new(6.0, 0.0, 0.0),
            Vec3::new(6.0, 0.0, 6.0),
        ];
        let p = walk("t", &pts, 1.5, std::f32::consts::FRAC_PI_2);
        assert!(p.validate().is_ok());
        // Far from the corner the eye looks along X.
        assert!(angle_at(&p, 0.5, Vec3::X) < 1.0);
        // Reaching the corner, it already looks into the second leg, halfway round or more.
        let corner = p
            .keyframes
            .iter()
            .find(|k| Vec3::from(k.eye).distance(pts[1]) < 1e-4)
            .unwrap();
        let d = Vec3::from(corner.dir);
        assert!(d.angle_between(Vec3::Z).to_degrees() < 50.0, "{d}");
        // It never stops: every keyframe moves on.
        assert!(
            p.keyframes
                .windows(2)
                .all(|w| Vec3::from(w[0].eye).distance(w[1].eye.into()) > 0.1)
        );
        // At the end it looks along the last leg.
        assert!(angle_at(&p, p.duration(), Vec3::Z) < 1.0);
    }

    #[test]
    fn a_sharp_turn_is_walked_up_to_looking_ahead_and_made_standing() {
        // Into a dead end 4 m long and back out.
        let pts = [
            Vec3::ZERO,
            Vec3::new(4.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 0.1),
        ];
        let turn = std::f32::consts::FRAC_PI_2;
        let p = walk("t", &pts, 1.0, turn);
        let at_end: Vec<&Keyframe> = p
            .keyframes
            .iter()
            .filter(|k| Vec3::from(k.eye).distance(pts[1]) < 1e-4)
            .collect();
        assert_eq!(at_end.len(), 2, "{:#?}", p.keyframes);
        // Arrives looking forward, leaves looking back, after turning at the turn rate.
        assert!(
            Vec3::from(at_end[0].dir)
                .angle_between(Vec3::X)
                .to_degrees()
                < 1.0
        );
        assert!(
            Vec3::from(at_end[1].dir)
                .angle_between(Vec3::NEG_X)
                .to_degrees()
                < 5.0
        );
        let turned = Vec3::from(at_end[0].dir).angle_between(at_end[1].dir.into());
        assert!((at_end[1].t - at_end[0].t - turned / turn).abs() < 1e-3);
        // Walking in, the view never looks back.
        assert!(
            p.keyframes
                .iter()
                .take_while(|k| k.t < at_end[0].t)
                .all(|k| k.dir[0] > 0.99)
        );
    }

    #[test]
    fn a_corner_just_past_a_step_is_kept_and_its_sharp_turn_made_standing() {
        let pts = [
            Vec3::ZERO,
            Vec3::new(4.01, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 0.1),
        ];
        let p = walk("t", &pts, 1.0, 1.0);
        let at_end = p
            .keyframes
            .iter()
            .filter(|k| Vec3::from(k.eye).distance(pts[1]) < 1e-4)
            .count();
        assert_eq!(at_end, 2, "{:#?}", p.keyframes);
        // The last point too, 0.01 m past a step.
        let last = p.keyframes.last().unwrap();
        assert!(Vec3::from(last.eye).distance(pts[2]) < 1e-4);
    }

    #[test]
    fn speed_and_turn_rate_are_kept() {
        let pts = [
            Vec3::ZERO,
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::new(5.0, 0.0, 5.0),
            Vec3::new(0.0, 0.0, 5.0),
            Vec3::new(0.0, 3.0, 5.0),
            Vec3::new(0.0, 3.0, 0.0),
        ];
        let (speed, turn) = (1.5, 1.0);
        let p = walk("t", &pts, speed, turn);
        let length: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
        assert!(p.duration() >= length / speed - 1e-3);
        for w in p.keyframes.windows(2) {
            let dt = w[1].t - w[0].t;
            let moved = Vec3::from(w[0].eye).distance(w[1].eye.into());
            let turned = Vec3::from(w[0].dir).angle_between(w[1].dir.into());
            assert!(moved <= speed * dt + 1e-3, "{w:?}");
            assert!(turned <= turn * dt + 1e-3, "{w:?}");
            let pitch = w[1].dir[1].asin().to_degrees().abs();
            assert!(pitch <= MAX_PITCH_DEGREES + 0.01, "{w:?}");
        }
        // The eye passes through every point.
        for q in pts {
            assert!(
                p.keyframes
                    .iter()
                    .any(|k| Vec3::from(k.eye).distance(q) < 1e-4)
            );
        }
        // Climbing the stair's hole it looks ahead and up, not at the ceiling.
        let (_, d) = p.sample(p.keyframes.iter().find(|k| k.eye[1] > 1.4).unwrap().t);
        assert!(d.y > 0.0 && d.y < 0.5, "{d}");
    }

    #[test]
    fn degenerate_paths_still_give_a_path() {
        let p = walk("t", &[Vec3::ONE], 1.0, 1.0);
        assert_eq!(p.keyframes.len(), 1);
        assert!(p.validate().is_ok());
        let p = walk("t", &[Vec3::ZERO, Vec3::Y * 3.0], 1.0, 1.0);
        assert!(p.validate().is_ok());
        assert!((p.duration() - 3.0).abs() < 1e-3);
    }

    #[test]
    fn paths_along_travel_respect_speed_and_turn_rate() {
        let pts = [
            Vec3::ZERO,
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(3.0, 0.0, 4.0),
        ];
        let p = along_travel("t", &pts, 1.0, std::f32::consts::FRAC_PI_2);
        // 3 m + a 90° turn at 90°/s + 4 m, at 1 m/s.
        assert!((p.duration() - 8.0).abs() < 1e-4, "{}", p.duration());
        assert!(p.validate().is_ok());
    }
}
