//! Small accessories: plants, coffee cups, waste bins and coat racks.

use super::{BLACK, GREENS, METALS, POT, Params, SOIL, Shape, WHITE, WOODS, rgb};
use crate::mesh::Axis;

pub(super) fn plant(p: &mut Params, s: &mut Shape) {
    let tall = p.chance(0.6);
    let scale = if tall { p.f(1.0, 1.6) } else { p.f(0.35, 0.5) };
    let pot = p.pick(&[POT, WHITE, BLACK, rgb(120, 120, 140)]);
    let green = p.pick(&GREENS);
    let blobs = p.n(3, 5);
    let r = 0.16 * scale.sqrt();
    let pot_h = 0.3 * scale.sqrt();
    let offsets: Vec<[f32; 3]> = (0..blobs)
        .map(|_| {
            [
                p.f(-0.5, 0.5) * r,
                p.f(0.45, 0.95) * scale,
                p.f(-0.5, 0.5) * r,
            ]
        })
        .collect();
    let sizes: Vec<f32> = (0..blobs).map(|_| p.f(0.8, 1.3) * r).collect();
    s.cone([0.0, 0.0, 0.0], pot_h, (r * 0.75, r), 12, pot);
    if s.fine() {
        s.cyl(Axis::Y, [0.0, pot_h, 0.0], 0.01, r * 0.9, 12, SOIL);
    }
    if s.fine() {
        s.cyl(
            Axis::Y,
            [0.0, pot_h, 0.0],
            scale * 0.6,
            0.012,
            6,
            rgb(90, 70, 40),
        );
    }
    if s.medium() {
        for (o, size) in offsets.iter().zip(&sizes) {
            s.ball(
                [o[0], pot_h + o[1] * 0.8, o[2]],
                [*size, *size * 1.1, *size],
                8,
                green,
            );
        }
    } else {
        let top = pot_h + scale * 0.6;
        s.ball([0.0, top, 0.0], [r * 1.4, scale * 0.45, r * 1.4], 4, green);
    }
}

pub(super) fn coffee_cup(p: &mut Params, s: &mut Shape) {
    let c = p.pick(&[WHITE, rgb(180, 40, 40), rgb(40, 80, 160), BLACK]);
    let h = p.f(0.08, 0.11);
    s.cyl(Axis::Y, [0.0, 0.0, 0.0], h, 0.04, 16, c);
    if s.fine() {
        s.bx([0.04, h * 0.2, -0.005], [0.065, h * 0.3, 0.005], c);
        s.bx([0.055, h * 0.2, -0.005], [0.065, h * 0.8, 0.005], c);
        s.bx([0.04, h * 0.7, -0.005], [0.065, h * 0.8, 0.005], c);
    }
}

pub(super) fn trash_bin(p: &mut Params, s: &mut Shape) {
    let c = p.pick(&[METALS[1], rgb(40, 80, 160), rgb(60, 120, 60)]);
    let h = p.f(0.3, 0.45);
    s.cone([0.0, 0.0, 0.0], h, (0.12, 0.15), 16, c);
    if s.fine() {
        s.cyl(Axis::Y, [0.0, h, 0.0], 0.02, 0.16, 16, c);
    }
}

pub(super) fn coat_rack(p: &mut Params, s: &mut Shape) {
    let c = p.pick(&[WOODS[2], METALS[3]]);
    let h = p.f(1.7, 1.9);
    s.cyl(Axis::Y, [0.0, 0.0, 0.0], 0.03, 0.2, 12, c);
    s.cyl(Axis::Y, [0.0, 0.03, 0.0], h - 0.03, 0.02, 8, c);
    if s.fine() {
        s.cyl(Axis::X, [-0.15, h - 0.15, 0.0], 0.3, 0.01, 8, c);
        s.cyl(Axis::Z, [0.0, h - 0.2, -0.15], 0.3, 0.01, 8, c);
        s.ball([0.0, h, 0.0], [0.035; 3], 8, c);
    }
}
