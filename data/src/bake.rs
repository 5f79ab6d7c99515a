//! A simple baked lighting, the stand-in for Funkhouser's radiosity pass (§3.1, Fig. 3.5): once
//! lighting is baked into vertex colours, every instance of a definition looks different, so a
//! flattened build must store every instance's geometry separately — the out-of-core case
//! (Soda Hall: 21.5 MB shared, 349.5 MB flattened).
//!
//! The light is a sky term from above, a lattice of ceiling lights (about one every 3 m in plan,
//! one per 3.75 m storey) attenuated with distance, and a slow daylight variation. It is deterministic and depends only on the
//! world-space position and normal.

use crate::geometry::{Mesh, Vertex};
use glam::Vec3;

/// Spacing of the ceiling-light lattice (x, y, z) in metres.
const LATTICE: Vec3 = Vec3::new(3.1, 3.75, 3.3);
/// Height of a light above its storey's floor, as a fraction of the storey height.
const LIGHT_HEIGHT: f32 = 0.9;

/// Light arriving at a world-space point with a world-space unit normal, in 0..=1.
pub fn irradiance(p: Vec3, n: Vec3) -> f32 {
    let sky = 0.5 + 0.5 * n.y;
    let cell = (p / LATTICE).floor();
    let mut lamp = 0.0;
    for dx in [0.0, 1.0] {
        for dz in [0.0, 1.0] {
            let light = Vec3::new(
                (cell.x + dx) * LATTICE.x,
                (cell.y + LIGHT_HEIGHT) * LATTICE.y,
                (cell.z + dz) * LATTICE.z,
            );
            let d = light - p;
            let dist2 = d.length_squared().max(0.25);
            lamp += n.dot(d.normalize_or_zero()).max(0.0) * 4.0 / dist2;
        }
    }
    // Slow daylight variation across the floor plate, so no two places are lit alike.
    let daylight = 0.05 * ((0.31 * p.x).sin() + (0.23 * p.z).cos());
    (0.2 + 0.25 * sky + 0.45 * lamp.min(1.5) / 1.5 + daylight).clamp(0.0, 1.0)
}

/// Multiplies a world-space mesh's vertex colours by the light at each vertex.
pub fn bake(mesh: &mut Mesh) {
    for v in &mut mesh.vertices {
        let l = irradiance(Vec3::from(v.position), v.normal_f32().normalize_or_zero());
        let c = v.color_f32();
        *v = Vertex::new(
            v.position,
            v.normal_f32().into(),
            [c[0] * l, c[1] * l, c[2] * l, c[3]],
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upward_faces_under_a_light_are_brighter_than_faces_turned_away() {
        let under = Vec3::new(3.0, 1.0, 3.0);
        assert!(irradiance(under, Vec3::Y) > irradiance(under, -Vec3::Y));
    }

    #[test]
    fn light_varies_with_position_so_instances_differ() {
        let a = irradiance(Vec3::new(3.1, 2.5, 3.3), Vec3::Y); // under a lamp
        let b = irradiance(Vec3::new(4.65, 2.5, 4.95), Vec3::Y); // between lamps
        assert!((a - b).abs() > 0.01, "{a} vs {b}");
        for x in 0..50 {
            let l = irradiance(Vec3::new(x as f32 * 0.37, 2.0, 1.0), Vec3::X);
            assert!((0.0..=1.0).contains(&l));
        }
    }
}
