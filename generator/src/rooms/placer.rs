//! Placing pieces in a room's local frame: rectangles that may not overlap, the four walls,
//! quarter turns about +Y, and the [`Placer`] that puts furniture against walls, on top of or in
//! front of other pieces while rejecting overlaps.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::Placed;
use crate::furniture::{DefKey, FurnitureType as F, Library};

/// An axis-aligned rectangle in the room's (u, w) frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Rect {
    pub(super) u: [f32; 2],
    pub(super) w: [f32; 2],
}

impl Rect {
    fn overlaps(&self, o: &Rect) -> bool {
        self.u[0] < o.u[1] && o.u[0] < self.u[1] && self.w[0] < o.w[1] && o.w[0] < self.w[1]
    }
}

/// The walls of a room in its local frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Wall {
    /// w = 0, the wall with the main door.
    Near,
    /// w = depth.
    Far,
    /// u = 0.
    Left,
    /// u = width.
    Right,
}

/// Rotates a local (x, z) offset by `q` quarter turns about +Y.
fn turn(q: u8, x: f32, z: f32) -> (f32, f32) {
    match q % 4 {
        0 => (x, z),
        1 => (z, -x),
        2 => (-x, -z),
        _ => (-z, x),
    }
}

/// Places furniture in one room, rejecting overlaps.
pub(super) struct Placer<'a> {
    pub(super) lib: &'a mut Library,
    pub(super) rng: &'a mut ChaCha8Rng,
    pub(super) width: f32,
    pub(super) depth: f32,
    pub(super) height: f32,
    pub(super) blocked: Vec<Rect>,
    pub(super) items: Vec<Placed>,
}

impl Placer<'_> {
    /// A random variant of a generator (Funkhouser: "numerous parameters are available").
    pub(super) fn pick(&mut self, ty: F) -> DefKey {
        let variant = self.rng.random_range(0..ty.variants());
        DefKey { ty, variant }
    }

    fn footprint(&mut self, key: DefKey, u: f32, w: f32, q: u8) -> Rect {
        let i = self.lib.get(key);
        let def = &self.lib.defs[i];
        let (a, b) = turn(q, def.min[0], def.min[2]);
        let (c, d) = turn(q, def.max[0], def.max[2]);
        Rect {
            u: [u + a.min(c), u + a.max(c)],
            w: [w + b.min(d), w + b.max(d)],
        }
    }

    /// Places `key` at (u, y, w) turned `q` quarter turns; when `check`, only if it lies inside
    /// the room and overlaps nothing placed or reserved before.
    pub(super) fn place(&mut self, key: DefKey, at: [f32; 3], q: u8, check: bool) -> Option<usize> {
        let rect = self.footprint(key, at[0], at[2], q);
        if check {
            let inside = rect.u[0] >= 0.0
                && rect.w[0] >= 0.0
                && rect.u[1] <= self.width
                && rect.w[1] <= self.depth;
            if !inside || self.blocked.iter().any(|b| b.overlaps(&rect)) {
                return None;
            }
            self.blocked.push(rect);
        }
        let def = self.lib.get(key);
        self.items.push(Placed {
            def,
            pos: at,
            quarter: q % 4,
            jitter: 0.0,
        });
        Some(self.items.len() - 1)
    }

    /// Places `key` on the floor with its back against `wall`, centred at `along`.
    pub(super) fn against(
        &mut self,
        wall: Wall,
        along: f32,
        key: DefKey,
        gap: f32,
    ) -> Option<usize> {
        let q = match wall {
            Wall::Near => 0,
            Wall::Far => 2,
            Wall::Left => 1,
            Wall::Right => 3,
        };
        let r = self.footprint(key, 0.0, 0.0, q);
        let (u, w) = match wall {
            Wall::Near => (along, gap - r.w[0]),
            Wall::Far => (along, self.depth - gap - r.w[1]),
            Wall::Left => (gap - r.u[0], along),
            Wall::Right => (self.width - gap - r.u[1], along),
        };
        self.place(key, [u, 0.0, w], q, true)
    }

    /// Places `key` relative to a placed `parent`, at parent-local (x, z), at height `y` above the
    /// parent's base, turned `q_rel` from the parent.
    pub(super) fn relative(
        &mut self,
        parent: usize,
        key: DefKey,
        xyz: [f32; 3],
        q_rel: u8,
        check: bool,
    ) -> Option<usize> {
        let p = self.items[parent];
        let (du, dw) = turn(p.quarter, xyz[0], xyz[2]);
        let at = [p.pos[0] + du, p.pos[1] + xyz[1], p.pos[2] + dw];
        self.place(key, at, p.quarter + q_rel, check)
    }

    /// Places `key` on top of `parent` at parent-local (x, z).
    pub(super) fn on_top(
        &mut self,
        parent: usize,
        key: DefKey,
        x: f32,
        z: f32,
        q_rel: u8,
    ) -> Option<usize> {
        let top = self.lib.defs[self.items[parent].def].max[1];
        self.relative(parent, key, [x, top, z], q_rel, false)
    }

    /// A seat in front of `parent`'s front (+Z) side, facing it, with a little yaw jitter.
    pub(super) fn seat_in_front(&mut self, parent: usize, key: DefKey, x: f32) -> Option<usize> {
        let front = self.lib.defs[self.items[parent].def].max[2];
        let i = self.relative(parent, key, [x, 0.0, front + 0.32], 2, true)?;
        self.items[i].jitter = self.rng.random_range(-0.15..0.15);
        Some(i)
    }

    pub(super) fn half_extent(&mut self, key: DefKey) -> [f32; 2] {
        let i = self.lib.get(key);
        let def = &self.lib.defs[i];
        [
            (def.max[0] - def.min[0]) / 2.0,
            (def.max[2] - def.min[2]) / 2.0,
        ]
    }

    /// Tries `key` against `wall` at each position in turn until one fits.
    pub(super) fn along_wall(
        &mut self,
        wall: Wall,
        positions: &[f32],
        key: DefKey,
    ) -> Option<usize> {
        positions
            .iter()
            .find_map(|&a| self.against(wall, a, key, 0.02))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turning_is_a_rotation_about_y() {
        assert_eq!(turn(1, 0.0, 1.0), (1.0, 0.0));
        assert_eq!(turn(2, 1.0, 2.0), (-1.0, -2.0));
        assert_eq!(turn(3, 0.0, 1.0), (-1.0, 0.0));
        assert_eq!(turn(4, 3.0, 4.0), (3.0, 4.0));
    }
}
