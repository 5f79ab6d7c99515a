//! Materials on the GPU: base-colour textures uploaded from their mip segments
//! ([`portico_data::texture`]: each segment a whole mip chain, sampled alone), and the
//! pipelines that draw textured, cut-out and blended surfaces beside the walkthrough's plain
//! one.

use crate::pipeline::{Blending, surface_pipeline, vertex_layouts};
use crate::{RenderError, extent};
use portico_data::texture::{
    BlockFormat, TexelFormat, Wrap, block_format, compress, decode_segment, is_opaque,
};
use wgpu::util::DeviceExt;

/// One texture segment on the GPU (a mip chain from its finest level down), with the bind
/// group that samples it; dropping it frees the texture.
#[derive(Debug)]
pub struct GpuTexture {
    pub(crate) bind_group: wgpu::BindGroup,
    bytes: u64,
    texel_bytes: u64,
    width: u32,
    /// Charged to the renderer's account of GPU memory held while the texture lives.
    _held: crate::held::Charge,
}

impl GpuTexture {
    /// GPU memory held by the texels (bytes): the segment's levels, RGBA8 or block-compressed
    /// ([`crate::Renderer::texel_format`]).
    pub fn gpu_bytes(&self) -> u64 {
        self.bytes
    }

    /// Width of its finest level (texels).
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Bytes its levels take as RGBA8 texels: what it decoded to before any block
    /// compression.
    pub fn texel_bytes(&self) -> u64 {
        self.texel_bytes
    }
}

/// The pipelines of material surfaces and what every texture shares.
#[derive(Debug)]
pub(crate) struct Materials {
    layout: wgpu::BindGroupLayout,
    /// Textured, opaque or cut out.
    pub(crate) textured: wgpu::RenderPipeline,
    /// Textured and blended.
    pub(crate) textured_over: wgpu::RenderPipeline,
    /// Plain and blended.
    pub(crate) plain_over: wgpu::RenderPipeline,
    /// Plain, opaque and single-sided: back faces culled.
    pub(crate) plain_culled: wgpu::RenderPipeline,
    /// The same under a mirroring transform (clockwise fronts).
    pub(crate) plain_culled_mirrored: wgpu::RenderPipeline,
    /// How textures are held ([`texels_code`]): shared by the renderer and its uploaders.
    texels: std::sync::atomic::AtomicU8,
}

impl Materials {
    /// How textures are held now.
    pub(crate) fn texels(&self) -> TexelFormat {
        texels_of(self.texels.load(std::sync::atomic::Ordering::Relaxed))
    }

    /// Holds textures uploaded from now on as `t` (one the device offers: [`offers`]).
    pub(crate) fn set_texels(&self, t: TexelFormat) {
        self.texels
            .store(texels_code(t), std::sync::atomic::Ordering::Relaxed);
    }

    /// Creates the pipelines; `globals` is the walkthrough pipeline's group 0 layout.
    pub(crate) fn new(
        device: &wgpu::Device,
        globals: &wgpu::BindGroupLayout,
        samples: u32,
    ) -> Materials {
        let layout = crate::pipeline::texture_layout(device, "base colour");
        let shader = device.create_shader_module(wgpu::include_wgsl!("shader.wgsl"));
        let textured_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("textured"),
            bind_group_layouts: &[Some(globals), Some(&layout)],
            immediate_size: 0,
        });
        let plain_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("plain"),
            bind_group_layouts: &[Some(globals)],
            immediate_size: 0,
        });
        let (with_uv, without) = (vertex_layouts(true), vertex_layouts(false));
        let textured_entries = ("vs_textured", "fs_textured");
        let pipeline = |label, layout, entries, buffers: &[_], blending| {
            surface_pipeline(
                device,
                label,
                layout,
                &shader,
                entries,
                buffers,
                None,
                wgpu::FrontFace::Ccw,
                samples,
                blending,
            )
        };
        // Single-sided plain surfaces: back faces culled by the rasteriser, not discarded in the
        // shader (a discard would cost every opaque draw its early depth test); a mirroring
        // transform turns which winding is the front.
        let culled = |label, front_face| {
            surface_pipeline(
                device,
                label,
                &plain_layout,
                &shader,
                ("vs_main", "fs_main"),
                &without,
                Some(wgpu::Face::Back),
                front_face,
                samples,
                Blending::Opaque,
            )
        };
        Materials {
            texels: std::sync::atomic::AtomicU8::new(texels_code(default_texels(device))),
            textured: pipeline(
                "textured",
                &textured_layout,
                textured_entries,
                &with_uv,
                Blending::Opaque,
            ),
            textured_over: pipeline(
                "textured, blended",
                &textured_layout,
                textured_entries,
                &with_uv,
                Blending::Over,
            ),
            plain_over: pipeline(
                "blended",
                &plain_layout,
                ("vs_main", "fs_over"),
                &without,
                Blending::Over,
            ),
            plain_culled: culled("single-sided", wgpu::FrontFace::Ccw),
            plain_culled_mirrored: culled("single-sided, mirrored", wgpu::FrontFace::Cw),
            layout,
        }
    }

    /// Decodes a texture segment (raw, PNG or JPEG: [`decode_segment`]) and uploads its whole
    /// mip chain, in one texture, to be sampled with `wrap`, charged to `held`: compressed to
    /// BC1 (opaque) or BC3 first where the device takes BC textures and the size is whole
    /// 4 × 4 blocks ([`portico_data::texture::compress`]), else as RGBA8.
    pub(crate) fn upload(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        held: &crate::held::Held,
        segment: &[u8],
        wrap: [Wrap; 2],
    ) -> Result<GpuTexture, RenderError> {
        // Decoded here, where the segment arrives: the native client's IO thread; in the
        // browser, the page's one thread between frames.
        let view = decode_segment(segment).map_err(RenderError::Texture)?;
        let max = device.limits().max_texture_dimension_2d;
        if view.width > max || view.height > max {
            return Err(RenderError::Texture(format!(
                "{}x{} texels is beyond the device's {max}",
                view.width, view.height
            )));
        }
        // Transcoded here too (van Waveren's real-time DXT: the wire keeps the smaller codec).
        let opaque = is_opaque(&view.texels);
        let blocks = block_format(self.texels(), view.width, view.height, opaque)
            .and_then(|f| compress(&view, f));
        let (format, texels) = match &blocks {
            Some(b) => (
                match b.format {
                    BlockFormat::Bc1 => wgpu::TextureFormat::Bc1RgbaUnormSrgb,
                    BlockFormat::Bc3 => wgpu::TextureFormat::Bc3RgbaUnormSrgb,
                    BlockFormat::Etc2Rgb => wgpu::TextureFormat::Etc2Rgb8UnormSrgb,
                },
                &b.bytes,
            ),
            None => (wgpu::TextureFormat::Rgba8UnormSrgb, &view.texels),
        };
        let texture = device.create_texture_with_data(
            queue,
            &wgpu::TextureDescriptor {
                label: Some("base colour"),
                size: extent(view.width, view.height),
                mip_level_count: view.levels,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::MipMajor,
            texels,
        );
        let address = |w: Wrap| match w {
            Wrap::Repeat => wgpu::AddressMode::Repeat,
            Wrap::Mirror => wgpu::AddressMode::MirrorRepeat,
            Wrap::Clamp => wgpu::AddressMode::ClampToEdge,
        };
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("base colour"),
            address_mode_u: address(wrap[0]),
            address_mode_v: address(wrap[1]),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            ..Default::default()
        });
        let tv = texture.create_view(&Default::default());
        let bind_group =
            crate::pipeline::texture_bind_group(device, &self.layout, "base colour", &tv, &sampler);
        let bytes = texels.len() as u64;
        Ok(GpuTexture {
            bind_group,
            bytes,
            texel_bytes: view.texels.len() as u64,
            width: view.width,
            _held: held.charge(bytes),
        })
    }
}

/// The features a device asks of `adapter`: the texture compression it offers of BC (desktop
/// GPUs, llvmpipe, WebGPU on desktops, WebGL2 with the S3TC, S3TC sRGB, RGTC and BPTC
/// extensions) and ETC2 (mobile GPUs, OpenGL ES 3).
pub(crate) fn block_features(adapter: &wgpu::Adapter) -> wgpu::Features {
    adapter.features()
        & (wgpu::Features::TEXTURE_COMPRESSION_BC | wgpu::Features::TEXTURE_COMPRESSION_ETC2)
}

/// Whether `device` can hold textures as `texels`.
pub(crate) fn offers(device: &wgpu::Device, texels: TexelFormat) -> bool {
    let f = device.features();
    match texels {
        TexelFormat::Rgba8 => true,
        TexelFormat::Block => f.contains(wgpu::Features::TEXTURE_COMPRESSION_BC),
        TexelFormat::Etc2 => f.contains(wgpu::Features::TEXTURE_COMPRESSION_ETC2),
    }
}

/// How a renderer on `device` holds textures unless told otherwise: BC where offered, else
/// ETC2, else RGBA8; `PORTICO_TEXELS=rgba8|bc|etc2` picks one the device offers (to compare).
pub(crate) fn default_texels(device: &wgpu::Device) -> TexelFormat {
    let asked =
        std::env::var("PORTICO_TEXELS")
            .ok()
            .and_then(|v| match v.to_ascii_lowercase().as_str() {
                "rgba8" => Some(TexelFormat::Rgba8),
                "bc" | "block" => Some(TexelFormat::Block),
                "etc2" => Some(TexelFormat::Etc2),
                _ => None,
            });
    asked
        .into_iter()
        .chain([TexelFormat::Block, TexelFormat::Etc2])
        .find(|&t| offers(device, t))
        .unwrap_or(TexelFormat::Rgba8)
}

/// A texel format as a byte (to share one between the renderer and its uploaders).
pub(crate) fn texels_code(t: TexelFormat) -> u8 {
    match t {
        TexelFormat::Rgba8 => 0,
        TexelFormat::Block => 1,
        TexelFormat::Etc2 => 2,
    }
}

/// [`texels_code`] back.
pub(crate) fn texels_of(code: u8) -> TexelFormat {
    match code {
        1 => TexelFormat::Block,
        2 => TexelFormat::Etc2,
        _ => TexelFormat::Rgba8,
    }
}
