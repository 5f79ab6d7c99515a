//! `portico walk`: the walkthrough client's frame loop (Funkhouser Ch. 6, DESIGN §5).
//!
//! Each frame: take what the IO stage delivered into the byte-budgeted cache → observer from
//! the path → eye-to-object visibility → candidates → detail elision at the frame budget over
//! RESIDENT LODs only → render → publish the observer and the held set to the IO stage. The
//! loop never waits for the network: what has not arrived is skipped and counted (§5.2.4).

use crate::drive::{Ask, Event};
use crate::io::{Catalogue, IoConfig, IoStage, Payload};
use crate::net::Remote;
use anyhow::{Context, Result};
use glam::{Mat4, Vec3};
use portico_client::cache::ObjectCache;
use portico_client::cluster::Stand;
use portico_client::cost::{CostModel, OnlineCost};
use portico_client::elision::Algorithm;
use portico_client::frame::{Decider, Scene};
use portico_client::stats::{FrameRow, Series, write_csv};
use portico_client::view::{self, Viewpoint};
use portico_data::cells::{CellGraph, StabList};
use portico_data::format::Header;
use portico_data::geometry::encode_geometry;
use portico_data::hierarchy::{Hierarchy, colour_box};
use portico_data::path::CameraPath;
use portico_protocol::{Observer, Policy};
use portico_render::{Draw, GpuImpostor, GpuMesh, Renderer};
use serde::Serialize;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Everything `portico walk` can be told.
#[derive(Debug, Clone)]
pub struct WalkConfig {
    /// Server base URL.
    pub server: String,
    /// Bearer token, if the server wants one.
    pub token: Option<String>,
    /// The path to replay.
    pub path: CameraPath,
    /// Frame-time budget in seconds.
    pub budget_s: f64,
    /// Cache byte budget.
    pub cache_bytes: u64,
    /// Image size.
    pub size: (u32, u32),
    /// Detail elision algorithm.
    pub elision: Algorithm,
    /// Prefetch policy (its `cache_bytes`, `screen` and `frame_time_s` are set from the above).
    pub policy: Policy,
    /// Output directory (frames.csv, summary.json, PNGs).
    pub out: Option<PathBuf>,
    /// Save every n-th frame as PNG (0 = none).
    pub png_every: u64,
    /// Stop after this many frames.
    pub max_frames: Option<u64>,
    /// Hold each frame to the budget, as a display at that rate would (path time stays in step
    /// with wall time). Off: frames run back to back.
    pub pace: bool,
    /// Vertical field of view in radians.
    pub fovy: f32,
    /// Maximum observer speed (m/s) and turn rate (rad/s) announced to the server.
    pub max_speed: f32,
    /// See `max_speed`.
    pub max_turn: f32,
}

/// The result of a walk (`summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct WalkSummary {
    /// GPU adapter the frames were drawn on.
    pub adapter: String,
    /// Server URL.
    pub server: String,
    /// Model name and database id.
    pub model: String,
    /// Database id (content hash).
    pub database_id: String,
    /// Path kind and hash.
    pub path: String,
    /// Path hash.
    pub path_hash: String,
    /// Elision algorithm.
    pub elision: String,
    /// Frame budget (s).
    pub budget_s: f64,
    /// Frames drawn.
    pub frames: u64,
    /// Frame time.
    pub frame_s: Series,
    /// Render time alone.
    pub render_s: Series,
    /// Frames whose frame time exceeded the budget.
    pub frames_over_budget: u64,
    /// LODs skipped per frame.
    pub lods_skipped: Series,
    /// Objects skipped per frame.
    pub objects_skipped: Series,
    /// Objects visible per frame.
    pub visible_objects: Series,
    /// Triangles drawn per frame.
    pub drawn_triangles: Series,
    /// Triangles of the whole model at the finest LOD.
    pub model_triangles: u64,
    /// Mean drawn triangles as a fraction of the whole model.
    pub drawn_fraction: f64,
    /// Frames whose eye cell stab list was not resident.
    pub visibility_fallback_frames: u64,
    /// Cache budget (bytes).
    pub cache_budget: u64,
    /// Most bytes ever resident (never above the budget).
    pub cache_peak_bytes: u64,
    /// Segments released.
    pub evictions: u64,
    /// Segments and bytes read from the server.
    pub segments_read: u64,
    /// Bytes read.
    pub bytes_read: u64,
    /// Seconds from the prefetch request listing a segment to its arrival.
    pub fetch_latency_s: Series,
    /// IO failures (logged, not fatal).
    pub io_failures: u64,
    /// The server stopped serving the walk's database (rebuilt and reloaded): reading stopped
    /// there, and the rest of the walk drew what it held.
    #[serde(default)]
    pub database_changed: bool,
    /// Calibrated cost model.
    pub cost_model: CostModel,
    /// Final online correction factor.
    pub cost_factor: f64,
    /// Wall-clock seconds of the whole walk.
    pub wall_s: f64,
}

/// A cached segment.
enum Resident {
    Mesh(GpuMesh),
    Stab(Arc<StabList>),
    Impostor(GpuImpostor),
}

/// The model as the client knows it.
struct Model {
    header: Header,
    graph: Option<CellGraph>,
    bounds: Vec<portico_data::geometry::Aabb>,
    database_id: String,
    model_triangles: u64,
    catalogue: Catalogue,
}

/// Runs a walk; `on_frame(done, total)` reports progress.
pub fn walk(cfg: &WalkConfig, on_frame: &mut dyn FnMut(u64, u64)) -> Result<WalkSummary> {
    cfg.path
        .validate()
        .map_err(anyhow::Error::msg)
        .context("the walk path")?;
    let mut session = Session::open(cfg)?;
    let dt = cfg.budget_s.max(1e-3);
    let total = ((cfg.path.duration() as f64 / dt).ceil() as u64 + 1)
        .min(cfg.max_frames.unwrap_or(u64::MAX));
    if let Some(out) = &cfg.out {
        std::fs::create_dir_all(out.join("frames"))
            .with_context(|| format!("creating {}", out.display()))?;
    }
    let mut outcome = Ok(());
    for frame in 0..total {
        let t0 = Instant::now();
        let t = frame as f64 * dt;
        let obs = session.path_observer(t);
        if let Err(e) = session.frame(t, &obs) {
            outcome = Err(e);
            break;
        }
        on_frame(frame + 1, total);
        if cfg.png_every > 0 && frame % cfg.png_every == 0 {
            session.save_png(frame)?;
        }
        if cfg.pace {
            std::thread::sleep(Duration::from_secs_f64(dt).saturating_sub(t0.elapsed()));
        }
    }
    outcome?;
    session.finish()
}

/// A connected client drawing one frame per observer it is given: the walk's frame loop
/// without the path, so that a path ([`walk`]) or a person at a window drives it. Dropping it
/// stops the IO stage.
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
        let start = Instant::now();
        let remote = Remote::new(&cfg.server, cfg.token.clone())?;
        let model = load_model(&remote)?;
        let mut renderer =
            Renderer::new(cfg.size.0, cfg.size.1).context("starting the renderer")?;
        let cost = portico_render::calibrate(&mut renderer)?;
        let policy = Policy {
            impostors: cfg.elision == Algorithm::Impostors,
            cache_bytes: cfg.cache_bytes,
            screen: [cfg.size.0, cfg.size.1],
            frame_time_s: cfg.budget_s as f32,
            ..cfg.policy
        };
        let io = IoStage::start(
            remote,
            renderer.uploader(),
            model.catalogue.clone(),
            IoConfig {
                policy,
                parallel: 8,
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
        let (next, _) = self.walker.cfg.path.sample((t + dt) as f32);
        self.observer(eye, dir, (next - eye) / dt as f32)
    }

    /// An observer at `eye` looking along `dir`, moving at `velocity`, with this client's field
    /// of view and announced speeds.
    pub fn observer(&self, eye: Vec3, dir: Vec3, velocity: Vec3) -> Observer {
        self.walker.observer(eye, dir, velocity)
    }

    /// Takes what arrived, then visibility → elision → render for `obs` (shown at `t` seconds,
    /// the time of the frame's row), then tells the IO stage where the observer is. Never waits
    /// for the network.
    pub fn frame(&mut self, t: f64, obs: &Observer) -> Result<&FrameRow> {
        let t0 = Instant::now();
        let frame = self.rows.len() as u64;
        let io = self.io.as_mut().context("the session is closed")?;
        let mut row = FrameRow {
            frame,
            t,
            ..FrameRow::default()
        };
        self.walker.take_arrivals(io, &mut row);
        self.walker.frame(&mut self.renderer, obs, &mut row)?;
        row.frame_s = t0.elapsed().as_secs_f64();
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

    /// Saves the last frame as `OUT/frames/frame_NNNNN.png` (when there is an output directory).
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

fn load_model(remote: &Remote) -> Result<Model> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    rt.block_on(async {
        let m = remote.manifest().await?;
        let graph = match m.header.cells {
            Some(_) => Some(remote.cells().await?),
            None => None,
        };
        let bounds: Vec<_> = m.header.instances.iter().map(|i| i.bounds).collect();
        // Indices from the manifest are used as they are below: check them once.
        if let Some(h) = &m.header.hierarchy {
            h.check(&bounds)
                .map_err(|e| anyhow::anyhow!("{}: the manifest's hierarchy: {e}", remote.base()))?;
        }
        let model_triangles = m
            .header
            .instances
            .iter()
            .map(|i| {
                m.header
                    .lods_of(i)
                    .first()
                    .map_or(0, |l| l.triangles as u64)
            })
            .sum();
        let stabs = m
            .header
            .cells
            .as_ref()
            .map(|c| c.stab_segments.iter().copied().collect())
            .unwrap_or_default();
        let textures = m
            .header
            .hierarchy
            .iter()
            .flat_map(|h| &h.nodes)
            .filter(|n| n.texture != u32::MAX)
            .map(|n| (n.texture, (n.bounds, n.tile)))
            .collect();
        Ok(Model {
            catalogue: Catalogue {
                segments: m.segments,
                stabs,
                textures,
            },
            header: m.header,
            graph,
            bounds,
            database_id: m.database_id,
            model_triangles,
        })
    })
}

/// The frame loop's state.
struct Walker<'a> {
    cfg: &'a WalkConfig,
    model: Model,
    cache: ObjectCache<Resident>,
    decider: Decider,
    cost: CostModel,
    online: OnlineCost,
    consumed: u64,
    colour_boxes: std::collections::HashMap<u32, GpuMesh>,
    /// Segments larger than the whole cache: reported as held so no answer lists them again.
    too_big: std::collections::HashSet<u32>,
    latencies: Vec<f64>,
    failures: u64,
    database_changed: bool,
    segments_read: u64,
    bytes_read: u64,
    last_frame_s: Option<f64>,
}

impl<'a> Walker<'a> {
    fn new(cfg: &'a WalkConfig, model: Model, cost: CostModel) -> Walker<'a> {
        Walker {
            cfg,
            model,
            cache: ObjectCache::new(cfg.cache_bytes),
            decider: Decider::new(
                cfg.elision,
                cfg.budget_s,
                Some(cfg.policy.size_threshold_px),
            ),
            cost,
            online: OnlineCost::default(),
            consumed: 0,
            colour_boxes: std::collections::HashMap::new(),
            too_big: std::collections::HashSet::new(),
            latencies: Vec::new(),
            failures: 0,
            database_changed: false,
            segments_read: 0,
            bytes_read: 0,
            last_frame_s: None,
        }
    }

    /// Moves everything the IO stage delivered into the cache (never above its budget).
    fn take_arrivals(&mut self, io: &mut IoStage, row: &mut FrameRow) {
        while let Ok(a) = io.arrivals.try_recv() {
            self.consumed += 1;
            match a {
                Event::Segment {
                    id,
                    body,
                    bytes,
                    listed_at,
                } => {
                    row.read_segments += 1;
                    row.read_bytes += bytes;
                    self.segments_read += 1;
                    self.bytes_read += bytes;
                    self.latencies.push(listed_at.elapsed().as_secs_f64());
                    // An atlas is charged what it holds on the GPU, not its PNG size.
                    let (value, charge) = match body {
                        Payload::Mesh(m) => (Resident::Mesh(m), bytes),
                        Payload::Stab(s) => (Resident::Stab(s), bytes),
                        Payload::Impostor(i) => {
                            let gpu = i.gpu_bytes();
                            (Resident::Impostor(i), bytes.max(gpu))
                        }
                    };
                    match self.cache.insert(id, value, charge) {
                        Ok(released) => row.released_segments += released.len() as u32,
                        // Larger than the whole cache: never ask for it again.
                        Err(_) => {
                            self.too_big.insert(id);
                        }
                    }
                }
                Event::Answer(resp) => resp.evict.iter().for_each(|&id| self.cache.demote(id)),
                Event::Failed(e) => {
                    self.failures += 1;
                    tracing::warn!("io: {e}");
                }
                Event::Stale(e) => {
                    self.failures += 1;
                    self.database_changed = true;
                    tracing::warn!("io stopped: {e}");
                }
            }
        }
    }

    fn observer(&self, eye: Vec3, dir: Vec3, velocity: Vec3) -> Observer {
        let aspect = self.cfg.size.0 as f32 / self.cfg.size.1.max(1) as f32;
        view::observer(
            eye,
            dir,
            velocity,
            self.cfg.fovy,
            aspect,
            self.cfg.max_speed,
            self.cfg.max_turn,
        )
    }

    /// The frame decision ([`portico_client::frame`]), then its draws on the GPU.
    fn frame(&mut self, r: &mut Renderer, obs: &Observer, row: &mut FrameRow) -> Result<()> {
        let view = Viewpoint::of(
            obs,
            self.cfg.size,
            view::far_plane(&self.model.header.bounds),
        );
        let scene = Scene {
            header: &self.model.header,
            graph: self.model.graph.as_ref(),
            bounds: &self.model.bounds,
        };
        let cost = self.online.apply(&self.cost);
        let d = self.decider.decide(
            &scene,
            &view,
            &Cached(&self.cache, &scene),
            &cost,
            self.last_frame_s,
        );
        row.visibility_s = d.visibility_s;
        row.visible_cells = d.visible.cells;
        row.visible_objects = d.visible.objects.len() as u32;
        row.visibility_fallback = d.visible.fallback;
        row.elision_s = d.elision_s;
        row.predicted_s = d.frame.predicted_s;
        row.lods_skipped = d.frame.lods_skipped;
        row.objects_skipped = d.frame.objects_skipped;

        if let Some(h) = &self.model.header.hierarchy {
            make_colour_boxes(&mut self.colour_boxes, h, &d.boxes, r);
        }
        let header = &self.model.header;
        let cache = &self.cache;
        let mut draws = Vec::with_capacity(d.drawn.len() + d.boxes.len());
        for o in &d.drawn {
            if let Some(Resident::Mesh(mesh)) = cache.get(o.segment) {
                let inst = &header.instances[o.instance as usize];
                let color = header
                    .materials
                    .get(inst.material as usize)
                    .map_or([1.0; 4], |m| m.base_color);
                draws.push(Draw {
                    mesh,
                    transform: Mat4::from_cols_array(&inst.transform),
                    color,
                });
            }
        }
        let textured = match &header.hierarchy {
            Some(h) => stand_ins(cache, &self.colour_boxes, h, &d.boxes, &mut draws),
            None => Vec::new(),
        };
        let timing = r.render_with_boxes(&view.camera, &draws, &textured)?;
        row.render_s = timing.total_s;
        row.drawn_objects = timing.draws;
        row.drawn_triangles = timing.triangles;
        for &s in &d.touched {
            self.cache.touch(s);
        }
        row.resident_segments = self.cache.len() as u32;
        row.resident_bytes = self.cache.bytes();
        Ok(())
    }

    fn publish(&self, io: &IoStage, observer: Observer) {
        let _ = io.state.send(Some(Ask {
            observer,
            held: self
                .cache
                .ids()
                .chain(self.too_big.iter().copied())
                .collect(),
            consumed: self.consumed,
            wants: None,
            at: std::time::Instant::now(),
        }));
    }

    fn save_png(&self, r: &mut Renderer, frame: u64) -> Result<()> {
        let Some(out) = &self.cfg.out else {
            return Ok(());
        };
        let img = r.read_pixels()?;
        let p = out.join("frames").join(format!("frame_{frame:05}.png"));
        img.save(&p)
            .with_context(|| format!("writing {}", p.display()))
    }

    fn finish(&self, r: &Renderer, rows: &[FrameRow], wall_s: f64) -> Result<WalkSummary> {
        let col =
            |f: &dyn Fn(&FrameRow) -> f64| Series::of(&rows.iter().map(f).collect::<Vec<_>>());
        let drawn = col(&|r| r.drawn_triangles as f64);
        let s = WalkSummary {
            adapter: r.adapter_info(),
            server: self.cfg.server.clone(),
            model: self.model.header.name.clone(),
            database_id: self.model.database_id.clone(),
            path: self.cfg.path.kind.clone(),
            path_hash: format!("{:016x}", self.cfg.path.hash()),
            elision: self.cfg.elision.to_string(),
            budget_s: self.cfg.budget_s,
            frames: rows.len() as u64,
            frame_s: col(&|r| r.frame_s),
            render_s: col(&|r| r.render_s),
            frames_over_budget: rows
                .iter()
                .filter(|r| r.frame_s > self.cfg.budget_s)
                .count() as u64,
            lods_skipped: col(&|r| r.lods_skipped as f64),
            objects_skipped: col(&|r| r.objects_skipped as f64),
            visible_objects: col(&|r| r.visible_objects as f64),
            drawn_triangles: drawn,
            model_triangles: self.model.model_triangles,
            drawn_fraction: drawn.mean / self.model.model_triangles.max(1) as f64,
            visibility_fallback_frames: rows.iter().filter(|r| r.visibility_fallback).count()
                as u64,
            cache_budget: self.cache.budget(),
            cache_peak_bytes: self.cache.peak_bytes(),
            evictions: self.cache.evictions(),
            segments_read: self.segments_read,
            bytes_read: self.bytes_read,
            fetch_latency_s: Series::of(&self.latencies),
            io_failures: self.failures,
            database_changed: self.database_changed,
            cost_model: self.cost,
            cost_factor: self.online.factor(),
            wall_s,
        };
        if let Some(out) = &self.cfg.out {
            write_csv(&out.join("frames.csv"), rows).context("writing frames.csv")?;
            let json = serde_json::to_vec_pretty(&s)?;
            std::fs::write(out.join("summary.json"), json).context("writing summary.json")?;
        }
        Ok(s)
    }
}

/// What the walker's cache holds, as the frame decision asks it.
struct Cached<'a>(&'a ObjectCache<Resident>, &'a Scene<'a>);

impl portico_client::frame::Resident for Cached<'_> {
    fn has(&self, id: u32) -> bool {
        self.0.contains(id)
    }

    fn stab(&self, cell: u32) -> Option<Arc<StabList>> {
        match self.0.get(self.1.stab_segment(cell)?) {
            Some(Resident::Stab(l)) => Some(l.clone()),
            _ => None,
        }
    }
}

/// Makes the average-colour boxes of `boxes` that do not exist yet (their colours are in the
/// header: nothing to fetch) and frees the others, so they never add up outside the cache.
fn make_colour_boxes(
    made: &mut std::collections::HashMap<u32, GpuMesh>,
    h: &Hierarchy,
    boxes: &[(u32, Stand)],
    r: &Renderer,
) {
    let wanted: std::collections::HashSet<u32> = boxes.iter().map(|b| b.0).collect();
    made.retain(|n, _| wanted.contains(n));
    for &(n, _) in boxes {
        if let std::collections::hash_map::Entry::Vacant(e) = made.entry(n) {
            let node = &h.nodes[n as usize];
            let mesh = encode_geometry(&colour_box(&node.bounds, &node.face_colors));
            if let Ok(gpu) = r.upload(&mesh) {
                e.insert(gpu);
            }
        }
    }
}

/// Adds the average-colour boxes to `draws` and returns the resident textured boxes; the
/// textures used count as touched (§5.2.3).
fn stand_ins<'c>(
    cache: &'c ObjectCache<Resident>,
    colour: &'c std::collections::HashMap<u32, GpuMesh>,
    h: &Hierarchy,
    boxes: &[(u32, Stand)],
    draws: &mut Vec<Draw<'c>>,
) -> Vec<&'c GpuImpostor> {
    let mut textured = Vec::new();
    for &(n, stand) in boxes {
        let t = h.nodes[n as usize].texture;
        match (stand, cache.get(t)) {
            (Stand::Textured, Some(Resident::Impostor(i))) => textured.push(i),
            _ => {
                if let Some(mesh) = colour.get(&n) {
                    draws.push(Draw {
                        mesh,
                        transform: Mat4::IDENTITY,
                        color: [1.0; 4],
                    });
                }
            }
        }
    }
    textured
}
