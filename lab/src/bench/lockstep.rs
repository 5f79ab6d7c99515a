//! The benchmark in progress: every run's state, the frames drawn in lockstep (Regular first,
//! the reference of every other run; Yuan 2001 §5.3.2), each frame's timed decision and render
//! (Funkhouser 1993 §4.2.4), its fidelity score against the reference (Yuan 2001 §5.3), and each
//! run's summary.

use super::depth::DepthBuffer;
use super::fidelity::{self, FidelityAccumulator, RefPoint};
use super::scene::Scene;
use super::summary::{machine, self_test};
use super::{
    BenchConfig, BenchSummary, CriticalSummary, FrameRecord, ModelInfo, Parameters, PathInfo,
    RunKind, RunSummary,
};
use crate::drawn::DrawnLog;
use anyhow::{Context, Result, bail};
use glam::Mat4;
use image::RgbaImage;
use portico_client::cluster::Stand;
use portico_client::cost::{CostModel, OnlineCost};
use portico_client::elision::Algorithm;
use portico_client::frame::Decider;
use portico_client::stats::Series;
use portico_client::view::{self, NEAR};
use portico_render::GpuImpostor;
use portico_render::{Draw, Renderer};
use std::time::Instant;

/// Where frame `i` is seen from.
struct FrameView {
    frame: u64,
    t: f64,
    view: view::Viewpoint,
}

/// One run's state across frames.
struct Run {
    kind: RunKind,
    /// The name in reports: the kind's, or `streamed <run>` for a replay.
    name: String,
    decider: Decider,
    online: OnlineCost,
    last_frame_s: Option<f64>,
    fidelity: FidelityAccumulator,
    rows: Vec<FrameRecord>,
}

impl RunKind {
    /// The frame decision's algorithm for this run: Regular is every object at its finest LOD
    /// with everything resident (`none`), the reference the others are scored against.
    fn algorithm(self) -> Algorithm {
        match self {
            RunKind::Regular => Algorithm::None,
            RunKind::Coarsest => Algorithm::Coarsest,
            RunKind::Impostors => Algorithm::Impostors,
            RunKind::Elision(a) => a,
            // Replays decide nothing: they draw what the log says.
            RunKind::Replay(_) => Algorithm::None,
        }
    }

    /// Whether the run's choice depends on the frame budget (and learns from its frame times).
    fn budgeted(self) -> bool {
        matches!(self, RunKind::Elision(_) | RunKind::Impostors)
    }
}

/// Everything in the benchmark is resident: its runs differ in what they choose, not in what
/// they have.
struct Everything<'a>(&'a Scene);

impl portico_client::frame::Resident for Everything<'_> {
    fn has(&self, _: u32) -> bool {
        true
    }

    fn stab(&self, cell: u32) -> Option<std::sync::Arc<portico_data::cells::StabList>> {
        self.0.stabs.get(cell as usize).cloned().flatten()
    }
}

/// The benchmark in progress.
pub(super) struct Bench<'a> {
    cfg: &'a BenchConfig,
    scene: &'a Scene,
    cost: CostModel,
    runs: Vec<Run>,
    depth: DepthBuffer,
    /// The replayed runs' logs, by [`RunKind::Replay`] index.
    logs: Vec<DrawnLog>,
}

impl<'a> Bench<'a> {
    pub(super) fn new(
        cfg: &'a BenchConfig,
        scene: &'a Scene,
        cost: CostModel,
        logs: Vec<DrawnLog>,
    ) -> Self {
        let runs = cfg
            .runs()
            .into_iter()
            .map(|kind| Run {
                kind,
                name: match kind {
                    RunKind::Replay(i) => replay_name(cfg, &logs, usize::from(i)),
                    _ => kind.name().to_owned(),
                },
                decider: Decider::new(kind.algorithm(), cfg.budget_s, None),
                online: OnlineCost::default(),
                last_frame_s: None,
                fidelity: FidelityAccumulator::new(cfg.patch_px),
                rows: Vec::new(),
            })
            .collect();
        Bench {
            cfg,
            scene,
            cost,
            runs,
            depth: DepthBuffer::new(cfg.size.0, cfg.size.1, NEAR),
            logs,
        }
    }

    /// All frames of all runs, in lockstep.
    pub(super) fn run(
        &mut self,
        r: &mut Renderer,
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<()> {
        let total = self.cfg.frame_count();
        self.warm_up(r)?;
        for frame in 0..total {
            let view = self.view_at(frame);
            let mut reference: Option<(RgbaImage, Vec<RefPoint>)> = None;
            for k in 0..self.runs.len() {
                let (mut row, drawn) = self.draw(r, k, &view)?;
                let img = r.read_pixels().context("reading the frame back")?;
                if k == 0 {
                    let points = self.reference_points(&drawn, &view, &img);
                    reference = Some((img.clone(), points));
                }
                let Some((ref_img, points)) = reference.as_ref() else {
                    bail!("the regular run must come first");
                };
                self.score(k, &mut row, ref_img, points, &img);
                self.runs[k].rows.push(row);
            }
            progress(frame + 1, total);
        }
        Ok(())
    }

    /// One untimed Regular frame, so that first-use costs (shader compilation, buffer growth)
    /// do not land in frame 0 of the first run.
    fn warm_up(&mut self, r: &mut Renderer) -> Result<()> {
        let view = self.view_at(0);
        let d = Decider::new(Algorithm::None, self.cfg.budget_s, None).decide(
            &self.scene.frame_scene(),
            &view.view,
            &Everything(self.scene),
            &self.cost,
            None,
        );
        let drawn: Vec<(u32, usize)> = d.drawn.iter().map(|o| (o.instance, o.lod)).collect();
        let draws = self.draws(&drawn);
        r.render(&view.view.camera, &draws)?;
        Ok(())
    }

    fn view_at(&self, frame: u64) -> FrameView {
        let t = frame as f64 * self.cfg.dt_s;
        let (eye, dir) = self.cfg.path.sample(t as f32);
        FrameView {
            frame,
            t,
            view: view::Viewpoint::new(eye, dir, self.cfg.fovy, self.cfg.size, self.scene.far()),
        }
    }

    /// The frame decision ([`portico_client::frame`]) and render of run `k`'s frame; returns its record
    /// and the drawn `(instance, lod)` pairs sorted by instance.
    fn draw(
        &mut self,
        r: &mut Renderer,
        k: usize,
        v: &FrameView,
    ) -> Result<(FrameRecord, Vec<(u32, usize)>)> {
        if let RunKind::Replay(i) = self.runs[k].kind {
            return self.replay(r, usize::from(i), v);
        }
        let t0 = Instant::now();
        let run = &mut self.runs[k];
        let cost = run.online.apply(&self.cost);
        let d = run.decider.decide(
            &self.scene.frame_scene(),
            &v.view,
            &Everything(self.scene),
            &cost,
            run.last_frame_s,
        );
        let mut drawn: Vec<(u32, usize)> = d.drawn.iter().map(|o| (o.instance, o.lod)).collect();
        drawn.sort_unstable();
        let mut draws = self.draws(&drawn);
        let textured = self.boxes(&d.boxes, &mut draws);
        let timing = r.render_with_boxes(&v.view.camera, &draws, &textured)?;
        let frame_s = t0.elapsed().as_secs_f64();
        let run = &mut self.runs[k];
        run.last_frame_s = Some(frame_s);
        if run.kind.budgeted() {
            run.online.observe(d.frame.predicted_s, timing.total_s);
        }
        let row = FrameRecord {
            frame: v.frame,
            t: v.t,
            frame_s,
            visibility_s: d.visibility_s,
            elision_s: d.elision_s,
            render_s: timing.total_s,
            predicted_s: d.frame.predicted_s,
            visible_objects: d.visible.objects.len() as u32,
            drawn_objects: timing.draws,
            triangles: timing.triangles,
            ..FrameRecord::default()
        };
        Ok((row, drawn))
    }

    /// Draws frame `v` as replay `i`'s log drew it: each object at its LOD with the texture
    /// segment and tint it had, and its boxes.
    fn replay(
        &mut self,
        r: &mut Renderer,
        i: usize,
        v: &FrameView,
    ) -> Result<(FrameRecord, Vec<(u32, usize)>)> {
        let scene = self.scene;
        let t0 = Instant::now();
        let frame = self.logs.get(i).and_then(|l| l.at(v.frame));
        let Some(frame) = frame else {
            let file = self.cfg.replays.get(i).map(|p| p.display().to_string());
            bail!("{} has no frame {}", file.unwrap_or_default(), v.frame);
        };
        let mut draws: Vec<Draw<'a>> = frame
            .objects
            .iter()
            .filter_map(|o| {
                let mesh = scene
                    .meshes
                    .get(&scene.segment(o.instance, o.lod as usize)?)?;
                let (_, _, alpha, surface) = scene.material(o.instance, o.lod as usize);
                Some(Draw {
                    mesh,
                    transform: scene.transforms[o.instance as usize],
                    color: o.tint,
                    texture: o.texture.and_then(|s| scene.textures.get(&s)),
                    alpha,
                    surface,
                })
            })
            .collect();
        let boxes: Vec<(u32, Stand)> = frame
            .boxes
            .iter()
            .map(|&(n, t)| (n, if t { Stand::Textured } else { Stand::Colour }))
            .collect();
        let textured = self.boxes(&boxes, &mut draws);
        let timing = r.render_with_boxes(&v.view.camera, &draws, &textured)?;
        let row = FrameRecord {
            frame: v.frame,
            t: v.t,
            frame_s: t0.elapsed().as_secs_f64(),
            render_s: timing.total_s,
            visible_objects: frame.visible,
            drawn_objects: timing.draws,
            triangles: timing.triangles,
            ..FrameRecord::default()
        };
        let mut drawn: Vec<(u32, usize)> = frame
            .objects
            .iter()
            .map(|o| (o.instance, o.lod as usize))
            .collect();
        drawn.sort_unstable();
        Ok((row, drawn))
    }

    /// Adds the average-colour boxes to `draws`; returns the textured boxes.
    fn boxes(&self, boxes: &[(u32, Stand)], draws: &mut Vec<Draw<'a>>) -> Vec<&'a GpuImpostor> {
        let scene = self.scene;
        let mut textured = Vec::new();
        for &(n, stand) in boxes {
            match (stand, scene.textured.get(&n)) {
                (Stand::Textured, Some(t)) => textured.push(t),
                _ => {
                    if let Some(mesh) = scene.colour_boxes.get(n as usize) {
                        draws.push(Draw::new(mesh, Mat4::IDENTITY, [1.0; 4]));
                    }
                }
            }
        }
        textured
    }

    fn draws(&self, drawn: &[(u32, usize)]) -> Vec<Draw<'a>> {
        let scene = self.scene;
        drawn
            .iter()
            .filter_map(|&(o, l)| {
                let mesh = scene.meshes.get(&scene.segment(o, l)?)?;
                let (texture, color, alpha, surface) = scene.material(o, l);
                Some(Draw {
                    mesh,
                    transform: scene.transforms[o as usize],
                    color,
                    texture,
                    alpha,
                    surface,
                })
            })
            .collect()
    }

    /// The critical vertices visible in the reference frame, with their intensities `I0`.
    fn reference_points(
        &mut self,
        drawn: &[(u32, usize)],
        v: &FrameView,
        img: &RgbaImage,
    ) -> Vec<RefPoint> {
        let scene = self.scene;
        let vp = v.view.view_proj;
        self.depth.clear();
        let finest = |o: u32| scene.finest_segment(o);
        for &(o, _) in drawn {
            if let Some(mesh) = finest(o).and_then(|s| scene.cpu.get(&s)) {
                let mvp = vp * scene.transforms[o as usize];
                self.depth.draw_mesh(&mvp, &mesh.positions, &mesh.indices);
            }
        }
        let mut visible = Vec::new();
        for &(o, _) in drawn {
            let Some(set) = finest(o).and_then(|s| scene.critical.get(&s)) else {
                continue;
            };
            let mvp: Mat4 = vp * scene.transforms[o as usize];
            let base = scene.cv_base[o as usize];
            for (j, cv) in set.vertices.iter().enumerate() {
                if let Some((x, y)) = self.depth.visible_pixel(mvp * cv.position.extend(1.0)) {
                    visible.push((base + j as u32, x, y));
                }
            }
        }
        fidelity::reference_points(img, &visible, self.cfg.patch_px)
    }

    /// Es, Et and PSNR of run `k`'s frame against the reference frame.
    fn score(
        &mut self,
        k: usize,
        row: &mut FrameRecord,
        ref_img: &RgbaImage,
        points: &[RefPoint],
        img: &RgbaImage,
    ) {
        let f = self.runs[k].fidelity.frame(points, img);
        row.critical_visible = points.len() as u32;
        row.es = f.es;
        row.et = f.et;
        row.mse = fidelity::mse(ref_img, img);
        row.psnr = fidelity::psnr_of_mse(row.mse);
    }

    pub(super) fn runs_rows(&self) -> Vec<(String, &[FrameRecord])> {
        self.runs
            .iter()
            .map(|r| (r.name.clone(), r.rows.as_slice()))
            .collect()
    }

    pub(super) fn summarise(&self, r: &Renderer, wall_s: f64) -> BenchSummary {
        let cfg = self.cfg;
        let scene = self.scene;
        let regular_polys = self
            .runs
            .first()
            .map_or(0.0, |r| mean_of(&r.rows, |x| x.triangles as f64));
        let runs: Vec<RunSummary> = self
            .runs
            .iter()
            .map(|run| summarise_run(run, cfg.budget_s, regular_polys, scene.cv_counts.critical))
            .collect();
        let self_test = self_test(&runs[0]);
        let visible = self.runs.first().map_or(Vec::new(), |r| {
            r.rows
                .iter()
                .map(|x| f64::from(x.critical_visible))
                .collect()
        });
        let counts = scene.cv_counts;
        BenchSummary {
            machine: machine(),
            adapter: r.adapter_info(),
            cpu_adapter: r.is_cpu_adapter(),
            model: ModelInfo {
                name: scene.header.name.clone(),
                file: cfg.db.display().to_string(),
                database_id: scene.database_id.clone(),
                instances: scene.header.instances.len(),
                triangles: scene.model_triangles,
                gpu_bytes: scene.gpu_bytes,
            },
            path: PathInfo {
                kind: cfg.path.kind.clone(),
                hash: format!("{:016x}", cfg.path.hash()),
                keyframes: cfg.path.keyframes.len(),
                duration_s: cfg.path.duration(),
            },
            parameters: Parameters {
                budget_s: cfg.budget_s,
                size: cfg.size,
                frames: cfg.frame_count(),
                max_frames: cfg.max_frames,
                dt_s: cfg.dt_s,
                fov_deg: cfg.fovy.to_degrees(),
                patch_px: cfg.patch_px,
                intensity: fidelity::INTENSITY_FORMULA.to_owned(),
                critical: cfg.critical,
                visibility_test: "CPU depth buffer of the Regular frame (farthest of 3x3 nearest \
                                  surfaces, +1% +1 cm)"
                    .to_owned(),
                runs: self.runs.iter().map(|r| r.name.clone()).collect(),
            },
            critical: CriticalSummary {
                counts,
                fraction: counts.critical as f64 / counts.vertices.max(1) as f64,
                visible_per_frame: Series::of(&visible),
            },
            cost_model: self.cost,
            self_test,
            runs,
            files: Vec::new(),
            wall_s,
        }
    }
}

/// `streamed <run>`; when two logs name the same run (two load tests' `demand`), each also
/// names the directory its `drawn/` is in.
fn replay_name(cfg: &BenchConfig, logs: &[DrawnLog], i: usize) -> String {
    let Some(log) = logs.get(i) else {
        return "streamed".to_owned();
    };
    if logs.iter().filter(|l| l.run == log.run).count() < 2 {
        return format!("streamed {}", log.run);
    }
    let dir = cfg
        .replays
        .get(i)
        .and_then(|p| p.parent()?.parent()?.file_name())
        .map_or(i.to_string(), |d| d.to_string_lossy().into_owned());
    format!("streamed {} ({dir})", log.run)
}

fn mean_of(rows: &[FrameRecord], f: impl Fn(&FrameRecord) -> f64) -> f64 {
    if rows.is_empty() {
        0.0
    } else {
        rows.iter().map(f).sum::<f64>() / rows.len() as f64
    }
}

fn series_of(rows: &[FrameRecord], f: impl Fn(&FrameRecord) -> f64) -> Series {
    Series::of(&rows.iter().map(f).collect::<Vec<_>>())
}

/// Summarises one run's frames.
fn summarise_run(run: &Run, budget_s: f64, regular_polys: f64, total_critical: u64) -> RunSummary {
    let rows = &run.rows;
    let fid = run.fidelity.finish(total_critical);
    let psnrs: Vec<f64> = rows.iter().filter_map(|x| x.psnr).collect();
    let polygons = series_of(rows, |x| x.triangles as f64);
    RunSummary {
        name: run.name.clone(),
        budget: budget_s,
        budgeted: run.kind.budgeted(),
        frames: rows.len() as u64,
        frame_time: series_of(rows, |x| x.frame_s),
        render_time: series_of(rows, |x| x.render_s),
        elision_time: series_of(rows, |x| x.elision_s),
        frames_over_budget: rows.iter().filter(|x| x.frame_s > budget_s).count() as u64,
        polygons_mean: polygons.mean,
        polygons,
        polygons_vs_regular: if regular_polys > 0.0 {
            polygons.mean / regular_polys
        } else {
            0.0
        },
        es_mean: fid.es,
        es_max: rows.iter().map(|x| x.es).fold(0.0, f64::max),
        et_mean: fid.et,
        et_max: rows.iter().filter_map(|x| x.et).fold(0.0, f64::max),
        es_rrb: fid.es_rrb,
        et_rrb: fid.et_rrb,
        psnr_mean: (!psnrs.is_empty()).then(|| psnrs.iter().sum::<f64>() / psnrs.len() as f64),
        psnr_min: psnrs.iter().copied().reduce(f64::min),
        psnr_of_mean_mse: fidelity::psnr_of_mse(mean_of(rows, |x| x.mse)),
        identical_frames: (rows.len() - psnrs.len()) as u64,
    }
}
