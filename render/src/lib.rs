//! Headless wgpu renderer of the walkthrough client.
//!
//! Funkhouser's walkthrough system (§3.3) ends its pipeline with a render stage that draws, every
//! frame, the objects and levels of detail chosen by the detail-elision stage, and measures how
//! long that took so the cost model can be refitted. This module is that stage:
//!
//! * geometry segments from the display database are uploaded **as they are**: the vertex and
//!   index streams of a segment become GPU buffers byte for byte ([`Renderer::upload`]), so the
//!   cache's byte budget is the segments' size ([`GpuMesh::gpu_bytes`]);
//! * a frame is one render pass into offscreen colour and depth targets; the per-draw transform
//!   and material colour live in one per-frame instance buffer, so a draw is just
//!   `draw_indexed(.., i..i + 1)` with no per-draw bind groups;
//! * [`Renderer::render`] waits for the GPU, so [`FrameTiming::total_s`] is the real frame time
//!   that the `feedback` and `optimize` elision algorithms consume;
//! * [`Renderer::sample_costs`] and [`Renderer::sample_fill`] time sample frames so the client
//!   can calibrate the cost model `max(C1·polys + C2·verts, C3·pixels)` at start-up (§4.2.3).
//!
//! It runs on any wgpu adapter, including CPU ones (llvmpipe through GL, lavapipe through
//! Vulkan); `WGPU_BACKEND` / `WGPU_ADAPTER_NAME` pick one.

#![forbid(unsafe_code)]

mod calibrate;
mod held;
#[cfg(not(target_arch = "wasm32"))]
pub mod impostor;
mod material;
mod mesh;
mod pipeline;
mod readback;
mod renderer;
#[cfg(not(target_arch = "wasm32"))]
pub mod sheet;
mod stand_in;
pub mod textured;

pub use calibrate::calibrate;
pub use material::GpuTexture;
pub use mesh::{GpuMesh, Uploader};
pub use portico_client::view::Camera;
pub use portico_data::model::{Surface, TextureRole};
pub use portico_data::texture::AlphaMode;
pub use renderer::Renderer;
pub use stand_in::StandIns;
pub use textured::GpuImpostor;
/// The wgpu this renderer draws with, for callers that give it a surface.
pub use wgpu;

use glam::Mat4;
pub(crate) use renderer::{extent, scoped};

/// Format of the colour target: 8-bit sRGB, so linear shader output is encoded on write.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Format of the depth target.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Samples per pixel (MSAA) on a GPU. Faces thinner than a pixel — a door panel's 6 mm raised
/// edge, a chair leg far away — are otherwise hit or missed pixel by pixel and show as dashed
/// lines; with 4 samples they shade each pixel by how much of it they cover. WebGPU guarantees 4
/// for both target formats on every adapter. On a CPU rasteriser (llvmpipe) 4 samples nearly
/// triple the frame time, so there the default is 1; `PORTICO_MSAA=1|4` chooses either way.
pub const SAMPLES: u32 = 4;
/// The sky colour every frame is cleared to (linear RGB).
pub const SKY_COLOR: wgpu::Color = wgpu::Color {
    r: 0.30,
    g: 0.50,
    b: 0.80,
    a: 1.0,
};

/// Draws reserved in the instance buffer before the first frame needs more.
pub(crate) const INITIAL_INSTANCES: u64 = 64;
/// Frames timed per sample in the calibration functions; the fastest one is kept.
pub(crate) const SAMPLE_REPEATS: usize = 2;
/// Overlapping layers drawn per fill sample, nearest last, so every layer passes the depth test.
pub(crate) const FILL_LAYERS: usize = 4;

/// Why the renderer could not do what it was asked.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// No graphics adapter (not even a CPU one) could be found.
    #[error("no graphics adapter: {0}")]
    NoAdapter(#[from] wgpu::RequestAdapterError),
    /// The adapter refused to create a device.
    #[error("cannot create a device: {0}")]
    NoDevice(#[from] wgpu::RequestDeviceError),
    /// The target size is zero or beyond the device's texture limit.
    #[error("invalid target size {0}x{1}")]
    BadSize(u32, u32),
    /// The bytes are not a valid geometry segment.
    #[error("invalid geometry segment: {0}")]
    Geometry(String),
    /// The bytes are not a valid texture segment, or the device cannot hold it.
    #[error("invalid texture segment: {0}")]
    Texture(String),
    /// A buffer would exceed the device's maximum buffer size.
    #[error("buffer of {size} bytes exceeds the device limit of {limit} bytes")]
    TooLarge {
        /// Requested size in bytes.
        size: u64,
        /// The device's `max_buffer_size`.
        limit: u64,
    },
    /// The device reported an error (out of memory, validation) while doing the work.
    #[error("GPU error: {0}")]
    Gpu(String),
    /// Waiting for the GPU failed.
    #[error("waiting for the GPU failed: {0}")]
    Poll(#[from] wgpu::PollError),
    /// Mapping the readback buffer failed.
    #[error("reading back the frame failed: {0}")]
    Readback(String),
    /// [`Renderer::read_pixels`] was called before any frame was rendered.
    #[error("no frame has been rendered yet")]
    NoFrame,
}

/// One object to draw in a frame.
#[derive(Debug, Clone, Copy)]
pub struct Draw<'a> {
    /// The resident geometry.
    pub mesh: &'a GpuMesh,
    /// Object-to-world transform (rigid motion plus uniform scale: normals use its upper 3x3).
    pub transform: Mat4,
    /// Material base colour (linear RGBA), multiplied with the vertex colours (and the
    /// texture): a textured object whose texture is not resident passes the texture's average
    /// colour here.
    pub color: [f32; 4],
    /// The base-colour texture, sampled at the mesh's coordinates; ignored for a mesh without
    /// them.
    pub texture: Option<&'a GpuTexture>,
    /// How alpha is used: opaque, cut out at a cutoff (textured draws) or blended (drawn after
    /// every opaque draw, in the order given, without writing depth).
    pub alpha: AlphaMode,
    /// What the texture colours, the light given off (added after lighting: a texture that is
    /// emissive and not resident adds `color`'s share instead), whether it is lit, and whether
    /// faces seen from behind are drawn (a single-sided surface culls them; a transform that
    /// mirrors turns which side is the front, as glTF §3.7.4 says).
    pub surface: Surface,
}

impl<'a> Draw<'a> {
    /// An opaque, untextured draw of `mesh`.
    pub fn new(mesh: &'a GpuMesh, transform: Mat4, color: [f32; 4]) -> Draw<'a> {
        Draw {
            mesh,
            transform,
            color,
            texture: None,
            alpha: AlphaMode::Opaque,
            surface: Surface::default(),
        }
    }

    /// The draw of an object the frame decision chose ([`portico_client::frame::Drawn`]): its
    /// instance's transform, its tint, its texture when `texture` finds that segment resident,
    /// and its material's alpha mode.
    pub fn of(
        header: &portico_data::format::Header,
        drawn: &portico_client::frame::Drawn,
        mesh: &'a GpuMesh,
        texture: impl Fn(u32) -> Option<&'a GpuTexture>,
    ) -> Draw<'a> {
        let inst = header.instances.get(drawn.instance as usize);
        let material = inst.and_then(|i| header.materials.get(i.material as usize));
        Draw {
            mesh,
            transform: inst.map_or(Mat4::IDENTITY, |i| Mat4::from_cols_array(&i.transform)),
            color: drawn.tint,
            texture: drawn.texture.and_then(texture),
            alpha: material.map_or(AlphaMode::Opaque, |m| m.alpha),
            surface: material.map_or(Surface::default(), |m| m.surface()),
        }
    }

    /// Whether this draw samples its texture.
    pub(crate) fn textured(&self) -> bool {
        self.texture.is_some() && self.mesh.uv.is_some()
    }
}

/// What one frame cost and contained.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FrameTiming {
    /// Seconds from the start of [`Renderer::render`] until the commands were submitted.
    pub cpu_submit_s: f64,
    /// Seconds from the start of [`Renderer::render`] until the GPU finished the frame.
    pub total_s: f64,
    /// Triangles submitted.
    pub triangles: u64,
    /// Vertices of the submitted meshes (summed per draw).
    pub vertices: u64,
    /// Draw calls issued (empty meshes are skipped).
    pub draws: u32,
}

#[cfg(test)]
mod tests;
