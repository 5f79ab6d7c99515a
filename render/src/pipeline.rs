//! The pipeline, its uniforms and per-draw instance data, and the offscreen targets.

use crate::{COLOR_FORMAT, DEPTH_FORMAT, RenderError, extent};
use bytemuck::{Pod, Zeroable};
use portico_data::geometry::Vertex;

/// Per-frame uniforms; must match `Globals` in `shader.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(crate) struct Globals {
    pub(crate) view_proj: [[f32; 4]; 4],
    pub(crate) light_dir: [f32; 4],
    pub(crate) ambient: [f32; 4],
}

/// Per-draw instance attributes (locations 3..=8 and 10); 112 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(crate) struct InstanceData {
    pub(crate) model: [[f32; 4]; 4],
    pub(crate) color: [f32; 4],
    /// x: alpha cutoff of a cut-out material (0: none); y: 1 for a blended material; z: the
    /// surface's [`flags`]; w: zero.
    pub(crate) params: [f32; 4],
    /// The light the surface gives off (linear RGB; w zero).
    pub(crate) emissive: [f32; 4],
}

/// `shader.wgsl`'s surface flags: drawn unlit.
pub(crate) const UNLIT: u32 = 1;
/// Faces seen from behind are discarded.
pub(crate) const CULL_BACK: u32 = 2;
/// The transform mirrors: the winding's front is the other side.
pub(crate) const MIRRORED: u32 = 4;
/// The texture (or, not resident, the colour passed) multiplies the base colour.
pub(crate) const TEXTURE_BASE: u32 = 8;
/// The texture (or, not resident, the colour passed) multiplies the emissive colour.
pub(crate) const TEXTURE_EMISSIVE: u32 = 16;

/// A surface's flags for `shader.wgsl` under `transform`.
pub(crate) fn flags(surface: &crate::Surface, transform: &glam::Mat4) -> u32 {
    let mut f = 0;
    if surface.unlit {
        f |= UNLIT;
    }
    if !surface.double_sided {
        f |= CULL_BACK;
    }
    if transform.determinant() < 0.0 {
        f |= MIRRORED;
    }
    if surface.texture_role.base() {
        f |= TEXTURE_BASE;
    }
    if surface.texture_role.emissive() {
        f |= TEXTURE_EMISSIVE;
    }
    f
}

/// The offscreen targets and the buffer frames are read back through: frames are drawn into
/// multisampled colour and depth (`samples` per pixel) and resolved into `color`.
#[derive(Debug)]
pub(crate) struct Targets {
    pub(crate) color: wgpu::Texture,
    pub(crate) color_view: wgpu::TextureView,
    /// The multisampled colour target; `None` with one sample per pixel.
    pub(crate) msaa_view: Option<wgpu::TextureView>,
    pub(crate) depth_view: wgpu::TextureView,
    pub(crate) readback: wgpu::Buffer,
    pub(crate) padded_row: u32,
}

pub(crate) fn create_targets(
    device: &wgpu::Device,
    width: u32,
    height: u32,
    samples: u32,
) -> Result<Targets, RenderError> {
    let max = device.limits().max_texture_dimension_2d;
    if width == 0 || height == 0 || width > max || height > max {
        return Err(RenderError::BadSize(width, height));
    }
    let texture = |label, format, usage, sample_count| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: extent(width, height),
            mip_level_count: 1,
            sample_count,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let color = texture(
        "colour",
        COLOR_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        1,
    );
    let msaa = (samples > 1).then(|| {
        texture(
            "colour samples",
            COLOR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
            samples,
        )
    });
    let depth = texture(
        "depth",
        DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
        samples,
    );
    let padded_row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: u64::from(padded_row) * u64::from(height),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    Ok(Targets {
        color_view: color.create_view(&Default::default()),
        msaa_view: msaa.map(|m| m.create_view(&Default::default())),
        depth_view: depth.create_view(&Default::default()),
        color,
        readback,
        padded_row,
    })
}

pub(crate) fn create_instance_buffer(device: &wgpu::Device, capacity: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("instances"),
        size: capacity * std::mem::size_of::<InstanceData>() as u64,
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

pub(crate) fn globals_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("globals"),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: wgpu::BufferSize::new(std::mem::size_of::<Globals>() as u64),
            },
            count: None,
        }],
    })
}

pub(crate) const VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 3] =
    wgpu::vertex_attr_array![0 => Float32x3, 1 => Snorm8x4, 2 => Unorm8x4];
pub(crate) const INSTANCE_ATTRIBUTES: [wgpu::VertexAttribute; 7] = wgpu::vertex_attr_array![
    3 => Float32x4, 4 => Float32x4, 5 => Float32x4, 6 => Float32x4, 7 => Float32x4,
    8 => Float32x4, 10 => Float32x4
];
/// A textured mesh's coordinates (vertex buffer 2).
pub(crate) const UV_ATTRIBUTES: [wgpu::VertexAttribute; 1] =
    wgpu::vertex_attr_array![9 => Float32x2];

/// Vertex buffers 0 (vertices) and 1 (instances), and 2 (texture coordinates) when `textured`.
pub(crate) fn vertex_layouts(textured: bool) -> Vec<Option<wgpu::VertexBufferLayout<'static>>> {
    let mut out = vec![
        Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Vertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &VERTEX_ATTRIBUTES,
        }),
        Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<InstanceData>() as u64,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &INSTANCE_ATTRIBUTES,
        }),
    ];
    if textured {
        out.push(Some(wgpu::VertexBufferLayout {
            array_stride: 8,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &UV_ATTRIBUTES,
        }));
    }
    out
}

/// The walkthrough's pipeline: depth-tested opaque triangles, no culling (building models are
/// often two-sided or inconsistently wound; the shader lights both sides). Single-sided
/// surfaces draw through the culling variants of `material.rs`.
pub(crate) fn create_pipeline(
    device: &wgpu::Device,
    globals: &wgpu::BindGroupLayout,
    samples: u32,
) -> wgpu::RenderPipeline {
    let shader = device.create_shader_module(wgpu::include_wgsl!("shader.wgsl"));
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("walkthrough"),
        bind_group_layouts: &[Some(globals)],
        immediate_size: 0,
    });
    let buffers = vertex_layouts(false);
    opaque_pipeline(
        device,
        "walkthrough",
        &layout,
        &shader,
        &buffers,
        None,
        samples,
    )
}

/// How a surface pipeline treats what it draws over.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Blending {
    /// Opaque (cut-outs included): depth written.
    Opaque,
    /// Blended over what is behind: depth tested, not written.
    Over,
}

/// A pipeline of depth-tested triangles from `shader`'s `entries` (vertex, fragment) into the
/// one colour target; `cull_mode` as the geometry's winding allows; `samples` per pixel as the
/// targets have.
#[allow(clippy::too_many_arguments)]
pub(crate) fn surface_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::PipelineLayout,
    shader: &wgpu::ShaderModule,
    entries: (&str, &str),
    buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
    cull_mode: Option<wgpu::Face>,
    front_face: wgpu::FrontFace,
    samples: u32,
    blending: Blending,
) -> wgpu::RenderPipeline {
    let over = blending == Blending::Over;
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(label),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module: shader,
            entry_point: Some(entries.0),
            compilation_options: Default::default(),
            buffers,
        },
        primitive: wgpu::PrimitiveState {
            cull_mode,
            front_face,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(!over),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: wgpu::MultisampleState {
            count: samples,
            ..Default::default()
        },
        fragment: Some(wgpu::FragmentState {
            module: shader,
            entry_point: Some(entries.1),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: COLOR_FORMAT,
                blend: over.then_some(wgpu::BlendState::ALPHA_BLENDING),
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A pipeline of depth-tested opaque triangles from `shader`'s `vs_main` and `fs_main` into the
/// one colour target (the walkthrough's and the impostor boxes' alike); `cull_mode` as the
/// geometry's winding allows; `samples` per pixel as the targets have.
pub(crate) fn opaque_pipeline(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::PipelineLayout,
    shader: &wgpu::ShaderModule,
    buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
    cull_mode: Option<wgpu::Face>,
    samples: u32,
) -> wgpu::RenderPipeline {
    surface_pipeline(
        device,
        label,
        layout,
        shader,
        ("vs_main", "fs_main"),
        buffers,
        cull_mode,
        wgpu::FrontFace::Ccw,
        samples,
        Blending::Opaque,
    )
}

/// The layout of a texture (binding 0, filterable) and its sampler (binding 1), seen by the
/// fragment stage: impostor atlases and material textures alike.
pub(crate) fn texture_layout(device: &wgpu::Device, label: &str) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries: &[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: true },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            },
            wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ],
    })
}

/// A bind group of [`texture_layout`]: `view` sampled with `sampler`.
pub(crate) fn texture_bind_group(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    label: &str,
    view: &wgpu::TextureView,
    sampler: &wgpu::Sampler,
) -> wgpu::BindGroup {
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(view),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::Sampler(sampler),
            },
        ],
    })
}
