//! Textured boxes: the GPU side of a cluster's impostor (Maciel §5.2, Selçuk's far boxes). The
//! atlas PNG from the display database is decoded and uploaded as one sRGB texture; the box is
//! 24 vertices (four per face, so each face maps its own tile of the atlas, exactly where the
//! build-time capture put it: [`portico_data::hierarchy::face_uv`]) and 36 indices.

use super::pipeline::opaque_pipeline;
use super::{RenderError, extent};
use bytemuck::{Pod, Zeroable};
use portico_data::geometry::Aabb;
use portico_data::hierarchy::{FACES, face_frame, face_uv};
use wgpu::util::DeviceExt;

/// One vertex of a textured box.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct BoxVertex {
    position: [f32; 3],
    uv: [f32; 2],
}

/// A cluster's textured box on the GPU; dropping it frees the texture and buffers.
#[derive(Debug)]
pub struct GpuImpostor {
    vertex: wgpu::Buffer,
    index: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    bytes: u64,
    /// Charged to the renderer's account of GPU memory held while the box lives.
    _held: crate::held::Charge,
}

impl GpuImpostor {
    /// GPU memory held (texture and buffers), in bytes.
    pub fn gpu_bytes(&self) -> u64 {
        self.bytes
    }
}

/// The pipeline and what every textured box shares.
#[derive(Debug)]
pub struct Textured {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
}

impl Textured {
    /// Creates the pipeline; `globals` is the walkthrough pipeline's group 0 layout, `samples`
    /// the targets' samples per pixel.
    pub fn new(device: &wgpu::Device, globals: &wgpu::BindGroupLayout, samples: u32) -> Textured {
        let layout = crate::pipeline::texture_layout(device, "impostor atlas");
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("impostor atlas"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        let shader = device.create_shader_module(wgpu::include_wgsl!("textured.wgsl"));
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("impostors"),
            bind_group_layouts: &[Some(globals), Some(&layout)],
            immediate_size: 0,
        });
        const ATTRIBUTES: [wgpu::VertexAttribute; 2] =
            wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x2];
        let buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<BoxVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &ATTRIBUTES,
        })];
        // Faces wind counter-clockwise seen from outside: through a transparent texel of a
        // near face one sees what is behind the box, not the far face's mirrored inside.
        let pipeline = opaque_pipeline(
            device,
            "impostors",
            &pipeline_layout,
            &shader,
            &buffers,
            Some(wgpu::Face::Back),
            samples,
        );
        Textured {
            pipeline,
            layout,
            sampler,
        }
    }

    /// Decodes an atlas (PNG, 3 × 2 tiles of `tile` pixels) and makes the box of `bounds`,
    /// charged to `held`.
    pub(crate) fn upload(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        held: &crate::held::Held,
        png: &[u8],
        bounds: &Aabb,
        tile: u32,
    ) -> Result<GpuImpostor, RenderError> {
        let img = image::load_from_memory_with_format(png, image::ImageFormat::Png)
            .map_err(|e| RenderError::Geometry(format!("impostor atlas: {e}")))?
            .to_rgba8();
        let (w, h) = img.dimensions();
        let expected = tile.checked_mul(3).zip(tile.checked_mul(2));
        if tile == 0 || expected != Some((w, h)) {
            return Err(RenderError::Geometry(format!(
                "impostor atlas is {w}x{h}, not 3 x 2 tiles of {tile}"
            )));
        }
        let texture = device.create_texture_with_data(
            queue,
            &wgpu::TextureDescriptor {
                label: Some("impostor atlas"),
                size: extent(w, h),
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba8UnormSrgb,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            img.as_raw(),
        );
        let view = texture.create_view(&Default::default());
        let bind_group = crate::pipeline::texture_bind_group(
            device,
            &self.layout,
            "impostor atlas",
            &view,
            &self.sampler,
        );
        let (vertices, indices) = box_mesh(bounds, tile);
        let vertex = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("impostor box"),
            contents: bytemuck::cast_slice(&vertices),
            usage: wgpu::BufferUsages::VERTEX,
        });
        let index = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("impostor box"),
            contents: bytemuck::cast_slice(&indices),
            usage: wgpu::BufferUsages::INDEX,
        });
        let bytes = u64::from(w) * u64::from(h) * 4 + vertex.size() + index.size();
        Ok(GpuImpostor {
            _held: held.charge(bytes),
            vertex,
            index,
            bind_group,
            bytes,
        })
    }

    /// Draws textured boxes in an open render pass whose group 0 is already the globals.
    pub fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        globals: &wgpu::BindGroup,
        boxes: &[&GpuImpostor],
    ) {
        if boxes.is_empty() {
            return;
        }
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, globals, &[]);
        for b in boxes {
            pass.set_bind_group(1, &b.bind_group, &[]);
            pass.set_vertex_buffer(0, b.vertex.slice(..));
            pass.set_index_buffer(b.index.slice(..), wgpu::IndexFormat::Uint16);
            pass.draw_indexed(0..36, 0, 0..1);
        }
    }
}

/// The 24 vertices and 36 indices of a textured box: face `i` takes atlas tile `i` (column
/// `i % 3`, row `i / 3`), half a texel in from the tile's edges so filtering never reads the
/// neighbouring tile.
fn box_mesh(b: &Aabb, tile: u32) -> (Vec<BoxVertex>, Vec<u16>) {
    let inset = 0.5 / tile.max(1) as f32;
    let mut vertices = Vec::with_capacity(24);
    let mut indices = Vec::with_capacity(36);
    let c = b.center();
    let half = b.size() * 0.5;
    for face in 0..FACES.len() {
        let (n, right, up) = face_frame(face);
        let base = vertices.len() as u16;
        let (col, row) = ((face % 3) as f32, (face / 3) as f32);
        for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let p = c
                + n * n.abs().dot(half)
                + right * sx * right.abs().dot(half)
                + up * sy * up.abs().dot(half);
            let [u, v] = face_uv(b, face, p);
            let (u, v) = (u.clamp(inset, 1.0 - inset), v.clamp(inset, 1.0 - inset));
            vertices.push(BoxVertex {
                position: p.into(),
                uv: [(col + u) / 3.0, (row + v) / 2.0],
            });
        }
        indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    (vertices, indices)
}
