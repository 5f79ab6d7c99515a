//! Geometry segments on the GPU: a plain segment's vertex and index streams become buffers byte
//! for byte, so the cache's byte budget is the segments' decoded size (a compressed segment is
//! decoded before it gets here).

use crate::{GpuImpostor, GpuTexture, RenderError, scoped, textured};
use glam::Vec3;
use portico_data::geometry::{Aabb, GeometryView, Vertex};
use portico_data::texture::Wrap;
use std::sync::Arc;
use wgpu::util::DeviceExt;

/// One uploaded geometry segment (one LOD of one object) in GPU memory.
///
/// The buffers are freed when the mesh is dropped, which is how the client's cache releases them.
#[derive(Debug)]
pub struct GpuMesh {
    pub(crate) vertex: wgpu::Buffer,
    /// Texture coordinates, for a textured mesh.
    pub(crate) uv: Option<wgpu::Buffer>,
    pub(crate) index: wgpu::Buffer,
    pub(crate) index_format: wgpu::IndexFormat,
    pub(crate) index_count: u32,
    pub(crate) vertex_count: u32,
    pub(crate) bounds: Aabb,
    /// Charged to the renderer's account of GPU memory held while the mesh lives.
    pub(crate) _held: crate::held::Charge,
}

impl GpuMesh {
    /// GPU memory held by the vertex, texture-coordinate and index buffers, in bytes.
    pub fn gpu_bytes(&self) -> u64 {
        self.vertex.size() + self.index.size() + self.uv.as_ref().map_or(0, wgpu::Buffer::size)
    }

    /// Whether the mesh has texture coordinates.
    pub fn has_uvs(&self) -> bool {
        self.uv.is_some()
    }

    /// Number of triangles drawn per instance.
    pub fn triangles(&self) -> u32 {
        self.index_count / 3
    }

    /// Number of vertices in the vertex buffer.
    pub fn vertices(&self) -> u32 {
        self.vertex_count
    }

    /// Object-space bounding box of the vertices (empty for an empty mesh).
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// Whether indices are 32-bit (else 16-bit).
    pub fn wide_indices(&self) -> bool {
        self.index_format == wgpu::IndexFormat::Uint32
    }
}

/// A cloneable, thread-safe handle for uploading geometry segments to the renderer's device from
/// another thread (the IO → GPU-upload stage), while the render thread draws.
#[derive(Debug, Clone)]
pub struct Uploader {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pub(crate) textured: Arc<textured::Textured>,
    pub(crate) materials: Arc<crate::material::Materials>,
    pub(crate) held: crate::held::Held,
}

impl Uploader {
    /// Same as [`crate::Renderer::upload`].
    pub fn upload(&self, segment_bytes: &[u8]) -> Result<GpuMesh, RenderError> {
        upload_segment(&self.device, &self.held, segment_bytes)
    }

    /// Same as [`crate::Renderer::upload_texture`].
    pub fn upload_texture(
        &self,
        segment: &[u8],
        wrap: [Wrap; 2],
    ) -> Result<GpuTexture, RenderError> {
        scoped(&self.device, || {
            self.materials
                .upload(&self.device, &self.queue, &self.held, segment, wrap)
        })?
    }

    /// Same as [`crate::Renderer::upload_impostor`].
    pub fn upload_impostor(
        &self,
        png: &[u8],
        bounds: &Aabb,
        tile: u32,
    ) -> Result<GpuImpostor, RenderError> {
        scoped(&self.device, || {
            self.textured
                .upload(&self.device, &self.queue, &self.held, png, bounds, tile)
        })?
    }
}

/// Parses a segment and creates its buffers straight from the vertex and index byte streams.
pub(crate) fn upload_segment(
    device: &wgpu::Device,
    held: &crate::held::Held,
    segment_bytes: &[u8],
) -> Result<GpuMesh, RenderError> {
    let view = GeometryView::parse(segment_bytes).map_err(RenderError::Geometry)?;
    let limit = device.limits().max_buffer_size;
    for size in [
        view.vertex_bytes.len() as u64,
        view.uv_bytes.len() as u64,
        view.index_bytes.len() as u64,
    ] {
        if size > limit {
            return Err(RenderError::TooLarge { size, limit });
        }
    }
    let (vertex, index, uv) = scoped(device, || {
        (
            buffer_init(
                device,
                "vertices",
                view.vertex_bytes,
                wgpu::BufferUsages::VERTEX,
            ),
            buffer_init(
                device,
                "indices",
                view.index_bytes,
                wgpu::BufferUsages::INDEX,
            ),
            (!view.uv_bytes.is_empty()).then(|| {
                buffer_init(
                    device,
                    "texture coordinates",
                    view.uv_bytes,
                    wgpu::BufferUsages::VERTEX,
                )
            }),
        )
    })?;
    let index_format = if view.wide_indices() {
        wgpu::IndexFormat::Uint32
    } else {
        wgpu::IndexFormat::Uint16
    };
    Ok(GpuMesh {
        _held: held.charge(vertex.size() + index.size() + uv.as_ref().map_or(0, |b| b.size())),
        vertex,
        uv,
        index,
        index_format,
        index_count: view.header.index_count,
        vertex_count: view.header.vertex_count,
        bounds: vertex_bounds(view.vertex_bytes),
    })
}

/// A buffer holding `bytes`. `create_buffer_init` pads the size to a multiple of
/// `COPY_BUFFER_ALIGNMENT` (4), so odd-length `u16` index streams need no manual padding.
pub(crate) fn buffer_init(
    device: &wgpu::Device,
    label: &str,
    bytes: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytes,
        usage,
    })
}

/// Bounding box of a raw vertex stream (positions are the first 12 bytes of each vertex).
pub(crate) fn vertex_bounds(vertex_bytes: &[u8]) -> Aabb {
    let mut b = Aabb::EMPTY;
    for v in vertex_bytes.chunks_exact(std::mem::size_of::<Vertex>()) {
        let p: [f32; 3] = bytemuck::pod_read_unaligned(&v[..12]);
        b.include(Vec3::from(p));
    }
    b
}
