//! The connected walkthrough client (Funkhouser Ch. 6): [`Session`] loads the model's
//! manifest and cell graph, starts the renderer and the IO stage, and draws one frame per
//! observer it is given, whether a path or a person at a window drives it.

use super::walker::Walker;
use super::{Model, WalkConfig, WalkSummary};
use crate::io::{IoConfig, IoStage};
use crate::net::Remote;
use crate::pages::PageBook;
use anyhow::{Context, Result};
use glam::Vec3;
use portico_client::elision::Algorithm;
use portico_client::engine::catalogue::Start;
use portico_client::parts::Parts;
use portico_client::stats::FrameRow;
use portico_client::view;
use portico_data::texture::TexelFormat;
use portico_protocol::{Observer, Policy};
use portico_render::Renderer;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// A connected client drawing one frame per observer it is given: the walk's frame loop
/// without the path, so that a path ([`walk`](super::walk)) or a person at a window drives it.
/// Dropping it stops the IO stage.
pub struct Session<'a> {
    walker: Walker<'a>,
    renderer: Renderer,
    io: Option<IoStage>,
    rows: Vec<FrameRow>,
    start: Instant,
}

impl<'a> Session<'a> {
    /// Loads the manifest and cell graph, starts the renderer (calibrating the cost model)
    /// and the IO stage. `cfg.path` is only used by [`Session::path_observer`].
    pub fn open(cfg: &'a WalkConfig) -> Result<Session<'a>> {
        let renderer = Renderer::new(cfg.size.0, cfg.size.1).context("starting the renderer")?;
        Self::open_on(cfg, renderer)
    }

    /// [`Session::open`] drawing with `renderer` (one made on a window's adapter, so that its
    /// frames can go into the window's surface: [`Session::frame_into`]).
    pub fn open_on(cfg: &'a WalkConfig, mut renderer: Renderer) -> Result<Session<'a>> {
        let start = Instant::now();
        let remote = Remote::new(&cfg.server, cfg.token.clone())?;
        let texels = renderer.texel_format();
        let (model, pages) = load_model(&remote, cfg.paged, texels)?;
        let cost = portico_render::calibrate(&mut renderer)?;
        let (cache_bytes, window) = portico_client::cache::split_budget(cfg.cache_bytes);
        let policy = Policy {
            impostors: cfg.elision == Algorithm::Impostors,
            cache_bytes,
            screen: [cfg.size.0, cfg.size.1],
            frame_time_s: cfg.budget_s as f32,
            block_textures: texels == TexelFormat::Block,
            ..cfg.policy
        };
        let io = IoStage::start(
            remote,
            renderer.uploader(),
            model.catalogue.clone(),
            model.parts.clone(),
            pages,
            IoConfig {
                policy,
                parallel: portico_client::defaults::PARALLEL,
                window,
                transport: cfg.transport,
            },
        )?;
        Ok(Session {
            walker: Walker::new(cfg, model, cost),
            renderer,
            io: Some(io),
            rows: Vec::new(),
            start,
        })
    }

    /// The observer on the configured path at `t` seconds.
    pub fn path_observer(&self, t: f64) -> Observer {
        let dt = self.walker.cfg.budget_s.max(1e-3);
        let (eye, dir) = self.walker.cfg.path.sample(t as f32);
        let (next, next_dir) = self.walker.cfg.path.sample((t + dt) as f32);
        let motion = view::Motion::between(eye, dir, next, next_dir, dt as f32);
        self.observer(eye, dir, motion)
    }

    /// The eye walked from `from` towards `to` over `dt` seconds, as a person walks
    /// ([`portico_client::walk`]).
    pub fn walk(&mut self, from: Vec3, to: Vec3, dt: f32) -> Vec3 {
        self.walker.walk(from, to, dt)
    }

    /// Forgets the walk's fall and cell (after flying, or a jump).
    pub fn reset_walk(&mut self) {
        self.walker.reset_walk();
    }

    /// An observer at `eye` looking along `dir`, moving with `motion`, with this client's field
    /// of view and announced speeds.
    pub fn observer(&self, eye: Vec3, dir: Vec3, motion: view::Motion) -> Observer {
        self.walker.observer(eye, dir, motion)
    }

    /// Takes what arrived, then visibility → elision → render for `obs` (shown at `t` seconds,
    /// the time of the frame's row), then tells the IO stage where the observer is. Never waits
    /// for the network.
    pub fn frame(&mut self, t: f64, obs: &Observer) -> Result<&FrameRow> {
        self.draw(t, obs, None)
    }

    /// [`Session::frame`] drawn into `target` (a surface texture of the renderer's size and
    /// [`portico_render::COLOR_FORMAT`]) instead of the offscreen targets: no read-back.
    pub fn frame_into(
        &mut self,
        t: f64,
        obs: &Observer,
        target: &portico_render::wgpu::TextureView,
    ) -> Result<&FrameRow> {
        self.draw(t, obs, Some(target))
    }

    /// The renderer (its device and queue present a window's surface).
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    fn draw(
        &mut self,
        t: f64,
        obs: &Observer,
        target: Option<&portico_render::wgpu::TextureView>,
    ) -> Result<&FrameRow> {
        let t0 = Instant::now();
        let frame = self.rows.len() as u64;
        let io = self.io.as_mut().context("the session is closed")?;
        let mut row = FrameRow {
            frame,
            t,
            ..FrameRow::default()
        };
        self.walker.take_arrivals(io, &mut row);
        self.walker
            .frame(&mut self.renderer, obs, &mut row, target)?;
        row.frame_s = (t0.elapsed().as_secs_f64() - self.walker.picture_s).max(0.0);
        self.walker.last_frame_s = Some(row.frame_s);
        self.walker.online.observe(row.predicted_s, row.render_s);
        self.walker.publish(io, *obs);
        self.rows.push(row);
        Ok(&self.rows[self.rows.len() - 1])
    }

    /// The last frame's pixels.
    pub fn image(&mut self) -> Result<image::RgbaImage> {
        Ok(self.renderer.read_pixels()?)
    }

    /// Draws the next frame a second time as a picture for [`Session::save_png`] (antialiased
    /// even on a CPU rasteriser; the time it takes is not part of the frame time).
    pub fn want_picture(&mut self) {
        self.walker.want_picture = true;
    }

    /// Saves the last frame as `OUT/frames/frame_NNNNN.png` (when there is an output directory):
    /// its picture when [`Session::want_picture`] asked for one, else the frame as drawn.
    pub fn save_png(&mut self, frame: u64) -> Result<()> {
        self.walker.save_png(&mut self.renderer, frame)
    }

    /// Stops the IO stage and returns the summary (and writes frames.csv and summary.json when
    /// there is an output directory).
    pub fn finish(mut self) -> Result<WalkSummary> {
        if let Some(io) = self.io.take() {
            io.stop();
        }
        let wall_s = self.start.elapsed().as_secs_f64();
        self.walker.finish(&self.renderer, &self.rows, wall_s)
    }
}

impl Drop for Session<'_> {
    fn drop(&mut self) {
        if let Some(io) = self.io.take() {
            io.stop();
        }
    }
}

/// The model from the core manifest when `paged` and the server has one, else from the whole
/// manifest and the cell graph.
fn load_model(
    remote: &Remote,
    paged: bool,
    texels: TexelFormat,
) -> Result<(Model, Option<PageBook>)> {
    let t0 = Instant::now();
    let core = if paged {
        crate::net::core_blocking(remote)?
    } else {
        None
    };
    let (start, how, bytes) = match core {
        Some(core) => {
            let bytes = portico_protocol::to_bincode(&core).map_or(0, |b| b.len() as u64);
            (Start::paged(core, texels), "paged", bytes)
        }
        None => {
            let (m, graph) = crate::net::model_blocking(remote)?;
            let bytes = portico_protocol::to_bincode(&m).map_or(0, |b| b.len() as u64)
                + graph
                    .as_ref()
                    .map_or(0, |g| portico_data::format::encode_segment(g).len() as u64);
            (Start::whole(m, graph, texels), "whole", bytes)
        }
    };
    let start = start.map_err(|e| anyhow::anyhow!("{}: {e}", remote.base()))?;
    let parts = Arc::new(Mutex::new(Parts::new(&start.header.textures)));
    let model = Model {
        header: start.header,
        graph: start.graph,
        bounds: start.bounds,
        database_id: start.database_id,
        model_triangles: start.model_triangles,
        catalogue: start.catalogue,
        parts,
        startup: (how.into(), t0.elapsed().as_secs_f64(), bytes),
    };
    Ok((model, start.pages.map(PageBook::new)))
}
