//! The hidden-vertex test of the fidelity measures: a CPU depth buffer of the reference frame.
//!
//! RRB marks a critical vertex *Invisible* in a frame "if it is hidden or out of view" (§5.3.1)
//! but does not say how; its `I0 ≠ 0` test relies on a black background (§5.3.2). The notes
//! (seed-004-rrb.md §6 item 4) ask for an explicit test against the reference depth buffer. The
//! GPU depth target is not readable, so we rasterise the reference frame's triangles (the finest
//! LOD of every object the Regular run draws) into a small CPU depth buffer of the same size:
//! triangles are clipped to the near plane in clip space, projected, and scan-converted with
//! edge functions at pixel centres, keeping the largest `1/w` (the nearest surface; `1/w` is
//! affine in screen space).
//!
//! A vertex at clip position `c` is **visible** when it is in front of the near plane, inside the
//! viewport, and not behind the farthest of the nearest surfaces in the 3×3 pixels around its
//! pixel by more than 1 % of that distance plus 1 cm. Taking the farthest of nine samples keeps
//! silhouette and grazing-angle vertices (whose own pixel may show a neighbouring face) visible,
//! while anything covered by an occluder over its whole neighbourhood is hidden.

use glam::{Mat4, Vec2, Vec3, Vec4};

/// Relative depth tolerance of the visibility test.
const REL_TOLERANCE: f32 = 0.01;
/// Absolute depth tolerance of the visibility test, in metres (view depth).
const ABS_TOLERANCE: f32 = 0.01;

/// A CPU depth buffer holding `1/w` of the nearest surface per pixel (0 = nothing drawn).
#[derive(Debug, Clone)]
pub struct DepthBuffer {
    width: u32,
    height: u32,
    near: f32,
    inv_w: Vec<f32>,
}

impl DepthBuffer {
    /// An empty buffer of `width` × `height` pixels for a projection with near plane `near`.
    pub fn new(width: u32, height: u32, near: f32) -> Self {
        DepthBuffer {
            width,
            height,
            near,
            inv_w: vec![0.0; (width as usize) * (height as usize)],
        }
    }

    /// Forgets everything drawn.
    pub fn clear(&mut self) {
        self.inv_w.fill(0.0);
    }

    /// Draws an indexed triangle list with object-to-clip matrix `mvp`.
    pub fn draw_mesh(&mut self, mvp: &Mat4, positions: &[Vec3], indices: &[u32]) {
        let clip: Vec<Vec4> = positions.iter().map(|p| *mvp * p.extend(1.0)).collect();
        for t in indices.chunks_exact(3) {
            let (Some(a), Some(b), Some(c)) = (
                clip.get(t[0] as usize),
                clip.get(t[1] as usize),
                clip.get(t[2] as usize),
            ) else {
                continue;
            };
            self.draw_triangle([*a, *b, *c]);
        }
    }

    /// Draws one triangle given in clip space (WebGPU: visible depth `0 ≤ z ≤ w`).
    pub fn draw_triangle(&mut self, clip: [Vec4; 3]) {
        let poly = clip_near(&clip);
        if poly.len() < 3 {
            return;
        }
        let screen: Vec<Vec3> = poly.iter().map(|c| self.to_screen(*c)).collect();
        for k in 1..screen.len() - 1 {
            self.fill([screen[0], screen[k], screen[k + 1]]);
        }
    }

    /// `(x, y, 1/w)` in pixels (y down).
    fn to_screen(&self, c: Vec4) -> Vec3 {
        let inv = 1.0 / c.w;
        Vec3::new(
            (c.x * inv + 1.0) * 0.5 * self.width as f32,
            (1.0 - c.y * inv) * 0.5 * self.height as f32,
            inv,
        )
    }

    /// Scan-converts a screen-space triangle, keeping the largest `1/w` per pixel centre.
    fn fill(&mut self, v: [Vec3; 3]) {
        let area = edge(v[0].truncate(), v[1].truncate(), v[2].truncate());
        if !area.is_finite() || area.abs() < 1e-12 {
            return;
        }
        let lo = v[0].min(v[1]).min(v[2]);
        let hi = v[0].max(v[1]).max(v[2]);
        let x0 = lo.x.floor().max(0.0) as u32;
        let y0 = lo.y.floor().max(0.0) as u32;
        let x1 = (hi.x.ceil().min(self.width as f32)).max(0.0) as u32;
        let y1 = (hi.y.ceil().min(self.height as f32)).max(0.0) as u32;
        for y in y0..y1 {
            for x in x0..x1 {
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let w0 = edge(v[1].truncate(), v[2].truncate(), p) / area;
                let w1 = edge(v[2].truncate(), v[0].truncate(), p) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = w0 * v[0].z + w1 * v[1].z + w2 * v[2].z;
                let slot = &mut self.inv_w[(y * self.width + x) as usize];
                if z > *slot {
                    *slot = z;
                }
            }
        }
    }

    /// The pixel a clip-space point projects to, if it is in front of the near plane, inside
    /// the viewport and not hidden by what was drawn (see the module docs).
    pub fn visible_pixel(&self, clip: Vec4) -> Option<(u32, u32)> {
        if clip.w < self.near || clip.z < 0.0 {
            return None;
        }
        let s = self.to_screen(clip);
        let inside = s.x >= 0.0 && s.y >= 0.0;
        if !inside || s.x >= self.width as f32 || s.y >= self.height as f32 {
            return None;
        }
        let (x, y) = (s.x as u32, s.y as u32);
        let farthest = self.farthest_around(x, y);
        let depth = clip.w;
        let limit = if farthest > 0.0 {
            (1.0 / farthest) * (1.0 + REL_TOLERANCE) + ABS_TOLERANCE
        } else {
            f32::INFINITY
        };
        (depth <= limit).then_some((x, y))
    }

    /// The smallest `1/w` (farthest surface; 0 = empty) in the 3×3 pixels around `(x, y)`.
    fn farthest_around(&self, x: u32, y: u32) -> f32 {
        let mut out = f32::INFINITY;
        for yy in y.saturating_sub(1)..=(y + 1).min(self.height - 1) {
            for xx in x.saturating_sub(1)..=(x + 1).min(self.width - 1) {
                out = out.min(self.inv_w[(yy * self.width + xx) as usize]);
            }
        }
        out
    }
}

/// Twice the signed area of `(a, b, p)`.
fn edge(a: Vec2, b: Vec2, p: Vec2) -> f32 {
    (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x)
}

/// Clips a clip-space triangle to the near plane `z ≥ 0` (Sutherland–Hodgman).
fn clip_near(tri: &[Vec4; 3]) -> Vec<Vec4> {
    let mut out = Vec::with_capacity(4);
    for i in 0..3 {
        let (a, b) = (tri[i], tri[(i + 1) % 3]);
        let (da, db) = (a.z, b.z);
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            let t = da / (da - db);
            out.push(a + (b - a) * t);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use portico_render::Camera;

    const W: u32 = 64;
    const H: u32 = 48;

    fn view_proj() -> Mat4 {
        Camera {
            eye: Vec3::new(0.0, 0.0, 5.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fovy: 1.0,
            near: 0.1,
            far: 100.0,
        }
        .view_proj(W as f32 / H as f32)
    }

    /// A square of half-size `h` at depth z (facing the camera).
    fn square(h: f32, z: f32) -> (Vec<Vec3>, Vec<u32>) {
        let p = [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, y)| Vec3::new(x, y, z));
        (p.to_vec(), vec![0, 1, 2, 0, 2, 3])
    }

    #[test]
    fn an_occluder_hides_what_is_behind_it_and_nothing_else() {
        let vp = view_proj();
        let mut d = DepthBuffer::new(W, H, 0.1);
        let (wall, wi) = square(3.0, -2.0);
        let (card, ci) = square(0.5, 1.0);
        d.draw_mesh(&vp, &wall, &wi);
        d.draw_mesh(&vp, &card, &ci);
        let at = |p: Vec3| d.visible_pixel(vp * p.extend(1.0));
        assert!(
            at(Vec3::new(0.0, 0.0, -2.0)).is_none(),
            "wall centre is behind the card"
        );
        assert!(
            at(Vec3::new(2.0, 0.0, -2.0)).is_some(),
            "wall beside the card is seen"
        );
        assert!(
            at(Vec3::new(0.5, 0.5, 1.0)).is_some(),
            "the card's own corner is seen"
        );
        assert!(at(Vec3::new(0.0, 0.0, 1.0)).is_some());
        assert!(at(Vec3::new(0.0, 0.0, 9.0)).is_none(), "behind the eye");
        assert!(at(Vec3::new(40.0, 0.0, 0.0)).is_none(), "out of view");
    }

    #[test]
    fn triangles_through_the_near_plane_are_clipped_not_dropped() {
        let vp = view_proj();
        let mut d = DepthBuffer::new(W, H, 0.1);
        // A floor from behind the eye to far in front: the part in front must be drawn.
        let floor = vec![
            Vec3::new(-5.0, -1.0, 10.0),
            Vec3::new(5.0, -1.0, 10.0),
            Vec3::new(5.0, -1.0, -20.0),
            Vec3::new(-5.0, -1.0, -20.0),
        ];
        d.draw_mesh(&vp, &floor, &[0, 1, 2, 0, 2, 3]);
        let below_floor = Vec3::new(0.0, -3.0, -4.0);
        assert!(d.visible_pixel(vp * below_floor.extend(1.0)).is_none());
        assert!(
            d.visible_pixel(vp * Vec3::new(0.0, -1.0, -4.0).extend(1.0))
                .is_some()
        );
        d.clear();
        assert!(d.visible_pixel(vp * below_floor.extend(1.0)).is_some());
    }
}
