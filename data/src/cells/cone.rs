//! Exact box-against-cone tests: whether an object's box meets a view frustum or a wedge
//! through portals (Funkhouser §4.1.2's eye-to-object culling), without the plane-by-plane
//! test's false positives, by the separating-axis theorem (Gottschalk, Lin & Manocha 1996's
//! test for boxes, with the cone's edge rays for edges).

use super::polytope::Plane;
use crate::geometry::Aabb;
use glam::Vec3;

/// Whether a box meets the cone of the halfspaces `planes` (all through `apex`): [`Cone::meets`].
/// For many boxes, make the [`Cone`] once.
pub fn cone_meets(apex: Vec3, planes: &[Plane], b: &Aabb) -> bool {
    Cone::new(apex, planes).meets(b)
}

/// A cone of halfspaces through one apex (a frustum, or a wedge through portals) with its edge
/// rays, for [`Cone::meets`].
#[derive(Debug, Clone)]
pub struct Cone<'a> {
    apex: Vec3,
    planes: &'a [Plane],
    /// The edge rays (unit); `None` where the plane-by-plane test is all there is (fewer than
    /// three planes, or a cone holding a whole line).
    edges: Option<Vec<Vec3>>,
}

impl<'a> Cone<'a> {
    /// The cone of `planes` (all through `apex`).
    pub fn new(apex: Vec3, planes: &'a [Plane]) -> Cone<'a> {
        Cone {
            apex,
            planes,
            edges: edge_rays(planes),
        }
    }

    /// Whether a box meets the cone, without the plane-by-plane test's false positives (a
    /// large box beside or behind the apex that meets each plane's inside but not the cone): a
    /// separating-axis test over the planes' normals, the box's axes and the cross products
    /// of the box's edges with the cone's edge rays (the cone is unbounded: its extent along
    /// an axis is infinite on each side some edge ray points to). Within 2 mm of touching
    /// counts as meeting.
    pub fn meets(&self, b: &Aabb) -> bool {
        if !self.planes.iter().all(|p| p.touches_box(b)) {
            return false;
        }
        let Some(edges) = &self.edges else {
            return true;
        };
        let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
        let centre = (lo + hi) * 0.5;
        if self.planes.iter().all(|p| p.eval(centre) <= 0.0) {
            return true; // the common case: the box's centre is inside
        }
        let half = (hi - lo) * 0.5;
        let corner_inside = (0..8).any(|i| {
            let pick = |k: usize| if i >> k & 1 == 1 { hi[k] } else { lo[k] };
            let p = Vec3::new(pick(0), pick(1), pick(2));
            self.planes.iter().all(|pl| pl.eval(p) <= 0.0)
        });
        if corner_inside {
            return true;
        }
        let separates = |axis: Vec3| {
            let len = axis.length();
            if len < 1e-6 {
                return false;
            }
            let axis = axis / len;
            let c = axis.dot(centre);
            let r = axis.abs().dot(half);
            let at = axis.dot(self.apex);
            // An edge at right angles to the axis (the axis is made from it) adds nothing; one
            // within 1e-6 of it moves the cone's extent by at most a millimetre a kilometre
            // out, inside the margin.
            let below = edges.iter().any(|e| e.dot(axis) < -1e-6);
            let above = edges.iter().any(|e| e.dot(axis) > 1e-6);
            (!above && c - r > at + MEETS_MARGIN) || (!below && c + r < at - MEETS_MARGIN)
        };
        let axes = [Vec3::X, Vec3::Y, Vec3::Z];
        !axes.iter().any(|&a| separates(a))
            && !edges
                .iter()
                .any(|e| axes.iter().any(|&a| separates(e.cross(a))))
    }
}

/// The edge rays of the cone of `planes` (where two planes meet inside all the others);
/// `None` for fewer than three planes, fewer than three rays, or a cone holding a line.
fn edge_rays(planes: &[Plane]) -> Option<Vec<Vec3>> {
    if planes.len() < 3 {
        return None;
    }
    let n: Vec<Vec3> = planes
        .iter()
        .map(|p| Vec3::from(p.normal).normalize_or_zero())
        .collect();
    let mut edges: Vec<Vec3> = Vec::new();
    for i in 0..n.len() {
        for j in i + 1..n.len() {
            let d = n[i].cross(n[j]);
            if d.length_squared() < 1e-12 {
                continue;
            }
            let d = d.normalize();
            let inside = |v: Vec3| n.iter().all(|m| m.dot(v) <= 1e-5);
            match (inside(d), inside(-d)) {
                (true, true) => return None, // the cone holds a line
                (true, false) => edges.push(d),
                (false, true) => edges.push(-d),
                (false, false) => {}
            }
        }
    }
    (edges.len() >= 3).then_some(edges)
}

/// How far outside a cone a box may be and still meet it ([`cone_meets`]), metres.
pub const MEETS_MARGIN: f32 = 2e-3;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cells::realtime::Frustum;

    /// A wide slab behind the eye meets each side plane's inside (so `touches` takes it: the
    /// case that made a shared predicted answer miss what one observer's took) but not the
    /// frustum.
    #[test]
    fn meets_drops_a_box_behind_the_eye_that_touches_takes() {
        let view = Frustum::new(Vec3::ZERO, Vec3::Z, Vec3::Y, 0.6, 0.45);
        let behind = Aabb {
            min: [-10.0, -10.0, -5.0],
            max: [10.0, 10.0, -4.0],
        };
        assert!(view.touches(&behind));
        assert!(!view.meets(&behind));
        let ahead = Aabb {
            min: [-1.0, -1.0, 6.0],
            max: [0.0, 0.0, 7.0],
        };
        assert!(view.meets(&ahead));
        let beside = Aabb {
            min: [9.0, -1.0, 1.0],
            max: [10.0, 1.0, 2.0],
        };
        assert!(!view.meets(&beside));
    }

    /// `meets` is never false where a point of the box is inside the frustum, and never true
    /// where `touches` is false.
    #[test]
    fn meets_keeps_every_box_with_a_point_inside() {
        let mut seed = 7u32;
        let mut rnd = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let (mut kept, mut dropped) = (0, 0);
        for _ in 0..3000 {
            let dir = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5);
            let view = Frustum::new(Vec3::ZERO, dir, Vec3::Y, 0.2 + rnd(), 0.2 + rnd());
            let c = Vec3::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5) * 10.0;
            let h = Vec3::new(rnd(), rnd(), rnd()) * 3.0;
            let b = Aabb {
                min: (c - h).into(),
                max: (c + h).into(),
            };
            let inside = |p: Vec3| view.planes.iter().all(|pl| pl.eval(p) <= 0.0);
            let mut any = false;
            for i in 0..=6 {
                for j in 0..=6 {
                    for k in 0..=6 {
                        let t = Vec3::new(i as f32, j as f32, k as f32) / 6.0;
                        any |= inside(c - h + 2.0 * h * t);
                    }
                }
            }
            if any {
                assert!(view.meets(&b), "{dir} {b:?}");
            }
            if !view.touches(&b) {
                assert!(!view.meets(&b));
            }
            if view.touches(&b) && !view.meets(&b) {
                dropped += 1;
            } else if view.meets(&b) {
                kept += 1;
            }
        }
        // It is tighter than `touches` on some boxes, and keeps many.
        assert!(dropped > 10 && kept > 100, "{dropped} {kept}");
    }
}
