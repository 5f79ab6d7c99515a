//! Compressed geometry segments: quantised attributes through meshoptimizer's vertex and index
//! codecs (Kapoulkine, "meshoptimizer": `meshopt_encodeVertexBuffer`/`meshopt_encodeIndexBuffer`,
//! the codecs of glTF's `EXT_meshopt_compression`).
//!
//! A compressed segment is a geometry segment whose header carries [`GEOMETRY_MESHOPT`]:
//!
//! ```text
//! 0   GeometryHeader (32 B)  vertex/index counts of the decoded mesh; flags keep
//!                            GEOMETRY_U32_INDICES of the decoded layout; vertex_offset and
//!                            index_offset locate the two encoded streams, reserved = their lengths
//! 32  origin [f32; 3], step [f32; 3]   position = origin + q * step, q: u16 per axis
//! 56  encoded vertex stream  16 B per vertex before encoding: q [u16; 3], 0u16, the normal's
//!                            snorm8 bytes and the colour's unorm8 bytes exactly as stored;
//!                            with GEOMETRY_UV, 24 B: then the texture coordinates as f32 × 2
//!                            (kept bit for bit: repeating textures need their full range)
//! ..  encoded index stream   triangles, in the order the LOD step optimised them for (the
//!                            codec keeps order and winding; a triangle may start at another
//!                            of its corners)
//! ```
//!
//! Then, when it is smaller, the whole body after the header is deflated (raw deflate, RFC
//! 1951, miniz's highest level) and the header gets [`GEOMETRY_DEFLATE`]: meshopt's byte-wise
//! output of small segments (84 triangles on average on flattened `soda`) leaves enough
//! redundancy that this takes flattened `soda` from 13.0 to 7.9 bytes per triangle on the wire,
//! losslessly (meshoptimizer's own advice: its codecs are meant to go under a general-purpose
//! compressor). The header stays in the clear: its counts are checked against the LOD record
//! before anything is inflated, and the body inflates to exactly the length its streams end
//! at, never further.
//!
//! Positions lose at most half a step. Each axis's extent is cut into whole steps: as few as
//! keep a step within [`MIN_STEP`], and at most 65,535 (a 50 m wall gets 0.76 mm steps).
//! Normals and colours are kept bit for bit. [`decode`] turns such a segment
//! back into the plain layout of [`encode_geometry`] (what GPUs bind), so everything past the
//! client's IO thread sees one layout. Segments without the flag are passed through untouched:
//! files written before compression still open, and so do meshopt segments without the
//! deflate stage.
//!
//! The decoder takes untrusted bytes: counts are bounded by what the encoded streams could
//! possibly hold before anything is allocated, and the decoded mesh is parsed (every index in
//! range) before it is returned.

#[cfg(feature = "native")]
use crate::geometry::GEOMETRY_U32_INDICES;
use crate::geometry::{
    GEOMETRY_DEFLATE, GEOMETRY_MAGIC, GEOMETRY_MESHOPT, GEOMETRY_UV, GEOMETRY_VERSION,
    GeometryHeader, GeometryView, Mesh, Vertex, encode_geometry,
};
use bytemuck::{Pod, Zeroable};
use meshoptimizer_rs::{Limits, Workspace};
use std::borrow::Cow;

/// One vertex before the vertex codec: quantised position, normal and colour (16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
struct Packed {
    q: [u16; 4],
    normal: [i8; 4],
    color: [u8; 4],
}

/// A textured vertex before the vertex codec (24 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, Pod, Zeroable)]
struct PackedUv {
    p: Packed,
    uv: [f32; 2],
}

const HEADER: usize = std::mem::size_of::<GeometryHeader>();
const QUANT: usize = 24;
/// The vertex codec (version 1) spends nothing on a byte channel whose deltas are all zero: a
/// block of 256 identical 16-byte vertices costs 4 bytes. No stream it writes decodes to more
/// than about 1,024 bytes per encoded byte; a header claiming more is refused before anything
/// is allocated. (Builds keep a segment plain unless its compressed form decodes, so nothing
/// written is ever refused.)
const MAX_VERTEX_EXPANSION: usize = 1100;
/// The step a small object's positions are rounded to, at most (metres): a quarter of a
/// millimetre, far below what a pixel shows at walking distance. A grid coarser than 16 bits
/// over a small object leaves smaller deltas for the vertex codec; past 16 m an axis gets 65,535
/// steps instead.
pub const MIN_STEP: f32 = 1.0 / 4096.0;
/// Deflate level of the second stage (miniz's highest: builds are offline).
#[cfg(feature = "native")]
const DEFLATE_LEVEL: u8 = 10;
/// Most bytes a deflated segment may inflate to (its meshopt streams: far beyond any LOD).
const MAX_INFLATED: u64 = 1 << 30;
/// Most vertices or indices one compressed segment may declare (the decoder refuses more).
pub const MAX_DECODED_COUNT: u32 = 1 << 26;

/// Encodes a mesh as a compressed geometry segment (layout in the module docs): meshopt, then
/// deflate over everything after the header when that is smaller.
#[cfg(feature = "native")]
pub fn encode(mesh: &Mesh) -> Vec<u8> {
    let meshopt = encode_meshopt(mesh);
    let deflated = miniz_oxide::deflate::compress_to_vec(&meshopt[HEADER..], DEFLATE_LEVEL);
    if deflated.len() + 4 >= meshopt.len() - HEADER {
        return meshopt;
    }
    let mut h: GeometryHeader = bytemuck::pod_read_unaligned(&meshopt[..HEADER]);
    h.flags |= GEOMETRY_DEFLATE;
    let mut out = Vec::with_capacity(HEADER + deflated.len() + 3);
    out.extend_from_slice(bytemuck::bytes_of(&h));
    out.extend_from_slice(&deflated);
    out.resize(out.len().next_multiple_of(4), 0);
    out
}

/// The meshopt stage alone (the layout of segments built before the deflate stage, which still
/// open: tests build them with this).
#[cfg(feature = "native")]
pub fn encode_meshopt(mesh: &Mesh) -> Vec<u8> {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for v in &mesh.vertices {
        for a in 0..3 {
            lo[a] = lo[a].min(v.position[a]);
            hi[a] = hi[a].max(v.position[a]);
        }
    }
    let origin = if mesh.vertices.is_empty() {
        [0.0; 3]
    } else {
        lo
    };
    // A whole number of steps spans each axis, so the largest coordinate lands on the grid and
    // no decoded vertex leaves the mesh's bounds.
    let step = std::array::from_fn::<f32, 3, _>(|a| {
        let extent = hi[a] - lo[a];
        if extent > 0.0 && extent.is_finite() {
            extent / (extent / MIN_STEP).ceil().clamp(1.0, 65535.0)
        } else {
            0.0
        }
    });
    let uv = mesh.has_uvs();
    let packed: Vec<Packed> = mesh
        .vertices
        .iter()
        .map(|v| Packed {
            q: std::array::from_fn(|a| {
                if a == 3 || step[a] == 0.0 {
                    0
                } else {
                    ((v.position[a] - origin[a]) / step[a])
                        .round()
                        .clamp(0.0, 65535.0) as u16
                }
            }),
            normal: v.normal,
            color: v.color,
        })
        .collect();
    let vertices = if uv {
        let with_uv: Vec<PackedUv> = packed
            .iter()
            .zip(&mesh.uvs)
            .map(|(&p, &uv)| PackedUv { p, uv })
            .collect();
        meshopt::encode_vertex_buffer_level(&with_uv, 3, Some(1))
    } else {
        meshopt::encode_vertex_buffer_level(&packed, 3, Some(1))
    }
    .expect("meshopt vertex encoding");
    let indices = if mesh.indices.is_empty() {
        Vec::new()
    } else {
        meshopt::encode_index_buffer(&mesh.indices, mesh.vertices.len())
            .expect("meshopt index encoding")
    };
    let wide = mesh.vertices.len() > u16::MAX as usize + 1;
    let vertex_offset = HEADER + QUANT;
    let index_offset = vertex_offset + vertices.len();
    let header = GeometryHeader {
        magic: GEOMETRY_MAGIC,
        version: GEOMETRY_VERSION,
        flags: GEOMETRY_MESHOPT
            | if wide { GEOMETRY_U32_INDICES } else { 0 }
            | if uv { GEOMETRY_UV } else { 0 },
        vertex_count: mesh.vertices.len() as u32,
        index_count: mesh.indices.len() as u32,
        vertex_offset: vertex_offset as u32,
        index_offset: index_offset as u32,
        reserved: [vertices.len() as u32, indices.len() as u32],
    };
    let mut out = Vec::with_capacity(index_offset + indices.len() + 4);
    out.extend_from_slice(bytemuck::bytes_of(&header));
    out.extend_from_slice(bytemuck::cast_slice(&origin));
    out.extend_from_slice(bytemuck::cast_slice(&step));
    out.extend_from_slice(&vertices);
    out.extend_from_slice(&indices);
    out.resize(out.len().next_multiple_of(4), 0);
    out
}

/// A geometry segment in the layout GPUs bind: borrowed when it is plain, decoded when it
/// carries [`GEOMETRY_MESHOPT`]. Errors name what is wrong (one line); the result always parses
/// with [`GeometryView::parse`].
pub fn to_gpu_layout(bytes: &[u8]) -> Result<Cow<'_, [u8]>, String> {
    if is_compressed(bytes) {
        decode(bytes).map(Cow::Owned)
    } else {
        GeometryView::parse(bytes)?;
        Ok(Cow::Borrowed(bytes))
    }
}

/// [`to_gpu_layout`] for geometry segment `id`, whose LOD record says it occupies `expected`
/// bytes decoded ([`crate::geometry::plain_size`]; `None` when the client has no record of it).
/// A compressed segment's counts must match that record before anything is decoded, which
/// bounds what decoding allocates by what the manifest promised.
///
/// # Errors
/// One line naming the segment: counts that disagree with the record, or what
/// [`to_gpu_layout`] refuses.
pub fn to_gpu_layout_as(
    id: u32,
    bytes: &[u8],
    expected: Option<u64>,
) -> Result<Cow<'_, [u8]>, String> {
    if let Some(h) = compressed_header(bytes) {
        let uv = h.flags & GEOMETRY_UV != 0;
        let claims = crate::geometry::plain_size(h.vertex_count, h.index_count / 3, uv);
        if expected != Some(claims) || h.index_count % 3 != 0 {
            return Err(format!(
                "segment {id}: its counts ({} vertices, {} indices) disagree with its LOD record",
                h.vertex_count, h.index_count
            ));
        }
    }
    to_gpu_layout(bytes).map_err(|e| format!("segment {id}: {e}"))
}

/// Whether a segment's header carries [`GEOMETRY_MESHOPT`] (false for anything too short).
pub fn is_compressed(bytes: &[u8]) -> bool {
    compressed_header(bytes).is_some()
}

/// The header of a compressed segment (`None` for anything else): its counts say what the
/// segment will decode to, so a caller can check them against the LOD record before decoding.
pub fn compressed_header(bytes: &[u8]) -> Option<GeometryHeader> {
    bytes
        .get(..HEADER)
        .map(bytemuck::pod_read_unaligned::<GeometryHeader>)
        .filter(|h| h.magic == GEOMETRY_MAGIC && h.flags & GEOMETRY_MESHOPT != 0)
}

/// Decodes a compressed segment into the plain layout of [`encode_geometry`].
///
/// Errors: too short, a bad magic or version, streams past the end, counts larger than the
/// streams could hold (or than [`MAX_DECODED_COUNT`]), a stream meshoptimizer rejects, or a
/// decoded index out of range.
pub fn decode(bytes: &[u8]) -> Result<Vec<u8>, String> {
    if let Some(h) = compressed_header(bytes).filter(|h| h.flags & GEOMETRY_DEFLATE != 0) {
        return decode(&inflated(&h, &bytes[HEADER..])?);
    }
    let head = bytes.get(..HEADER + QUANT).ok_or_else(|| {
        format!(
            "compressed geometry segment of {} bytes is too short",
            bytes.len()
        )
    })?;
    let h: GeometryHeader = bytemuck::pod_read_unaligned(&head[..HEADER]);
    if h.magic != GEOMETRY_MAGIC || h.version != GEOMETRY_VERSION || h.flags & GEOMETRY_MESHOPT == 0
    {
        return Err("not a compressed geometry segment (bad magic, version or flags)".into());
    }
    let quant: [f32; 6] = bytemuck::pod_read_unaligned(&head[HEADER..]);
    if quant.iter().any(|x| !x.is_finite()) {
        return Err("compressed geometry segment has a non-finite origin or step".into());
    }
    let stream = |offset: u32, len: u32, what: &str| {
        let start = offset as usize;
        bytes
            .get(start..start.saturating_add(len as usize))
            .ok_or_else(|| format!("compressed {what} stream runs past the end of the segment"))
    };
    let vs = stream(h.vertex_offset, h.reserved[0], "vertex")?;
    let is = stream(h.index_offset, h.reserved[1], "index")?;
    let (nv, ni) = (h.vertex_count as usize, h.index_count as usize);
    let uv = h.flags & GEOMETRY_UV != 0;
    let stride = if uv {
        std::mem::size_of::<PackedUv>()
    } else {
        std::mem::size_of::<Packed>()
    };
    // In u64: on wasm32 a usize product of a few megabytes would wrap.
    let too_many = h.vertex_count > MAX_DECODED_COUNT
        || h.index_count > MAX_DECODED_COUNT
        || nv as u64 * stride as u64 > (vs.len() as u64 + 64) * MAX_VERTEX_EXPANSION as u64
        || ni as u64 > is.len() as u64 * 3;
    if too_many {
        return Err(format!(
            "compressed geometry segment claims {nv} vertices and {ni} indices: more than its \
             {} + {} encoded bytes can hold, or than {MAX_DECODED_COUNT}",
            vs.len(),
            is.len()
        ));
    }
    if !ni.is_multiple_of(3) {
        return Err("geometry index count is not a multiple of 3".into());
    }
    // The decoders write into buffers sized by the counts checked above (at most
    // MAX_DECODED_COUNT each); the workspace is the codecs' scratch, bounded by the crate's
    // default limits.
    let mut ws = Workspace::new(Limits::default());
    let mut packed = vec![PackedUv::zeroed(); nv];
    if nv > 0 {
        let out: &mut [u8] = bytemuck::cast_slice_mut(&mut packed);
        meshoptimizer_rs::codec::decode_vertex_buffer_into(
            &mut out[..nv * stride],
            nv,
            stride,
            vs,
            &mut ws,
        )
        .map_err(|e| format!("vertex stream: {e}"))?;
        if !uv {
            // The stream was written 16 bytes a vertex: spread it into the wider records.
            let raw: Vec<Packed> = bytemuck::cast_slice(&out[..nv * stride]).to_vec();
            for (dst, p) in packed.iter_mut().zip(raw) {
                *dst = PackedUv { p, uv: [0.0; 2] };
            }
        }
    }
    let mut indices = vec![0u32; ni];
    if ni > 0 {
        meshoptimizer_rs::codec::decode_index_buffer_into(
            bytemuck::cast_slice_mut(&mut indices),
            ni,
            4,
            is,
            &mut ws,
        )
        .map_err(|e| format!("index stream: {e}"))?;
    }
    if let Some(bad) = indices.iter().find(|&&i| i as usize >= nv) {
        return Err(format!(
            "geometry index {bad} out of range for {nv} vertices"
        ));
    }
    let (origin, step) = (&quant[..3], &quant[3..]);
    let vertices = packed
        .iter()
        .map(|PackedUv { p, .. }| Vertex {
            position: std::array::from_fn(|a| origin[a] + p.q[a] as f32 * step[a]),
            normal: p.normal,
            color: p.color,
        })
        .collect();
    let uvs = if uv {
        let uvs: Vec<[f32; 2]> = packed.iter().map(|p| p.uv).collect();
        if uvs.iter().flatten().any(|x| !x.is_finite()) {
            return Err("a decoded texture coordinate is not a finite number".into());
        }
        uvs
    } else {
        Vec::new()
    };
    Ok(encode_geometry(&Mesh {
        vertices,
        indices,
        uvs,
    }))
}

/// The meshopt segment a deflated one holds: its header without [`GEOMETRY_DEFLATE`], then
/// `body` inflated to exactly the length the header's streams end at (rounded up to 4 bytes):
/// no more is ever inflated, whatever the deflate stream says.
fn inflated(h: &GeometryHeader, body: &[u8]) -> Result<Vec<u8>, String> {
    let end = (h.index_offset as u64 + h.reserved[1] as u64)
        .max(h.vertex_offset as u64 + h.reserved[0] as u64)
        .next_multiple_of(4);
    let want = end
        .checked_sub(HEADER as u64)
        .filter(|&n| n >= QUANT as u64 && n <= MAX_INFLATED)
        .ok_or_else(|| format!("deflated geometry segment declares streams ending at byte {end}"))?
        as usize;
    let body = miniz_oxide::inflate::decompress_to_vec_with_limit(body, want)
        .map_err(|e| format!("deflated geometry segment does not inflate: {e:?}"))?;
    if body.len() != want {
        return Err(format!(
            "deflated geometry segment inflates to {} bytes, its header says {want}",
            body.len()
        ));
    }
    let plain = GeometryHeader {
        flags: h.flags & !GEOMETRY_DEFLATE,
        ..*h
    };
    let mut out = Vec::with_capacity(HEADER + want);
    out.extend_from_slice(bytemuck::bytes_of(&plain));
    out.extend_from_slice(&body);
    Ok(out)
}

/// The largest distance a position moves through [`encode`] then [`decode`] on each axis:
/// half a quantisation step (metres).
pub fn position_tolerance(mesh: &Mesh) -> [f32; 3] {
    let b = mesh.bounds();
    std::array::from_fn(|a| {
        let extent = (b.max[a] - b.min[a]).max(0.0);
        extent / (extent / MIN_STEP).ceil().clamp(1.0, 65535.0) * 0.5
    })
}
