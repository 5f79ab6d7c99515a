//! Critical vertices: where the image-fidelity measures look (RRB §5.3.3).
//!
//! RRB compares images only in small *areas of interest* around **critical vertices**, the
//! vertices that carry the most shape information (Attneave): curvature extrema and
//! discontinuities. For one mesh (the finest LOD of an object, in object space) we:
//!
//! 1. **weld** vertices by position (flat-shaded meshes repeat a corner once per face; without
//!    welding every corner would look like a flat boundary vertex), within
//!    [`CriticalParams::weld_epsilon`] × the mesh's bounding-box diagonal;
//! 2. **curvature extrema** (§5.3.3, eq. 5.11–5.12): sum Garland–Heckbert's plane quadrics of the
//!    faces around each welded vertex. The 3×3 normal block of `Q = Σ K_p` is
//!    `A = Σ_f w_f n_f n_fᵀ`. Garland weights each plane by its triangle's area; we weight it
//!    by the triangle's interior angle at the vertex and divide by the angle sum, so that the
//!    eigenvalues are scale-free, sum to 1 and do not depend on how a polygon was split into
//!    triangles (with area weights a box corner touching one triangle of one face and two of
//!    another would look less curved than its neighbour). With the eigenvalues (Jacobi, as RRB) sorted
//!    `a1 ≥ a2 ≥ a3`, `a2 ∝ k1²` and `a3 ∝ k2²`, and the vertex is an extremum when
//!    `max(a2, a3) = a2 > τ` ([`CriticalParams::curvature_threshold`], default 0.05). On a flat
//!    patch `a2 = 0`; on a crease between two equal faces at dihedral angle θ,
//!    `a2 = (1 − cos θ)/2`, so τ = 0.05 means "sharper than about 26°"; a box corner has
//!    `a1 = a2 = a3 = 1/3`;
//! 3. **discontinuities**: *boundary* vertices (on an edge used by exactly one non-degenerate
//!    triangle after welding) and *colour-border* vertices (whose copies carry vertex colours
//!    differing by more than [`CriticalParams::colour_tolerance`] in some RGB channel).
//!
//! Every vertex in at least one class is critical. RRB also lets the user cap the count; we keep
//! all of them (their share is reported), because a building made of boxes has almost only
//! corners.

use glam::{Mat3, Vec3};
use portico_data::geometry::Mesh;
use serde::Serialize;
use std::collections::HashMap;

/// Parameters of the critical-vertex selection.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CriticalParams {
    /// τ: a welded vertex is a curvature extremum when the second eigenvalue of its normalised
    /// quadric normal block exceeds this (0..1; 0.05 ≈ a 26° crease).
    pub curvature_threshold: f32,
    /// Largest per-channel difference (0..255) of vertex colours that still counts as one colour.
    pub colour_tolerance: u8,
    /// Welding distance as a fraction of the mesh's bounding-box diagonal.
    pub weld_epsilon: f32,
}

impl Default for CriticalParams {
    /// τ = 0.05, colour tolerance 8/255, weld within 1e-5 of the diagonal.
    fn default() -> Self {
        CriticalParams {
            curvature_threshold: 0.05,
            colour_tolerance: 8,
            weld_epsilon: 1e-5,
        }
    }
}

/// One critical vertex of a mesh, in the mesh's own coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CriticalVertex {
    /// Position (object space).
    pub position: Vec3,
    /// `a2`, the second-largest eigenvalue of the normalised quadric normal block (0..0.5).
    pub curvature: f32,
    /// A curvature extremum (`curvature > τ`).
    pub extremum: bool,
    /// On an open boundary edge.
    pub boundary: bool,
    /// On a border between vertex colours.
    pub colour_border: bool,
}

/// How many vertices a mesh has and how many of them are critical, by class.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct CriticalCounts {
    /// Welded vertices (distinct positions used by some triangle).
    pub vertices: u64,
    /// Critical vertices (in at least one class).
    pub critical: u64,
    /// Curvature extrema.
    pub extrema: u64,
    /// Boundary vertices.
    pub boundary: u64,
    /// Colour-border vertices.
    pub colour_border: u64,
}

impl CriticalCounts {
    /// Adds another mesh's counts `times` times (e.g. once per instance).
    pub fn add(&mut self, other: &CriticalCounts, times: u64) {
        self.vertices += other.vertices * times;
        self.critical += other.critical * times;
        self.extrema += other.extrema * times;
        self.boundary += other.boundary * times;
        self.colour_border += other.colour_border * times;
    }
}

/// The critical vertices of a mesh and the counts behind them.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct CriticalSet {
    /// Critical vertices, in first-appearance order of their welded vertex.
    pub vertices: Vec<CriticalVertex>,
    /// Counts by class.
    pub counts: CriticalCounts,
}

/// Per welded vertex: summed angle-weighted normal block, angle sum, colour state.
#[derive(Debug, Clone, Copy)]
struct Welded {
    position: Vec3,
    quadric: Mat3,
    weight: f32,
    colour: [u8; 4],
    colour_border: bool,
    used: bool,
}

/// Selects the critical vertices of `mesh` (see the module docs).
pub fn critical_vertices(mesh: &Mesh, params: &CriticalParams) -> CriticalSet {
    let (map, mut welded) = weld(mesh, params);
    let edges = accumulate_faces(mesh, &map, &mut welded);
    let mut boundary = vec![false; welded.len()];
    for (&(a, b), &count) in &edges {
        if count == 1 {
            boundary[a as usize] = true;
            boundary[b as usize] = true;
        }
    }
    classify(&welded, &boundary, params)
}

/// Maps every vertex to a welded vertex and collects the welded vertices' colour state.
fn weld(mesh: &Mesh, params: &CriticalParams) -> (Vec<u32>, Vec<Welded>) {
    let diag = mesh.bounds().size().length();
    let q = (diag * params.weld_epsilon).max(f32::MIN_POSITIVE);
    let mut index: HashMap<[i64; 3], u32> = HashMap::with_capacity(mesh.vertices.len());
    let mut welded: Vec<Welded> = Vec::new();
    let map = mesh
        .vertices
        .iter()
        .map(|v| {
            let p = Vec3::from(v.position);
            let key = [0, 1, 2].map(|i| (f64::from(p[i]) / f64::from(q)).round() as i64);
            let id = *index.entry(key).or_insert_with(|| {
                welded.push(Welded {
                    position: p,
                    quadric: Mat3::ZERO,
                    weight: 0.0,
                    colour: v.color,
                    colour_border: false,
                    used: false,
                });
                (welded.len() - 1) as u32
            });
            let w = &mut welded[id as usize];
            let tol = i16::from(params.colour_tolerance);
            let differs =
                (0..3).any(|c| (i16::from(w.colour[c]) - i16::from(v.color[c])).abs() > tol);
            w.colour_border |= differs;
            id
        })
        .collect();
    (map, welded)
}

/// Adds each non-degenerate triangle's angle-weighted normal block to its three welded vertices
/// and counts how many triangles use each welded edge.
fn accumulate_faces(mesh: &Mesh, map: &[u32], welded: &mut [Welded]) -> HashMap<(u32, u32), u32> {
    let mut edges: HashMap<(u32, u32), u32> = HashMap::with_capacity(mesh.indices.len());
    for tri in mesh.indices.chunks_exact(3) {
        let w = [0, 1, 2].map(|k| map[tri[k] as usize]);
        if w[0] == w[1] || w[1] == w[2] || w[0] == w[2] {
            continue;
        }
        let p = w.map(|i| welded[i as usize].position);
        let cross = (p[1] - p[0]).cross(p[2] - p[0]);
        let area = cross.length() * 0.5;
        if !area.is_finite() || area <= 0.0 {
            continue;
        }
        let n = cross / (2.0 * area);
        let block = Mat3::from_cols(n * n.x, n * n.y, n * n.z);
        for k in 0..3 {
            let angle = corner_angle(p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
            let v = &mut welded[w[k] as usize];
            v.quadric += block * angle;
            v.weight += angle;
            v.used = true;
        }
        for (a, b) in [(w[0], w[1]), (w[1], w[2]), (w[2], w[0])] {
            *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    edges
}

/// The interior angle at `at` of the triangle `(at, b, c)`, radians.
fn corner_angle(at: Vec3, b: Vec3, c: Vec3) -> f32 {
    (b - at).angle_between(c - at)
}

/// Turns the welded vertices' sums into critical vertices and counts.
fn classify(welded: &[Welded], boundary: &[bool], params: &CriticalParams) -> CriticalSet {
    let mut set = CriticalSet::default();
    for (w, &on_boundary) in welded.iter().zip(boundary) {
        if !w.used {
            continue;
        }
        set.counts.vertices += 1;
        let curvature = second_eigenvalue(&(w.quadric * (1.0 / w.weight)));
        let cv = CriticalVertex {
            position: w.position,
            curvature,
            extremum: curvature > params.curvature_threshold,
            boundary: on_boundary,
            colour_border: w.colour_border,
        };
        if cv.extremum || cv.boundary || cv.colour_border {
            set.counts.critical += 1;
            set.counts.extrema += u64::from(cv.extremum);
            set.counts.boundary += u64::from(cv.boundary);
            set.counts.colour_border += u64::from(cv.colour_border);
            set.vertices.push(cv);
        }
    }
    set
}

/// The middle eigenvalue of a symmetric 3×3 matrix.
fn second_eigenvalue(m: &Mat3) -> f32 {
    let mut e = symmetric_eigenvalues(m);
    e.sort_by(|a, b| b.total_cmp(a));
    e[1] as f32
}

/// Eigenvalues of a symmetric 3×3 matrix by cyclic Jacobi rotations (RRB §5.3.3 uses Jacobi).
pub fn symmetric_eigenvalues(m: &Mat3) -> [f64; 3] {
    let mut a = [[0f64; 3]; 3];
    for (c, col) in [m.x_axis, m.y_axis, m.z_axis].iter().enumerate() {
        for r in 0..3 {
            a[r][c] = f64::from(col[r]);
        }
    }
    for _sweep in 0..32 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        if off < 1e-24 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            rotate(&mut a, p, q);
        }
    }
    [a[0][0], a[1][1], a[2][2]]
}

/// One Jacobi rotation zeroing `a[p][q]`.
fn rotate(a: &mut [[f64; 3]; 3], p: usize, q: usize) {
    if a[p][q].abs() < 1e-300 {
        return;
    }
    let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
    let t = if theta == 0.0 { 1.0 } else { t };
    let c = 1.0 / (t * t + 1.0).sqrt();
    let s = t * c;
    for row in a.iter_mut() {
        let (akp, akq) = (row[p], row[q]);
        row[p] = c * akp - s * akq;
        row[q] = s * akp + c * akq;
    }
    let (rp, rq) = (a[p], a[q]);
    a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
    a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
}

#[cfg(test)]
mod tests {
    use super::*;
    use portico_data::geometry::Vertex;

    const GREY: [f32; 4] = [0.5, 0.5, 0.5, 1.0];

    /// A flat-shaded unit cube: 24 vertices (each corner once per face), like the generator's.
    fn cube() -> Mesh {
        let mut m = Mesh::default();
        for (n, u, v) in [
            (Vec3::X, Vec3::Y, Vec3::Z),
            (Vec3::Y, Vec3::Z, Vec3::X),
            (Vec3::Z, Vec3::X, Vec3::Y),
        ] {
            for s in [1.0f32, -1.0] {
                let base = m.vertices.len() as u32;
                for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    let p = (n * s + u * a + v * b) * 0.5;
                    m.vertices.push(Vertex::new(p.into(), (n * s).into(), GREY));
                }
                m.indices
                    .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
            }
        }
        m
    }

    /// An open `n`×`n`-quad grid in the plane y = 0 with shared vertices; `colour(i, j)` per vertex.
    fn grid(n: u32, colour: impl Fn(u32, u32) -> [f32; 4]) -> Mesh {
        let mut m = Mesh::default();
        for j in 0..=n {
            for i in 0..=n {
                let p = [i as f32, 0.0, j as f32];
                m.vertices
                    .push(Vertex::new(p, [0.0, 1.0, 0.0], colour(i, j)));
            }
        }
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                m.indices
                    .extend([a, a + n + 1, a + 1, a + 1, a + n + 1, a + n + 2]);
            }
        }
        m
    }

    #[test]
    fn jacobi_finds_the_eigenvalues_of_a_rotated_diagonal_matrix() {
        let r = Mat3::from_rotation_y(0.7) * Mat3::from_rotation_x(0.3);
        let m = r * Mat3::from_diagonal(Vec3::new(3.0, 2.0, 0.5)) * r.transpose();
        let mut e = symmetric_eigenvalues(&m);
        e.sort_by(|a, b| b.total_cmp(a));
        for (got, want) in e.iter().zip([3.0, 2.0, 0.5]) {
            assert!((got - want).abs() < 1e-5, "{e:?}");
        }
    }

    #[test]
    fn cube_corners_are_curvature_extrema() {
        let set = critical_vertices(&cube(), &CriticalParams::default());
        assert_eq!(
            set.counts.vertices, 8,
            "24 flat-shaded copies weld to 8 corners"
        );
        assert_eq!(set.counts.critical, 8);
        assert_eq!(set.counts.extrema, 8);
        assert_eq!(set.counts.boundary, 0, "a welded cube is closed");
        assert_eq!(set.counts.colour_border, 0);
        for v in &set.vertices {
            assert!((v.curvature - 1.0 / 3.0).abs() < 1e-4, "{v:?}");
            assert!(v.position.abs().cmpeq(Vec3::splat(0.5)).all());
        }
    }

    #[test]
    fn flat_grid_interior_is_not_critical_but_its_open_boundary_is() {
        let n = 4;
        let set = critical_vertices(&grid(n, |_, _| GREY), &CriticalParams::default());
        assert_eq!(set.counts.vertices, u64::from((n + 1) * (n + 1)));
        assert_eq!(set.counts.extrema, 0, "a plane has no curvature");
        assert_eq!(set.counts.boundary, u64::from(4 * n));
        assert_eq!(set.counts.critical, u64::from(4 * n));
        for v in &set.vertices {
            let on_edge = [v.position.x, v.position.z]
                .iter()
                .any(|&c| c == 0.0 || c == n as f32);
            assert!(on_edge && v.boundary && v.curvature.abs() < 1e-6, "{v:?}");
        }
    }

    #[test]
    fn colour_borders_are_critical() {
        let n = 4;
        // Left half red, right half blue; the column i = 2 is shared by both through
        // duplicate vertices only when the colour changes, so split the grid's vertices.
        let mut m = grid(n, |i, _| {
            if i < 2 {
                [1.0, 0.0, 0.0, 1.0]
            } else {
                [0.0, 0.0, 1.0, 1.0]
            }
        });
        // Re-colour the quads right of i = 2 through copies of the i = 2 column, as an
        // exporter does at a material border: copy vertex (2, j) with the red colour.
        let copies: Vec<u32> = (0..=n)
            .map(|j| {
                let mut v = m.vertices[(j * (n + 1) + 2) as usize];
                v.color = [255, 0, 0, 255];
                m.vertices.push(v);
                (m.vertices.len() - 1) as u32
            })
            .collect();
        for tri in m.indices.chunks_exact_mut(3) {
            let left = tri.iter().all(|&k| k % (n + 1) <= 2);
            if left {
                for k in tri.iter_mut() {
                    if *k % (n + 1) == 2 {
                        *k = copies[(*k / (n + 1)) as usize];
                    }
                }
            }
        }
        let set = critical_vertices(&m, &CriticalParams::default());
        let border: Vec<&CriticalVertex> =
            set.vertices.iter().filter(|v| v.colour_border).collect();
        assert_eq!(border.len(), (n + 1) as usize);
        assert!(border.iter().all(|v| v.position.x == 2.0));
        assert_eq!(set.counts.extrema, 0);
    }

    #[test]
    fn a_gentle_fold_is_not_an_extremum_but_a_sharp_one_is() {
        for (angle_deg, sharp) in [(10.0f32, false), (60.0, true)] {
            let a = angle_deg.to_radians();
            let p = [
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
                Vec3::new(-1.0, 0.0, 0.0),
                Vec3::new(a.cos(), a.sin(), 0.0),
            ];
            let m = Mesh {
                vertices: p
                    .iter()
                    .map(|p| Vertex::new((*p).into(), [0.0, 1.0, 0.0], GREY))
                    .collect(),
                indices: vec![0, 1, 2, 0, 3, 1],
                uvs: Vec::new(),
            };
            let set = critical_vertices(&m, &CriticalParams::default());
            let fold: Vec<_> = set
                .vertices
                .iter()
                .filter(|v| v.position.x == 0.0)
                .collect();
            assert_eq!(fold.len(), 2, "{angle_deg}°: {:?}", set.vertices);
            assert!(
                fold.iter().all(|v| v.extremum == sharp),
                "{angle_deg}°: {:?}",
                set.vertices
            );
        }
    }
}
