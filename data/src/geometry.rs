//! In-memory meshes and the on-disk geometry segment layout.
//!
//! A geometry segment is laid out for direct GPU upload: a 32-byte header, then the
//! interleaved vertex stream (`Vertex`, 20 bytes: position `f32x3`, normal `snorm8x4`, colour
//! `unorm8x4`), then, for a textured mesh ([`GEOMETRY_UV`]), its texture coordinates (`f32x2`
//! per vertex, glTF's convention: origin at the image's top left), then the index stream (`u16`
//! when every index fits, else `u32`), each 4-byte aligned. A client binds the vertex and index ranges straight from these bytes (a compressed
//! segment, [`GEOMETRY_MESHOPT`], is decoded into this layout first).

use bytemuck::{Pod, Zeroable};
use glam::{Mat3, Mat4, Vec3};
use serde::{Deserialize, Serialize};

/// One interleaved vertex as stored on disk and in GPU buffers.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Pod, Zeroable)]
pub struct Vertex {
    /// Position in the mesh's coordinate system (metres).
    pub position: [f32; 3],
    /// Unit normal, signed-normalised bytes (x, y, z, 0).
    pub normal: [i8; 4],
    /// Linear RGBA colour, unsigned-normalised bytes.
    pub color: [u8; 4],
}

impl Vertex {
    /// Builds a vertex from float attributes, quantising normal and colour.
    pub fn new(position: [f32; 3], normal: [f32; 3], color: [f32; 4]) -> Self {
        let n = Vec3::from(normal).normalize_or_zero();
        let q = |x: f32| (x.clamp(-1.0, 1.0) * 127.0).round() as i8;
        let c = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
        Vertex {
            position,
            normal: [q(n.x), q(n.y), q(n.z), 0],
            color: [c(color[0]), c(color[1]), c(color[2]), c(color[3])],
        }
    }

    /// The normal as a float vector (not re-normalised).
    pub fn normal_f32(&self) -> Vec3 {
        Vec3::new(
            self.normal[0] as f32 / 127.0,
            self.normal[1] as f32 / 127.0,
            self.normal[2] as f32 / 127.0,
        )
    }

    /// The colour as floats in 0..=1.
    pub fn color_f32(&self) -> [f32; 4] {
        self.color.map(|c| c as f32 / 255.0)
    }
}

/// Axis-aligned bounding box. An empty box has `min > max`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Smallest corner.
    pub min: [f32; 3],
    /// Largest corner.
    pub max: [f32; 3],
}

/// Ray–box intersection (the slab test): the interval of `t` for which `o + t·d` is inside the
/// box, if any (`t` may be negative: behind the origin).
pub fn slab(o: Vec3, d: Vec3, b: &Aabb) -> Option<(f32, f32)> {
    let (mut t0, mut t1) = (f32::NEG_INFINITY, f32::INFINITY);
    for k in 0..3 {
        if d[k].abs() < 1e-12 {
            if o[k] < b.min[k] || o[k] > b.max[k] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / d[k];
        let (a, c) = ((b.min[k] - o[k]) * inv, (b.max[k] - o[k]) * inv);
        t0 = t0.max(a.min(c));
        t1 = t1.min(a.max(c));
    }
    (t0 <= t1).then_some((t0, t1))
}

impl Aabb {
    /// The empty box, the identity for [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb {
        min: [f32::INFINITY; 3],
        max: [f32::NEG_INFINITY; 3],
    };

    /// Whether the box contains no point.
    pub fn is_empty(&self) -> bool {
        (0..3).any(|i| self.min[i] > self.max[i])
    }

    /// Grows the box to contain `p`.
    pub fn include(&mut self, p: Vec3) {
        self.min = Vec3::from(self.min).min(p).into();
        self.max = Vec3::from(self.max).max(p).into();
    }

    /// The smallest box containing both.
    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            min: Vec3::from(self.min).min(Vec3::from(other.min)).into(),
            max: Vec3::from(self.max).max(Vec3::from(other.max)).into(),
        }
    }

    /// Whether `other` lies inside this box (faces may touch).
    pub fn contains_box(&self, other: &Aabb) -> bool {
        (0..3).all(|i| self.min[i] <= other.min[i] && other.max[i] <= self.max[i])
    }

    /// Extent along each axis (zero for an empty box).
    pub fn size(&self) -> Vec3 {
        if self.is_empty() {
            Vec3::ZERO
        } else {
            Vec3::from(self.max) - Vec3::from(self.min)
        }
    }

    /// The centre point.
    pub fn center(&self) -> Vec3 {
        (Vec3::from(self.min) + Vec3::from(self.max)) * 0.5
    }

    /// The box of the eight transformed corners (a conservative world box).
    pub fn transformed(&self, m: &Mat4) -> Aabb {
        let mut out = Aabb::EMPTY;
        if self.is_empty() {
            return out;
        }
        for i in 0..8 {
            let c = Vec3::new(
                if i & 1 == 0 { self.min[0] } else { self.max[0] },
                if i & 2 == 0 { self.min[1] } else { self.max[1] },
                if i & 4 == 0 { self.min[2] } else { self.max[2] },
            );
            out.include(m.transform_point3(c));
        }
        out
    }
}

/// An indexed triangle list with interleaved vertices: one LOD of one object.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mesh {
    /// Vertex data.
    pub vertices: Vec<Vertex>,
    /// Triangle list; every index is `< vertices.len()`.
    pub indices: Vec<u32>,
    /// Texture coordinates, one per vertex (glTF's convention: (0, 0) is the image's top left,
    /// values past 0..1 repeat), or empty for a mesh without a texture.
    pub uvs: Vec<[f32; 2]>,
}

impl Mesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Bounding box of the vertices.
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for v in &self.vertices {
            b.include(Vec3::from(v.position));
        }
        b
    }

    /// Whether the mesh has texture coordinates.
    pub fn has_uvs(&self) -> bool {
        !self.uvs.is_empty()
    }

    /// Largest extent of the texture coordinates on either axis (how many times a texture
    /// repeats across the mesh; 0 without coordinates). The finest mip worth fetching for an
    /// object `p` pixels across is about `p / uv_span` texels wide
    /// ([`crate::texture::useful_width`]).
    pub fn uv_span(&self) -> f32 {
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for uv in &self.uvs {
            for a in 0..2 {
                lo[a] = lo[a].min(uv[a]);
                hi[a] = hi[a].max(uv[a]);
            }
        }
        (0..2)
            .map(|a| hi[a] - lo[a])
            .filter(|x| x.is_finite())
            .fold(0.0, f32::max)
    }

    /// Checks the invariants: whole triangles, indices in range, one finite texture
    /// coordinate per vertex or none.
    pub fn validate(&self) -> Result<(), String> {
        if self.has_uvs() && self.uvs.len() != self.vertices.len() {
            return Err(format!(
                "{} texture coordinates for {} vertices",
                self.uvs.len(),
                self.vertices.len()
            ));
        }
        if self.uvs.iter().flatten().any(|x| !x.is_finite()) {
            return Err("a texture coordinate is not a finite number".into());
        }
        if !self.indices.len().is_multiple_of(3) {
            return Err(format!(
                "index count {} is not a multiple of 3",
                self.indices.len()
            ));
        }
        let n = self.vertices.len() as u32;
        if let Some(bad) = self.indices.iter().find(|&&i| i >= n) {
            return Err(format!("index {bad} out of range for {n} vertices"));
        }
        Ok(())
    }

    /// The mesh with positions and normals transformed by `m` (normals by its inverse transpose).
    /// A mirroring `m` (negative determinant) also reverses each triangle's winding, so the
    /// side its front was on stays the front (glTF §3.7.4), as single-sided culling needs.
    pub fn transformed(&self, m: &Mat4) -> Mesh {
        let normal_matrix = Mat3::from_mat4(*m).inverse().transpose();
        let vertices = self
            .vertices
            .iter()
            .map(|v| {
                let p = m.transform_point3(Vec3::from(v.position));
                let n = normal_matrix * v.normal_f32();
                Vertex::new(p.into(), n.into(), v.color_f32())
            })
            .collect();
        let mut indices = self.indices.clone();
        if m.determinant() < 0.0 {
            for t in indices.chunks_exact_mut(3) {
                t.swap(1, 2);
            }
        }
        Mesh {
            vertices,
            indices,
            uvs: self.uvs.clone(),
        }
    }

    /// Area-weighted average colour of the surface (Maciel §5.2's average-colour box uses it).
    pub fn average_color(&self) -> [f32; 4] {
        let mut sum = [0.0f64; 4];
        let mut total = 0.0f64;
        for t in self.indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| self.vertices[i as usize]);
            let area = (Vec3::from(b.position) - Vec3::from(a.position))
                .cross(Vec3::from(c.position) - Vec3::from(a.position))
                .length() as f64
                * 0.5;
            for v in [a, b, c] {
                for (s, x) in sum.iter_mut().zip(v.color_f32()) {
                    *s += area * x as f64 / 3.0;
                }
            }
            total += area;
        }
        if total <= 0.0 {
            return [0.5, 0.5, 0.5, 1.0];
        }
        sum.map(|s| (s / total) as f32)
    }
}

/// Magic number at the start of every geometry segment ("PGEO", little-endian).
pub const GEOMETRY_MAGIC: u32 = u32::from_le_bytes(*b"PGEO");
/// Layout version of geometry segments.
pub const GEOMETRY_VERSION: u16 = 1;
/// Flag: the index stream holds `u32` indices (else `u16`).
pub const GEOMETRY_U32_INDICES: u16 = 1;
/// Flag: the streams are quantised and meshopt-encoded (`codec`, native builds); such a
/// segment must be decoded into the plain layout before [`GeometryView::parse`] takes it.
pub const GEOMETRY_MESHOPT: u16 = 2;
/// Flag: a texture-coordinate stream (`[f32; 2]` per vertex) follows the vertex stream.
pub const GEOMETRY_UV: u16 = 4;
/// Flag (with [`GEOMETRY_MESHOPT`]): everything after the header is raw deflate (RFC 1951) of
/// the meshopt segment's body (`codec`); segments without it are meshopt alone.
pub const GEOMETRY_DEFLATE: u16 = 8;

/// The fixed 32-byte header at the start of a geometry segment.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GeometryHeader {
    /// [`GEOMETRY_MAGIC`].
    pub magic: u32,
    /// [`GEOMETRY_VERSION`].
    pub version: u16,
    /// [`GEOMETRY_U32_INDICES`] (of the plain layout), [`GEOMETRY_MESHOPT`],
    /// [`GEOMETRY_UV`], or 0.
    pub flags: u16,
    /// Number of vertices.
    pub vertex_count: u32,
    /// Number of indices (3 per triangle).
    pub index_count: u32,
    /// Byte offset of the vertex stream within the segment.
    pub vertex_offset: u32,
    /// Byte offset of the index stream within the segment.
    pub index_offset: u32,
    /// Zero in a plain segment; a compressed one's encoded vertex and index stream lengths.
    pub reserved: [u32; 2],
}

/// The length in bytes of [`encode_geometry`]'s segment for a mesh of `vertices` vertices and
/// `triangles` triangles (with texture coordinates when `uv`): what a geometry segment occupies
/// once decoded, whatever it weighed on the wire.
pub fn plain_size(vertices: u32, triangles: u32, uv: bool) -> u64 {
    let wide = vertices as usize > u16::MAX as usize + 1;
    let indices = triangles as u64 * 3 * if wide { 4 } else { 2 };
    let head = std::mem::size_of::<GeometryHeader>() as u64;
    let stride = std::mem::size_of::<Vertex>() as u64 + if uv { UV_BYTES } else { 0 };
    head + vertices as u64 * stride + indices.next_multiple_of(4)
}

/// Bytes of one vertex's texture coordinates in a segment.
const UV_BYTES: u64 = 8;

/// Encodes a mesh as a geometry segment (header, vertices, indices).
pub fn encode_geometry(mesh: &Mesh) -> Vec<u8> {
    let wide = mesh.vertices.len() > u16::MAX as usize + 1;
    let uv = mesh.has_uvs();
    let vertex_offset = std::mem::size_of::<GeometryHeader>();
    let index_offset = vertex_offset
        + mesh.vertices.len() * std::mem::size_of::<Vertex>()
        + if uv {
            std::mem::size_of_val(mesh.uvs.as_slice())
        } else {
            0
        };
    let header = GeometryHeader {
        magic: GEOMETRY_MAGIC,
        version: GEOMETRY_VERSION,
        flags: if wide { GEOMETRY_U32_INDICES } else { 0 } | if uv { GEOMETRY_UV } else { 0 },
        vertex_count: mesh.vertices.len() as u32,
        index_count: mesh.indices.len() as u32,
        vertex_offset: vertex_offset as u32,
        index_offset: index_offset as u32,
        reserved: [0; 2],
    };
    let mut out = Vec::with_capacity(index_offset + mesh.indices.len() * 4 + 4);
    out.extend_from_slice(bytemuck::bytes_of(&header));
    out.extend_from_slice(bytemuck::cast_slice(&mesh.vertices));
    if uv {
        out.extend_from_slice(bytemuck::cast_slice(&mesh.uvs));
    }
    if wide {
        out.extend_from_slice(bytemuck::cast_slice(&mesh.indices));
    } else {
        for &i in &mesh.indices {
            out.extend_from_slice(&(i as u16).to_le_bytes());
        }
        if out.len() % 4 != 0 {
            out.extend_from_slice(&[0, 0]);
        }
    }
    out
}

/// A validated, borrowed view of a geometry segment's bytes.
#[derive(Debug, Clone, Copy)]
pub struct GeometryView<'a> {
    /// The parsed header.
    pub header: GeometryHeader,
    /// The raw vertex stream (`vertex_count * 20` bytes), ready for a vertex buffer.
    pub vertex_bytes: &'a [u8],
    /// The raw texture-coordinate stream (`vertex_count * 8` bytes), empty without
    /// [`GEOMETRY_UV`].
    pub uv_bytes: &'a [u8],
    /// The raw index stream, ready for an index buffer.
    pub index_bytes: &'a [u8],
}

impl<'a> GeometryView<'a> {
    /// Parses and bounds-checks a geometry segment. Every index is checked against the vertex
    /// count, so a corrupt segment can never make a renderer read out of bounds.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, String> {
        let hsize = std::mem::size_of::<GeometryHeader>();
        let head = bytes
            .get(..hsize)
            .ok_or_else(|| format!("geometry segment of {} bytes is too short", bytes.len()))?;
        let header: GeometryHeader = bytemuck::pod_read_unaligned(head);
        if header.magic != GEOMETRY_MAGIC || header.version != GEOMETRY_VERSION {
            return Err("geometry segment has a bad magic or version".into());
        }
        if header.flags & GEOMETRY_MESHOPT != 0 {
            return Err("geometry segment is compressed (meshopt): decode it first".into());
        }
        // In u64, then checked into usize: on wasm32 a hostile count would wrap.
        let isize = if header.flags & GEOMETRY_U32_INDICES != 0 {
            4
        } else {
            2
        };
        let uv = if header.flags & GEOMETRY_UV != 0 {
            UV_BYTES
        } else {
            0
        };
        let count = header.vertex_count as u64;
        let span = |start: u64, len: u64| -> Option<std::ops::Range<usize>> {
            let end = start.checked_add(len)?;
            Some(usize::try_from(start).ok()?..usize::try_from(end).ok()?)
        };
        let vstart = header.vertex_offset as u64;
        let vlen = count * std::mem::size_of::<Vertex>() as u64;
        let (Some(vr), Some(ur), Some(ir)) = (
            span(vstart, vlen),
            span(vstart + vlen, count * uv),
            span(
                header.index_offset as u64,
                header.index_count as u64 * isize,
            ),
        ) else {
            return Err("geometry streams run past the end of the segment".into());
        };
        let (Some(vertex_bytes), Some(uv_bytes), Some(index_bytes)) =
            (bytes.get(vr), bytes.get(ur.clone()), bytes.get(ir.clone()))
        else {
            return Err("geometry streams run past the end of the segment".into());
        };
        if ir.start < ur.end && !ir.is_empty() {
            return Err("geometry index stream overlaps the vertex streams".into());
        }
        if !header.index_count.is_multiple_of(3) {
            return Err("geometry index count is not a multiple of 3".into());
        }
        let view = GeometryView {
            header,
            vertex_bytes,
            uv_bytes,
            index_bytes,
        };
        let n = header.vertex_count;
        if let Some(bad) = view.indices().find(|&i| i >= n) {
            return Err(format!(
                "geometry index {bad} out of range for {n} vertices"
            ));
        }
        Ok(view)
    }

    /// Whether indices are `u32` (else `u16`).
    pub fn wide_indices(&self) -> bool {
        self.header.flags & GEOMETRY_U32_INDICES != 0
    }

    /// The indices, widened to `u32`.
    pub fn indices(&self) -> impl Iterator<Item = u32> + '_ {
        let wide = self.wide_indices();
        let step = if wide { 4 } else { 2 };
        self.index_bytes.chunks_exact(step).map(move |c| {
            if wide {
                u32::from_le_bytes([c[0], c[1], c[2], c[3]])
            } else {
                u16::from_le_bytes([c[0], c[1]]) as u32
            }
        })
    }

    /// Copies the segment back into an owned [`Mesh`].
    pub fn to_mesh(&self) -> Mesh {
        Mesh {
            vertices: self
                .vertex_bytes
                .chunks_exact(std::mem::size_of::<Vertex>())
                .map(bytemuck::pod_read_unaligned)
                .collect(),
            indices: self.indices().collect(),
            uvs: self
                .uv_bytes
                .chunks_exact(UV_BYTES as usize)
                .map(bytemuck::pod_read_unaligned)
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(n: usize) -> Mesh {
        let vertices = (0..n)
            .map(|i| Vertex::new([i as f32, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.5, 0.0, 1.0]))
            .collect();
        let indices = (0..n as u32 - 2).flat_map(|i| [0, i + 1, i + 2]).collect();
        Mesh {
            vertices,
            indices,
            uvs: Vec::new(),
        }
    }

    fn textured(n: usize) -> Mesh {
        let mut m = quad(n);
        m.uvs = (0..n).map(|i| [i as f32 * 0.5, 1.0 - i as f32]).collect();
        m
    }

    #[test]
    fn plain_size_is_the_encoded_length() {
        // One triangle (6 index bytes, padded), two (12, no padding), narrow and wide indices.
        for n in [3usize, 4, 7, 65_536, 65_537, 70_000] {
            let m = if n % 2 == 0 { textured(n) } else { quad(n) };
            let (v, t) = (m.vertices.len() as u32, m.triangle_count() as u32);
            assert_eq!(
                plain_size(v, t, m.has_uvs()),
                encode_geometry(&m).len() as u64,
                "{n} vertices"
            );
        }
    }

    #[test]
    fn geometry_round_trips_with_narrow_and_wide_indices() {
        for n in [3usize, 7, 70_000] {
            for m in [quad(n), textured(n)] {
                let bytes = encode_geometry(&m);
                assert_eq!(bytes.len() % 4, 0);
                let view = GeometryView::parse(&bytes).expect("parse");
                assert_eq!(view.wide_indices(), n > 65_536);
                assert_eq!(view.uv_bytes.len(), m.uvs.len() * 8);
                assert_eq!(view.to_mesh(), m);
            }
        }
    }

    #[test]
    fn out_of_range_index_is_rejected() {
        let mut bytes = encode_geometry(&quad(5));
        let view = GeometryView::parse(&bytes).unwrap();
        let last = view.header.index_offset as usize + (view.header.index_count as usize - 1) * 2;
        bytes[last..last + 2].copy_from_slice(&999u16.to_le_bytes());
        let err = GeometryView::parse(&bytes).unwrap_err();
        assert!(err.contains("out of range"), "{err}");
    }

    #[test]
    fn short_segment_is_rejected() {
        for m in [quad(5), textured(5)] {
            let bytes = encode_geometry(&m);
            for cut in [0, 10, 31, bytes.len() - 3] {
                assert!(GeometryView::parse(&bytes[..cut]).is_err(), "cut at {cut}");
            }
        }
    }

    #[test]
    fn a_uv_stream_under_the_indices_is_rejected() {
        let mut bytes = encode_geometry(&textured(5));
        let mut h: GeometryHeader = bytemuck::pod_read_unaligned(&bytes[..32]);
        h.index_offset -= 8;
        bytes[..32].copy_from_slice(bytemuck::bytes_of(&h));
        let err = GeometryView::parse(&bytes).unwrap_err();
        assert!(err.contains("overlaps"), "{err}");
    }

    #[test]
    fn uv_span_counts_repeats() {
        let mut m = textured(4);
        assert_eq!(m.uv_span(), 3.0);
        m.uvs.clear();
        assert_eq!(m.uv_span(), 0.0);
        assert!(m.validate().is_ok());
        m.uvs = vec![[0.0; 2]; 3];
        assert!(m.validate().is_err());
    }

    #[test]
    fn transform_moves_points_and_keeps_normals_unit() {
        let m = quad(4);
        let t = Mat4::from_scale_rotation_translation(
            Vec3::new(2.0, 1.0, 1.0),
            glam::Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
            Vec3::new(10.0, 0.0, 0.0),
        );
        let out = m.transformed(&t);
        let p = Vec3::from(out.vertices[1].position);
        assert!((p - Vec3::new(10.0, 2.0, 1.0)).length() < 1e-5, "{p}");
        let n = out.vertices[0].normal_f32();
        assert!((n - Vec3::new(-1.0, 0.0, 0.0)).length() < 0.02, "{n}");
    }
}
