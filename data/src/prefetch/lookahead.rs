//! The lookahead set and each object's maximum LOD (Funkhouser §5.2.2).
//!
//! For every range cell (in the order Dijkstra found them) the cells in its cell-to-cell
//! visibility that pass the lookahead cull contribute objects: the ones in the range cell's
//! cell-to-object visibility (object granularity) or every object incident upon the visible cell
//! (cell granularity). Each object is stored only up to the LOD a static size threshold allows
//! at the nearest point of the observer range, so near objects get finer LODs than far ones
//! (Fig. 5.8).

use super::range::{ObserverRange, distance_to_box};
use crate::format::LodRecord;
use crate::geometry::Aabb;
use portico_protocol::Policy;

/// Projected screen area (pixels) of a box seen from `distance` metres: the area of its
/// bounding sphere's disc, capped at the screen.
pub fn projected_pixels(bounds: &Aabb, distance: f32, policy: &Policy, half_fov_y: f32) -> f32 {
    let screen = policy.screen[0] as f32 * policy.screen[1] as f32;
    let radius = bounds.size().length() * 0.5;
    let focal = policy.screen[1] as f32 * 0.5 / half_fov_y.clamp(0.05, 1.5).tan();
    if distance <= radius {
        return screen;
    }
    let r_px = radius * focal / distance;
    (std::f32::consts::PI * r_px * r_px).min(screen)
}

/// Index (0 = finest) of the finest LOD whose average polygon covers at least `threshold`
/// pixels when the object covers `pixels`; the coarsest LOD when none does.
pub fn max_lod(lods: &[LodRecord], pixels: f32, threshold: f32) -> usize {
    let last = lods.len().saturating_sub(1);
    lods.iter()
        .position(|l| pixels / (l.triangles.max(1) as f32) >= threshold)
        .unwrap_or(last)
}

/// The finest LOD an observer anywhere in the range could want for an object.
pub fn max_lod_in_range(
    lods: &[LodRecord],
    bounds: &Aabb,
    range: &ObserverRange,
    policy: &Policy,
    half_fov_y: f32,
) -> usize {
    let nearest = (distance_to_box(range.eye, bounds) - range.radius).max(0.0);
    let px = projected_pixels(bounds, nearest, policy, half_fov_y);
    max_lod(lods, px, policy.size_threshold_px.max(0.0))
}
