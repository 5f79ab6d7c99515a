//! Walk mode: the observer as a person's body in the building, not a free-flying eye. Every
//! architectural walkthrough has it (and Funkhouser's observer walks at eye height, §3.3.1);
//! the cells and portals already say where a person can go:
//!
//! - **walls**: the body is a few vertical probes (its centre and four points at its radius, at
//!   knee, chest and head height), and each moves only through open space, from a cell to the
//!   next through a portal (`space.rs`); a move a probe cannot make is tried again along each
//!   axis alone, so the body slides along a wall (cells are axis-aligned);
//! - **objects**: the boxes of the placed objects near the body that reach between a step above
//!   its feet and the top of its head stop it; those below a step are stepped onto;
//! - **floors**: the eye stays [`EYE_HEIGHT`] above the floor below it: the highest of the cell
//!   bottoms under it (down through holes: `space::floor`) and the objects stepped onto.
//!   Steps down are taken at once; a drop deeper than a step is fallen, under gravity;
//! - **stairs**: an object that rises more than a step and meets a floor at its foot and the
//!   next floor at its head (a flight, as stair objects are modelled in BIM exports and by the
//!   generator) is walked as the ramp along its treads.
//!
//! [`Walker`] is pure state, driven by the displacement the controls ask for and the frame's
//! time step; it never reads a clock. Lengths in metres, times in seconds.

mod space;

use glam::Vec3;
use portico_data::cells::CellGraph;
use portico_data::format::Header;
use portico_data::geometry::Aabb;
pub use portico_data::person::{DOOR_SILL, EYE_HEIGHT};

/// How the observer moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Gait {
    /// On foot: walls and objects stop it, the floor carries it, holes drop it.
    #[default]
    Walk,
    /// Free flight through everything (the navigator alone).
    Fly,
}

/// A person's body (metres).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Body {
    /// Half the shoulder width: how far the body keeps from walls and objects.
    pub radius: f32,
    /// Eye height above the floor.
    pub eye: f32,
    /// The highest step climbed without a stair (a door sill, a kerb, a tread).
    pub step: f32,
    /// The top of the head above the eye.
    pub head: f32,
}

impl Default for Body {
    fn default() -> Self {
        Body {
            radius: 0.25,
            eye: EYE_HEIGHT,
            step: DOOR_SILL,
            head: 0.15,
        }
    }
}

/// Gravity (m/s²) and the fastest fall (m/s).
const GRAVITY: f32 = 9.81;
const MAX_FALL: f32 = 20.0;
/// The longest horizontal move checked at once (metres): longer ones are cut into moves this
/// long, so no probe passes through a thin object between two frames.
const MAX_MOVE: f32 = 0.1;
const MAX_MOVES: f32 = 32.0;
/// The objects gathered around the body reach this far from it horizontally and vertically
/// (metres), and are gathered again once the body is half that far from where they were.
const GATHER: [f32; 2] = [6.0, 5.0];

/// A flight of stairs, walked as the ramp along its treads.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Flight {
    bounds: Aabb,
    /// The horizontal axis it climbs along (0 = x, 2 = z).
    axis: usize,
    /// Whether it rises towards the axis's larger end.
    rises: bool,
    /// The floors at its foot and at its head (metres).
    floors: [f32; 2],
}

impl Flight {
    /// The ramp's height above `p`, if `p` is over the flight.
    fn height(&self, p: Vec3) -> Option<f32> {
        self.span(p, 0.0).map(|(low, _)| low)
    }

    /// The lowest and highest the ramp stands over the square of half side `r` about `p`
    /// (a body's footprint), if the square meets the flight.
    fn span(&self, p: Vec3, r: f32) -> Option<(f32, f32)> {
        let b = &self.bounds;
        let over = [0, 2]
            .iter()
            .all(|&k| b.min[k] <= p[k] + r && p[k] - r <= b.max[k]);
        if !over {
            return None;
        }
        let a = self.axis;
        let at = |x: f32| {
            let f = ((x - b.min[a]) / (b.max[a] - b.min[a]).max(1e-6)).clamp(0.0, 1.0);
            let f = if self.rises { f } else { 1.0 - f };
            self.floors[0] + f * (self.floors[1] - self.floors[0])
        };
        let (u, v) = (at(p[a] - r), at(p[a] + r));
        Some((u.min(v), u.max(v)))
    }
}

/// The walking observer's state between frames.
#[derive(Debug, Clone, Default)]
pub struct Walker {
    /// The body it walks with.
    pub body: Body,
    /// Downward speed (m/s) while falling.
    fall: f32,
    /// The cell the eye was last in (where the next search starts).
    cell: Option<u32>,
    /// Where the objects were gathered, and how many boxes were offered then.
    gathered: Option<(Vec3, usize)>,
    solids: Vec<Aabb>,
    flights: Vec<Flight>,
}

impl Walker {
    /// A walker with a person's [`Body`].
    pub fn new() -> Walker {
        Walker::default()
    }

    /// Forgets the fall and the cell (after a jump to another viewpoint).
    pub fn reset(&mut self) {
        self.fall = 0.0;
        self.cell = None;
    }

    /// Whether it is falling now.
    pub fn falling(&self) -> bool {
        self.fall > 0.0
    }

    /// Takes the placed objects' world boxes (`boxes`, structural occluders left out: the
    /// cells stand for them) near `eye` as the obstacles and stairs of the next moves. Cheap
    /// when called every frame: it looks at `boxes` again only when the eye has moved away
    /// from where it last did or `known` (how many objects the caller knows) has changed.
    pub fn gather<'a>(
        &mut self,
        graph: &CellGraph,
        boxes: impl IntoIterator<Item = &'a Aabb>,
        known: usize,
        eye: Vec3,
    ) {
        let half = Vec3::new(GATHER[0], GATHER[1], GATHER[0]);
        if let Some((at, n)) = self.gathered
            && n == known
            && ((at - eye).abs().cmple(half * 0.5)).all()
        {
            return;
        }
        self.gathered = Some((eye, known));
        let region = Aabb {
            min: (eye - half).to_array(),
            max: (eye + half).to_array(),
        };
        self.solids.clear();
        self.flights.clear();
        for b in boxes {
            if b.is_empty() || !overlaps(b, &region) {
                continue;
            }
            match flight(graph, self.cell, &self.body, b) {
                Some(f) => self.flights.push(f),
                None => self.solids.push(*b),
            }
        }
    }

    /// [`Walker::gather`] over `header`'s placed objects, structural occluders left out.
    /// `learned` counts what the caller has learned of the header (pages taken): when it
    /// changes, the objects are looked at again.
    pub fn gather_header(&mut self, graph: &CellGraph, header: &Header, learned: usize, eye: Vec3) {
        let boxes = header
            .instances
            .iter()
            .filter(|i| !i.occluder)
            .map(|i| &i.bounds);
        self.gather(graph, boxes, learned, eye);
    }

    /// The eye after one frame: `eye` moved by the horizontal part of `wanted` (metres) as far
    /// as walls and objects let it, climbing steps and stairs, then `dt` seconds of gravity.
    pub fn step(&mut self, graph: &CellGraph, eye: Vec3, wanted: Vec3, dt: f32) -> Vec3 {
        let mut feet = eye - Vec3::Y * self.body.eye;
        // At most `MAX_MOVES` moves of `MAX_MOVE` a frame (48 m/s at 15 frames a second):
        // anything longer is cut short rather than checked in longer strides.
        let flat = Vec3::new(wanted.x, 0.0, wanted.z).clamp_length_max(MAX_MOVE * MAX_MOVES);
        let moves = (flat.length() / MAX_MOVE).ceil().clamp(1.0, MAX_MOVES);
        let part = flat / moves;
        for _ in 0..moves as usize {
            // The whole move, else along each axis alone (sliding along an axis-aligned wall),
            // else ever shorter ones: the body comes to rest within 1 cm of what stops it.
            let tries = [
                part,
                Vec3::new(part.x, 0.0, 0.0),
                Vec3::new(0.0, 0.0, part.z),
            ];
            let shorter = (1..=4).map(|k| part / (1 << k) as f32);
            let made = tries
                .into_iter()
                .chain(shorter)
                .filter(|d| d.length_squared() > 1e-12)
                .find_map(|d| self.moved(graph, feet, d));
            match made {
                Some(to) => feet = to,
                None => break,
            }
        }
        feet = self.settle(graph, feet, dt);
        let eye = feet + Vec3::Y * self.body.eye;
        self.cell = space::locate(graph, self.cell, eye).or(self.cell);
        eye
    }

    /// The floor under feet at `p`: the highest cell bottom, object top or ramp at most a step
    /// above `p`. `None` where no live cell holds the point a step above `p`.
    pub fn ground(&self, graph: &CellGraph, p: Vec3) -> Option<f32> {
        let from = p + Vec3::Y * self.body.step;
        let mut h = space::floor(graph, self.cell, from)?;
        // A body stands on whatever floor is under any part of its footprint (it does not drop
        // through a hole narrower than itself), where that part is on its side of the walls.
        for off in self.footprint() {
            if self.reaches(graph, from, off)
                && let Some(f) = space::floor(graph, self.cell, from + off)
            {
                h = h.max(f);
            }
        }
        let over =
            |b: &Aabb| b.min[0] <= p.x && p.x <= b.max[0] && b.min[2] <= p.z && p.z <= b.max[2];
        for s in self.solids.iter().filter(|s| over(s)) {
            if s.max[1] <= from.y {
                h = h.max(s.max[1]);
            }
        }
        for y in self.flights.iter().filter_map(|f| f.height(p)) {
            if y <= from.y {
                h = h.max(y);
            }
        }
        Some(h)
    }

    /// The feet moved by `d` (horizontal) and onto what is there, if the body fits the way.
    fn moved(&self, graph: &CellGraph, feet: Vec3, d: Vec3) -> Option<Vec3> {
        let mut to = feet + d;
        if let Some(g) = self.ground(graph, to) {
            to.y = to.y.max(g);
        }
        self.free(graph, feet, to).then_some(to)
    }

    /// Whether the body can go from feet at `from` to feet at `to`.
    fn free(&self, graph: &CellGraph, from: Vec3, to: Vec3) -> bool {
        let b = &self.body;
        let r = b.radius;
        for h in [b.step + 0.05, 1.0, b.eye + b.head] {
            let up = Vec3::Y * h;
            // The centre, and each side probe that is on the centre's side of the walls (one
            // across a wall thinner than the body's radius — after a jump, or a start by a
            // wall — says nothing of where the body can go).
            let probes = std::iter::once(Vec3::ZERO).chain(
                self.footprint()
                    .into_iter()
                    .filter(|&off| self.reaches(graph, from + up, off)),
            );
            for off in probes {
                let lift = off + up;
                if let Some((t, _)) = space::trace(graph, self.cell, from + lift, to + lift)
                    && t < 1.0
                {
                    return false;
                }
            }
        }
        let (was, now) = (self.body_box(from), self.body_box(to));
        if self
            .solids
            .iter()
            .any(|s| overlaps(s, &now) && !overlaps(s, &was))
        {
            return false;
        }
        let cuts = |f: &Flight, feet: Vec3| {
            f.span(feet, r)
                .is_some_and(|(low, high)| high > feet.y + b.step && low < feet.y + b.eye + b.head)
        };
        !self.flights.iter().any(|f| cuts(f, to) && !cuts(f, from))
    }

    /// The body's four side points about its centre (at its radius along each axis).
    fn footprint(&self) -> [Vec3; 4] {
        let r = self.body.radius;
        [Vec3::X * r, -Vec3::X * r, Vec3::Z * r, -Vec3::Z * r]
    }

    /// Whether `at + off` is reached from `at` through open space (or nothing is known there).
    fn reaches(&self, graph: &CellGraph, at: Vec3, off: Vec3) -> bool {
        space::trace(graph, self.cell, at, at + off).is_none_or(|(t, _)| t >= 1.0)
    }

    /// The box the body fills above a step, feet at `feet`.
    fn body_box(&self, feet: Vec3) -> Aabb {
        let b = &self.body;
        Aabb {
            min: [feet.x - b.radius, feet.y + b.step, feet.z - b.radius],
            max: [
                feet.x + b.radius,
                feet.y + b.eye + b.head,
                feet.z + b.radius,
            ],
        }
    }

    /// The feet after `dt` seconds of gravity: down a step at once, further falling.
    fn settle(&mut self, graph: &CellGraph, mut feet: Vec3, dt: f32) -> Vec3 {
        let Some(g) = self.ground(graph, feet) else {
            self.fall = 0.0;
            return feet;
        };
        if feet.y - g <= self.body.step {
            feet.y = g;
            self.fall = 0.0;
        } else {
            self.fall = (self.fall + GRAVITY * dt).min(MAX_FALL);
            feet.y = (feet.y - self.fall * dt).max(g);
            if feet.y <= g {
                self.fall = 0.0;
            }
        }
        feet
    }
}

/// Whether two closed boxes overlap with some volume.
fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    (0..3).all(|k| a.min[k] < b.max[k] && b.min[k] < a.max[k])
}

/// A handrail's height over a flight's treads (metres): a flight's box may rise this much above
/// the floor its head meets.
const HANDRAIL: f32 = 1.2;

/// `b` as a flight of stairs, if it is one: along its longer horizontal side, a floor at its
/// bottom's height just past one end and a floor more than a step higher just past the other,
/// no higher than its top and at most a handrail below it, no steeper than 50°, at most 8 m up.
fn flight(graph: &CellGraph, hint: Option<u32>, body: &Body, b: &Aabb) -> Option<Flight> {
    let axis = if b.max[0] - b.min[0] >= b.max[2] - b.min[2] {
        0
    } else {
        2
    };
    let run = b.max[axis] - b.min[axis];
    if b.max[1] - b.min[1] <= body.step || b.max[1] - b.min[1] > 8.0 + HANDRAIL {
        return None;
    }
    let centre = b.center();
    // The floor just past the end at `end`, found from `from` down.
    let past = |end: f32, from: f32| {
        let mut p = centre;
        p[axis] = end;
        p.y = from;
        space::floor(graph, hint, p)
    };
    let (lo, hi) = (b.min[axis] - 0.3, b.max[axis] + 0.3);
    let foot =
        |end: f32| past(end, b.min[1] + body.step).filter(|f| (f - b.min[1]).abs() <= body.step);
    let head = |end: f32| {
        past(end, b.max[1] + body.step).filter(|&f| {
            f > b.min[1] + body.step && f <= b.max[1] + body.step && f >= b.max[1] - HANDRAIL
        })
    };
    let (rises, bottom, top) = match (foot(lo), head(hi), foot(hi), head(lo)) {
        (Some(f), Some(h), _, _) => (true, f, h),
        (_, _, Some(f), Some(h)) => (false, f, h),
        _ => return None,
    };
    (run * 1.19 >= top - bottom).then_some(Flight {
        bounds: *b,
        axis,
        rises,
        floors: [bottom, top],
    })
}

#[cfg(test)]
mod tests;
