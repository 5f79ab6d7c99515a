//! Headless wgpu renderer of the walkthrough client (DESIGN §5).
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

pub mod textured;

pub use textured::GpuImpostor;

use std::sync::{Arc, mpsc};
use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};
use portico_data::geometry::{Aabb, GeometryView, Vertex};
use wgpu::util::DeviceExt;

/// Format of the colour target: 8-bit sRGB, so linear shader output is encoded on write.
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Format of the depth target.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// The sky colour every frame is cleared to (linear RGB).
pub const SKY_COLOR: wgpu::Color = wgpu::Color {
    r: 0.30,
    g: 0.50,
    b: 0.80,
    a: 1.0,
};

/// Draws reserved in the instance buffer before the first frame needs more.
const INITIAL_INSTANCES: u64 = 64;
/// Frames timed per sample in the calibration functions; the fastest one is kept.
const SAMPLE_REPEATS: usize = 2;
/// Overlapping layers drawn per fill sample, nearest last, so every layer passes the depth test.
const FILL_LAYERS: usize = 4;

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

/// One uploaded geometry segment (one LOD of one object) in GPU memory.
///
/// The buffers are freed when the mesh is dropped, which is how the client's cache releases them.
#[derive(Debug)]
pub struct GpuMesh {
    vertex: wgpu::Buffer,
    index: wgpu::Buffer,
    index_format: wgpu::IndexFormat,
    index_count: u32,
    vertex_count: u32,
    bounds: Aabb,
}

impl GpuMesh {
    /// GPU memory held by the vertex and index buffers, in bytes.
    pub fn gpu_bytes(&self) -> u64 {
        self.vertex.size() + self.index.size()
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
/// another thread (DESIGN §5: the IO → GPU-upload stage), while the render thread draws.
#[derive(Debug, Clone)]
pub struct Uploader {
    device: wgpu::Device,
    queue: wgpu::Queue,
    textured: Arc<textured::Textured>,
}

impl Uploader {
    /// Same as [`Renderer::upload`].
    pub fn upload(&self, segment_bytes: &[u8]) -> Result<GpuMesh, RenderError> {
        upload_segment(&self.device, segment_bytes)
    }

    /// Same as [`Renderer::upload_impostor`].
    pub fn upload_impostor(
        &self,
        png: &[u8],
        bounds: &Aabb,
        tile: u32,
    ) -> Result<GpuImpostor, RenderError> {
        scoped(&self.device, || {
            self.textured
                .upload(&self.device, &self.queue, png, bounds, tile)
        })?
    }
}

/// One object to draw in a frame.
#[derive(Debug, Clone, Copy)]
pub struct Draw<'a> {
    /// The resident geometry.
    pub mesh: &'a GpuMesh,
    /// Object-to-world transform (rigid motion plus uniform scale: normals use its upper 3x3).
    pub transform: Mat4,
    /// Material base colour (linear RGBA), multiplied with the vertex colours.
    pub color: [f32; 4],
}

pub use crate::view::Camera;

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

/// Per-frame uniforms; must match `Globals` in `shader.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct Globals {
    view_proj: [[f32; 4]; 4],
    light_dir: [f32; 4],
    ambient: [f32; 4],
}

/// Per-draw instance attributes (locations 3..=7); 80 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct InstanceData {
    model: [[f32; 4]; 4],
    color: [f32; 4],
}

/// The offscreen targets and the buffer frames are read back through.
#[derive(Debug)]
struct Targets {
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    readback: wgpu::Buffer,
    padded_row: u32,
}

/// The headless renderer: device, offscreen targets, pipeline and per-frame buffers.
#[derive(Debug)]
pub struct Renderer {
    _instance: wgpu::Instance,
    info: wgpu::AdapterInfo,
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::RenderPipeline,
    globals: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    instances: wgpu::Buffer,
    targets: Targets,
    width: u32,
    height: u32,
    light_dir: Vec3,
    ambient: f32,
    has_frame: bool,
    textured: Arc<textured::Textured>,
    clear: wgpu::Color,
}

impl Renderer {
    /// Creates a device on the default adapter (or the one `WGPU_BACKEND` / `WGPU_ADAPTER_NAME`
    /// select) with offscreen targets of `width` x `height` pixels.
    pub fn new(width: u32, height: u32) -> Result<Renderer, RenderError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle().with_env());
        let adapter = pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
            &instance, None,
        ))?;
        let (device, queue) =
            pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
                label: Some("portico"),
                required_limits: adapter.limits(),
                ..Default::default()
            }))?;
        let layout = globals_layout(&device);
        let pipeline = create_pipeline(&device, &layout);
        let globals = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("globals"),
            size: std::mem::size_of::<Globals>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("globals"),
            layout: &layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: globals.as_entire_binding(),
            }],
        });
        let instances = create_instance_buffer(&device, INITIAL_INSTANCES);
        let targets = create_targets(&device, width, height)?;
        let textured = Arc::new(textured::Textured::new(&device, &layout));
        let info = adapter.get_info();
        tracing::info!(adapter = %info.name, backend = ?info.backend, width, height, "renderer ready");
        Ok(Renderer {
            _instance: instance,
            info,
            device,
            queue,
            pipeline,
            globals,
            bind_group,
            instances,
            targets,
            width,
            height,
            light_dir: Vec3::new(0.4, 0.8, 0.45).normalize(),
            ambient: 0.35,
            has_frame: false,
            textured,
            clear: SKY_COLOR,
        })
    }

    /// Sets the colour frames are cleared to (default [`SKY_COLOR`]; a transparent one for
    /// impostor captures).
    pub fn set_clear(&mut self, color: wgpu::Color) {
        self.clear = color;
    }

    /// Decodes an impostor atlas (PNG) and makes its textured box for `bounds`.
    pub fn upload_impostor(
        &self,
        png: &[u8],
        bounds: &Aabb,
        tile: u32,
    ) -> Result<GpuImpostor, RenderError> {
        self.uploader().upload_impostor(png, bounds, tile)
    }

    /// A one-line description of the adapter, e.g. `Gl Cpu 'llvmpipe (LLVM 15.0.6, 256 bits)' ...`.
    pub fn adapter_info(&self) -> String {
        let i = &self.info;
        format!(
            "{:?} {:?} '{}' driver='{}' '{}'",
            i.backend, i.device_type, i.name, i.driver, i.driver_info
        )
    }

    /// Whether the adapter is a software rasteriser (llvmpipe, lavapipe, WARP).
    pub fn is_cpu_adapter(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// Size of the offscreen targets in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Width over height of the targets.
    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    /// Recreates the offscreen targets at a new size (the last frame is discarded).
    pub fn resize(&mut self, width: u32, height: u32) -> Result<(), RenderError> {
        self.targets = create_targets(&self.device, width, height)?;
        self.width = width;
        self.height = height;
        self.has_frame = false;
        Ok(())
    }

    /// Sets the directional light (direction towards the light, world space; normalised here)
    /// and the ambient fraction (clamped to 0..=1).
    pub fn set_light(&mut self, towards_light: Vec3, ambient: f32) {
        self.light_dir = towards_light.try_normalize().unwrap_or(Vec3::Z);
        self.ambient = ambient.clamp(0.0, 1.0);
    }

    /// Parses a geometry segment and copies its vertex and index streams into GPU buffers.
    pub fn upload(&self, segment_bytes: &[u8]) -> Result<GpuMesh, RenderError> {
        upload_segment(&self.device, segment_bytes)
    }

    /// A handle that uploads on other threads (e.g. the IO stage) while this renderer draws.
    pub fn uploader(&self) -> Uploader {
        Uploader {
            device: self.device.clone(),
            queue: self.queue.clone(),
            textured: self.textured.clone(),
        }
    }

    /// Renders one frame from `camera` and waits until the GPU has finished it.
    pub fn render(
        &mut self,
        camera: &Camera,
        draws: &[Draw<'_>],
    ) -> Result<FrameTiming, RenderError> {
        self.render_view_proj(camera.view_proj(self.aspect()), draws)
    }

    /// Like [`Renderer::render_view_proj`], with textured boxes (cluster impostors) drawn too.
    pub fn render_with_boxes_view_proj(
        &mut self,
        view_proj: Mat4,
        draws: &[Draw<'_>],
        boxes: &[&GpuImpostor],
    ) -> Result<FrameTiming, RenderError> {
        self.render_frame(view_proj, draws, boxes)
    }

    /// Like [`Renderer::render`], with textured boxes (cluster impostors) drawn too.
    pub fn render_with_boxes(
        &mut self,
        camera: &Camera,
        draws: &[Draw<'_>],
        boxes: &[&GpuImpostor],
    ) -> Result<FrameTiming, RenderError> {
        self.render_frame(camera.view_proj(self.aspect()), draws, boxes)
    }

    /// Like [`Renderer::render`] with an explicit world-to-clip matrix (WebGPU clip space),
    /// e.g. an orthographic bird's-eye view.
    pub fn render_view_proj(
        &mut self,
        view_proj: Mat4,
        draws: &[Draw<'_>],
    ) -> Result<FrameTiming, RenderError> {
        self.render_frame(view_proj, draws, &[])
    }

    fn render_frame(
        &mut self,
        view_proj: Mat4,
        draws: &[Draw<'_>],
        boxes: &[&GpuImpostor],
    ) -> Result<FrameTiming, RenderError> {
        let start = Instant::now();
        let device = self.device.clone();
        let mut timing = scoped(&device, || self.submit_frame(view_proj, draws, boxes))??;
        timing.cpu_submit_s = start.elapsed().as_secs_f64();
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        timing.total_s = start.elapsed().as_secs_f64();
        self.has_frame = true;
        Ok(timing)
    }

    /// Copies the last rendered frame back to the CPU (sRGB-encoded RGBA8).
    pub fn read_pixels(&mut self) -> Result<image::RgbaImage, RenderError> {
        if !self.has_frame {
            return Err(RenderError::NoFrame);
        }
        self.copy_to_readback();
        let bytes = self.map_readback()?;
        image::RgbaImage::from_raw(self.width, self.height, bytes)
            .ok_or_else(|| RenderError::Readback("pixel buffer has the wrong size".into()))
    }

    /// Renders a frame and reads it back.
    pub fn render_to_image(
        &mut self,
        camera: &Camera,
        draws: &[Draw<'_>],
    ) -> Result<(FrameTiming, image::RgbaImage), RenderError> {
        let timing = self.render(camera, draws)?;
        Ok((timing, self.read_pixels()?))
    }

    /// Times frames of `n` separate draws of `mesh` for each `n` in `counts`, all squeezed into a
    /// small patch of the screen so that pixel fill stays negligible. Returns
    /// `(triangles, vertices, seconds)` per count, for fitting `C1·polys + C2·verts` (§4.2.3).
    pub fn sample_costs(
        &mut self,
        mesh: &GpuMesh,
        counts: &[u32],
    ) -> Result<Vec<(u64, u64, f64)>, RenderError> {
        let view_proj = fit_to_patch(&mesh.bounds(), 0.1);
        let draw = Draw {
            mesh,
            transform: Mat4::IDENTITY,
            color: [1.0; 4],
        };
        self.render_view_proj(view_proj, &[draw])?; // warm-up: first use compiles state
        counts
            .iter()
            .map(|&n| {
                let draws = vec![draw; n as usize];
                let t = self.fastest_frame(view_proj, &draws)?;
                Ok((t.triangles, t.vertices, t.total_s))
            })
            .collect()
    }

    /// Times frames of [`FILL_LAYERS`] overlapping screen-aligned quads, each covering the given
    /// fraction of the screen. Returns `(pixels written, seconds)` per coverage, for fitting
    /// `C3·pixels` (§4.2.3).
    pub fn sample_fill(&mut self, coverage: &[f32]) -> Result<Vec<(f64, f64)>, RenderError> {
        let quad = self.upload(&portico_data::geometry::encode_geometry(&unit_quad()))?;
        let screen = f64::from(self.width) * f64::from(self.height);
        self.render_view_proj(Mat4::IDENTITY, &[])?; // warm-up
        coverage
            .iter()
            .map(|&c| {
                let c = c.clamp(0.0, 1.0);
                let draws = fill_layers(&quad, c);
                let t = self.fastest_frame(Mat4::IDENTITY, &draws)?;
                Ok((
                    (f64::from(c) * screen).round() * FILL_LAYERS as f64,
                    t.total_s,
                ))
            })
            .collect()
    }

    /// The fastest of [`SAMPLE_REPEATS`] frames of the same draws.
    fn fastest_frame(
        &mut self,
        view_proj: Mat4,
        draws: &[Draw<'_>],
    ) -> Result<FrameTiming, RenderError> {
        let mut best = self.render_view_proj(view_proj, draws)?;
        for _ in 1..SAMPLE_REPEATS {
            let t = self.render_view_proj(view_proj, draws)?;
            if t.total_s < best.total_s {
                best = t;
            }
        }
        Ok(best)
    }

    /// Uploads the frame's uniforms and instances, encodes the pass and submits it.
    fn submit_frame(
        &mut self,
        view_proj: Mat4,
        draws: &[Draw<'_>],
        boxes: &[&GpuImpostor],
    ) -> Result<FrameTiming, RenderError> {
        self.write_globals(view_proj);
        self.write_instances(draws)?;
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        let timing = self.encode_pass(&mut encoder, draws, boxes);
        self.queue.submit([encoder.finish()]);
        Ok(timing)
    }

    fn write_globals(&self, view_proj: Mat4) {
        let g = Globals {
            view_proj: view_proj.to_cols_array_2d(),
            light_dir: self.light_dir.extend(0.0).to_array(),
            ambient: [self.ambient, 0.0, 0.0, 0.0],
        };
        self.queue
            .write_buffer(&self.globals, 0, bytemuck::bytes_of(&g));
    }

    /// Writes one [`InstanceData`] per draw, growing the buffer to a power of two if needed.
    fn write_instances(&mut self, draws: &[Draw<'_>]) -> Result<(), RenderError> {
        let needed = draws.len() as u64;
        let stride = std::mem::size_of::<InstanceData>() as u64;
        if needed * stride > self.instances.size() {
            let capacity = needed.next_power_of_two();
            let limit = self.device.limits().max_buffer_size;
            if capacity * stride > limit {
                return Err(RenderError::TooLarge {
                    size: capacity * stride,
                    limit,
                });
            }
            self.instances = create_instance_buffer(&self.device, capacity);
        }
        let data: Vec<InstanceData> = draws
            .iter()
            .map(|d| InstanceData {
                model: d.transform.to_cols_array_2d(),
                color: d.color,
            })
            .collect();
        if !data.is_empty() {
            self.queue
                .write_buffer(&self.instances, 0, bytemuck::cast_slice(&data));
        }
        Ok(())
    }

    /// Records the render pass: clear, then one instanced draw per non-empty mesh, then the
    /// textured boxes.
    fn encode_pass(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        draws: &[Draw<'_>],
        boxes: &[&GpuImpostor],
    ) -> FrameTiming {
        let mut pass = self.begin_pass(encoder);
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.set_vertex_buffer(1, self.instances.slice(..));
        let mut timing = FrameTiming::default();
        let mut bound: Option<&GpuMesh> = None;
        for (i, d) in (0u32..).zip(draws) {
            if d.mesh.index_count == 0 {
                continue;
            }
            if !bound.is_some_and(|b| std::ptr::eq(b, d.mesh)) {
                pass.set_vertex_buffer(0, d.mesh.vertex.slice(..));
                pass.set_index_buffer(d.mesh.index.slice(..), d.mesh.index_format);
                bound = Some(d.mesh);
            }
            pass.draw_indexed(0..d.mesh.index_count, 0, i..i + 1);
            timing.triangles += u64::from(d.mesh.triangles());
            timing.vertices += u64::from(d.mesh.vertex_count);
            timing.draws += 1;
        }
        self.textured.draw(&mut pass, &self.bind_group, boxes);
        timing.triangles += 12 * boxes.len() as u64;
        timing.vertices += 24 * boxes.len() as u64;
        timing.draws += boxes.len() as u32;
        timing
    }

    fn begin_pass<'e>(&self, encoder: &'e mut wgpu::CommandEncoder) -> wgpu::RenderPass<'e> {
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("frame"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &self.targets.color_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(self.clear),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.targets.depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        })
    }

    fn copy_to_readback(&self) {
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("readback"),
            });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.targets.color,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &self.targets.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.targets.padded_row),
                    rows_per_image: Some(self.height),
                },
            },
            extent(self.width, self.height),
        );
        self.queue.submit([encoder.finish()]);
    }

    /// Maps the readback buffer and returns the pixels without the row padding.
    fn map_readback(&self) -> Result<Vec<u8>, RenderError> {
        let slice = self.targets.readback.slice(..);
        let (tx, rx) = mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        rx.recv()
            .map_err(|e| RenderError::Readback(e.to_string()))?
            .map_err(|e| RenderError::Readback(e.to_string()))?;
        let pixels = {
            let mapped = slice
                .get_mapped_range()
                .map_err(|e| RenderError::Readback(e.to_string()))?;
            strip_padding(&mapped, self.targets.padded_row, self.width * 4)
        };
        self.targets.readback.unmap();
        Ok(pixels)
    }
}

/// Parses a segment and creates its buffers straight from the vertex and index byte streams.
fn upload_segment(device: &wgpu::Device, segment_bytes: &[u8]) -> Result<GpuMesh, RenderError> {
    let view = GeometryView::parse(segment_bytes).map_err(RenderError::Geometry)?;
    let limit = device.limits().max_buffer_size;
    for size in [
        view.vertex_bytes.len() as u64,
        view.index_bytes.len() as u64,
    ] {
        if size > limit {
            return Err(RenderError::TooLarge { size, limit });
        }
    }
    let (vertex, index) = scoped(device, || {
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
        )
    })?;
    let index_format = if view.wide_indices() {
        wgpu::IndexFormat::Uint32
    } else {
        wgpu::IndexFormat::Uint16
    };
    Ok(GpuMesh {
        vertex,
        index,
        index_format,
        index_count: view.header.index_count,
        vertex_count: view.header.vertex_count,
        bounds: vertex_bounds(view.vertex_bytes),
    })
}

/// A buffer holding `bytes`. `create_buffer_init` pads the size to a multiple of
/// `COPY_BUFFER_ALIGNMENT` (4), so odd-length `u16` index streams need no manual padding.
fn buffer_init(
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

/// Runs `f` with out-of-memory and validation errors captured as [`RenderError::Gpu`] instead of
/// reaching wgpu's default handler, which panics.
fn scoped<T>(device: &wgpu::Device, f: impl FnOnce() -> T) -> Result<T, RenderError> {
    let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let out = f();
    let errors = [
        pollster::block_on(validation.pop()),
        pollster::block_on(oom.pop()),
    ];
    match errors.into_iter().flatten().next() {
        Some(e) => Err(RenderError::Gpu(e.to_string())),
        None => Ok(out),
    }
}

/// Copies the first `row` bytes of each `padded`-byte row.
fn strip_padding(bytes: &[u8], padded: u32, row: u32) -> Vec<u8> {
    bytes
        .chunks(padded as usize)
        .flat_map(|r| &r[..(row as usize).min(r.len())])
        .copied()
        .collect()
}

fn extent(width: u32, height: u32) -> wgpu::Extent3d {
    wgpu::Extent3d {
        width,
        height,
        depth_or_array_layers: 1,
    }
}

/// Bounding box of a raw vertex stream (positions are the first 12 bytes of each vertex).
fn vertex_bounds(vertex_bytes: &[u8]) -> Aabb {
    let mut b = Aabb::EMPTY;
    for v in vertex_bytes.chunks_exact(std::mem::size_of::<Vertex>()) {
        let p: [f32; 3] = bytemuck::pod_read_unaligned(&v[..12]);
        b.include(Vec3::from(p));
    }
    b
}

/// A clip-space matrix that maps `bounds` into a centred square patch of half-size `half`
/// (in NDC units) at depths within 0.1..0.9.
fn fit_to_patch(bounds: &Aabb, half: f32) -> Mat4 {
    let radius = if bounds.is_empty() {
        1.0
    } else {
        (bounds.size().max_element() * 0.5).max(1e-6)
    };
    Mat4::from_translation(Vec3::new(0.0, 0.0, 0.5))
        * Mat4::from_scale(Vec3::new(half, half, 0.4) / radius)
        * Mat4::from_translation(-bounds.center())
}

/// A quad covering NDC `[-1, 1]²` at z = 0, facing +z, white.
fn unit_quad() -> portico_data::geometry::Mesh {
    let corner = |x: f32, y: f32| Vertex::new([x, y, 0.0], [0.0, 0.0, 1.0], [1.0; 4]);
    portico_data::geometry::Mesh {
        vertices: vec![
            corner(-1.0, -1.0),
            corner(1.0, -1.0),
            corner(1.0, 1.0),
            corner(-1.0, 1.0),
        ],
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

/// [`FILL_LAYERS`] centred quads each covering `coverage` of the screen, drawn far to near.
fn fill_layers(quad: &GpuMesh, coverage: f32) -> Vec<Draw<'_>> {
    let s = coverage.sqrt();
    (0..FILL_LAYERS)
        .map(|k| {
            let z = 0.9 - 0.8 * k as f32 / FILL_LAYERS as f32;
            Draw {
                mesh: quad,
                transform: Mat4::from_translation(Vec3::new(0.0, 0.0, z))
                    * Mat4::from_scale(Vec3::new(s, s, 1.0)),
                color: [1.0; 4],
            }
        })
        .collect()
}

fn create_targets(device: &wgpu::Device, width: u32, height: u32) -> Result<Targets, RenderError> {
    let max = device.limits().max_texture_dimension_2d;
    if width == 0 || height == 0 || width > max || height > max {
        return Err(RenderError::BadSize(width, height));
    }
    let texture = |label, format, usage| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: extent(width, height),
            mip_level_count: 1,
            sample_count: 1,
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
    );
    let depth = texture(
        "depth",
        DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
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
        depth_view: depth.create_view(&Default::default()),
        color,
        readback,
        padded_row,
    })
}

fn create_instance_buffer(device: &wgpu::Device, capacity: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("instances"),
        size: capacity * std::mem::size_of::<InstanceData>() as u64,
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

fn globals_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
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

const VERTEX_ATTRIBUTES: [wgpu::VertexAttribute; 3] =
    wgpu::vertex_attr_array![0 => Float32x3, 1 => Snorm8x4, 2 => Unorm8x4];
const INSTANCE_ATTRIBUTES: [wgpu::VertexAttribute; 5] = wgpu::vertex_attr_array![
    3 => Float32x4, 4 => Float32x4, 5 => Float32x4, 6 => Float32x4, 7 => Float32x4
];

fn vertex_layouts() -> [Option<wgpu::VertexBufferLayout<'static>>; 2] {
    [
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
    ]
}

/// The one pipeline: depth-tested opaque triangles, no culling (building models are often
/// two-sided or inconsistently wound; the shader lights both sides).
fn create_pipeline(device: &wgpu::Device, globals: &wgpu::BindGroupLayout) -> wgpu::RenderPipeline {
    let shader = device.create_shader_module(wgpu::include_wgsl!("shader.wgsl"));
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("walkthrough"),
        bind_group_layouts: &[Some(globals)],
        immediate_size: 0,
    });
    let buffers = vertex_layouts();
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("walkthrough"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module: &shader,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: &buffers,
        },
        primitive: wgpu::PrimitiveState {
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: &shader,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(COLOR_FORMAT.into())],
        }),
        multiview_mask: None,
        cache: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use portico_data::geometry::{
        GEOMETRY_MAGIC, GEOMETRY_U32_INDICES, GEOMETRY_VERSION, GeometryHeader, Mesh,
        encode_geometry,
    };

    const W: u32 = 64;
    const H: u32 = 48;
    const RED: [f32; 4] = [1.0, 0.0, 0.0, 1.0];
    const GREEN: [f32; 4] = [0.0, 1.0, 0.0, 1.0];
    const BLUE: [f32; 4] = [0.0, 0.0, 1.0, 1.0];

    /// A renderer on the test machine's adapter; failing to get one fails the test.
    fn renderer() -> Renderer {
        match Renderer::new(W, H) {
            Ok(r) => r,
            Err(e) => panic!("no wgpu adapter/device (CI has llvmpipe): {e}"),
        }
    }

    fn camera() -> Camera {
        Camera {
            eye: Vec3::new(0.0, 0.0, 3.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fovy: 60f32.to_radians(),
            near: 0.1,
            far: 100.0,
        }
    }

    /// A white square of half-size `half` in the plane z = 0, facing +z.
    fn square(half: f32) -> Mesh {
        let v = |x: f32, y: f32| Vertex::new([x * half, y * half, 0.0], [0.0, 0.0, 1.0], [1.0; 4]);
        Mesh {
            vertices: vec![v(-1.0, -1.0), v(1.0, -1.0), v(1.0, 1.0), v(-1.0, 1.0)],
            indices: vec![0, 1, 2, 0, 2, 3],
        }
    }

    fn at(mesh: &GpuMesh, offset: Vec3, color: [f32; 4]) -> Draw<'_> {
        Draw {
            mesh,
            transform: Mat4::from_translation(offset),
            color,
        }
    }

    /// The pixel a world point projects to.
    fn pixel_of(p: Vec3) -> (u32, u32) {
        let ndc = camera().view_proj(W as f32 / H as f32).project_point3(p);
        let x = (ndc.x + 1.0) * 0.5 * W as f32;
        let y = (1.0 - ndc.y) * 0.5 * H as f32;
        (x as u32, y as u32)
    }

    /// The clear colour as read back (from a frame with nothing in it).
    fn sky(r: &mut Renderer) -> image::Rgba<u8> {
        let (_, img) = r.render_to_image(&camera(), &[]).expect("empty frame");
        *img.get_pixel(0, 0)
    }

    #[test]
    fn visible_square_covers_centre_not_corners() {
        let mut r = renderer();
        assert!(!r.adapter_info().is_empty());
        assert_eq!(r.size(), (W, H));
        let sky = sky(&mut r);
        let mesh = r.upload(&encode_geometry(&square(0.5))).expect("upload");
        assert!(mesh.gpu_bytes() > 0);
        assert_eq!((mesh.triangles(), mesh.vertices()), (2, 4));
        assert!(!mesh.wide_indices());
        let (t, img) = r
            .render_to_image(&camera(), &[at(&mesh, Vec3::ZERO, [1.0; 4])])
            .expect("render");
        assert_eq!((t.triangles, t.vertices, t.draws), (2, 4, 1));
        assert!(t.total_s >= t.cpu_submit_s && t.total_s > 0.0);
        assert_ne!(*img.get_pixel(W / 2, H / 2), sky);
        for (x, y) in [(0, 0), (W - 1, 0), (0, H - 1), (W - 1, H - 1)] {
            assert_eq!(*img.get_pixel(x, y), sky, "corner {x},{y}");
        }
    }

    #[test]
    fn uploads_from_another_thread_render() {
        fn shareable<T: Send + Sync>() {}
        shareable::<Renderer>();
        shareable::<GpuMesh>();
        shareable::<Uploader>();
        let mut r = renderer();
        let sky = sky(&mut r);
        let uploader = r.uploader();
        let bytes = encode_geometry(&square(0.5));
        let mesh = std::thread::spawn(move || uploader.upload(&bytes))
            .join()
            .expect("upload thread")
            .expect("upload");
        let (_, img) = r
            .render_to_image(&camera(), &[at(&mesh, Vec3::ZERO, BLUE)])
            .expect("render");
        assert_ne!(*img.get_pixel(W / 2, H / 2), sky);
    }

    #[test]
    fn mesh_behind_camera_leaves_only_sky() {
        let mut r = renderer();
        let sky = sky(&mut r);
        let mesh = r.upload(&encode_geometry(&square(5.0))).expect("upload");
        let draw = at(&mesh, Vec3::new(0.0, 0.0, 6.0), [1.0; 4]);
        let (_, img) = r.render_to_image(&camera(), &[draw]).expect("render");
        assert!(img.pixels().all(|p| *p == sky));
    }

    #[test]
    fn nearer_colour_wins_regardless_of_draw_order() {
        let mut r = renderer();
        let mesh = r.upload(&encode_geometry(&square(0.5))).expect("upload");
        let (near, far) = (Vec3::new(0.0, 0.0, 0.5), Vec3::ZERO);
        for (near_color, far_color) in [(RED, GREEN), (GREEN, RED)] {
            let a = at(&mesh, near, near_color);
            let b = at(&mesh, far, far_color);
            for draws in [[a, b], [b, a]] {
                let (_, img) = r.render_to_image(&camera(), &draws).expect("render");
                let p = img.get_pixel(W / 2, H / 2).0;
                let red_wins = u16::from(p[0]) > 2 * u16::from(p[1]);
                assert_eq!(red_wins, near_color == RED, "pixel {p:?}");
            }
        }
    }

    #[test]
    fn each_draw_gets_its_own_transform_and_colour() {
        let mut r = renderer();
        let mesh = r.upload(&encode_geometry(&square(0.25))).expect("upload");
        // More draws than the initial instance capacity, most of them behind the camera.
        let mut draws = vec![at(&mesh, Vec3::new(0.0, 0.0, 10.0), [1.0; 4]); 97];
        let spots = [(-0.8, RED, 0), (0.0, GREEN, 1), (0.8, BLUE, 2)];
        draws.extend(spots.map(|(x, c, _)| at(&mesh, Vec3::new(x, 0.0, 0.0), c)));
        let (t, img) = r.render_to_image(&camera(), &draws).expect("render");
        assert_eq!(t.draws, 100);
        for (x, _, channel) in spots {
            let (px, py) = pixel_of(Vec3::new(x, 0.0, 0.0));
            let p = img.get_pixel(px, py).0;
            let max = (0..3).max_by_key(|&i| p[i]).unwrap_or(3);
            assert_eq!(max, channel, "pixel {p:?} at {px},{py}");
        }
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let mut r = renderer();
        assert!(matches!(r.read_pixels(), Err(RenderError::NoFrame)));
        let good = encode_geometry(&square(1.0));
        let mut bad_index = good.clone();
        let last = bad_index.len() - 2;
        bad_index[last..].copy_from_slice(&[0xff, 0xff]);
        let noise: Vec<u8> = (0..200u32).map(|i| (i * 37 % 251) as u8).collect();
        for bytes in [&[][..], &noise, &good[..good.len() - 4], &bad_index] {
            assert!(matches!(r.upload(bytes), Err(RenderError::Geometry(_))));
        }
        assert!(matches!(r.resize(0, 10), Err(RenderError::BadSize(0, 10))));
    }

    /// A segment with u32 indices even though u16 would do (the encoder only widens when needed).
    fn wide_segment(mesh: &Mesh) -> Vec<u8> {
        let vertex_offset = std::mem::size_of::<GeometryHeader>();
        let header = GeometryHeader {
            magic: GEOMETRY_MAGIC,
            version: GEOMETRY_VERSION,
            flags: GEOMETRY_U32_INDICES,
            vertex_count: mesh.vertices.len() as u32,
            index_count: mesh.indices.len() as u32,
            vertex_offset: vertex_offset as u32,
            index_offset: (vertex_offset + mesh.vertices.len() * 20) as u32,
            reserved: [0; 2],
        };
        let mut out = bytemuck::bytes_of(&header).to_vec();
        out.extend_from_slice(bytemuck::cast_slice(&mesh.vertices));
        out.extend_from_slice(bytemuck::cast_slice(&mesh.indices));
        out
    }

    #[test]
    fn wide_index_and_empty_meshes_render() {
        let mut r = renderer();
        let sky = sky(&mut r);
        let wide = r.upload(&wide_segment(&square(0.5))).expect("wide upload");
        assert!(wide.wide_indices());
        let empty = r.upload(&encode_geometry(&Mesh::default())).expect("empty");
        assert_eq!(empty.triangles(), 0);
        let draws = [at(&empty, Vec3::ZERO, RED), at(&wide, Vec3::ZERO, GREEN)];
        let (t, img) = r.render_to_image(&camera(), &draws).expect("render");
        assert_eq!((t.draws, t.triangles), (1, 2));
        let p = img.get_pixel(W / 2, H / 2).0;
        assert!(p[1] > p[0] && p[1] > p[2], "{p:?}");
        assert_eq!(*img.get_pixel(0, 0), sky);
    }

    #[test]
    fn calibration_samples_report_work_and_time() {
        let mut r = renderer();
        let sky = sky(&mut r);
        let mesh = r.upload(&encode_geometry(&square(3.0))).expect("upload");
        let costs = r.sample_costs(&mesh, &[1, 8]).expect("costs");
        let work: Vec<(u64, u64)> = costs.iter().map(|c| (c.0, c.1)).collect();
        assert_eq!(work, [(2, 4), (16, 32)]);
        assert!(costs.iter().all(|c| c.2 > 0.0));
        let fill = r.sample_fill(&[0.25, 1.0]).expect("fill");
        let screen = f64::from(W * H) * FILL_LAYERS as f64;
        assert_eq!(fill.len(), 2);
        assert_eq!(
            fill.iter().map(|f| f.0).collect::<Vec<_>>(),
            [0.25 * screen, screen]
        );
        let img = r.read_pixels().expect("last fill frame");
        assert!(
            img.pixels().all(|p| *p != sky),
            "full coverage leaves no sky"
        );
    }
}
