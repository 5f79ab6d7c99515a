//! The frame loop's state (Funkhouser Ch. 6): arrivals into the byte-budgeted cache, the frame
//! decision over resident LODs and its draws, the observer and held set published to the IO
//! stage (§5.2.4), and the walk's summary. Also the colour and textured stand-in boxes of
//! Maciel's cluster traversal.

use super::{Model, Resident, WalkConfig, WalkSummary};
use crate::drive::{Ask, Event};
use crate::io::{IoStage, Payload};
use anyhow::{Context, Result};
use glam::Vec3;
use portico_client::cost::{CostModel, OnlineCost};
use portico_client::engine::catalogue::Start;
use portico_client::engine::holdings::Holdings;
use portico_client::frame::{Cached, Decider, Scene};
use portico_client::stats::{FrameRow, Series, write_csv};
use portico_client::view::{self, Viewpoint};
use portico_protocol::Observer;
use portico_render::{Draw, Renderer, StandIns};

/// The frame loop's state.
pub(super) struct Walker<'a> {
    pub(super) cfg: &'a WalkConfig,
    model: Model,
    /// A person's body for walk mode, and the cell pages taken so far (it looks at the
    /// objects again when one comes).
    body: portico_client::walk::Walker,
    pages: usize,
    /// The cache, what is held beside it, and what the last frame lacked.
    held: Holdings<Resident>,
    decider: Decider,
    cost: CostModel,
    pub(super) online: OnlineCost,
    consumed: u64,
    stand_ins: StandIns,
    latencies: Vec<f64>,
    failures: u64,
    database_changed: bool,
    segments_read: u64,
    bytes_read: u64,
    pub(super) last_frame_s: Option<f64>,
    /// Whether the next frame is also drawn as a picture ([`Renderer::picture_with_boxes`]).
    pub(super) want_picture: bool,
    /// The last picture, until it is saved.
    picture: Option<image::RgbaImage>,
    /// Seconds the last frame spent drawing its picture (not part of its frame time).
    pub(super) picture_s: f64,
    /// Most GPU memory the renderer's meshes and boxes held at the end of a frame.
    gpu_held_peak: u64,
}

impl<'a> Walker<'a> {
    /// The eye walked from `from` towards `to` over `dt` seconds ([`portico_client::walk`]):
    /// walls and furniture stop it, floors carry it, stairs lift it, holes drop it. Without
    /// cells (a model with none, a grid) it goes to `to`.
    pub(super) fn reset_walk(&mut self) {
        self.body.reset();
    }

    pub(super) fn walk(&mut self, from: Vec3, to: Vec3, dt: f32) -> Vec3 {
        let Some(graph) = self.model.graph.as_ref().filter(|g| !g.grid_fallback) else {
            return to;
        };
        self.body
            .gather_header(graph, &self.model.header, self.pages, from);
        self.body.step(graph, from, to - from, dt)
    }

    pub(super) fn new(cfg: &'a WalkConfig, model: Model, cost: CostModel) -> Walker<'a> {
        Walker {
            cfg,
            model,
            body: Default::default(),
            pages: 0,
            held: Holdings::new(portico_client::cache::split_budget(cfg.cache_bytes).0),
            decider: Decider::new(
                cfg.elision,
                cfg.budget_s,
                Some(cfg.policy.size_threshold_px),
            ),
            cost,
            online: OnlineCost::default(),
            consumed: 0,
            stand_ins: StandIns::default(),
            latencies: Vec::new(),
            failures: 0,
            database_changed: false,
            segments_read: 0,
            bytes_read: 0,
            last_frame_s: None,
            want_picture: false,
            picture: None,
            picture_s: 0.0,
            gpu_held_peak: 0,
        }
    }

    /// Moves everything the IO stage delivered into the cache (never above its budget).
    pub(super) fn take_arrivals(&mut self, io: &mut IoStage, row: &mut FrameRow) {
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
                    let shared = self.model.parts.clone();
                    let mut parts = shared.lock().unwrap_or_else(|e| e.into_inner());
                    // An atlas is charged what it holds on the GPU, not its PNG size; a
                    // compressed mesh what it decoded to; a texture joined from its parts is
                    // held under its head's id, the parts before it are not held at all.
                    let mut key = id;
                    let (value, charge) = match body {
                        Payload::Mesh(m) => {
                            let gpu = m.gpu_bytes();
                            (Resident::Mesh(m), bytes.max(gpu))
                        }
                        Payload::Stab(s, page) => {
                            // The instances its cell's page brought (paged manifest): known
                            // from this frame on.
                            if let Some(p) = page {
                                let m = &mut self.model;
                                Start::learn(&mut m.header, m.graph.as_mut(), &mut m.bounds, &p);
                                self.pages += 1;
                            }
                            (Resident::Stab(s), bytes)
                        }
                        Payload::Impostor(i) => {
                            let gpu = i.gpu_bytes();
                            (Resident::Impostor(i), bytes.max(gpu))
                        }
                        // What the GPU holds (RGBA8, or BC1 / BC3 where the adapter takes
                        // them): the coded image is dropped once decoded.
                        Payload::Texture(t) => {
                            let gpu = t.gpu_bytes();
                            (Resident::Texture(t), gpu)
                        }
                        Payload::Joined(head, t) => {
                            let gpu = t.gpu_bytes();
                            key = head;
                            (Resident::Texture(t), gpu)
                        }
                        Payload::Piece => {
                            self.held.piece_waits(&mut parts, id);
                            continue;
                        }
                        Payload::Unusable(head, e) => {
                            self.failures += 1;
                            tracing::warn!("io: {e}");
                            self.held.unusable(&mut parts, head);
                            continue;
                        }
                    };
                    let released = self.held.hold(&mut parts, key, value, charge);
                    row.released_segments += released.len() as u32;
                }
                Event::Answer(resp) => resp.evict.iter().for_each(|&id| self.held.cache.demote(id)),
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

    pub(super) fn observer(&self, eye: Vec3, dir: Vec3, motion: view::Motion) -> Observer {
        let aspect = self.cfg.size.0 as f32 / self.cfg.size.1.max(1) as f32;
        view::observer(
            eye,
            dir,
            motion,
            self.cfg.fovy,
            aspect,
            self.cfg.max_speed,
            self.cfg.max_turn,
        )
    }

    /// The frame decision ([`portico_client::frame`]), then its draws on the GPU: into the
    /// renderer's offscreen targets, or into `target` (a window's surface texture).
    pub(super) fn frame(
        &mut self,
        r: &mut Renderer,
        obs: &Observer,
        row: &mut FrameRow,
        target: Option<&portico_render::wgpu::TextureView>,
    ) -> Result<()> {
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
            &Cached(&self.held.cache, &scene),
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
        let parts = self.model.parts.clone();
        self.held
            .decided(&parts.lock().unwrap_or_else(|e| e.into_inner()), &d, &scene);

        if let Some(h) = &self.model.header.hierarchy {
            self.stand_ins.update(h, &d.boxes, r);
        }
        let header = &self.model.header;
        let cache = &self.held.cache;
        let mut draws = Vec::with_capacity(d.drawn.len() + d.boxes.len());
        for o in &d.drawn {
            if let Some(Resident::Mesh(mesh)) = cache.get(o.segment) {
                draws.push(Draw::of(header, o, mesh, |s| match cache.get(s) {
                    Some(Resident::Texture(t)) => Some(t),
                    _ => None,
                }));
            }
        }
        let textured = match &header.hierarchy {
            Some(h) => {
                let impostor = |s| match cache.get(s) {
                    Some(Resident::Impostor(i)) => Some(i),
                    _ => None,
                };
                self.stand_ins.draws(h, &d.boxes, impostor, &mut draws)
            }
            None => Vec::new(),
        };
        let timing = match target {
            Some(t) => r.render_into(view.camera.view_proj(r.aspect()), &draws, &textured, t)?,
            None => r.render_with_boxes(&view.camera, &draws, &textured)?,
        };
        row.render_s = timing.total_s;
        row.drawn_objects = timing.draws;
        row.drawn_triangles = timing.triangles;
        self.picture_s = 0.0;
        if std::mem::take(&mut self.want_picture) {
            let t = std::time::Instant::now();
            self.picture = Some(r.picture_with_boxes(&view.camera, &draws, &textured)?);
            self.picture_s = t.elapsed().as_secs_f64();
        }
        row.resident_segments = self.held.cache.len() as u32;
        row.resident_bytes = self.held.cache.bytes();
        self.gpu_held_peak = self.gpu_held_peak.max(r.gpu_bytes_held());
        Ok(())
    }

    fn parts(&self) -> std::sync::MutexGuard<'_, portico_client::parts::Parts> {
        self.model.parts.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub(super) fn publish(&self, io: &IoStage, observer: Observer) {
        let _ = io.state.send(Some(Ask {
            observer,
            // A held texture segment with its parts, and the parts waiting for the rest.
            held: self.held.held(&self.parts()),
            consumed: self.consumed,
            wants: None,
            lacking: self.held.lacking.clone(),
            incomplete: self.held.incomplete,
            at: std::time::Instant::now(),
        }));
    }

    pub(super) fn save_png(&mut self, r: &mut Renderer, frame: u64) -> Result<()> {
        let Some(out) = &self.cfg.out else {
            return Ok(());
        };
        let img = match self.picture.take() {
            Some(picture) => picture,
            None => r.read_pixels()?,
        };
        let p = out.join("frames").join(format!("frame_{frame:05}.png"));
        img.save(&p)
            .with_context(|| format!("writing {}", p.display()))
    }

    pub(super) fn finish(
        &self,
        r: &Renderer,
        rows: &[FrameRow],
        wall_s: f64,
    ) -> Result<WalkSummary> {
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
            cache_budget: self.cfg.cache_bytes,
            cache_peak_bytes: self.held.cache.peak_bytes(),
            gpu_held_peak_bytes: self.gpu_held_peak,
            evictions: self.held.cache.evictions(),
            first_complete: first_complete(rows),
            segments_read: self.segments_read,
            bytes_read: self.bytes_read,
            fetch_latency_s: Series::of(&self.latencies),
            io_failures: self.failures,
            database_changed: self.database_changed,
            cost_model: self.cost,
            cost_factor: self.online.factor(),
            wall_s,
            manifest: self.model.startup.0.clone(),
            startup_s: self.model.startup.1,
            startup_bytes: self.model.startup.2,
        };
        if let Some(out) = &self.cfg.out {
            write_csv(&out.join("frames.csv"), rows).context("writing frames.csv")?;
            let json = serde_json::to_vec_pretty(&s)?;
            std::fs::write(out.join("summary.json"), json).context("writing summary.json")?;
        }
        Ok(s)
    }
}

/// The first frame with visible objects and none of them skipped, and the bytes read until then.
fn first_complete(rows: &[FrameRow]) -> Option<super::FirstComplete> {
    let mut bytes = 0u64;
    rows.iter().find_map(|r| {
        bytes += r.read_bytes;
        (r.visible_objects > 0 && r.objects_skipped == 0).then_some(super::FirstComplete {
            frame: r.frame,
            bytes,
        })
    })
}
