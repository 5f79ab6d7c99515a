//! One room generator per room kind (offices, labs, classrooms, conference rooms, auditoria,
//! libraries, corridors and stairwells), plus the desk workstation that offices and libraries
//! share.

use rand::Rng;

use super::placer::{Placer, Rect, Wall};
use crate::furniture::{DefKey, FurnitureType as F};
use crate::layout::{PlannedRoom, STAIR_RUN, STAIR_START, stair_lane};

/// A desk with a chair, a monitor, keyboard, lamp, books and a cup.
fn workstation(pl: &mut Placer, wall: Wall, along: f32, desk: DefKey, chair: DefKey) -> bool {
    let Some(d) = pl.against(wall, along, desk, 0.03) else {
        return false;
    };
    let [hx, _] = pl.half_extent(desk);
    pl.seat_in_front(d, chair, 0.0);
    let extras = [
        (F::Monitor, 0.0, -0.12),
        (F::Keyboard, 0.0, 0.15),
        (F::DeskLamp, -hx + 0.18, -0.12),
        (F::Books, hx - 0.25, -0.1),
        (F::Phone, hx - 0.2, 0.2),
    ];
    for (ty, x, z) in extras {
        let key = pl.pick(ty);
        pl.on_top(d, key, x, z, 0);
    }
    if pl.rng.random_bool(0.6) {
        let cup = pl.pick(F::CoffeeCup);
        pl.on_top(d, cup, hx - 0.45, 0.25, 0);
    }
    if pl.rng.random_bool(0.4) {
        let plant = pl.pick(F::Plant);
        pl.on_top(d, plant, -hx + 0.45, -0.15, 0);
    }
    true
}

pub(super) fn office(pl: &mut Placer) {
    let (w, d) = (pl.width, pl.depth);
    let desk = pl.pick(F::Desk);
    let chair = if pl.rng.random_bool(0.7) {
        pl.pick(F::OfficeChair)
    } else {
        pl.pick(F::Chair)
    };
    let desks = ((w / 2.0).floor() as u32).clamp(1, 3);
    for k in 0..desks {
        let along = w * (k as f32 + 0.5) / desks as f32;
        workstation(pl, Wall::Far, along, desk, chair);
    }
    if d > 6.0 && pl.rng.random_bool(0.6) {
        workstation(pl, Wall::Left, d * 0.55, desk, chair);
    }
    let shelf = pl.pick(F::Bookshelf);
    let shelves = pl.rng.random_range(1..=2);
    let mut at = 1.8;
    for _ in 0..shelves {
        if pl.against(Wall::Right, at, shelf, 0.02).is_some() {
            at += pl.half_extent(shelf)[0] * 2.0 + 0.02;
        }
    }
    let cabinet = pl.pick(F::FilingCabinet);
    pl.along_wall(Wall::Far, &[w - 0.35, 0.35], cabinet);
    let plant = pl.pick(F::Plant);
    pl.along_wall(Wall::Left, &[d - 0.4, 1.7, d * 0.3], plant);
    let bin = pl.pick(F::TrashBin);
    pl.along_wall(Wall::Far, &[w * 0.5 + 1.0, w * 0.5 - 1.0, 0.3], bin);
    let guest = pl.pick(F::Chair);
    pl.along_wall(Wall::Right, &[d * 0.75, d * 0.4], guest);
    let rack = pl.pick(F::CoatRack);
    pl.along_wall(Wall::Left, &[1.6, 2.0], rack);
    if pl.rng.random_bool(0.5) {
        let board = pl.pick(F::Whiteboard);
        pl.along_wall(Wall::Near, &[w * 0.5], board);
    }
    if pl.rng.random_bool(0.4) {
        let lamp = pl.pick(F::FloorLamp);
        pl.along_wall(Wall::Right, &[d - 0.4, 1.6], lamp);
    }
}

pub(super) fn lab(pl: &mut Placer) {
    let (w, d) = (pl.width, pl.depth);
    let bench = pl.pick(F::LabBench);
    let stool = pl.pick(F::Stool);
    let [bx, bz] = pl.half_extent(bench);
    let mut row_w = 1.7;
    while row_w + bz * 2.0 + 0.9 < d {
        let mut u = 0.5 + bx;
        while u + bx < w - 0.4 {
            if let Some(b) = pl.place(bench, [u, 0.0, row_w + bz], 0, true) {
                for x in [-bx * 0.5, bx * 0.5] {
                    pl.seat_in_front(b, stool, x);
                    let monitor = pl.pick(F::Monitor);
                    pl.on_top(b, monitor, x, -0.1, 0);
                    let kb = pl.pick(F::Keyboard);
                    pl.on_top(b, kb, x, 0.2, 0);
                }
                let pc = pl.pick(F::Computer);
                pl.on_top(b, pc, 0.0, -0.1, 0);
            }
            u += bx * 2.0 + 0.3;
        }
        row_w += bz * 2.0 + 1.3;
    }
    let board = pl.pick(F::Whiteboard);
    pl.along_wall(Wall::Left, &[d * 0.5], board);
    let cabinet = pl.pick(F::FilingCabinet);
    for a in [d - 0.4, d - 0.9, d - 1.4] {
        pl.against(Wall::Right, a, cabinet, 0.02);
    }
    let shelf = pl.pick(F::Bookshelf);
    pl.along_wall(Wall::Far, &[w * 0.5, w * 0.25], shelf);
    for wall in [Wall::Far, Wall::Near] {
        let plant = pl.pick(F::Plant);
        pl.along_wall(wall, &[0.4, w - 0.4], plant);
    }
    let bin = pl.pick(F::TrashBin);
    pl.along_wall(Wall::Right, &[1.6, d * 0.5], bin);
}

pub(super) fn classroom(pl: &mut Placer) {
    let (w, d) = (pl.width, pl.depth);
    let board = pl.pick(F::Whiteboard);
    pl.along_wall(Wall::Left, &[d * 0.5], board);
    let lectern = pl.pick(F::Lectern);
    if let Some(l) = pl.place(lectern, [1.3, 0.0, d * 0.5 + 1.2], 1, true) {
        let lamp = pl.pick(F::DeskLamp);
        pl.on_top(l, lamp, -0.15, -0.1, 0);
    }
    let desk = pl.pick(F::StudentDesk);
    let chair = pl.pick(F::Chair);
    let [hx, hz] = pl.half_extent(desk);
    let mut u = 2.6;
    while u + hz < w - 0.3 {
        let mut wpos = 0.6 + hx;
        while wpos + hx < d - 0.3 {
            if let Some(k) = pl.place(desk, [u, 0.0, wpos], 1, true) {
                for x in [-hx * 0.5, hx * 0.5] {
                    pl.seat_in_front(k, chair, x);
                }
                if pl.rng.random_bool(0.3) {
                    let books = pl.pick(F::Books);
                    pl.on_top(k, books, -hx * 0.5, 0.0, 0);
                }
            }
            wpos += hx * 2.0 + 0.5;
        }
        u += hz * 2.0 + 0.95;
    }
    let shelf = pl.pick(F::Bookshelf);
    pl.along_wall(Wall::Right, &[d * 0.5, d * 0.25], shelf);
    let bin = pl.pick(F::TrashBin);
    pl.along_wall(Wall::Left, &[0.4, d - 0.4], bin);
    let projector = pl.pick(F::Projector);
    let table = pl.pick(F::StudentDesk);
    if let Some(t) = pl.place(table, [1.4, 0.0, d * 0.5 - 1.3], 1, true) {
        pl.on_top(t, projector, 0.0, 0.0, 0);
    }
}

pub(super) fn conference(pl: &mut Placer) {
    let (w, d) = (pl.width, pl.depth);
    let round = pl.rng.random_bool(0.3);
    let table = if round {
        pl.pick(F::RoundTable)
    } else {
        pl.pick(F::Table)
    };
    let chair = pl.pick(F::Chair);
    let q = if d > w { 1 } else { 0 };
    let center = [w * 0.5, 0.0, (d + 1.3) * 0.5];
    let Some(t) = pl.place(table, center, q, true) else {
        return;
    };
    let [hx, hz] = pl.half_extent(table);
    let around: Vec<([f32; 3], u8)> = if round {
        vec![
            ([0.0, 0.0, hz + 0.32], 2),
            ([0.0, 0.0, -hz - 0.32], 0),
            ([hx + 0.32, 0.0, 0.0], 3),
            ([-hx - 0.32, 0.0, 0.0], 1),
        ]
    } else {
        let n = ((hx * 2.0 - 0.2) / 0.7).floor().max(1.0) as u32;
        let mut v = Vec::new();
        for k in 0..n {
            let x = -hx + 0.1 + 0.7 * (k as f32 + 0.5) * (hx * 2.0 - 0.2) / (0.7 * n as f32);
            v.push(([x, 0.0, hz + 0.32], 2));
            v.push(([x, 0.0, -hz - 0.32], 0));
        }
        v.push(([hx + 0.32, 0.0, 0.0], 3));
        v.push(([-hx - 0.32, 0.0, 0.0], 1));
        v
    };
    for (at, q_rel) in around {
        if let Some(c) = pl.relative(t, chair, at, q_rel, true) {
            pl.items[c].jitter = pl.rng.random_range(-0.12..0.12);
        }
    }
    let projector = pl.pick(F::Projector);
    pl.on_top(t, projector, 0.0, 0.0, 0);
    for x in [-0.5, 0.5] {
        let cup = pl.pick(F::CoffeeCup);
        pl.on_top(t, cup, x * hx, hz * 0.5, 0);
    }
    let board = pl.pick(F::Whiteboard);
    pl.along_wall(Wall::Far, &[w * 0.5], board);
    for (wall, a) in [
        (Wall::Left, d - 0.4),
        (Wall::Right, d - 0.4),
        (Wall::Right, 1.7),
    ] {
        let plant = pl.pick(F::Plant);
        pl.against(wall, a, plant, 0.02);
    }
    let cooler = pl.pick(F::WaterCooler);
    pl.along_wall(Wall::Left, &[1.7, d * 0.5], cooler);
}

pub(super) fn auditorium(pl: &mut Placer) {
    let (w, d) = (pl.width, pl.depth);
    let board = pl.pick(F::Whiteboard);
    for a in [d * 0.3, d * 0.7] {
        pl.against(Wall::Left, a, board, 0.01);
    }
    let lectern = pl.pick(F::Lectern);
    pl.place(lectern, [1.5, 0.0, d * 0.5], 1, true);
    let seat = pl.pick(F::AuditoriumSeat);
    let mut u = 3.5;
    while u < w - 0.5 {
        let mut wpos = 0.7;
        while wpos < d - 0.4 {
            let aisle = (wpos - d * 0.5).abs() < 0.55;
            if !aisle {
                pl.place(seat, [u, 0.0, wpos], 3, true);
            }
            wpos += 0.58;
        }
        u += 0.95;
    }
    for a in [0.4, d - 0.4] {
        let plant = pl.pick(F::Plant);
        pl.against(Wall::Left, a, plant, 0.02);
        let bin = pl.pick(F::TrashBin);
        pl.against(Wall::Right, a, bin, 0.02);
    }
}

pub(super) fn library(pl: &mut Placer) {
    let (w, d) = (pl.width, pl.depth);
    let shelf = pl.pick(F::LibraryShelf);
    let [sx, sz] = pl.half_extent(shelf);
    let mut u = w * 0.4 + sz;
    while u + sz < w - 0.5 {
        let mut wpos = 1.6 + sx;
        while wpos + sx < d - 1.0 {
            pl.place(shelf, [u, 0.0, wpos], 1, true);
            wpos += sx * 2.0 + 0.01;
        }
        u += sz * 2.0 + 1.2;
    }
    let table = pl.pick(F::Table);
    let chair = pl.pick(F::Chair);
    let [tx, tz] = pl.half_extent(table);
    let mut wpos = 1.6 + tx;
    while wpos + tx < d - 0.5 {
        if let Some(t) = pl.place(table, [w * 0.2, 0.0, wpos], 1, true) {
            let n = ((tx * 2.0) / 0.75).floor().max(1.0) as u32;
            for k in 0..n {
                let x = -tx + 0.75 * (k as f32 + 0.5);
                pl.seat_in_front(t, chair, x);
                if let Some(c) = pl.relative(t, chair, [x, 0.0, -tz - 0.32], 0, true) {
                    pl.items[c].jitter = pl.rng.random_range(-0.15..0.15);
                }
                let lamp = pl.pick(F::DeskLamp);
                pl.on_top(t, lamp, x, 0.0, 0);
            }
        }
        wpos += tx * 2.0 + 1.6;
    }
    for (wall, a) in [
        (Wall::Left, 0.4),
        (Wall::Left, d - 0.4),
        (Wall::Far, w * 0.35),
    ] {
        let plant = pl.pick(F::Plant);
        pl.against(wall, a, plant, 0.02);
    }
    let sofa = pl.pick(F::Sofa);
    pl.along_wall(Wall::Far, &[w * 0.2, w * 0.3], sofa);
    let desk = pl.pick(F::Desk);
    let chair2 = pl.pick(F::OfficeChair);
    workstation(pl, Wall::Near, w * 0.4 - 1.0, desk, chair2);
}

pub(super) fn corridor(pl: &mut Placer) {
    let (w, d) = (pl.width, pl.depth);
    if w < d {
        // A short passage between two corridors (u runs across it).
        for (wall, a) in [(Wall::Left, d * 0.5), (Wall::Right, d * 0.5)] {
            let ty = if pl.rng.random_bool(0.5) {
                F::Sofa
            } else {
                F::Plant
            };
            let key = pl.pick(ty);
            pl.against(wall, a, key, 0.02);
        }
        return;
    }
    let kinds = [
        F::Plant,
        F::TrashBin,
        F::WaterCooler,
        F::Plant,
        F::Whiteboard,
        F::FloorLamp,
    ];
    let mut u = 1.5;
    let mut k = 0usize;
    while u < w - 1.0 {
        let wall = if k.is_multiple_of(2) {
            Wall::Near
        } else {
            Wall::Far
        };
        let key = pl.pick(kinds[k % kinds.len()]);
        pl.against(wall, u, key, 0.02);
        k += 1;
        u += pl.rng.random_range(1.8..3.2);
    }
}

pub(super) fn stairwell(pl: &mut Placer, room: &PlannedRoom) {
    let s = room.room.storey;
    let run = [STAIR_START, STAIR_START + STAIR_RUN];
    if s > 0 {
        let lane = stair_lane(pl.width, s - 1);
        pl.blocked.push(Rect { u: lane, w: run });
    }
    if room.stairs_up {
        let lane = stair_lane(pl.width, s);
        let stairs = DefKey {
            ty: F::Stairs,
            variant: 0,
        };
        let q = if s.is_multiple_of(2) { 0 } else { 2 };
        let at = [(lane[0] + lane[1]) / 2.0, 0.0, (run[0] + run[1]) / 2.0];
        pl.place(stairs, at, q, false);
        pl.blocked.push(Rect { u: lane, w: run });
    }
    let plant = pl.pick(F::Plant);
    pl.along_wall(Wall::Far, &[pl.width * 0.5, 0.4], plant);
}
