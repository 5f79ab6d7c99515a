//! Solid space, exactly: whether a cell lies wholly inside the union of the solid boxes (walls
//! and slabs, [`super::occluders`]), how much of it they fill, and where to cut a cell that is
//! partly solid so that its open part (a skylight in a roof, a window in a wall) becomes a cell
//! of its own.
//!
//! Only a cell wholly inside solid volume is dead (no observer can be there, and nothing in it
//! can be seen): Funkhouser §4.1's visibility is conservative, and a cell called solid where it
//! has an opening hides whatever is seen through that opening. Sampling a few points of a cell
//! is not enough (a 1 m skylight in a 10 × 8 m roof layer misses all of them), so the tests
//! here split the cell along the solids' own faces until each piece is inside one solid or
//! outside all of them. Gaps thinner than [`TOLERANCE`] are closed (the occluders are snapped
//! to a 1 mm grid, [`super::occluders::SNAP`]).

use crate::geometry::Aabb;

/// Gaps between solids, and overhangs past a cell's faces, thinner than this (metres) are
/// ignored.
pub const TOLERANCE: f32 = 1e-4;
/// Most pieces one question may cut a cell into; past it the answer is the conservative one
/// (not covered, less volume).
const MAX_PIECES: usize = 4096;

/// Whether `b` lies wholly inside the union of `solids` (up to [`TOLERANCE`]). Errs towards
/// `false` when the solids are too many to decide within the work bound.
pub fn covered(b: &Aabb, solids: &[Aabb]) -> bool {
    let near = clip_all(b, solids);
    if near.is_empty() {
        return false;
    }
    let mut budget = MAX_PIECES;
    covered_rec(b, &near, &mut budget)
}

/// The volume (cubic metres) of the part of `b` inside the union of `solids`; a lower bound when
/// the solids are too many to measure within the work bound.
pub fn solid_volume(b: &Aabb, solids: &[Aabb]) -> f64 {
    let near = clip_all(b, solids);
    let mut budget = MAX_PIECES;
    volume_rec(b, &near, &mut budget)
}

/// The plane `(axis, at)` to cut a partly solid `b` along: the face plane of the solids inside
/// `b` (at least `margin` from its faces) with the most solid face area in it, so that solid
/// and open parts fall on different sides. `None` when no solid face lies inside.
pub fn split_plane(b: &Aabb, solids: &[Aabb], margin: f32) -> Option<(usize, f32)> {
    let near = clip_all(b, solids);
    let mut best: Option<(f32, usize, f32)> = None;
    for s in &near {
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let area = (s.max[u] - s.min[u]) * (s.max[v] - s.min[v]);
            for at in [s.min[axis], s.max[axis]] {
                if at <= b.min[axis] + margin || at >= b.max[axis] - margin {
                    continue;
                }
                // The area of every solid face in this plane.
                let total: f32 = near
                    .iter()
                    .filter(|o| o.min[axis] == at || o.max[axis] == at)
                    .map(|o| (o.max[u] - o.min[u]) * (o.max[v] - o.min[v]))
                    .sum::<f32>()
                    .max(area);
                let better = best.is_none_or(|(a, ax, x)| {
                    (total, std::cmp::Reverse(axis), at.to_bits())
                        > (a, std::cmp::Reverse(ax), x.to_bits())
                });
                if better {
                    best = Some((total, axis, at));
                }
            }
        }
    }
    best.map(|(_, axis, at)| (axis, at))
}

fn volume(b: &Aabb) -> f64 {
    (0..3)
        .map(|k| (b.max[k] - b.min[k]).max(0.0) as f64)
        .product()
}

/// The solids overlapping `b`'s interior by more than [`TOLERANCE`] on every axis, clipped to
/// `b`.
fn clip_all(b: &Aabb, solids: &[Aabb]) -> Vec<Aabb> {
    solids.iter().filter_map(|s| clip(s, b)).collect()
}

fn clip(s: &Aabb, b: &Aabb) -> Option<Aabb> {
    let c = Aabb {
        min: std::array::from_fn(|k| s.min[k].max(b.min[k])),
        max: std::array::from_fn(|k| s.max[k].min(b.max[k])),
    };
    (0..3).all(|k| c.max[k] - c.min[k] > TOLERANCE).then_some(c)
}

fn contains(s: &Aabb, b: &Aabb) -> bool {
    (0..3).all(|k| s.min[k] <= b.min[k] + TOLERANCE && s.max[k] >= b.max[k] - TOLERANCE)
}

/// A face plane of the solids strictly inside `b` (by more than [`TOLERANCE`]): on `b`'s
/// longest axis that has one, the median of them.
fn cut(b: &Aabb, solids: &[Aabb]) -> Option<(usize, f32)> {
    let size = b.size();
    let mut axes = [0usize, 1, 2];
    axes.sort_by(|&x, &y| size[y].total_cmp(&size[x]));
    axes.into_iter().find_map(|a| {
        let mut at: Vec<f32> = solids
            .iter()
            .flat_map(|s| [s.min[a], s.max[a]])
            .filter(|&x| x > b.min[a] + TOLERANCE && x < b.max[a] - TOLERANCE)
            .collect();
        at.sort_by(f32::total_cmp);
        at.get(at.len() / 2).map(|&x| (a, x))
    })
}

fn halves(b: &Aabb, axis: usize, at: f32) -> (Aabb, Aabb) {
    let (mut lo, mut hi) = (*b, *b);
    lo.max[axis] = at;
    hi.min[axis] = at;
    (lo, hi)
}

fn covered_rec(b: &Aabb, solids: &[Aabb], budget: &mut usize) -> bool {
    if solids.iter().any(|s| contains(s, b)) {
        return true;
    }
    if *budget == 0 {
        return false;
    }
    *budget -= 1;
    let Some((axis, at)) = cut(b, solids) else {
        // No solid contains `b` and none has a face inside it: some of `b` is open.
        return false;
    };
    let (lo, hi) = halves(b, axis, at);
    [lo, hi].iter().all(|h| {
        let part = clip_all(h, solids);
        !part.is_empty() && covered_rec(h, &part, budget)
    })
}

fn volume_rec(b: &Aabb, solids: &[Aabb], budget: &mut usize) -> f64 {
    match solids.len() {
        0 => return 0.0,
        1 => return volume(&solids[0]),
        _ => {}
    }
    if solids.iter().any(|s| contains(s, b)) {
        return volume(b);
    }
    if *budget == 0 {
        return solids.iter().map(volume).fold(0.0, f64::max);
    }
    *budget -= 1;
    let Some((axis, at)) = cut(b, solids) else {
        return solids.iter().map(volume).fold(0.0, f64::max);
    };
    let (lo, hi) = halves(b, axis, at);
    [lo, hi]
        .iter()
        .map(|h| volume_rec(h, &clip_all(h, solids), budget))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bx(min: [f32; 3], max: [f32; 3]) -> Aabb {
        Aabb { min, max }
    }

    /// A 10 × 8 m roof layer 0.2 m thick with a 1 m skylight at x, z in 2..3, as the solid
    /// rectangles [`super::super::cover`] makes of it.
    fn roof_with_skylight() -> Vec<Aabb> {
        vec![
            bx([0.0, 3.0, 0.0], [10.0, 3.2, 2.0]),
            bx([0.0, 3.0, 2.0], [2.0, 3.2, 3.0]),
            bx([3.0, 3.0, 2.0], [10.0, 3.2, 3.0]),
            bx([0.0, 3.0, 3.0], [10.0, 3.2, 8.0]),
        ]
    }

    #[test]
    fn a_roof_with_a_skylight_is_not_covered_and_its_volume_is_exact() {
        let layer = bx([0.0, 3.0, 0.0], [10.0, 3.2, 8.0]);
        let solids = roof_with_skylight();
        // Every point a sampling test would look at (centre, corners pulled 10 % in) is solid.
        assert!(!covered(&layer, &solids));
        let v = solid_volume(&layer, &solids);
        assert!((v - (80.0 - 1.0) * 0.2).abs() < 1e-4, "{v}");
        // Without the hole it is covered, also when the pieces overlap or leave a 50 µm gap.
        let mut closed = solids.clone();
        closed.push(bx([1.5, 3.0, 1.5], [3.5, 3.2, 3.5]));
        assert!(covered(&layer, &closed));
        let gap = vec![
            bx([0.0, 3.0, 0.0], [5.0, 3.2, 8.0]),
            bx([5.00005, 3.0, 0.0], [10.0, 3.2, 8.0]),
        ];
        assert!(covered(&layer, &gap));
        // The skylight's own box is not covered, and the plane chosen to cut the layer is one
        // of the skylight's sides.
        assert!(!covered(&bx([2.0, 3.0, 2.0], [3.0, 3.2, 3.0]), &solids));
        let (axis, at) = split_plane(&layer, &solids, 0.005).unwrap();
        assert!(axis != 1 && (at == 2.0 || at == 3.0), "{axis} {at}");
    }

    #[test]
    fn a_box_beside_the_solids_is_open() {
        let solids = roof_with_skylight();
        assert!(!covered(&bx([0.0, 0.0, 0.0], [10.0, 3.0, 8.0]), &solids));
        assert_eq!(solid_volume(&bx([0.0; 3], [1.0; 3]), &solids), 0.0);
        assert_eq!(split_plane(&bx([0.0; 3], [1.0; 3]), &solids, 0.005), None);
    }
}
