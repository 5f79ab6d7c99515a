//! Fixtures of the building itself: door leaves, stair flights and wall-mounted whiteboards.

use super::{BLACK, METALS, Params, Shape, WHITE, WOODS, rgb};
use crate::layout::{BAY, STAIR_RUN, STOREY_HEIGHT, WALL};
use crate::mesh::Axis;

/// A door leaf, 4.5 cm thick along X, 0.92 m wide along Z; its handles are the N-sided prisms of
/// Funkhouser's Fig. 3.6.
pub(super) fn door(p: &mut Params, s: &mut Shape) {
    let (leaf, metal) = (
        p.pick(&[WOODS[1], WOODS[3], rgb(180, 180, 175)]),
        p.pick(&METALS),
    );
    let (t, w, h) = (0.045, 0.92, 2.05);
    s.bx([-t / 2.0, 0.0, -w / 2.0], [t / 2.0, h, w / 2.0], leaf);
    if s.medium() {
        for sx in [-1.0f32, 1.0] {
            let x0 = sx * t / 2.0;
            let x1 = x0 + sx * 0.006;
            let (a, b) = (x0.min(x1), x0.max(x1));
            s.bx([a, 0.2, -w / 2.0 + 0.12], [b, 0.95, w / 2.0 - 0.12], leaf);
            s.bx([a, 1.1, -w / 2.0 + 0.12], [b, 1.9, w / 2.0 - 0.12], leaf);
        }
    }
    if s.fine() {
        let z = w / 2.0 - 0.07;
        s.cyl(
            Axis::X,
            [-t / 2.0 - 0.06, 1.0, z],
            t + 0.12,
            0.025,
            12,
            metal,
        );
        for x in [-t / 2.0 - 0.06, t / 2.0 + 0.05] {
            s.cyl(Axis::Z, [x + 0.005, 1.0, z], -0.12, 0.01, 8, metal);
        }
    }
}

/// One straight flight climbing +Z by one storey height, sized for a stairwell lane.
pub(super) fn stairs(_p: &mut Params, s: &mut Shape) {
    let lane = ((BAY - WALL) - 0.6) / 2.0;
    let (steps, hw) = (20u32, lane / 2.0);
    let (rise, tread) = (STOREY_HEIGHT / steps as f32, STAIR_RUN / steps as f32);
    let z0 = -STAIR_RUN / 2.0;
    let concrete = rgb(150, 150, 145);
    let rail = METALS[1];
    if s.medium() {
        for i in 0..steps {
            let z = z0 + tread * i as f32;
            let top = rise * (i + 1) as f32;
            s.bx(
                [-hw, (top - 0.25).max(0.0), z],
                [hw, top, z + tread],
                concrete,
            );
            if s.fine() {
                s.cyl(
                    Axis::Y,
                    [hw - 0.05, top, z + tread / 2.0],
                    0.9,
                    0.012,
                    8,
                    rail,
                );
                s.bx(
                    [hw - 0.07, top + 0.88, z],
                    [hw - 0.03, top + 0.92, z + tread],
                    rail,
                );
            }
        }
        if !s.fine() {
            for k in 0..4 {
                let z = z0 + STAIR_RUN / 4.0 * k as f32;
                let top = STOREY_HEIGHT / 4.0 * (k + 1) as f32;
                s.bx(
                    [hw - 0.07, top + 0.5, z],
                    [hw - 0.03, top + 0.54, z + STAIR_RUN / 4.0],
                    rail,
                );
            }
        }
    } else {
        for k in 0..5 {
            let z = z0 + STAIR_RUN / 5.0 * k as f32;
            let top = STOREY_HEIGHT / 5.0 * (k + 1) as f32;
            s.bx(
                [-hw, (top - 0.9).max(0.0), z],
                [hw, top, z + STAIR_RUN / 5.0],
                concrete,
            );
        }
    }
}

pub(super) fn whiteboard(p: &mut Params, s: &mut Shape) {
    let (w, h) = (p.f(1.8, 3.6), p.f(1.0, 1.2));
    let frame = p.pick(&METALS);
    let hw = w / 2.0;
    let y0 = 0.9;
    s.bx([-hw, y0, -0.025], [hw, y0 + h, 0.0], WHITE);
    if s.medium() {
        s.bx(
            [-hw - 0.02, y0 - 0.02, -0.025],
            [hw + 0.02, y0, 0.01],
            frame,
        );
        s.bx(
            [-hw - 0.02, y0 + h, -0.025],
            [hw + 0.02, y0 + h + 0.02, 0.01],
            frame,
        );
        s.bx([-hw - 0.02, y0, -0.025], [-hw, y0 + h, 0.01], frame);
        s.bx([hw, y0, -0.025], [hw + 0.02, y0 + h, 0.01], frame);
        s.bx(
            [-hw * 0.6, y0 - 0.04, -0.025],
            [hw * 0.6, y0 - 0.02, 0.07],
            frame,
        );
    }
    if s.fine() {
        for (k, c) in [BLACK, rgb(200, 30, 30), rgb(30, 60, 200)]
            .into_iter()
            .enumerate()
        {
            let x = -hw * 0.5 + 0.15 * k as f32;
            s.cyl(Axis::X, [x, y0 - 0.01, 0.03], 0.12, 0.008, 8, c);
        }
        s.bx(
            [hw * 0.3, y0 - 0.02, 0.01],
            [hw * 0.3 + 0.14, y0 + 0.02, 0.06],
            BLACK,
        );
    }
}
