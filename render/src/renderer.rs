//! The headless renderer: device, pipeline, one render pass per frame into offscreen targets,
//! read-back (Funkhouser §3.3's render stage, timed so the cost model can be refitted).

use crate::mesh::{GpuMesh, Uploader, upload_segment};
use crate::pipeline::{
    Globals, InstanceData, Targets, create_instance_buffer, create_pipeline, create_targets,
    globals_layout,
};
use crate::{
    AlphaMode, Camera, Draw, FrameTiming, GpuImpostor, GpuTexture, INITIAL_INSTANCES, RenderError,
    SKY_COLOR, textured,
};
use glam::{Mat4, Vec3};
use portico_data::geometry::Aabb;
use portico_data::texture::TexelFormat;
use std::sync::Arc;
use web_time::Instant;

mod encode;

/// The headless renderer: device, offscreen targets, pipeline and per-frame buffers.
#[derive(Debug)]
pub struct Renderer {
    pub(crate) _instance: wgpu::Instance,
    pub(crate) info: wgpu::AdapterInfo,
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pub(crate) pipeline: wgpu::RenderPipeline,
    pub(crate) globals: wgpu::Buffer,
    pub(crate) bind_group: wgpu::BindGroup,
    pub(crate) instances: wgpu::Buffer,
    pub(crate) targets: Targets,
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) light_dir: Vec3,
    pub(crate) ambient: f32,
    pub(crate) has_frame: bool,
    pub(crate) textured: Arc<textured::Textured>,
    pub(crate) materials: Arc<crate::material::Materials>,
    pub(crate) clear: wgpu::Color,
    pub(crate) samples: u32,
    pub(crate) held: crate::held::Held,
}

impl Renderer {
    /// Creates a device on the default adapter (or the one `WGPU_BACKEND` / `WGPU_ADAPTER_NAME`
    /// select) with offscreen targets of `width` x `height` pixels, [`crate::SAMPLES`] per pixel
    /// on a GPU and one on a CPU rasteriser unless `PORTICO_MSAA` (1 or 4) says otherwise.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new(width: u32, height: u32) -> Result<Renderer, RenderError> {
        Self::with_samples(width, height, None)
    }

    /// As [`Renderer::new`] with `samples` per pixel (1 or 4; `None`: the adapter's default).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn with_samples(
        width: u32,
        height: u32,
        samples: Option<u32>,
    ) -> Result<Renderer, RenderError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle().with_env());
        let adapter = pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
            &instance, None,
        ))?;
        let samples = samples.or_else(msaa_from_env);
        pollster::block_on(Self::on_adapter(instance, &adapter, width, height, samples))
    }

    /// A renderer on `adapter` (found by the caller: a browser's, one compatible with a window's
    /// surface), with a device of the adapter's own limits and targets of `width` x `height`
    /// pixels; `samples` per pixel (1 or 4), or `None` for [`crate::SAMPLES`] on a GPU and one
    /// on a CPU rasteriser. Frames go to the offscreen targets ([`Renderer::render`]) or to a
    /// surface's texture ([`Renderer::render_into`]) of [`crate::COLOR_FORMAT`].
    ///
    /// # Errors
    /// [`RenderError::NoDevice`] when the adapter refuses a device; [`RenderError::BadSize`]
    /// for a zero or oversized target.
    pub async fn on_adapter(
        instance: wgpu::Instance,
        adapter: &wgpu::Adapter,
        width: u32,
        height: u32,
        samples: Option<u32>,
    ) -> Result<Renderer, RenderError> {
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("portico"),
                required_limits: adapter.limits(),
                required_features: crate::material::block_features(adapter),
                ..Default::default()
            })
            .await?;
        let info = adapter.get_info();
        let samples = match samples {
            Some(n) => n,
            None if info.device_type == wgpu::DeviceType::Cpu => 1,
            None => crate::SAMPLES,
        };
        let layout = globals_layout(&device);
        let pipeline = create_pipeline(&device, &layout, samples);
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
        let targets = create_targets(&device, width, height, samples)?;
        let textured = Arc::new(textured::Textured::new(&device, &layout, samples));
        let materials = Arc::new(crate::material::Materials::new(&device, &layout, samples));
        tracing::info!(adapter = %info.name, backend = ?info.backend, width, height, samples, "renderer ready");
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
            materials,
            clear: SKY_COLOR,
            samples,
            held: Default::default(),
        })
    }

    /// The device frames are drawn with (to configure a surface for [`Renderer::render_into`]).
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// The queue frames are submitted to (to present a surface's texture).
    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
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

    /// Uploads a texture segment ([`portico_data::texture`]: a mip chain) to be sampled with
    /// `wrap` along u and v.
    ///
    /// # Errors
    /// [`RenderError::Texture`] for bytes that are not a texture segment or a texture larger
    /// than the device allows.
    pub fn upload_texture(
        &self,
        segment: &[u8],
        wrap: [portico_data::texture::Wrap; 2],
    ) -> Result<GpuTexture, RenderError> {
        self.uploader().upload_texture(segment, wrap)
    }

    /// GPU memory held now by the meshes and impostor boxes this renderer and its uploaders
    /// created and that are still alive, wherever they are kept (bytes).
    pub fn gpu_bytes_held(&self) -> u64 {
        self.held.bytes()
    }

    /// How this renderer's GPU holds textures ([`portico_data::texture::TexelFormat`]): BC1 /
    /// BC3 where the adapter takes BC textures, else ETC2 (opaque ones) where it takes those,
    /// else RGBA8. What a texture segment costs a client's cache follows it.
    pub fn texel_format(&self) -> TexelFormat {
        self.materials.texels()
    }

    /// Holds the textures uploaded from now on as `texels`, when the device offers it (BC,
    /// ETC2, or RGBA8 always); returns whether it does. By default BC where offered, else
    /// ETC2, else RGBA8 (`PORTICO_TEXELS=rgba8|bc|etc2` picks another the device offers).
    pub fn set_texel_format(&mut self, texels: TexelFormat) -> bool {
        let ok = crate::material::offers(&self.device, texels);
        if ok {
            self.materials.set_texels(texels);
        }
        ok
    }

    /// Samples per pixel (1, or 4 with MSAA).
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// A one-line description of the adapter and the samples per pixel, e.g.
    /// `Gl Cpu 'llvmpipe (LLVM 15.0.6, 256 bits)' ..., 1 sample per pixel`.
    pub fn adapter_info(&self) -> String {
        let i = &self.info;
        let s = if self.samples == 1 { "" } else { "s" };
        format!(
            "{:?} {:?} '{}' driver='{}' '{}', {} sample{s} per pixel",
            i.backend, i.device_type, i.name, i.driver, i.driver_info, self.samples
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
        self.targets = create_targets(&self.device, width, height, self.samples)?;
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
        upload_segment(&self.device, &self.held, segment_bytes)
    }

    /// A handle that uploads on other threads (e.g. the IO stage) while this renderer draws.
    pub fn uploader(&self) -> Uploader {
        Uploader {
            device: self.device.clone(),
            queue: self.queue.clone(),
            textured: self.textured.clone(),
            materials: self.materials.clone(),
            held: self.held.clone(),
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
        let target = self.targets.color_view.clone();
        let mut timing = scoped(&device, || {
            self.submit_frame(view_proj, draws, boxes, &target)
        })??;
        timing.cpu_submit_s = start.elapsed().as_secs_f64();
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        timing.total_s = start.elapsed().as_secs_f64();
        self.has_frame = true;
        Ok(timing)
    }

    /// Draws one frame of `draws` and `boxes` with `view_proj` into `target` (a surface's
    /// texture of [`crate::COLOR_FORMAT`] and the renderer's size): the window and the browser
    /// present frames this way, with no read-back. Natively it waits for the GPU, so
    /// [`FrameTiming::total_s`] is the frame's time as with [`Renderer::render`]; in a browser
    /// it returns once submitted (the page measures its frame interval). With MSAA the samples
    /// are resolved into `target`.
    ///
    /// # Errors
    /// [`RenderError::TooLarge`] when the draws outgrow the device's buffers; natively, a GPU
    /// validation or out-of-memory error as [`RenderError::Gpu`].
    pub fn render_into(
        &mut self,
        view_proj: Mat4,
        draws: &[Draw<'_>],
        boxes: &[&GpuImpostor],
        target: &wgpu::TextureView,
    ) -> Result<FrameTiming, RenderError> {
        let start = Instant::now();
        let device = self.device.clone();
        let mut timing = scoped(&device, || {
            self.submit_frame(view_proj, draws, boxes, target)
        })??;
        timing.cpu_submit_s = start.elapsed().as_secs_f64();
        // Natively the frame time feeds the cost model, so wait for the GPU as `render` does;
        // a page may not block, and measures its frame interval instead.
        #[cfg(not(target_arch = "wasm32"))]
        self.device.poll(wgpu::PollType::wait_indefinitely())?;
        timing.total_s = start.elapsed().as_secs_f64();
        Ok(timing)
    }

    /// A picture of `draws` and `boxes` from `camera` for people to look at (saved frames,
    /// contact sheets). With one sample per pixel (a CPU rasteriser) it is drawn at twice the
    /// width and height and filtered down — four samples per pixel, as MSAA gives on a GPU, so
    /// faces thinner than a pixel do not break into dashes; with MSAA it is the frame as drawn.
    /// It costs up to four frames' fill, so timed frames never use it. The targets keep the last
    /// timed frame.
    pub fn picture_with_boxes(
        &mut self,
        camera: &Camera,
        draws: &[Draw<'_>],
        boxes: &[&GpuImpostor],
    ) -> Result<image::RgbaImage, RenderError> {
        self.picture_view_proj(camera.view_proj(self.aspect()), draws, boxes)
    }

    /// [`Renderer::picture_with_boxes`] with an explicit world-to-clip matrix.
    pub fn picture_view_proj(
        &mut self,
        view_proj: Mat4,
        draws: &[Draw<'_>],
        boxes: &[&GpuImpostor],
    ) -> Result<image::RgbaImage, RenderError> {
        let (w, h) = (self.width, self.height);
        let max = self.device.limits().max_texture_dimension_2d;
        if self.samples > 1 || w * 2 > max || h * 2 > max {
            self.render_frame(view_proj, draws, boxes)?;
            return self.read_pixels();
        }
        let big = create_targets(&self.device, w * 2, h * 2, 1)?;
        let frame = std::mem::replace(&mut self.targets, big);
        let had_frame = self.has_frame;
        (self.width, self.height) = (w * 2, h * 2);
        let picture = self
            .render_frame(view_proj, draws, boxes)
            .and_then(|_| self.read_pixels());
        self.targets = frame;
        (self.width, self.height, self.has_frame) = (w, h, had_frame);
        Ok(image::imageops::resize(
            &picture?,
            w,
            h,
            image::imageops::FilterType::Triangle,
        ))
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

    /// Uploads the frame's uniforms and instances, encodes the pass into `target` and submits
    /// it.
    fn submit_frame(
        &mut self,
        view_proj: Mat4,
        draws: &[Draw<'_>],
        boxes: &[&GpuImpostor],
        target: &wgpu::TextureView,
    ) -> Result<FrameTiming, RenderError> {
        self.write_globals(view_proj);
        self.write_instances(draws)?;
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        let timing = {
            let mut pass = self.begin_pass(&mut encoder, target);
            self.encode_draws(&mut pass, draws, boxes)
        };
        self.queue.submit([encoder.finish()]);
        Ok(timing)
    }
}

/// In a browser nothing may block: errors go to the device's handler (the console) instead.
#[cfg(target_arch = "wasm32")]
pub(crate) fn scoped<T>(_device: &wgpu::Device, f: impl FnOnce() -> T) -> Result<T, RenderError> {
    Ok(f())
}

/// Runs `f` with out-of-memory and validation errors captured as [`RenderError::Gpu`] instead of
/// reaching wgpu's default handler, which panics.
#[cfg(not(target_arch = "wasm32"))]
pub(crate) fn scoped<T>(device: &wgpu::Device, f: impl FnOnce() -> T) -> Result<T, RenderError> {
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

pub(crate) fn extent(width: u32, height: u32) -> wgpu::Extent3d {
    wgpu::Extent3d {
        width,
        height,
        depth_or_array_layers: 1,
    }
}

/// `PORTICO_MSAA` as a sample count: 1 or 4; anything else is ignored with a warning.
#[cfg(not(target_arch = "wasm32"))]
fn msaa_from_env() -> Option<u32> {
    let v = std::env::var("PORTICO_MSAA").ok()?;
    match v.trim() {
        "1" => Some(1),
        "4" => Some(4),
        other => {
            tracing::warn!("PORTICO_MSAA={other} ignored: samples per pixel are 1 or 4");
            None
        }
    }
}
