//! Work surfaces: office and student desks, tables, lab benches and the lectern.

use super::{BLACK, METALS, Params, Shape, WOODS, legs, rgb};
use crate::mesh::Axis;

pub(super) fn desk(p: &mut Params, s: &mut Shape) {
    let (w, d, h) = (p.f(1.2, 1.8), p.f(0.65, 0.85), p.f(0.72, 0.76));
    let (wood, metal) = (p.pick(&WOODS), p.pick(&METALS));
    let pedestal = p.chance(0.6);
    let sides = p.pick(&[8, 12, 16]);
    let drawers = p.n(2, 4);
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, h - 0.03, -hd], [hw, h, hd], wood);
    if pedestal {
        let px = hw - 0.42;
        s.bx(
            [px, 0.02, -hd + 0.02],
            [hw - 0.02, h - 0.03, hd - 0.04],
            wood,
        );
        let dh = (h - 0.08) / drawers as f32;
        for k in 0..drawers {
            let y0 = 0.04 + dh * k as f32;
            if s.medium() {
                s.bx(
                    [px + 0.02, y0, hd - 0.04],
                    [hw - 0.04, y0 + dh - 0.02, hd - 0.02],
                    wood,
                );
            }
            if s.fine() {
                let y = y0 + dh / 2.0;
                s.cyl(Axis::X, [px + 0.13, y, hd - 0.005], 0.14, 0.008, 8, metal);
            }
        }
        for z in [-hd + 0.05, hd - 0.05] {
            s.cyl(Axis::Y, [-hw + 0.05, 0.0, z], h - 0.03, 0.025, sides, metal);
        }
    } else {
        legs(s, hw - 0.05, hd - 0.05, h - 0.03, 0.025, sides, metal);
    }
    if s.medium() {
        s.bx(
            [-hw + 0.06, 0.3, -hd + 0.02],
            [hw - 0.06, h - 0.03, -hd + 0.04],
            wood,
        );
    }
}

pub(super) fn table(p: &mut Params, s: &mut Shape) {
    let (w, d, h) = (p.f(1.6, 2.8), p.f(0.9, 1.2), p.f(0.72, 0.76));
    let (top, leg) = (p.pick(&WOODS), p.pick(&[WOODS[2], METALS[0], METALS[3]]));
    let sides = p.pick(&[12, 16, 20]);
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, h - 0.04, -hd], [hw, h, hd], top);
    legs(s, hw - 0.08, hd - 0.08, h - 0.04, 0.03, sides, leg);
    if w > 2.2 {
        for z in [-hd + 0.08, hd - 0.08] {
            s.cyl(Axis::Y, [0.0, 0.0, z], h - 0.04, 0.03, sides, leg);
        }
    }
    if s.fine() {
        s.bx(
            [-hw + 0.1, h - 0.12, -hd + 0.07],
            [hw - 0.1, h - 0.04, -hd + 0.09],
            top,
        );
        s.bx(
            [-hw + 0.1, h - 0.12, hd - 0.09],
            [hw - 0.1, h - 0.04, hd - 0.07],
            top,
        );
        s.bx(
            [-hw + 0.07, h - 0.12, -hd + 0.1],
            [-hw + 0.09, h - 0.04, hd - 0.1],
            top,
        );
        s.bx(
            [hw - 0.09, h - 0.12, -hd + 0.1],
            [hw - 0.07, h - 0.04, hd - 0.1],
            top,
        );
    }
}

pub(super) fn student_desk(p: &mut Params, s: &mut Shape) {
    let (w, d, h) = (p.f(1.0, 1.3), p.f(0.5, 0.6), p.f(0.72, 0.76));
    let (top, metal) = (p.pick(&WOODS), p.pick(&METALS));
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, h - 0.03, -hd], [hw, h, hd], top);
    legs(s, hw - 0.04, hd - 0.04, h - 0.03, 0.018, 8, metal);
    if s.medium() {
        s.bx(
            [-hw + 0.05, h - 0.2, -hd + 0.02],
            [hw - 0.05, h - 0.18, hd - 0.1],
            metal,
        );
    }
    if s.fine() {
        for x in [-hw + 0.04, hw - 0.04] {
            s.cyl(Axis::Z, [x, 0.12, -hd + 0.04], d - 0.08, 0.01, 8, metal);
        }
    }
}

pub(super) fn round_table(p: &mut Params, s: &mut Shape) {
    let (r, h) = (p.f(0.5, 0.75), p.f(0.72, 0.76));
    let (top, metal) = (p.pick(&WOODS), p.pick(&METALS));
    s.cyl(Axis::Y, [0.0, h - 0.04, 0.0], 0.04, r, 32, top);
    s.cyl(Axis::Y, [0.0, 0.04, 0.0], h - 0.08, 0.05, 12, metal);
    if s.medium() {
        s.cyl(Axis::Y, [0.0, 0.0, 0.0], 0.04, r * 0.6, 16, metal);
    } else {
        s.bx([-r * 0.5, 0.0, -r * 0.5], [r * 0.5, 0.04, r * 0.5], metal);
    }
    if s.fine() {
        s.cyl(Axis::Y, [0.0, h - 0.1, 0.0], 0.06, 0.15, 12, metal);
    }
}

pub(super) fn lab_bench(p: &mut Params, s: &mut Shape) {
    let (w, d, h) = (p.f(1.8, 2.4), p.f(0.7, 0.8), p.f(0.88, 0.92));
    let (body, metal) = (
        p.pick(&[WOODS[3], rgb(200, 200, 190), rgb(150, 170, 190)]),
        p.pick(&METALS),
    );
    let rack = p.chance(0.6);
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, h - 0.04, -hd], [hw, h, hd], BLACK);
    for x0 in [-hw + 0.02, hw - 0.62] {
        s.bx([x0, 0.1, -hd + 0.05], [x0 + 0.6, h - 0.04, hd - 0.05], body);
        if s.medium() {
            s.bx(
                [x0 + 0.02, 0.0, -hd + 0.1],
                [x0 + 0.58, 0.1, hd - 0.1],
                BLACK,
            );
            s.bx(
                [x0 + 0.02, 0.12, hd - 0.05],
                [x0 + 0.29, h - 0.06, hd - 0.04],
                body,
            );
            s.bx(
                [x0 + 0.31, 0.12, hd - 0.05],
                [x0 + 0.58, h - 0.06, hd - 0.04],
                body,
            );
        }
        if s.fine() {
            for x in [x0 + 0.25, x0 + 0.35] {
                s.cyl(Axis::Y, [x, h - 0.3, hd - 0.035], 0.12, 0.007, 8, metal);
            }
        }
    }
    if s.medium() {
        s.bx(
            [-hw + 0.62, h - 0.2, -hd + 0.05],
            [hw - 0.62, h - 0.04, -hd + 0.07],
            body,
        );
    }
    if rack && s.medium() {
        for x in [-hw + 0.1, hw - 0.1] {
            s.cyl(Axis::Y, [x, h, -hd + 0.1], 0.7, 0.015, 12, metal);
        }
        s.bx(
            [-hw + 0.05, h + 0.55, -hd + 0.02],
            [hw - 0.05, h + 0.57, -hd + 0.3],
            body,
        );
    }
    if s.fine() {
        for x in [-0.5, 0.5] {
            s.cyl(Axis::Y, [x * hw, h, -hd + 0.08], 0.2, 0.012, 8, metal);
            s.cyl(
                Axis::Z,
                [x * hw, h + 0.18, -hd + 0.08],
                0.1,
                0.008,
                8,
                metal,
            );
        }
    }
}

pub(super) fn lectern(p: &mut Params, s: &mut Shape) {
    let wood = p.pick(&WOODS);
    let h = p.f(1.05, 1.2);
    s.bx([-0.3, 0.0, -0.22], [0.3, 0.05, 0.22], wood);
    s.bx([-0.25, 0.05, -0.18], [0.25, h - 0.05, 0.18], wood);
    s.bx([-0.32, h - 0.05, -0.25], [0.32, h, 0.25], wood);
    if s.medium() {
        s.bx([-0.32, h, -0.25], [0.32, h + 0.03, -0.22], wood);
        s.bx([-0.23, 0.5, 0.18], [0.23, 0.52, 0.22], wood);
    }
    if s.fine() {
        s.cyl(Axis::Y, [0.2, h, 0.1], 0.35, 0.006, 8, METALS[3]);
        s.ball([0.2, h + 0.37, 0.1], [0.02; 3], 8, BLACK);
    }
}
