//! What every simulated client shares, read-only: the model as a client knows it (manifest,
//! cell graph, segment sizes), the replayed path cut into frames, the stab lists of the cells
//! the path passes through (decoded once; a client only USES one while the segment is in its
//! own cache, exactly as the real client does), and for the oracle the "truth" of every frame:
//! what the elider would draw there if everything were resident.

use anyhow::{Context, Result};
use futures_util::StreamExt;
use glam::Vec3;
use portico_client::cost::CostModel;
use portico_client::elision::Algorithm;
use portico_client::frame::{Decider, Resident, Scene};
use portico_client::view::{self, Viewpoint};
use portico_data::cells::{CellGraph, StabList};
use portico_data::format::Header;
use portico_data::geometry::Aabb;
use portico_data::path::CameraPath;
use portico_data::texture::TexelFormat;
use portico_native::net::Remote;
use portico_protocol::Observer;
use std::collections::{HashMap, HashSet};
use std::sync::Arc;

/// Image size the simulated clients compute screen sizes for (the real client's default).
pub const SCREEN: (u32, u32) = (640, 480);
/// Vertical field of view of the simulated clients (the real client's default, 60°).
pub const FOVY_DEG: f32 = portico_client::defaults::FOV_Y_DEGREES;

/// One frame of the path: where the observer is and what it announces to the server.
#[derive(Debug, Clone)]
pub struct PathFrame {
    /// The observer (eye, view, velocity, speeds).
    pub observer: Observer,
    /// Screen-size inputs of the candidates.
    pub viewpoint: Viewpoint,
}

/// What an omniscient client would want at one path frame.
#[derive(Debug, Clone, Default)]
pub struct Truth {
    /// The eye cell's stab list (if any), then the LOD the elider draws for each visible object
    /// when every LOD is resident.
    pub wants: Vec<u32>,
    /// Bytes of those objects' LODs from the coarsest up to the drawn one (the "0 frames" curve
    /// of Funkhouser Fig. 5.11).
    pub visible_bytes: u64,
}

/// The shared, read-only state of one load test.
#[derive(Debug)]
pub struct World {
    /// The model header.
    pub header: Header,
    /// The cell graph, if the model has cells.
    pub graph: Option<CellGraph>,
    /// Instance bounds.
    pub bounds: Vec<Aabb>,
    /// Database id from the manifest.
    pub database_id: String,
    /// Bytes of every segment on the wire, by id.
    pub seg_bytes: Vec<u64>,
    /// What every segment costs a client's cache, by id ([`Header::cache_charges`]: a
    /// compressed geometry segment's plain size, a texture segment its GPU bytes).
    pub decoded_bytes: Vec<u64>,
    /// Decoded stab lists by cell.
    pub stabs: HashMap<u32, Arc<StabList>>,
    /// The path, one entry per frame.
    pub frames: Vec<PathFrame>,
    /// Per path frame, the oracle's truth (computed for the frames some client reaches).
    pub truth: Vec<Option<Truth>>,
    /// Frame time (s).
    pub dt: f64,
    /// The static size threshold (pixels per triangle) that caps every client's detail, as the
    /// server caps the lookahead (see [`view::cap_detail`]).
    pub size_threshold_px: f32,
    /// Each geometry segment's LOD chain and level, and every segment's kind (for the waste
    /// breakdown).
    pub chains: super::waste::Chains,
}

impl World {
    /// Number of path frames.
    pub fn path_frames(&self) -> usize {
        self.frames.len()
    }

    /// Bytes of a segment.
    pub fn bytes(&self, id: u32) -> u64 {
        self.seg_bytes.get(id as usize).copied().unwrap_or(0)
    }

    /// What a segment occupies in a client's cache: its decoded size.
    pub fn decoded(&self, id: u32) -> u64 {
        self.decoded_bytes.get(id as usize).copied().unwrap_or(0)
    }

    /// The segment of a cell's stab list.
    pub fn stab_segment(&self, cell: u32) -> Option<u32> {
        self.header.cells.as_ref()?.stab_segment(cell)
    }

    /// The cell the eye is in (live cells only).
    pub fn eye_cell(&self, eye: Vec3) -> Option<u32> {
        let g = self.graph.as_ref()?;
        g.locate(eye).filter(|&c| g.cells[c as usize].live)
    }

    /// The model as the frame decision sees it.
    pub fn scene(&self) -> Scene<'_> {
        Scene {
            header: &self.header,
            graph: self.graph.as_ref(),
            bounds: &self.bounds,
        }
    }
}

/// Which path frames the clients reach: client `i` starts at `offset(i)` and plays `frames`
/// frames, wrapping at the end of the path; `extra` more are marked for the oracle's lookahead.
pub fn reached(path_frames: usize, offsets: &[usize], frames: u64, extra: u64) -> Vec<bool> {
    let mut out = vec![false; path_frames];
    let span = (frames + extra).min(path_frames as u64) as usize;
    for &o in offsets {
        for f in 0..span {
            out[(o + f) % path_frames] = true;
        }
    }
    out
}

/// Frame offsets of `clients` clients spread evenly along `path_frames` frames.
pub fn offsets(clients: usize, path_frames: usize) -> Vec<usize> {
    (0..clients)
        .map(|i| i * path_frames / clients.max(1))
        .collect()
}

/// Fastest movement and turn along a path (m/s, rad/s), at least 0.5 each: what the clients
/// announce to the server as `max_speed` and `max_turn`.
pub fn path_speeds(path: &CameraPath) -> (f32, f32) {
    let (mut v, mut w) = (0.5f32, 0.5f32);
    for k in path.keyframes.windows(2) {
        let dt = k[1].t - k[0].t;
        if dt <= 1e-4 {
            continue;
        }
        let moved = (Vec3::from(k[1].eye) - Vec3::from(k[0].eye)).length();
        let turned = Vec3::from(k[0].dir).angle_between(Vec3::from(k[1].dir));
        v = v.max(moved / dt);
        if turned.is_finite() {
            w = w.max(turned / dt);
        }
    }
    (v * 1.1, w * 1.1)
}

/// Cuts the path into frames of `dt` seconds (as `portico walk` does: frame `f` at `f·dt`).
pub fn path_frames(path: &CameraPath, dt: f64, far: f32) -> Vec<PathFrame> {
    let n = (path.duration() as f64 / dt).ceil() as usize + 1;
    let (max_speed, max_turn) = path_speeds(path);
    let fovy = FOVY_DEG.to_radians();
    let aspect = SCREEN.0 as f32 / SCREEN.1 as f32;
    (0..n)
        .map(|f| {
            let t = (f as f64 * dt) as f32;
            let (eye, dir) = path.sample(t);
            let (next, next_dir) = path.sample(t + dt as f32);
            let motion = view::Motion::between(eye, dir, next, next_dir, dt as f32);
            let observer = view::observer(eye, dir, motion, fovy, aspect, max_speed, max_turn);
            PathFrame {
                viewpoint: Viewpoint::of(&observer, SCREEN, far),
                observer,
            }
        })
        .collect()
}

/// What [`load`] needs to know about the run.
#[derive(Debug, Clone, Copy)]
pub struct Plan {
    /// Frame time (s).
    pub dt: f64,
    /// Number of clients.
    pub clients: usize,
    /// Frames each client plays.
    pub frames: u64,
    /// Frames the oracle looks ahead (0 = no oracle truth needed).
    pub lookahead: u64,
    /// See [`World::size_threshold_px`].
    pub size_threshold_px: f32,
    /// How the clients hold textures (what a texture segment costs their caches).
    pub texels: TexelFormat,
}

/// Fetches the model and the stab lists along the path, and computes the oracle's truth.
pub async fn load(remote: &Remote, path: &CameraPath, plan: Plan) -> Result<World> {
    let (m, graph) = remote.model().await.context("loading the model")?;
    let far = view::far_plane(&m.header.bounds);
    let wire: Vec<u64> = m.segments.iter().map(|s| s.bytes).collect();
    let decoded_bytes = m.header.cache_charges(&wire, plan.texels);
    let mut world = World {
        bounds: m.header.instances.iter().map(|i| i.bounds).collect(),
        chains: super::waste::Chains::new(&m.header, m.segments.iter().map(|s| s.kind).collect()),
        header: m.header,
        graph,
        database_id: m.database_id,
        decoded_bytes,
        seg_bytes: m.segments.iter().map(|s| s.bytes).collect(),
        stabs: HashMap::new(),
        frames: path_frames(path, plan.dt, far),
        truth: Vec::new(),
        dt: plan.dt,
        size_threshold_px: plan.size_threshold_px,
    };
    let offs = offsets(plan.clients, world.path_frames());
    let marked = reached(world.path_frames(), &offs, plan.frames, plan.lookahead);
    world.stabs = fetch_stabs(remote, &world, &marked).await?;
    if plan.lookahead > 0 {
        world.truth = truth(&world, &marked, plan.dt);
    }
    Ok(world)
}

/// The stab lists of every eye cell on the marked frames (straight from the server, outside any
/// emulated link: this is the simulator's copy, not a client's).
async fn fetch_stabs(
    remote: &Remote,
    world: &World,
    marked: &[bool],
) -> Result<HashMap<u32, Arc<StabList>>> {
    let cells: HashSet<u32> = (0..world.path_frames())
        .filter(|&p| marked[p])
        .filter_map(|p| world.eye_cell(world.frames[p].observer.eye.into()))
        .collect();
    let wanted: Vec<(u32, u32)> = cells
        .into_iter()
        .filter_map(|c| world.stab_segment(c).map(|s| (c, s)))
        .collect();
    let mut got = futures_util::stream::iter(wanted)
        .map(|(cell, seg)| async move {
            let bytes = remote.segment(seg).await?;
            let list: StabList = portico_data::format::decode_segment(&bytes)
                .map_err(|e| anyhow::anyhow!("stab list of cell {cell} (segment {seg}) {e}"))?;
            Ok::<_, anyhow::Error>((cell, Arc::new(list)))
        })
        .buffer_unordered(8);
    let mut out = HashMap::new();
    while let Some(r) = got.next().await {
        let (cell, list) = r?;
        out.insert(cell, list);
    }
    Ok(out)
}

/// Everything resident, every stab list known: what an omniscient client holds.
struct Omniscient<'a>(&'a World);

impl Resident for Omniscient<'_> {
    fn has(&self, _: u32) -> bool {
        true
    }

    fn stab(&self, cell: u32) -> Option<Arc<StabList>> {
        self.0.stabs.get(&cell).cloned()
    }
}

/// The frame decision with everything resident along the marked frames, in path order: what a
/// client that had everything would draw.
fn truth(world: &World, marked: &[bool], dt: f64) -> Vec<Option<Truth>> {
    let mut decider = Decider::new(Algorithm::Optimize, dt, Some(world.size_threshold_px));
    let cost = CostModel::default();
    let scene = world.scene();
    let mut out = vec![None; world.path_frames()];
    let mut previous = false;
    for p in 0..world.path_frames() {
        if !marked[p] {
            previous = false;
            continue;
        }
        if !previous {
            decider.reset();
        }
        previous = true;
        let d = decider.decide(
            &scene,
            &world.frames[p].viewpoint,
            &Omniscient(world),
            &cost,
            None,
        );
        let mut t = Truth::default();
        t.wants.extend(d.eye_stab);
        let mut counted = HashSet::new();
        for o in &d.drawn {
            t.wants.push(o.segment);
            t.wants.extend(o.wants_texture);
            let lods = world
                .header
                .lods_of(&world.header.instances[o.instance as usize]);
            for lod in &lods[o.lod..] {
                if counted.insert(lod.segment) {
                    t.visible_bytes += world.bytes(lod.segment);
                }
            }
        }
        out[p] = Some(t);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use portico_data::path::Keyframe;

    #[test]
    fn offsets_spread_clients_and_reached_wraps() {
        assert_eq!(offsets(4, 100), vec![0, 25, 50, 75]);
        assert_eq!(offsets(1, 7), vec![0]);
        let r = reached(10, &[0, 8], 3, 1);
        let on: Vec<usize> = (0..10).filter(|&i| r[i]).collect();
        assert_eq!(on, vec![0, 1, 2, 3, 8, 9]);
        assert!(reached(5, &[2], 100, 0).iter().all(|&b| b));
    }

    #[test]
    fn speeds_come_from_the_path_with_a_margin() {
        let path = CameraPath {
            kind: "t".into(),
            keyframes: vec![
                Keyframe {
                    t: 0.0,
                    eye: [0.0; 3],
                    dir: [1.0, 0.0, 0.0],
                },
                Keyframe {
                    t: 2.0,
                    eye: [6.0, 0.0, 0.0],
                    dir: [0.0, 0.0, 1.0],
                },
            ],
        };
        let (v, w) = path_speeds(&path);
        assert!((v - 3.3).abs() < 1e-4, "{v}");
        assert!((w - std::f32::consts::FRAC_PI_4 * 1.1).abs() < 1e-4, "{w}");
        let frames = path_frames(&path, 0.5, 100.0);
        assert_eq!(frames.len(), 5);
        assert!((frames[0].observer.velocity[0] - 3.0).abs() < 1e-4);
    }
}
