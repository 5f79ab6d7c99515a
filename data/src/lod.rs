//! Automatic levels of detail (Funkhouser §3.1.3's guidelines, made automatic with meshopt).
//!
//! Starting from an object's own LODs (finest first), coarser LODs are added until the coarsest
//! has at most [`LOWEST_TARGET`] triangles, each at most half the triangles of the one above
//! (attribute-aware edge collapse; the topology-free "sloppy" simplifier when the mesh has too
//! many seams to halve), and finally an average-colour bounding box (Maciel §5.2). Every LOD
//! records its geometric error in metres: meshopt's error for simplified levels, and a measured
//! point-to-surface distance for the source's own levels and the box.
//!
//! Textured meshes keep their coordinates: the simplifier weighs them as attributes
//! (`meshopt_simplifyWithAttributes`) and never collapses across a UV seam (seam vertices share
//! a position but not an index, which meshopt keeps apart); every vertex reordering carries the
//! coordinates along. The box LOD has none: it is drawn in the texture's average colour.

use crate::geometry::{Aabb, Mesh, Vertex};
use glam::Vec3;

/// Stop simplifying once a LOD has at most this many triangles (Funkhouser: "no more than 100
/// polygons in the lowest LOD").
pub const LOWEST_TARGET: usize = 100;

/// Triangles in the average-colour box LOD.
pub const BOX_TRIANGLES: usize = 12;

/// Most LODs any object gets.
pub const MAX_LODS: usize = 12;

/// One LOD with its geometric error.
#[derive(Debug, Clone, PartialEq)]
pub struct LodMesh {
    /// The geometry.
    pub mesh: Mesh,
    /// Estimated maximum deviation from the finest LOD, in the mesh's units (metres).
    pub error: f32,
}

/// Completes an object's LOD chain (see the module docs). `given` is finest first and must not
/// be empty. Given LODs that break the halving rule are kept: they are the author's choice.
pub fn complete_lods(given: Vec<Mesh>) -> Vec<LodMesh> {
    let mut given = given.into_iter();
    let Some(finest) = given.next() else {
        return Vec::new();
    };
    let mut out = vec![LodMesh {
        mesh: optimize(finest.clone()),
        error: 0.0,
    }];
    for m in given {
        let error = deviation(&finest, &m);
        out.push(LodMesh {
            mesh: optimize(m),
            error,
        });
    }
    while out.len() < MAX_LODS {
        let last = out[out.len() - 1].mesh.triangle_count();
        if last <= LOWEST_TARGET {
            break;
        }
        match simplify(&finest, last / 2) {
            Some(lod) => out.push(lod),
            None => break,
        }
    }
    let last = out[out.len() - 1].mesh.triangle_count();
    if last >= 2 * BOX_TRIANGLES && out.len() < MAX_LODS {
        let mesh = average_color_box(&finest);
        let error = deviation(&finest, &mesh);
        out.push(LodMesh { mesh, error });
    }
    out
}

/// How much a texture coordinate's change weighs against a position's (metres per UV unit):
/// a texture repeating over a few metres should not slide by more than a texel or so.
const UV_WEIGHT: f32 = 0.5;

/// A vertex with its texture coordinate, so reorderings move both together.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
struct Textured {
    vertex: Vertex,
    uv: [f32; 2],
}

/// `mesh` with its vertices reordered by `f` (which reorders `indices` to match), texture
/// coordinates carried along.
fn reorder(
    mesh: &Mesh,
    mut indices: Vec<u32>,
    f: impl FnOnce(&mut Vec<u32>, &[Textured]) -> Vec<Textured>,
) -> Mesh {
    let joined: Vec<Textured> = mesh
        .vertices
        .iter()
        .enumerate()
        .map(|(i, &vertex)| Textured {
            vertex,
            uv: mesh.uvs.get(i).copied().unwrap_or_default(),
        })
        .collect();
    let out = f(&mut indices, &joined);
    Mesh {
        vertices: out.iter().map(|t| t.vertex).collect(),
        uvs: if mesh.has_uvs() {
            out.iter().map(|t| t.uv).collect()
        } else {
            Vec::new()
        },
        indices,
    }
}

/// Simplifies `finest` to at most `target` triangles, or gives up (`None`).
fn simplify(finest: &Mesh, target: usize) -> Option<LodMesh> {
    let positions: Vec<[f32; 3]> = finest.vertices.iter().map(|v| v.position).collect();
    let mut error = 0.0f32;
    let mut indices = if finest.has_uvs() {
        let uvs: Vec<f32> = finest.uvs.iter().flatten().copied().collect();
        meshopt::simplify_with_attributes_and_locks_decoder(
            &finest.indices,
            &positions,
            &uvs,
            &[UV_WEIGHT, UV_WEIGHT],
            8,
            &vec![false; positions.len()],
            target * 3,
            f32::MAX,
            meshopt::SimplifyOptions::ErrorAbsolute,
            Some(&mut error),
        )
    } else {
        meshopt::simplify_decoder(
            &finest.indices,
            &positions,
            target * 3,
            f32::MAX,
            meshopt::SimplifyOptions::ErrorAbsolute,
            Some(&mut error),
        )
    };
    if indices.len() / 3 > target {
        indices = meshopt::simplify_sloppy_decoder(
            &finest.indices,
            &positions,
            target * 3,
            f32::MAX,
            Some(&mut error),
        );
        // The sloppy simplifier reports a relative error.
        error *= meshopt::simplify_scale_decoder(&positions);
    }
    let tris = indices.len() / 3;
    if tris == 0 || tris > target {
        return None;
    }
    let mesh = reorder(finest, indices, |i, v| meshopt::optimize_vertex_fetch(i, v));
    Some(LodMesh {
        mesh: optimize(mesh),
        error,
    })
}

/// Reorders triangles for the post-transform cache and vertices for fetch locality.
fn optimize(mesh: Mesh) -> Mesh {
    if mesh.indices.is_empty() {
        return mesh;
    }
    let indices = meshopt::optimize_vertex_cache(&mesh.indices, mesh.vertices.len());
    reorder(&mesh, indices, |i, v| meshopt::optimize_vertex_fetch(i, v))
}

/// The bounding box as 12 flat-shaded triangles in the mesh's area-weighted average colour
/// (Maciel §5.2: the cheapest impostor).
pub fn average_color_box(mesh: &Mesh) -> Mesh {
    let b = mesh.bounds();
    let color = mesh.average_color();
    box_mesh(&b, color)
}

/// A flat-shaded box (24 vertices, 12 triangles, outward normals, counter-clockwise faces).
pub fn box_mesh(b: &Aabb, color: [f32; 4]) -> Mesh {
    let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
    let mut mesh = Mesh::default();
    for axis in 0..3 {
        for side in [0.0f32, 1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = if side > 0.5 { 1.0 } else { -1.0 };
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |a: f32, c: f32| {
                let mut p = lo;
                p[axis] = if side > 0.5 { hi[axis] } else { lo[axis] };
                p[u] = if a > 0.5 { hi[u] } else { lo[u] };
                p[v] = if c > 0.5 { hi[v] } else { lo[v] };
                Vertex::new(p.into(), n.into(), color)
            };
            let base = mesh.vertices.len() as u32;
            mesh.vertices.extend([
                corner(0.0, 0.0),
                corner(1.0, 0.0),
                corner(1.0, 1.0),
                corner(0.0, 1.0),
            ]);
            let quad = if side > 0.5 {
                [0, 1, 2, 0, 2, 3]
            } else {
                [0, 2, 1, 0, 3, 2]
            };
            mesh.indices.extend(quad.map(|i| base + i));
        }
    }
    mesh
}

/// Largest distance from a sample of `fine`'s vertices to the surface of `coarse`: a cheap
/// one-sided Hausdorff estimate used as the geometric error of LODs meshopt did not make.
pub fn deviation(fine: &Mesh, coarse: &Mesh) -> f32 {
    const SAMPLES: usize = 256;
    if coarse.indices.is_empty() || fine.vertices.is_empty() {
        return fine.bounds().size().length();
    }
    let step = fine.vertices.len().div_ceil(SAMPLES).max(1);
    let tris: Vec<[Vec3; 3]> = coarse
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]].map(|i| Vec3::from(coarse.vertices[i as usize].position)))
        .collect();
    fine.vertices
        .iter()
        .step_by(step)
        .map(|v| {
            let p = Vec3::from(v.position);
            tris.iter()
                .map(|t| point_triangle_distance(p, t))
                .fold(f32::INFINITY, f32::min)
        })
        .fold(0.0, f32::max)
}

/// Distance from `p` to triangle `t` (Ericson, Real-Time Collision Detection §5.1.5).
fn point_triangle_distance(p: Vec3, t: &[Vec3; 3]) -> f32 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.length();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.length();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (p - (a + ab * v)).length();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.length();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (p - (a + ac * w)).length();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + (c - b) * w)).length();
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (p - (a + ab * v + ac * w)).length()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A UV sphere with `n` segments: smooth, so the simplifier can halve it many times.
    fn sphere(n: u32) -> Mesh {
        let mut m = Mesh::default();
        for i in 0..=n {
            let th = std::f32::consts::PI * i as f32 / n as f32;
            for j in 0..=2 * n {
                let ph = std::f32::consts::PI * j as f32 / n as f32;
                let p = Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
                m.vertices
                    .push(Vertex::new(p.into(), p.into(), [0.2, 0.4, 0.8, 1.0]));
            }
        }
        let w = 2 * n + 1;
        for i in 0..n {
            for j in 0..2 * n {
                let (a, b) = (i * w + j, (i + 1) * w + j);
                m.indices.extend([a, b, a + 1, a + 1, b, b + 1]);
            }
        }
        m
    }

    #[test]
    fn each_lod_at_most_half_the_one_above_down_to_a_box() {
        let lods = complete_lods(vec![sphere(48)]);
        assert!(lods.len() >= 5, "only {} LODs", lods.len());
        for w in lods.windows(2) {
            let (hi, lo) = (w[0].mesh.triangle_count(), w[1].mesh.triangle_count());
            assert!(lo * 2 <= hi, "{lo} is more than half of {hi}");
        }
        let last = &lods[lods.len() - 1].mesh;
        assert_eq!(last.triangle_count(), BOX_TRIANGLES);
        assert!(lods[lods.len() - 2].mesh.triangle_count() <= LOWEST_TARGET);
        for l in &lods {
            l.mesh.validate().expect("valid LOD");
        }
    }

    #[test]
    fn errors_grow_as_detail_drops() {
        let lods = complete_lods(vec![sphere(32)]);
        assert_eq!(lods[0].error, 0.0);
        let box_err = lods[lods.len() - 1].error;
        assert!(box_err > 0.1 && box_err < 1.0, "box error {box_err}");
        assert!(lods[1].error < box_err);
    }

    #[test]
    fn box_lod_has_the_average_colour_and_the_bounds() {
        let s = sphere(8);
        let b = average_color_box(&s);
        assert_eq!(b.triangle_count(), 12);
        assert_eq!(b.vertices[0].color, s.vertices[0].color);
        assert_eq!(b.bounds(), s.bounds());
        // The average is over area: a red triangle three times the size of a blue one.
        let tri = |scale: f32, color: [f32; 4]| {
            [[0.0, 0.0, 0.0], [scale, 0.0, 0.0], [0.0, scale, 0.0]]
                .map(|p| Vertex::new(p, [0.0, 0.0, 1.0], color))
        };
        let two = Mesh {
            vertices: [
                tri(3f32.sqrt(), [1.0, 0.0, 0.0, 1.0]),
                tri(1.0, [0.0, 0.0, 1.0, 1.0]),
            ]
            .concat(),
            indices: (0..6).collect(),
            uvs: Vec::new(),
        };
        let c = average_color_box(&two).vertices[0].color_f32();
        let near = |a: f32, b: f32| (a - b).abs() < 1.0 / 255.0;
        assert!(
            near(c[0], 0.75) && near(c[1], 0.0) && near(c[2], 0.25),
            "{c:?}"
        );
    }

    #[test]
    fn textured_lods_keep_their_coordinates_and_seams() {
        // The sphere's seam: column 0 and column 2n share positions, at u = 0 and u = 1.
        let n = 32;
        let mut s = sphere(n);
        s.uvs = (0..=n)
            .flat_map(|i| {
                (0..=2 * n).map(move |j| [j as f32 / (2 * n) as f32, i as f32 / n as f32])
            })
            .collect();
        let key = |p: [f32; 3], uv: [f32; 2]| (p.map(f32::to_bits), uv.map(f32::to_bits));
        let source: std::collections::HashSet<_> = s
            .vertices
            .iter()
            .zip(&s.uvs)
            .map(|(v, uv)| key(v.position, *uv))
            .collect();
        let lods = complete_lods(vec![s]);
        assert!(lods.len() >= 4, "{} LODs", lods.len());
        let (boxed, simplified) = lods.split_last().unwrap();
        assert!(
            !boxed.mesh.has_uvs(),
            "the box is drawn in the average colour"
        );
        for (k, l) in simplified.iter().enumerate() {
            let m = &l.mesh;
            m.validate().expect("valid");
            assert_eq!(m.uvs.len(), m.vertices.len(), "LOD {k}");
            // Every vertex keeps the coordinate it had at its position (nothing invented), and
            // the seam is still there.
            for (v, uv) in m.vertices.iter().zip(&m.uvs) {
                assert!(source.contains(&key(v.position, *uv)), "LOD {k}: {uv:?}");
            }
            let on_seam = |u: f32| {
                m.vertices
                    .iter()
                    .zip(&m.uvs)
                    .any(|(v, uv)| uv[0] == u && v.position[0] > 0.1)
            };
            // (The coarsest levels may fall back to the sloppy simplifier, which welds.)
            if m.triangle_count() >= 500 {
                assert!(on_seam(0.0) && on_seam(1.0), "LOD {k} lost its seam");
            }
        }
    }

    #[test]
    fn small_meshes_keep_a_single_lod() {
        let b = box_mesh(
            &Aabb {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            [1.0; 4],
        );
        assert_eq!(complete_lods(vec![b]).len(), 1);
    }

    #[test]
    fn distance_to_triangle_regions() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        assert!((point_triangle_distance(Vec3::new(0.2, 0.2, 1.0), &t) - 1.0).abs() < 1e-6);
        assert!((point_triangle_distance(Vec3::new(-1.0, 0.0, 0.0), &t) - 1.0).abs() < 1e-6);
        assert!(
            (point_triangle_distance(Vec3::new(1.0, 1.0, 0.0), &t) - 0.5f32.sqrt()).abs() < 1e-6
        );
    }
}
