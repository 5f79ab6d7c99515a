//! Storage: bookshelves (with their books), library stacks, loose books and filing
//! cabinets.

use super::{BOOK_COLORS, METALS, Params, Shape, WHITE, WOODS, rgb};
use crate::mesh::{Axis, MeshData, Rgba};

/// Books standing on a shelf: `(x offset, width, height, colour)`, drawn once per definition.
fn shelf_books(p: &mut Params, width: f32, max_h: f32, count: u32) -> Vec<(f32, f32, f32, Rgba)> {
    let mut books = Vec::new();
    let mut x = 0.01;
    for _ in 0..count {
        let bw = p.f(0.03, 0.075);
        let bh = p.f(0.55, 0.95) * max_h;
        let c = p.pick(&BOOK_COLORS);
        if x + bw > width - 0.01 {
            break;
        }
        books.push((x, bw, bh, c));
        x += bw + p.f(0.0, 0.01);
    }
    books
}

/// Books of one shelf as boxes (fine) or one block of their average colour (medium).
fn place_books(s: &mut Shape, books: &[(f32, f32, f32, Rgba)], x0: f32, y: f32, z: [f32; 2]) {
    if s.fine() {
        for &(x, w, h, c) in books {
            s.bx([x0 + x, y, z[0]], [x0 + x + w, y + h, z[1]], c);
        }
    } else if s.medium()
        && let (Some(first), Some(last)) = (books.first(), books.last())
    {
        let mean_h = books.iter().map(|b| b.2).sum::<f32>() / books.len() as f32;
        let mut m = MeshData::default();
        for b in books {
            m.add_box([0.0; 3], [0.01; 3], b.3);
        }
        let x1 = x0 + last.0 + last.1;
        s.bx(
            [x0 + first.0, y, z[0]],
            [x1, y + mean_h, z[1]],
            m.average_color(),
        );
    }
}

pub(super) fn bookshelf(p: &mut Params, s: &mut Shape) {
    let (w, d, h) = (p.f(0.8, 1.2), p.f(0.3, 0.4), p.f(1.2, 2.1));
    let wood = p.pick(&WOODS);
    let levels = ((h - 0.1) / 0.36).floor().max(1.0) as u32;
    let pitch = (h - 0.1) / levels as f32;
    let rows: Vec<_> = (0..levels)
        .map(|_| shelf_books(p, w - 0.04, pitch - 0.04, 14))
        .collect();
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, 0.0, -hd], [-hw + 0.02, h, hd], wood);
    s.bx([hw - 0.02, 0.0, -hd], [hw, h, hd], wood);
    s.bx([-hw, h - 0.02, -hd], [hw, h, hd], wood);
    s.bx([-hw + 0.02, 0.0, -hd + 0.02], [hw - 0.02, 0.08, hd], wood);
    if s.medium() {
        s.bx(
            [-hw + 0.02, 0.08, -hd],
            [hw - 0.02, h - 0.02, -hd + 0.01],
            wood,
        );
    }
    for (k, books) in rows.iter().enumerate() {
        let y = 0.08 + pitch * k as f32;
        if k > 0 && s.medium() {
            s.bx([-hw + 0.02, y - 0.02, -hd + 0.01], [hw - 0.02, y, hd], wood);
        }
        place_books(s, books, -hw + 0.02, y, [-hd + 0.03, hd - 0.03]);
    }
}

pub(super) fn library_shelf(p: &mut Params, s: &mut Shape) {
    let (w, h) = (p.f(0.9, 1.2), p.f(1.8, 2.2));
    let d = 0.6;
    let wood = p.pick(&WOODS);
    let levels = ((h - 0.1) / 0.36).floor().max(1.0) as u32;
    let pitch = (h - 0.1) / levels as f32;
    let rows: Vec<_> = (0..levels * 2)
        .map(|_| shelf_books(p, w - 0.04, pitch - 0.04, 12))
        .collect();
    let (hw, hd) = (w / 2.0, d / 2.0);
    s.bx([-hw, 0.0, -hd], [-hw + 0.02, h, hd], wood);
    s.bx([hw - 0.02, 0.0, -hd], [hw, h, hd], wood);
    s.bx([-hw, h - 0.02, -hd], [hw, h, hd], wood);
    s.bx([-hw + 0.02, 0.0, -hd], [hw - 0.02, 0.08, hd], wood);
    s.bx([-hw + 0.02, 0.08, -0.01], [hw - 0.02, h - 0.02, 0.01], wood);
    for k in 0..levels {
        let y = 0.08 + pitch * k as f32;
        if k > 0 && s.medium() {
            s.bx([-hw + 0.02, y - 0.02, -hd], [hw - 0.02, y, hd], wood);
        }
        let (a, b) = (&rows[2 * k as usize], &rows[2 * k as usize + 1]);
        place_books(s, a, -hw + 0.02, y, [0.02, hd - 0.03]);
        place_books(s, b, -hw + 0.02, y, [-hd + 0.03, -0.02]);
    }
}

pub(super) fn books(p: &mut Params, s: &mut Shape) {
    let count = p.n(3, 6);
    let flat = p.chance(0.5);
    let sizes: Vec<(f32, f32, f32, Rgba)> = (0..count)
        .map(|_| {
            (
                p.f(0.02, 0.05),
                p.f(0.18, 0.28),
                p.f(0.13, 0.2),
                p.pick(&BOOK_COLORS),
            )
        })
        .collect();
    let mut at = 0.0;
    for &(t, h, d, c) in &sizes {
        if !s.medium() {
            break;
        }
        if flat {
            s.bx([-h / 2.0, at, -d / 2.0], [h / 2.0, at + t, d / 2.0], c);
        } else {
            s.bx([at - 0.1, 0.0, -d / 2.0], [at - 0.1 + t, h, d / 2.0], c);
        }
        at += t;
    }
    if !s.medium() {
        let (t, h, d, c) = sizes[0];
        s.bx(
            [-h / 2.0, 0.0, -d / 2.0],
            [h / 2.0, t * count as f32, d / 2.0],
            c,
        );
    }
}

pub(super) fn filing_cabinet(p: &mut Params, s: &mut Shape) {
    let h = p.f(0.7, 1.35);
    let body = p.pick(&[METALS[0], METALS[2], rgb(120, 130, 110), WOODS[1]]);
    let drawers = ((h / 0.33).round() as u32).max(2);
    s.bx([-0.225, 0.0, -0.3], [0.225, h, 0.28], body);
    let dh = (h - 0.04) / drawers as f32;
    for k in 0..drawers {
        let y = 0.02 + dh * k as f32;
        if s.medium() {
            s.bx([-0.21, y + 0.01, 0.28], [0.21, y + dh - 0.01, 0.3], body);
        }
        if s.fine() {
            s.cyl(
                Axis::X,
                [-0.07, y + dh * 0.7, 0.31],
                0.14,
                0.008,
                8,
                METALS[3],
            );
            s.bx(
                [-0.04, y + dh * 0.4, 0.3],
                [0.04, y + dh * 0.5, 0.305],
                WHITE,
            );
        }
    }
}
