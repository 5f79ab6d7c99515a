//! Flat-shaded triangle meshes built from a few standard shapes.
//!
//! Funkhouser §3.1.3 ("CSG modeling") builds objects from high-level shapes (boxes, cylinders,
//! cones, spheres) so that simpler representations only have to be defined for those few shapes:
//! a cylinder becomes a prism with fewer sides, a sphere gets fewer slices. This module provides
//! exactly those shapes, each with a side/slice count chosen by the caller, emitting flat-shaded
//! faces (one normal per face, so a box has 24 vertices) with a per-vertex RGBA colour.

/// An sRGB colour with alpha, stored per vertex as normalized unsigned bytes (glTF `COLOR_0`).
pub(crate) type Rgba = [u8; 4];

/// The axis along which a prism, cylinder or cone extends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Axis {
    /// Along +X.
    X,
    /// Along +Y (up).
    Y,
    /// Along +Z.
    Z,
}

impl Axis {
    /// Maps shape-local coordinates (`a`, `b` across the axis, `h` along it) to x, y, z.
    fn map(self, a: f32, b: f32, h: f32) -> [f32; 3] {
        match self {
            Axis::X => [h, a, b],
            Axis::Y => [a, h, b],
            Axis::Z => [a, b, h],
        }
    }
}

/// An indexed triangle list with per-vertex position, normal and colour.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct MeshData {
    /// Vertex positions in metres.
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals (per face, repeated on the face's vertices).
    pub normals: Vec<[f32; 3]>,
    /// Vertex colours.
    pub colors: Vec<Rgba>,
    /// Triangle indices, counter-clockwise seen from outside.
    pub indices: Vec<u32>,
}

fn add3(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn sub3(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot3(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(v: [f32; 3]) -> Option<[f32; 3]> {
    let len = dot3(v, v).sqrt();
    (len > 1e-12).then(|| [v[0] / len, v[1] / len, v[2] / len])
}

/// Newell's polygon normal: oriented by the polygon's winding (right-hand rule).
fn newell(pts: &[[f32; 3]]) -> [f32; 3] {
    let mut n = [0.0f32; 3];
    for (i, p) in pts.iter().enumerate() {
        let q = pts[(i + 1) % pts.len()];
        n[0] += (p[1] - q[1]) * (p[2] + q[2]);
        n[1] += (p[2] - q[2]) * (p[0] + q[0]);
        n[2] += (p[0] - q[0]) * (p[1] + q[1]);
    }
    n
}

impl MeshData {
    /// Number of triangles.
    pub(crate) fn triangle_count(&self) -> u64 {
        (self.indices.len() / 3) as u64
    }

    /// Axis-aligned bounds of the vertices, or `None` for an empty mesh.
    pub(crate) fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        let first = *self.positions.first()?;
        let mut min = first;
        let mut max = first;
        for p in &self.positions {
            for k in 0..3 {
                min[k] = min[k].min(p[k]);
                max[k] = max[k].max(p[k]);
            }
        }
        Some((min, max))
    }

    /// Area-weighted-free average of the vertex colours (used for the coarsest box LOD).
    pub(crate) fn average_color(&self) -> Rgba {
        if self.colors.is_empty() {
            return [200, 200, 200, 255];
        }
        let mut sum = [0u64; 4];
        for c in &self.colors {
            for k in 0..4 {
                sum[k] += u64::from(c[k]);
            }
        }
        let n = self.colors.len() as u64;
        sum.map(|s| u8::try_from(s / n).unwrap_or(u8::MAX))
    }

    /// Adds a planar convex polygon, fan-triangulated, wound so that its normal points along
    /// `outward` (the winding of `pts` does not matter).
    pub(crate) fn add_face(&mut self, pts: &[[f32; 3]], outward: [f32; 3], color: Rgba) {
        if pts.len() < 3 {
            return;
        }
        let raw = newell(pts);
        let flip = dot3(raw, outward) < 0.0;
        let oriented = if flip { raw.map(|c| -c) } else { raw };
        let Some(normal) = normalize(oriented).or_else(|| normalize(outward)) else {
            return;
        };
        let base = self.positions.len() as u32;
        for p in pts {
            self.positions.push(*p);
            self.normals.push(normal);
            self.colors.push(color);
        }
        for i in 1..(pts.len() as u32 - 1) {
            let (b, c) = if flip { (i + 1, i) } else { (i, i + 1) };
            self.indices.extend_from_slice(&[base, base + b, base + c]);
        }
    }

    /// Adds an axis-aligned box (6 faces, 12 triangles, 24 vertices).
    pub(crate) fn add_box(&mut self, min: [f32; 3], max: [f32; 3], color: Rgba) {
        let [x0, y0, z0] = min;
        let [x1, y1, z1] = max;
        let faces: [([[f32; 3]; 4], [f32; 3]); 6] = [
            (
                [[x0, y0, z0], [x0, y1, z0], [x0, y1, z1], [x0, y0, z1]],
                [-1.0, 0.0, 0.0],
            ),
            (
                [[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]],
                [1.0, 0.0, 0.0],
            ),
            (
                [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]],
                [0.0, -1.0, 0.0],
            ),
            (
                [[x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]],
                [0.0, 1.0, 0.0],
            ),
            (
                [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]],
                [0.0, 0.0, -1.0],
            ),
            (
                [[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]],
                [0.0, 0.0, 1.0],
            ),
        ];
        for (pts, n) in faces {
            self.add_face(&pts, n, color);
        }
    }

    /// Adds a closed prism/frustum/cone with `sides` sides (at least 3) along `axis`, starting at
    /// `base` (centre of the first cap) and extending `len` along the axis, with radius `r0` at the
    /// base and `r1` at the top (`r1 == 0` makes a cone). Triangles: `4·sides − 4` (cone:
    /// `2·sides − 2`). With 4 sides the cross-section is an axis-aligned square.
    pub(crate) fn add_frustum(
        &mut self,
        axis: Axis,
        base: [f32; 3],
        len: f32,
        radii: (f32, f32),
        sides: u32,
        color: Rgba,
    ) {
        let sides = sides.max(3);
        let (r0, r1) = radii;
        let step = std::f32::consts::TAU / sides as f32;
        let start = std::f32::consts::PI / sides as f32;
        let ring = |r: f32, h: f32| -> Vec<[f32; 3]> {
            (0..sides)
                .map(|i| {
                    let t = start + step * i as f32;
                    add3(base, axis.map(r * t.cos(), r * t.sin(), h))
                })
                .collect()
        };
        let bottom = ring(r0, 0.0);
        let top = ring(r1, len);
        let dir = axis.map(0.0, 0.0, if len >= 0.0 { 1.0 } else { -1.0 });
        if r0 > 0.0 {
            self.add_face(&bottom, dir.map(|c| -c), color);
        }
        if r1 > 0.0 {
            self.add_face(&top, dir, color);
        }
        let apex = add3(base, axis.map(0.0, 0.0, len));
        for i in 0..sides as usize {
            let j = (i + 1) % sides as usize;
            let mid = start + step * (i as f32 + 0.5);
            let out = axis.map(mid.cos(), mid.sin(), 0.0);
            if r1 > 0.0 {
                self.add_face(&[bottom[i], bottom[j], top[j], top[i]], out, color);
            } else {
                self.add_face(&[bottom[i], bottom[j], apex], out, color);
            }
        }
    }

    /// Adds a cylinder (a prism with `sides` sides) of radius `r`.
    pub(crate) fn add_cylinder(
        &mut self,
        axis: Axis,
        base: [f32; 3],
        len: f32,
        r: f32,
        sides: u32,
        color: Rgba,
    ) {
        self.add_frustum(axis, base, len, (r, r), sides, color);
    }

    /// Adds a flat-shaded ellipsoid with `slices` around Y and `stacks` from pole to pole.
    /// Triangles: `2·slices·(stacks − 1)`.
    pub(crate) fn add_sphere(
        &mut self,
        center: [f32; 3],
        radii: [f32; 3],
        slices: u32,
        stacks: u32,
        color: Rgba,
    ) {
        let slices = slices.max(3);
        let stacks = stacks.max(2);
        let point = |i: u32, j: u32| -> [f32; 3] {
            let theta = std::f32::consts::PI * j as f32 / stacks as f32;
            let phi = std::f32::consts::TAU * i as f32 / slices as f32;
            let (st, ct) = theta.sin_cos();
            let (sp, cp) = phi.sin_cos();
            add3(
                center,
                [radii[0] * st * cp, radii[1] * ct, radii[2] * st * sp],
            )
        };
        for j in 0..stacks {
            for i in 0..slices {
                let quad = [
                    point(i, j),
                    point(i + 1, j),
                    point(i + 1, j + 1),
                    point(i, j + 1),
                ];
                let pts: Vec<[f32; 3]> = if j == 0 {
                    vec![quad[0], quad[2], quad[3]]
                } else if j == stacks - 1 {
                    vec![quad[0], quad[1], quad[2]]
                } else {
                    quad.to_vec()
                };
                let centroid = pts
                    .iter()
                    .fold([0.0; 3], |acc, p| add3(acc, *p))
                    .map(|c| c / pts.len() as f32);
                self.add_face(&pts, sub3(centroid, center), color);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outward_ok(m: &MeshData, center: [f32; 3]) -> bool {
        m.indices.chunks(3).all(|t| {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| m.positions[i as usize]);
            let n = newell(&[a, b, c]);
            let centroid = add3(add3(a, b), c).map(|v| v / 3.0);
            dot3(n, sub3(centroid, center)) > 0.0
        })
    }

    #[test]
    fn box_has_24_vertices_12_triangles_outward() {
        let mut m = MeshData::default();
        m.add_box([0.0; 3], [1.0, 2.0, 3.0], [1, 2, 3, 255]);
        assert_eq!(m.positions.len(), 24);
        assert_eq!(m.triangle_count(), 12);
        assert!(outward_ok(&m, [0.5, 1.0, 1.5]));
    }

    #[test]
    fn prism_and_sphere_counts_and_orientation() {
        for axis in [Axis::X, Axis::Y, Axis::Z] {
            let mut m = MeshData::default();
            m.add_cylinder(axis, [0.0; 3], 1.0, 0.5, 8, [0; 4]);
            assert_eq!(m.triangle_count(), 4 * 8 - 4);
            assert!(outward_ok(&m, axis.map(0.0, 0.0, 0.5)));
            let mut c = MeshData::default();
            c.add_frustum(axis, [0.0; 3], 1.0, (0.5, 0.0), 6, [0; 4]);
            assert_eq!(c.triangle_count(), 2 * 6 - 2);
        }
        let mut s = MeshData::default();
        s.add_sphere([1.0; 3], [0.5; 3], 8, 5, [0; 4]);
        assert_eq!(s.triangle_count(), 2 * 8 * 4);
        assert!(outward_ok(&s, [1.0; 3]));
    }
}
