//! Walls and slabs as unions of axis-aligned boxes with true openings.
//!
//! Funkhouser §3.1.1 had to repair the architects' models (non-planar polygons, coincident faces,
//! inconsistent orientation) before they could be used for visibility. Generating structure as
//! unions of axis-aligned boxes avoids that: a wall with a door is the boxes left of, right of and
//! above the opening, a slab with a stair opening is the boxes around the hole, and every opening
//! is a real gap the cell/portal builder can find.

use crate::mesh::{MeshData, Rgba};

/// A rectangular opening in a panel, in the panel's (along, across) coordinates from its
/// minimum corner.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Opening {
    /// Start along the panel.
    pub u0: f32,
    /// End along the panel.
    pub u1: f32,
    /// Start across the panel (height for walls, Z for slabs).
    pub v0: f32,
    /// End across the panel.
    pub v1: f32,
}

/// The solid rectangles `[u0, u1, v0, v1]` of a `len × height` panel minus `openings`:
/// the panel is cut along `u` at every opening edge, each strip keeps the complement of the
/// openings crossing it, and neighbouring strips with the same profile are merged.
pub(crate) fn panel_solids(len: f32, height: f32, openings: &[Opening]) -> Vec<[f32; 4]> {
    let mut cuts: Vec<f32> = vec![0.0, len];
    for o in openings {
        cuts.push(o.u0.clamp(0.0, len));
        cuts.push(o.u1.clamp(0.0, len));
    }
    cuts.sort_by(f32::total_cmp);
    cuts.dedup_by(|a, b| (*a - *b).abs() < 1e-4);
    let mut strips: Vec<(f32, f32, Vec<[f32; 2]>)> = Vec::new();
    for pair in cuts.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let mid = (a + b) / 2.0;
        let profile = solid_profile(height, openings.iter().filter(|o| o.u0 < mid && mid < o.u1));
        match strips.last_mut() {
            Some(last) if last.2 == profile => last.1 = b,
            _ => strips.push((a, b, profile)),
        }
    }
    strips
        .into_iter()
        .flat_map(|(a, b, profile)| profile.into_iter().map(move |[v0, v1]| [a, b, v0, v1]))
        .collect()
}

/// The parts of `[0, height]` not covered by the given openings' `[v0, v1]`.
fn solid_profile<'a>(height: f32, openings: impl Iterator<Item = &'a Opening>) -> Vec<[f32; 2]> {
    let mut holes: Vec<[f32; 2]> = openings
        .map(|o| [o.v0.clamp(0.0, height), o.v1.clamp(0.0, height)])
        .collect();
    holes.sort_by(|a, b| a[0].total_cmp(&b[0]));
    let mut solid = Vec::new();
    let mut at = 0.0f32;
    for [h0, h1] in holes {
        if h0 > at + 1e-4 {
            solid.push([at, h0]);
        }
        at = at.max(h1);
    }
    if height > at + 1e-4 {
        solid.push([at, height]);
    }
    solid
}

/// A wall mesh in local coordinates (minimum corner at the origin): `length` along X (or Z when
/// `along_x` is false), `height` along Y, `thickness` across.
pub(crate) fn wall_mesh(
    along_x: bool,
    length: f32,
    height: f32,
    thickness: f32,
    openings: &[Opening],
    color: Rgba,
) -> MeshData {
    let mut mesh = MeshData::default();
    for [u0, u1, v0, v1] in panel_solids(length, height, openings) {
        if along_x {
            mesh.add_box([u0, v0, 0.0], [u1, v1, thickness], color);
        } else {
            mesh.add_box([0.0, v0, u0], [thickness, v1, u1], color);
        }
    }
    mesh
}

/// A slab mesh in local coordinates: `size[0]` along X, `size[1]` along Z, `thickness` up.
pub(crate) fn slab_mesh(
    size: [f32; 2],
    thickness: f32,
    holes: &[Opening],
    color: Rgba,
) -> MeshData {
    let mut mesh = MeshData::default();
    for [u0, u1, v0, v1] in panel_solids(size[0], size[1], holes) {
        mesh.add_box([u0, 0.0, v0], [u1, thickness, v1], color);
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(rects: &[[f32; 4]]) -> f32 {
        rects.iter().map(|r| (r[1] - r[0]) * (r[3] - r[2])).sum()
    }

    #[test]
    fn door_makes_three_boxes_and_leaves_a_gap() {
        let door = Opening {
            u0: 1.0,
            u1: 2.0,
            v0: 0.0,
            v1: 2.1,
        };
        let solids = panel_solids(4.0, 3.5, &[door]);
        assert_eq!(solids.len(), 3);
        assert!((area(&solids) - (4.0 * 3.5 - 2.1)).abs() < 1e-4);
        for r in &solids {
            let overlaps = r[0] < door.u1 && door.u0 < r[1] && r[2] < door.v1 && door.v0 < r[3];
            assert!(!overlaps, "{r:?} fills the door");
        }
    }

    #[test]
    fn windows_and_holes_are_subtracted() {
        let w = |a: f32| Opening {
            u0: a,
            u1: a + 1.0,
            v0: 0.9,
            v1: 2.5,
        };
        let solids = panel_solids(6.0, 3.5, &[w(1.0), w(4.0)]);
        assert!((area(&solids) - (6.0 * 3.5 - 2.0 * 1.6)).abs() < 1e-4);
        let slab = slab_mesh([3.0, 7.0], 0.15, &[w(1.0)], [0; 4]);
        assert_eq!(slab.triangle_count(), 4 * 12);
    }
}
