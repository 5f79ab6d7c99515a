//! Seating: chairs, office chairs, lab stools, auditorium seats and sofas.

use super::{BLACK, FABRICS, METALS, Params, Shape, WOODS, legs};
use crate::mesh::Axis;

pub(super) fn chair(p: &mut Params, s: &mut Shape) {
    let (sw, sd, sh) = (p.f(0.42, 0.5), p.f(0.42, 0.5), p.f(0.43, 0.47));
    let bh = p.f(0.35, 0.5);
    let r = p.f(0.014, 0.022);
    let sides = p.pick(&[6, 8]);
    let (frame, seat) = (
        p.pick(&[WOODS[0], WOODS[2], METALS[1], METALS[2]]),
        p.pick(&FABRICS),
    );
    let slats = p.n(3, 5);
    let arms = p.chance(0.35);
    let (hw, hd) = (sw / 2.0, sd / 2.0);
    legs(s, hw - 0.03, hd - 0.03, sh - 0.04, r, sides, frame);
    s.bx([-hw, sh - 0.04, -hd], [hw, sh, hd], frame);
    if s.fine() {
        s.bx(
            [-hw + 0.02, sh, -hd + 0.02],
            [hw - 0.02, sh + 0.03, hd - 0.02],
            seat,
        );
        for x in [-hw + 0.02, hw - 0.04] {
            s.bx([x, 0.14, -hd + 0.03], [x + 0.02, 0.16, hd - 0.03], frame);
        }
    }
    for x in [-hw + 0.01, hw - 0.05] {
        s.bx([x, sh, -hd + 0.01], [x + 0.04, sh + bh, -hd + 0.05], frame);
    }
    let back_z = [-hd + 0.015, -hd + 0.045];
    if s.fine() {
        let pitch = (sw - 0.1) / slats as f32;
        for k in 0..slats {
            let x0 = -hw + 0.06 + pitch * k as f32;
            s.bx(
                [x0, sh + 0.08, back_z[0]],
                [x0 + pitch * 0.6, sh + bh - 0.08, back_z[1]],
                seat,
            );
        }
        s.bx(
            [-hw + 0.03, sh + bh - 0.08, back_z[0]],
            [hw - 0.03, sh + bh, back_z[1]],
            frame,
        );
    } else {
        s.bx(
            [-hw + 0.03, sh + 0.08, back_z[0]],
            [hw - 0.03, sh + bh, back_z[1]],
            seat,
        );
    }
    if arms && s.medium() {
        for x in [-hw - 0.02, hw - 0.02] {
            s.bx(
                [x, sh + 0.2, -hd + 0.03],
                [x + 0.04, sh + 0.23, hd - 0.05],
                frame,
            );
            s.cyl(Axis::Y, [x + 0.02, sh, hd - 0.08], 0.2, 0.012, sides, frame);
        }
    }
}

pub(super) fn office_chair(p: &mut Params, s: &mut Shape) {
    let (sw, sh, bh) = (p.f(0.46, 0.54), p.f(0.44, 0.5), p.f(0.4, 0.65));
    let (fabric, metal) = (p.pick(&FABRICS), p.pick(&METALS));
    let arms = p.chance(0.6);
    let hw = sw / 2.0;
    s.bx([-0.3, 0.05, -0.03], [0.3, 0.09, 0.03], metal);
    s.bx([-0.03, 0.05, -0.3], [0.03, 0.09, 0.3], metal);
    for (x, z) in [(-0.28, 0.0), (0.28, 0.0), (0.0, -0.28), (0.0, 0.28)] {
        if s.fine() {
            s.ball([x, 0.025, z], [0.025; 3], 6, BLACK);
        } else if s.medium() {
            s.cyl(Axis::X, [x - 0.015, 0.025, z], 0.03, 0.025, 8, BLACK);
        }
    }
    s.cyl(Axis::Y, [0.0, 0.09, 0.0], sh - 0.17, 0.03, 10, metal);
    s.bx([-0.12, sh - 0.1, -0.12], [0.12, sh - 0.08, 0.12], metal);
    s.bx([-hw, sh - 0.08, -hw], [hw, sh, hw], fabric);
    if s.fine() {
        s.cyl(Axis::X, [-hw, sh - 0.02, hw - 0.03], sw, 0.03, 12, fabric);
    }
    if s.medium() {
        s.bx(
            [-0.03, sh - 0.05, -hw - 0.06],
            [0.03, sh + 0.2, -hw - 0.02],
            metal,
        );
    }
    s.bx(
        [-hw + 0.03, sh + 0.1, -hw - 0.1],
        [hw - 0.03, sh + bh, -hw - 0.03],
        fabric,
    );
    if arms && s.medium() {
        for x in [-hw - 0.04, hw] {
            s.bx([x + 0.01, sh, -0.05], [x + 0.03, sh + 0.2, 0.0], metal);
            s.bx([x, sh + 0.2, -0.15], [x + 0.04, sh + 0.23, 0.12], BLACK);
        }
    }
}

pub(super) fn stool(p: &mut Params, s: &mut Shape) {
    let (h, r) = (p.f(0.55, 0.7), p.f(0.15, 0.19));
    let (seat, metal) = (p.pick(&FABRICS), p.pick(&METALS));
    s.cyl(Axis::Y, [0.0, h - 0.04, 0.0], 0.04, r, 16, seat);
    legs(s, r * 0.65, r * 0.65, h - 0.04, 0.012, 6, metal);
    if s.fine() {
        let a = r * 0.65;
        s.bx([-a, 0.2, a - 0.01], [a, 0.22, a + 0.01], metal);
        s.bx([-a, 0.2, -a - 0.01], [a, 0.22, -a + 0.01], metal);
    }
}

pub(super) fn auditorium_seat(p: &mut Params, s: &mut Shape) {
    let w = p.f(0.5, 0.56);
    let (fabric, frame) = (p.pick(&FABRICS), p.pick(&[METALS[1], METALS[3], WOODS[2]]));
    let tablet = p.chance(0.5);
    let hw = w / 2.0;
    s.bx([-0.05, 0.0, -0.2], [0.05, 0.42, -0.1], frame);
    s.bx([-hw + 0.03, 0.38, -0.2], [hw - 0.03, 0.45, 0.22], fabric);
    s.bx([-hw + 0.03, 0.45, -0.28], [hw - 0.03, 0.95, -0.2], fabric);
    for x in [-hw, hw - 0.03] {
        s.bx([x, 0.0, -0.25], [x + 0.03, 0.62, 0.15], frame);
        if s.fine() {
            s.cyl(Axis::Z, [x + 0.015, 0.64, -0.25], 0.4, 0.025, 12, frame);
        }
    }
    if s.medium() {
        s.bx([-hw + 0.05, 0.45, -0.18], [hw - 0.05, 0.5, 0.2], fabric);
        s.bx([-hw + 0.05, 0.5, -0.2], [hw - 0.05, 0.9, -0.15], fabric);
    }
    if tablet && s.fine() {
        s.bx([hw - 0.03, 0.62, -0.25], [hw + 0.02, 0.64, 0.05], WOODS[1]);
    }
}

pub(super) fn sofa(p: &mut Params, s: &mut Shape) {
    let w = p.f(1.5, 2.2);
    let fabric = p.pick(&FABRICS);
    let cushions = p.n(2, 3);
    let (hw, d) = (w / 2.0, 0.85);
    let hd = d / 2.0;
    s.bx([-hw + 0.15, 0.1, -hd], [hw - 0.15, 0.4, hd], fabric);
    s.bx([-hw + 0.15, 0.4, -hd], [hw - 0.15, 0.85, -hd + 0.2], fabric);
    for x in [-hw, hw - 0.15] {
        s.bx([x, 0.1, -hd], [x + 0.15, 0.5, hd], fabric);
        s.cyl(Axis::Z, [x + 0.075, 0.55, -hd], d, 0.09, 16, fabric);
    }
    if s.medium() {
        let cw = (w - 0.3) / cushions as f32;
        for k in 0..cushions {
            let x = -hw + 0.15 + cw * k as f32;
            s.bx(
                [x + 0.01, 0.4, -hd + 0.2],
                [x + cw - 0.01, 0.52, hd - 0.02],
                fabric,
            );
            if s.fine() {
                s.bx(
                    [x + 0.02, 0.52, -hd + 0.2],
                    [x + cw - 0.02, 0.8, -hd + 0.3],
                    fabric,
                );
            }
        }
    }
    if s.fine() {
        legs(s, hw - 0.08, hd - 0.08, 0.1, 0.02, 8, WOODS[4]);
    }
}
