//! Lights: desk lamps, floor lamps and the ceiling lights hung in every room.

use super::{BLACK, LIGHT, METALS, Params, Shape, WHITE, rgb};
use crate::mesh::Axis;

pub(super) fn desk_lamp(p: &mut Params, s: &mut Shape) {
    let (metal, shade) = (
        p.pick(&METALS),
        p.pick(&[rgb(30, 90, 40), rgb(200, 40, 30), BLACK, WHITE]),
    );
    let (h, reach) = (p.f(0.3, 0.45), p.f(0.15, 0.28));
    let sides = p.pick(&[8, 12, 16]);
    let x0 = -reach / 2.0;
    s.cyl(Axis::Y, [x0, 0.0, 0.0], 0.02, 0.075, sides, metal);
    s.cyl(Axis::Y, [x0, 0.02, 0.0], h, 0.01, 8, metal);
    s.cyl(Axis::X, [x0, h, 0.0], reach, 0.01, 8, metal);
    if s.fine() {
        s.ball([x0, h, 0.0], [0.018; 3], 6, metal);
    }
    s.cone(
        [x0 + reach, h - 0.14, 0.0],
        0.13,
        (0.09, 0.025),
        sides,
        shade,
    );
    if s.fine() {
        s.ball([x0 + reach, h - 0.11, 0.0], [0.03; 3], 6, LIGHT);
    }
}

pub(super) fn floor_lamp(p: &mut Params, s: &mut Shape) {
    let (metal, shade) = (
        p.pick(&METALS),
        p.pick(&[WHITE, rgb(220, 200, 150), rgb(150, 40, 30)]),
    );
    let h = p.f(1.4, 1.8);
    s.cyl(Axis::Y, [0.0, 0.0, 0.0], 0.03, 0.16, 20, metal);
    s.cyl(Axis::Y, [0.0, 0.03, 0.0], h - 0.3, 0.015, 8, metal);
    s.cone([0.0, h - 0.3, 0.0], 0.3, (0.22, 0.13), 20, shade);
    if s.fine() {
        s.ball([0.0, h - 0.2, 0.0], [0.04; 3], 8, LIGHT);
    }
}

/// A ceiling light hanging *down* from y = 0 (placed at ceiling height): a fluorescent troffer
/// with tubes, or a round pendant.
pub(super) fn ceiling_light(p: &mut Params, s: &mut Shape) {
    let pendant = p.chance(0.35);
    let frame = p.pick(&[WHITE, METALS[2], METALS[0]]);
    if pendant {
        let r = p.f(0.2, 0.3);
        s.cyl(Axis::Y, [0.0, -0.6, 0.0], 0.6, 0.006, 6, METALS[1]);
        s.cone([0.0, -0.8, 0.0], 0.2, (r, 0.05), 16, frame);
        if s.fine() {
            s.ball([0.0, -0.75, 0.0], [0.05; 3], 8, LIGHT);
        }
        return;
    }
    let (w, d) = (p.f(1.2, 1.5), p.f(0.3, 0.6));
    let tubes = p.n(2, 3);
    s.bx([-w / 2.0, -0.08, -d / 2.0], [w / 2.0, 0.0, d / 2.0], frame);
    if s.medium() {
        s.bx(
            [-w / 2.0 + 0.02, -0.09, -d / 2.0 + 0.02],
            [w / 2.0 - 0.02, -0.08, d / 2.0 - 0.02],
            LIGHT,
        );
    }
    if s.fine() {
        for k in 0..tubes {
            let z = -d / 2.0 + d * (k as f32 + 1.0) / (tubes + 1) as f32;
            s.cyl(
                Axis::X,
                [-w / 2.0 + 0.05, -0.1, z],
                w - 0.1,
                0.013,
                6,
                LIGHT,
            );
        }
    }
}
