//! The page's frame loop (Funkhouser Ch. 6, one thread): take what the IO stage brought into
//! the byte-budgeted cache → move the observer → the frame decision over resident LODs
//! ([`portico_client::frame`]) → draw into the canvas's surface → tell the IO stage where the
//! observer is. It never waits for the network: what has not arrived is skipped and counted.

use crate::input::Input;
use crate::io::{Arrival, Io};
use glam::Vec3;
use portico_client::cost::CostModel;
use portico_client::elision::Algorithm;
use portico_client::engine::catalogue::{Kind, Start, decode_stab, plain_geometry};
use portico_client::engine::holdings::Holdings;
use portico_client::frame::{Cached, Decider, Scene};
use portico_client::navigate::Navigator;
use portico_client::parts::{Joined, Parts};
use portico_client::pick::{self, Picked};
use portico_client::view::{self, Viewpoint};
use portico_client::walk::{Gait, Walker};
use portico_data::cells::{CellGraph, StabList};
use portico_data::format::Header;
use portico_data::geometry::Aabb;
use portico_data::path::CameraPath;
use portico_protocol::Observer;
use portico_render::{Draw, GpuImpostor, GpuMesh, GpuTexture, Renderer, StandIns};
use serde::Serialize;
use std::sync::Arc;

pub use portico_client::defaults::{MAX_SPEED as SPEED, MAX_TURN as TURN};

/// A resident segment.
pub enum Resident {
    Mesh(GpuMesh),
    Stab(Arc<StabList>),
    Texture(GpuTexture),
    /// A cluster's textured box (Maciel & Shirley's impostor), from its atlas tile.
    Impostor(GpuImpostor),
}

impl portico_client::frame::MaybeStab for Resident {
    fn stab_list(&self) -> Option<&Arc<StabList>> {
        match self {
            Resident::Stab(l) => Some(l),
            _ => None,
        }
    }
}

/// The model as the manifest describes it.
pub struct Model {
    pub header: Header,
    pub graph: Option<CellGraph>,
    pub bounds: Vec<Aabb>,
    /// The model's standard tour (or orbit and fly-through), where the view starts.
    pub tour: Option<CameraPath>,
    /// Texture segments cut into parts, and the parts that came.
    pub parts: Parts,
}

/// What the overlay shows and the tests read (`viewer.stats()` in JavaScript).
#[derive(Debug, Clone, Default, Serialize)]
pub struct Stats {
    /// Frames drawn.
    pub frames: u64,
    /// The last frame's interval, milliseconds (what the person sees).
    pub frame_ms: f64,
    /// Mean frame interval over the last 60 frames, milliseconds.
    pub mean_frame_ms: f64,
    /// Bytes resident in the cache, and its budget.
    pub resident_bytes: u64,
    /// The cache's byte budget: seven eighths of [`Stats::budget_bytes`].
    pub cache_budget: u64,
    /// The whole byte budget asked for (`?cache_mb=`, 64 MiB by default): the cache and, for
    /// the IO stage's reads in flight, an eighth.
    pub budget_bytes: u64,
    /// Most bytes the cache ever held.
    pub cache_peak_bytes: u64,
    /// Most GPU memory the renderer's meshes held at the end of a frame, wherever they were
    /// kept (the cache or anywhere else): what the budget must bound.
    pub gpu_held_peak_bytes: u64,
    /// Segments that arrived intact but could not be used (a mesh over the device's limits,
    /// a compressed segment that does not decode): reported as held so that they are not sent
    /// again.
    pub unusable_segments: u64,
    /// Segments and bytes received (wire).
    pub segments_received: u64,
    /// See [`Stats::segments_received`].
    pub bytes_received: u64,
    /// Objects visible in the last frame, and how many of them had nothing resident.
    pub visible_objects: u32,
    /// See [`Stats::visible_objects`].
    pub objects_skipped: u32,
    /// LODs drawn coarser than the elision wanted, last frame.
    pub lods_skipped: u32,
    /// Triangles drawn, last frame.
    pub drawn_triangles: u64,
    /// The first frame with visible objects and none skipped, and its time since the page
    /// began loading (ms, the page's `performance.now()`).
    pub first_complete_frame: Option<u64>,
    /// See [`Stats::first_complete_frame`].
    pub first_complete_ms: Option<f64>,
    /// Prefetch answers received (one request in flight at a time, asked again once the
    /// observer has moved on: [`portico_client::engine::pull::Reask`]).
    pub answers: u64,
    /// Bytes of prefetch requests and answers (bodies), beside [`Stats::bytes_received`].
    pub prefetch_bytes: u64,
    /// Requests that failed.
    pub failures: u64,
    /// The last failure.
    pub last_error: Option<String>,
    /// The eye and view direction.
    pub eye: [f32; 3],
    /// See [`Stats::eye`].
    pub dir: [f32; 3],
    /// The backend wgpu draws with (`Gl` is WebGL2, `BrowserWebGpu` is WebGPU).
    pub backend: String,
    /// Whether the standard tour drives the view.
    pub touring: bool,
    /// `walk` or `fly` (while the tour does not drive the view).
    pub gait: &'static str,
    /// The last object picked (a click, a tap or `pick()`).
    pub picked: Option<Picked>,
    /// How segments come now: `stream` (pushed) or `pull` (HTTP).
    pub transport: &'static str,
    /// Stream sessions opened so far.
    pub stream_sessions: u64,
    /// How the GPU holds textures: `Block` (BC1 / BC3, where the adapter takes them), `Etc2`
    /// (opaque ones, where it takes ETC2 and not BC) or `Rgba8`.
    pub texel_format: String,
    /// How the page started: `paged` (the core manifest, then each cell's page with its stab
    /// list) or `whole` (the whole manifest and cell graph).
    pub manifest: String,
    /// The elision the page runs (`optimize` or `impostors`).
    pub elision: String,
    /// Cluster boxes the last frame drew (Maciel's traversal), and of them textured ones.
    pub boxes_drawn: u32,
    /// See [`Stats::boxes_drawn`].
    pub textured_boxes_drawn: u32,
    /// Frames that drew cluster boxes (where detail was missing or far).
    pub frames_with_boxes: u64,
    /// Bytes of what it read before its first frame (decoded: the core, or the whole manifest
    /// and cell graph).
    pub startup_bytes: u64,
    /// Texture segments decoded and uploaded so far.
    pub texture_segments: u64,
    /// Milliseconds the page spent on them (image decode, mip chain, BC re-coding, upload):
    /// time taken from its one thread between frames.
    pub texture_ms: f64,
    /// Bytes of RGBA8 texels those segments decoded to.
    pub texture_texel_bytes: u64,
    /// Bytes they hold on the GPU (a quarter or an eighth of the texels when block-compressed).
    pub texture_gpu_bytes: u64,
}

/// The viewer's state between frames.
pub struct Viewer {
    pub renderer: Renderer,
    pub surface: wgpu::Surface<'static>,
    pub config: wgpu::SurfaceConfiguration,
    pub model: Model,
    /// The cache, what is held beside it (larger than the cache, or unusable here), and what
    /// the last frame lacked.
    pub held: Holdings<Resident>,
    pub decider: Decider,
    pub cost: CostModel,
    pub io: Io,
    /// The colour boxes of clusters the traversal draws as boxes.
    pub stand_ins: StandIns,
    pub nav: Navigator,
    /// The tour and the time (s) it started, while it drives the view.
    pub touring: Option<f64>,
    pub stats: Stats,
    /// Walking or flying, and the walking body's state.
    pub gait: Gait,
    pub walker: Walker,
    /// Cell pages taken so far (the walker looks at the objects again when one comes).
    pub pages_learned: usize,
    /// The last frame's world-to-clip matrix (for picks).
    pub view_proj: glam::Mat4,
    /// The instances drawn in the last frame (for the mini-map and picks), with the LOD and
    /// segment each was drawn with.
    pub drawn: Vec<(u32, usize, u32)>,
    /// Recent frame intervals (ms), for the mean.
    pub recent: std::collections::VecDeque<f64>,
    pub last_t: Option<f64>,
}

impl Viewer {
    /// Takes the IO stage's arrivals into the cache (never above its budget).
    fn take_arrivals(&mut self) {
        for a in self.io.take() {
            match a {
                Arrival::Segment(id, bytes, _listed, page) => {
                    // The instances its cell's page brought (a paged start): known from this
                    // frame on.
                    if let Some(p) = page {
                        let m = &mut self.model;
                        Start::learn(&mut m.header, m.graph.as_mut(), &mut m.bounds, &p);
                        self.pages_learned += 1;
                    }
                    self.stats.segments_received += 1;
                    self.stats.bytes_received += bytes.len() as u64;
                    // A part of a texture segment waits for the rest; the last one makes the
                    // whole, held under its head's id.
                    let (id, bytes) = match self.model.parts.join(id, bytes) {
                        Joined::Whole(id, bytes) => (id, bytes),
                        // Decoded and held (or found unusable) right below.
                        Joined::Complete(head, bytes) => (head, bytes),
                        Joined::Waiting => {
                            self.held.piece_waits(&mut self.model.parts, id);
                            continue;
                        }
                    };
                    let made = match self.io.kind(id) {
                        Kind::Stab => decode_stab(id, &bytes)
                            .map(|l| (Resident::Stab(Arc::new(l)), bytes.len() as u64)),
                        Kind::Texture(wrap) => {
                            let t0 = web_time::Instant::now();
                            let made = self.renderer.upload_texture(&bytes, wrap);
                            if let Ok(t) = &made {
                                let s = &mut self.stats;
                                s.texture_segments += 1;
                                s.texture_ms += t0.elapsed().as_secs_f64() * 1e3;
                                s.texture_texel_bytes += t.texel_bytes();
                                s.texture_gpu_bytes += t.gpu_bytes();
                            }
                            made.map(|t| {
                                // What the GPU holds: the coded image is dropped.
                                let charge = t.gpu_bytes();
                                (Resident::Texture(t), charge)
                            })
                            .map_err(|e| format!("segment {id}: {e}"))
                        }
                        // A cluster's textured box: charged what the GPU holds.
                        Kind::Impostor(bounds, tile) => self
                            .renderer
                            .upload_impostor(&bytes, &bounds, tile)
                            .map(|i| {
                                let charge = i.gpu_bytes().max(bytes.len() as u64);
                                (Resident::Impostor(i), charge)
                            })
                            .map_err(|e| format!("segment {id}: {e}")),
                        // A compressed segment is decoded here (the page has one thread), after
                        // its counts are checked against its LOD record.
                        Kind::Geometry(expected) => plain_geometry(id, &bytes, expected)
                            .and_then(|plain| {
                                self.renderer
                                    .upload(&plain)
                                    .map_err(|e| format!("segment {id}: {e}"))
                            })
                            .map(|m| {
                                let charge = m.gpu_bytes().max(bytes.len() as u64);
                                (Resident::Mesh(m), charge)
                            }),
                    };
                    match made {
                        // What the cache released leaves the held set the next frame reports.
                        Ok((value, charge)) => {
                            self.held.hold(&mut self.model.parts, id, value, charge);
                        }
                        Err(e) => {
                            self.held.unusable(&mut self.model.parts, id);
                            self.stats.unusable_segments += 1;
                            self.fail(e);
                        }
                    }
                }
                Arrival::Release(ids) => {
                    self.stats.answers += 1;
                    ids.iter().for_each(|&id| self.held.cache.demote(id));
                }
                Arrival::Failed(e) | Arrival::Stale(e) => self.fail(e),
            }
        }
    }

    fn fail(&mut self, e: String) {
        self.stats.failures += 1;
        web_sys::console::warn_1(&format!("portico: {e}").into());
        self.stats.last_error = Some(e);
    }

    /// Resizes the surface and the renderer's targets to `width` x `height` device pixels.
    pub fn resize(&mut self, width: u32, height: u32) {
        if (width, height) == (self.config.width, self.config.height) || width == 0 || height == 0 {
            return;
        }
        self.config.width = width;
        self.config.height = height;
        self.surface.configure(self.renderer.device(), &self.config);
        if let Err(e) = self.renderer.resize(width, height) {
            self.fail(format!("resize to {width}x{height}: {e}"));
        }
    }

    /// One frame at `now_ms` (the page's clock): arrivals, movement, decision, draw, request.
    pub fn frame(&mut self, now_ms: f64, input: &mut Input) {
        let t = now_ms / 1e3;
        let dt = self.last_t.map_or(0.0, |l| (t - l).clamp(0.0, 0.25));
        if let Some(l) = self.last_t {
            self.stats.frame_ms = (t - l) * 1e3;
            self.recent.push_back(self.stats.frame_ms);
            if self.recent.len() > 60 {
                self.recent.pop_front();
            }
            self.stats.mean_frame_ms = self.recent.iter().sum::<f64>() / self.recent.len() as f64;
        }
        self.last_t = Some(t);
        self.take_arrivals();

        if std::mem::take(&mut input.toggle_tour) {
            self.touring = match self.touring {
                Some(_) => None,
                None => self.model.tour.as_ref().map(|_| t),
            };
        }
        if std::mem::take(&mut input.touched) {
            self.touring = None;
        }
        if std::mem::take(&mut input.toggle_gait) {
            self.gait = match self.gait {
                Gait::Walk => Gait::Fly,
                Gait::Fly => Gait::Walk,
            };
            self.walker.reset();
        }
        if let Some(at) = input.click.take() {
            self.pick(at);
        }
        let (eye, dir, motion) = match (self.touring, &self.model.tour) {
            (Some(start), Some(tour)) => {
                let s = ((t - start) as f32) % tour.duration().max(1e-3);
                let (eye, dir) = tour.sample(s);
                let (next, next_dir) = tour.sample(s + 0.05);
                self.nav = navigator(eye, dir);
                (
                    eye,
                    dir,
                    view::Motion::between(eye, dir, next, next_dir, 0.05),
                )
            }
            _ => {
                let before = self.nav.dir();
                let velocity = self.walk(input, dt as f32, now_ms);
                let (eye, dir) = (self.nav.eye, self.nav.dir());
                let turn = view::Motion::between(eye, before, eye, dir, dt as f32).turn;
                (eye, dir, view::Motion { velocity, turn })
            }
        };
        self.stats.touring = self.touring.is_some();
        let size = (self.config.width, self.config.height);
        let aspect = size.0 as f32 / size.1.max(1) as f32;
        let obs = view::observer(
            eye,
            dir,
            motion,
            portico_client::defaults::fov_y(),
            aspect,
            SPEED,
            TURN,
        );
        self.draw(&obs, size, now_ms);
        // A held texture segment with its parts, and the parts waiting for the rest.
        let held = self.held.held(&self.model.parts);
        let incomplete = self.held.incomplete;
        self.io.pump(
            obs,
            held.into_iter(),
            std::mem::take(&mut self.held.lacking),
            incomplete,
        );
        self.stats.transport = self.io.transport();
        self.stats.stream_sessions = self.io.sessions();
        self.stats.prefetch_bytes = self.io.prefetch_bytes();
        self.stats.eye = eye.to_array();
        self.stats.dir = dir.to_array();
        self.stats.resident_bytes = self.held.cache.bytes();
        self.stats.cache_peak_bytes = self.held.cache.peak_bytes();
        self.stats.gpu_held_peak_bytes = self
            .stats
            .gpu_held_peak_bytes
            .max(self.renderer.gpu_bytes_held());
    }

    fn draw(&mut self, obs: &Observer, size: (u32, u32), now_ms: f64) {
        let view = Viewpoint::of(obs, size, view::far_plane(&self.model.header.bounds));
        let scene = Scene {
            header: &self.model.header,
            graph: self.model.graph.as_ref(),
            bounds: &self.model.bounds,
        };
        let last = (self.stats.frames > 0).then_some(self.stats.frame_ms / 1e3);
        let d = self.decider.decide(
            &scene,
            &view,
            &Cached(&self.held.cache, &scene),
            &self.cost,
            last,
        );
        self.stats.visible_objects = d.visible.objects.len() as u32;
        self.stats.objects_skipped = d.frame.objects_skipped;
        self.stats.lods_skipped = d.frame.lods_skipped;
        self.held.decided(&self.model.parts, &d, &scene);
        if self.stats.first_complete_frame.is_none()
            && !d.visible.objects.is_empty()
            && d.frame.objects_skipped == 0
        {
            self.stats.first_complete_frame = Some(self.stats.frames);
            self.stats.first_complete_ms = Some(now_ms);
        }
        // What a pick reads: the drawn list and the view it was drawn in, set together.
        self.view_proj = view.camera.view_proj(size.0 as f32 / size.1.max(1) as f32);
        let header = &self.model.header;
        let mut draws = Vec::with_capacity(d.drawn.len());
        self.drawn.clear();
        for o in &d.drawn {
            if let Some(Resident::Mesh(mesh)) = self.held.cache.get(o.segment) {
                self.drawn.push((o.instance, o.lod, o.segment));
                let cache = &self.held.cache;
                draws.push(Draw::of(header, o, mesh, |s| match cache.get(s) {
                    Some(Resident::Texture(t)) => Some(t),
                    _ => None,
                }));
            }
        }
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            other => {
                // Lost or outdated: configure again and draw the next frame.
                tracing_free_warn(&format!("surface: {other:?}"));
                self.surface.configure(self.renderer.device(), &self.config);
                return;
            }
        };
        let target = frame.texture.create_view(&wgpu::TextureViewDescriptor {
            format: Some(portico_render::COLOR_FORMAT),
            ..Default::default()
        });
        let view_proj = self.view_proj;
        // The clusters the traversal drew as boxes: textured where the atlas tile is
        // resident, else in their colours.
        let textured = match &header.hierarchy {
            Some(h) => {
                self.stand_ins.update(h, &d.boxes, &self.renderer);
                let cache = &self.held.cache;
                let impostor = |s| match cache.get(s) {
                    Some(Resident::Impostor(i)) => Some(i),
                    _ => None,
                };
                self.stand_ins.draws(h, &d.boxes, impostor, &mut draws)
            }
            None => Vec::new(),
        };
        self.stats.boxes_drawn = d.boxes.len() as u32;
        self.stats.frames_with_boxes += u64::from(!d.boxes.is_empty());
        self.stats.textured_boxes_drawn = textured.len() as u32;
        let drawn = self
            .renderer
            .render_into(view_proj, &draws, &textured, &target);
        drop((draws, textured));
        match drawn {
            Ok(timing) => self.stats.drawn_triangles = timing.triangles,
            Err(e) => self.fail(format!("drawing: {e}")),
        }
        self.renderer.queue().present(frame);
        self.stats.frames += 1;
    }
}

impl Viewer {
    /// Moves the navigator by what is held for `dt` seconds, walking or flying; returns the
    /// velocity (m/s). Walking, the navigator's move is the walker's wish: walls stop it,
    /// floors carry it, stairs lift it, holes drop it.
    fn walk(&mut self, input: &Input, dt: f32, now_ms: f64) -> Vec3 {
        let before = self.nav.eye;
        let flown = input.apply(&mut self.nav, dt, now_ms);
        let graph = self.model.graph.as_ref().filter(|g| !g.grid_fallback);
        let (Gait::Walk, Some(graph)) = (self.gait, graph) else {
            self.stats.gait = "fly";
            return flown;
        };
        self.stats.gait = "walk";
        let header = &self.model.header;
        self.walker
            .gather_header(graph, header, self.pages_learned, before);
        self.nav.eye = self.walker.step(graph, before, self.nav.eye - before, dt);
        // The velocity the server's lookahead extrapolates: the walk's, along the floor (a step
        // taken in one frame is not a climb at metres a second).
        let moved = self.nav.eye - before;
        if dt > 0.0 {
            Vec3::new(moved.x, 0.0, moved.z) / dt
        } else {
            Vec3::ZERO
        }
    }

    /// Picks the object drawn at `ndc` (-1..1, y up) of the last frame; keeps it in the stats.
    pub fn pick(&mut self, ndc: [f32; 2]) -> Option<Picked> {
        let picked = self.picked_at(ndc);
        self.stats.picked = picked.clone();
        picked
    }

    fn picked_at(&self, ndc: [f32; 2]) -> Option<Picked> {
        let (origin, dir) = pick::ray(&self.view_proj, ndc)?;
        let header = &self.model.header;
        let boxes = self
            .drawn
            .iter()
            .filter_map(|&(i, _, _)| Some((i, &header.instances.get(i as usize)?.bounds)));
        let (instance, distance) = pick::pick(boxes, origin, dir)?;
        let &(_, lod, segment) = self.drawn.iter().find(|d| d.0 == instance)?;
        let bytes = match self.held.cache.get(segment) {
            Some(Resident::Mesh(m)) => m.gpu_bytes(),
            _ => 0,
        };
        Picked::of(header, instance, lod, bytes, distance)
    }
}

fn tracing_free_warn(msg: &str) {
    web_sys::console::warn_1(&msg.into());
}

/// The navigator at `eye` looking along `dir`, pitch included, at the viewer's speeds.
pub fn navigator(eye: Vec3, dir: Vec3) -> Navigator {
    let mut nav = Navigator::new(eye, dir, SPEED, TURN);
    nav.pitch = dir.normalize_or(Vec3::X).y.clamp(-1.0, 1.0).asin();
    nav
}

/// The elision the viewer runs by default: cost/benefit optimisation at the frame budget
/// (§4.2.3); `?elision=impostors` runs Maciel's cluster traversal, far clusters drawn as
/// their textured boxes.
pub const ELISION: Algorithm = Algorithm::Optimize;
