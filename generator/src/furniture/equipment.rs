//! Office and lab equipment: monitors, computers, keyboards, telephones, projectors and
//! water coolers.

use super::{BLACK, METALS, Params, Shape, WHITE, rgb};
use crate::mesh::Axis;

pub(super) fn monitor(p: &mut Params, s: &mut Shape) {
    let (w, h) = (p.f(0.45, 0.6), p.f(0.3, 0.4));
    let body = p.pick(&[BLACK, rgb(200, 200, 195), METALS[1]]);
    let hw = w / 2.0;
    s.cyl(Axis::Y, [0.0, 0.0, 0.0], 0.015, 0.1, 12, body);
    s.cyl(Axis::Y, [0.0, 0.015, -0.03], 0.12, 0.02, 8, body);
    s.bx([-hw, 0.12, -0.05], [hw, 0.12 + h, 0.0], body);
    if s.medium() {
        s.bx(
            [-hw + 0.015, 0.135, 0.0],
            [hw - 0.015, 0.105 + h, 0.005],
            rgb(20, 30, 45),
        );
    }
    if s.fine() {
        for k in 0..3 {
            let x = hw - 0.05 - 0.03 * k as f32;
            s.cyl(Axis::Z, [x, 0.127, 0.0], 0.006, 0.005, 8, rgb(90, 200, 90));
        }
    }
}

pub(super) fn computer(p: &mut Params, s: &mut Shape) {
    let (h, d) = (p.f(0.36, 0.46), p.f(0.4, 0.5));
    let body = p.pick(&[BLACK, rgb(200, 200, 195), METALS[0]]);
    s.bx([-0.09, 0.02, -d / 2.0], [0.09, h, d / 2.0], body);
    if s.medium() {
        s.bx(
            [-0.07, h - 0.1, d / 2.0],
            [0.07, h - 0.05, d / 2.0 + 0.005],
            METALS[1],
        );
        s.bx(
            [-0.07, h - 0.17, d / 2.0],
            [0.07, h - 0.12, d / 2.0 + 0.005],
            METALS[1],
        );
    }
    if s.fine() {
        s.cyl(
            Axis::Z,
            [0.0, h - 0.25, d / 2.0],
            0.008,
            0.012,
            12,
            rgb(90, 200, 90),
        );
        for (x, z) in [(-0.07, -0.15), (0.07, -0.15), (-0.07, 0.15), (0.07, 0.15)] {
            s.cyl(Axis::Y, [x, 0.0, z * d * 2.0], 0.02, 0.012, 8, BLACK);
        }
    }
}

pub(super) fn keyboard(p: &mut Params, s: &mut Shape) {
    let w = p.f(0.42, 0.48);
    let keys = p.pick(&[BLACK, rgb(210, 210, 200)]);
    let hw = w / 2.0;
    s.bx([-hw, 0.0, -0.075], [hw, 0.02, 0.075], METALS[1]);
    for row in 0..5 {
        let z = -0.06 + 0.025 * row as f32;
        if s.fine() {
            for seg in 0..2 {
                let x = -hw + 0.02 + (w - 0.04) / 2.0 * seg as f32;
                s.bx(
                    [x, 0.02, z],
                    [x + (w - 0.04) / 2.0 - 0.01, 0.03, z + 0.02],
                    keys,
                );
            }
        } else if s.medium() {
            s.bx([-hw + 0.02, 0.02, z], [hw - 0.02, 0.03, z + 0.02], keys);
        }
    }
}

/// A desk telephone: body, handset and (finest LOD) keypad buttons.
pub(super) fn phone(p: &mut Params, s: &mut Shape) {
    let c = p.pick(&[BLACK, rgb(210, 205, 190)]);
    s.bx([-0.1, 0.0, -0.1], [0.1, 0.05, 0.1], c);
    s.bx([-0.1, 0.05, -0.09], [0.1, 0.08, -0.03], c);
    if s.fine() {
        for k in 0..4 {
            let z = -0.01 + 0.025 * k as f32;
            s.bx([-0.05, 0.05, z], [0.05, 0.055, z + 0.015], METALS[0]);
        }
    }
}

pub(super) fn projector(p: &mut Params, s: &mut Shape) {
    let body = p.pick(&[rgb(210, 210, 205), METALS[1]]);
    s.bx([-0.15, 0.03, -0.17], [0.15, 0.14, 0.15], body);
    s.cyl(Axis::Z, [0.08, 0.085, 0.15], 0.03, 0.04, 16, BLACK);
    if s.fine() {
        for k in 0..4 {
            let x = -0.12 + 0.04 * k as f32;
            s.bx([x, 0.14, -0.1], [x + 0.02, 0.142, 0.05], BLACK);
        }
        for (x, z) in [(-0.12, -0.14), (0.12, -0.14), (-0.12, 0.12), (0.12, 0.12)] {
            s.cyl(Axis::Y, [x, 0.0, z], 0.03, 0.012, 8, BLACK);
        }
    }
}

pub(super) fn water_cooler(p: &mut Params, s: &mut Shape) {
    let body = p.pick(&[WHITE, METALS[0]]);
    s.bx([-0.16, 0.0, -0.16], [0.16, 1.0, 0.16], body);
    s.cyl(Axis::Y, [0.0, 1.0, 0.0], 0.4, 0.13, 20, rgb(150, 190, 230));
    if s.medium() {
        s.cyl(Axis::Y, [0.0, 1.4, 0.0], 0.05, 0.05, 12, rgb(40, 80, 160));
    }
    if s.fine() {
        for x in [-0.06, 0.06] {
            s.cyl(
                Axis::Z,
                [x, 0.85, 0.16],
                0.04,
                0.012,
                8,
                if x < 0.0 {
                    rgb(40, 80, 200)
                } else {
                    rgb(200, 40, 40)
                },
            );
        }
        s.bx([-0.1, 0.6, 0.16], [0.1, 0.62, 0.24], METALS[1]);
    }
}
