//! One frame's decision, the same for every front end — the native walk, the benchmark, the load
//! tester's simulated clients: what is visible, which representation of each visible thing is
//! drawn, and what the cache must hear. No rendering and no IO: the caller maps the decision
//! onto its GPU meshes (or onto its counters).
//!
//! 1. Visibility (Funkhouser §4.1.2, [`crate::view::visible`]): eye-to-cell through the portals
//!    and eye-to-object with the eye cell's stab list when it is resident, looser culling while
//!    it is not.
//! 2. Candidates ([`crate::view::candidates`]): each visible object's LODs with their screen size,
//!    focus and residency, capped at the static size threshold the server's lookahead uses
//!    (§5.3, [`crate::view::cap_detail`]).
//! 3. Choice over RESIDENT LODs only, at the frame budget: detail elision (§4.2,
//!    [`crate::elision`]) or Maciel's cluster traversal (§6.4, [`crate::cluster`]); every
//!    visible object not drawn and not stood in for by a box is counted as skipped.
//! 4. What the frame used (§5.2.3): the resident LODs of the visible objects, the textured
//!    boxes drawn and the eye cell's stab list move to the head of the cache.

use crate::cluster::{self, Stand, Traversal};
use crate::cost::CostModel;
use crate::elision::{Algorithm, Candidate, Choice, Elider, Frame};
use crate::view::{self, Viewpoint, Visible};
use portico_data::cells::{CellGraph, StabList};
use portico_data::format::Header;
use portico_data::geometry::Aabb;
use portico_data::hierarchy::Hierarchy;
use std::sync::Arc;
use web_time::Instant;

/// What the client's cache holds, as the decision asks it.
pub trait Resident {
    /// Whether segment `id` is resident.
    fn has(&self, id: u32) -> bool;
    /// A cell's stab list, if its segment is resident.
    fn stab(&self, cell: u32) -> Option<Arc<StabList>>;
}

/// A cache entry that may be a stab list (every front end's resident segment type).
pub trait MaybeStab {
    /// The stab list, if this entry is one.
    fn stab_list(&self) -> Option<&Arc<StabList>>;
}

/// A front end's [`crate::cache::ObjectCache`] as the frame decision asks it, with the scene
/// that says which segment is which cell's stab list.
#[derive(Debug, Clone, Copy)]
pub struct Cached<'a, V>(pub &'a crate::cache::ObjectCache<V>, pub &'a Scene<'a>);

impl<V: MaybeStab> Resident for Cached<'_, V> {
    fn has(&self, id: u32) -> bool {
        self.0.contains(id)
    }

    fn stab(&self, cell: u32) -> Option<Arc<StabList>> {
        self.0.get(self.1.stab_segment(cell)?)?.stab_list().cloned()
    }
}

/// The model as the client knows it: the manifest's header, the cell graph, the instance
/// bounds.
#[derive(Debug, Clone, Copy)]
pub struct Scene<'a> {
    /// The model header (instances, LOD tables, hierarchy, cell index).
    pub header: &'a Header,
    /// The cell graph, if the model has cells.
    pub graph: Option<&'a CellGraph>,
    /// Every instance's bounds.
    pub bounds: &'a [Aabb],
}

impl Scene<'_> {
    /// The segment of a cell's stab list.
    pub fn stab_segment(&self, cell: u32) -> Option<u32> {
        self.header.cells.as_ref()?.stab_segment(cell)
    }

    /// The segment of an instance's LOD `lod` (an index into its full LOD table).
    pub fn lod_segment(&self, instance: u32, lod: usize) -> Option<u32> {
        let inst = self.header.instances.get(instance as usize)?;
        Some(self.header.lods_of(inst).get(lod)?.segment)
    }
}

/// One object drawn: the instance and the LOD chosen (an index into its full LOD table).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drawn {
    /// The instance.
    pub instance: u32,
    /// LOD index, finest first.
    pub lod: usize,
    /// The LOD's geometry segment.
    pub segment: u32,
    /// The texture segment it is drawn with: the finest resident one of its material's
    /// texture, when the LOD has texture coordinates (never waited for).
    pub texture: Option<u32>,
    /// The colour the draw multiplies in (linear RGBA): white, or the texture's average colour
    /// when the object is textured but drawn without its texture. (The material's base colour
    /// is in the vertex colours already: the importers multiply it in.)
    pub tint: [f32; 4],
    /// The texture segment its size on screen asks for (about a texel per pixel:
    /// [`portico_data::texture::TextureRecord::useful_segment`]), resident or not; `None`
    /// for an untextured object or LOD. What demand fetch and the oracle fetch for textures.
    pub wants_texture: Option<u32>,
}

/// The texture segment and the tint an instance's LOD is drawn with ([`Drawn::texture`],
/// [`Drawn::tint`]), given what is resident.
pub fn material_of(
    header: &Header,
    instance: u32,
    lod: usize,
    has: &dyn Fn(u32) -> bool,
) -> (Option<u32>, [f32; 4]) {
    // The material's base colour is in the vertex colours already (the importers multiply it
    // in): the tint adds only what the texture would have.
    let Some(inst) = header.instances.get(instance as usize) else {
        return (None, [1.0; 4]);
    };
    let Some(t) = header.texture_of(inst) else {
        return (None, [1.0; 4]);
    };
    let uv = header.lods_of(inst).get(lod).is_some_and(|l| l.uv);
    let segment = t
        .segments
        .iter()
        .rev()
        .map(|s| s.segment)
        .find(|&s| uv && has(s));
    match segment {
        Some(s) => (Some(s), [1.0; 4]),
        None => (None, t.average),
    }
}

/// The decision for one frame.
#[derive(Debug, Clone, Default)]
pub struct Decision {
    /// What the visibility stage found.
    pub visible: Visible,
    /// The candidates (one per visible object with LODs), their finer LODs beyond the static
    /// cap dropped.
    pub candidates: Vec<Candidate>,
    /// Per candidate, how many finer LODs the cap dropped (add it to a choice's LOD index).
    pub capped: Vec<usize>,
    /// Per candidate choices, predicted render time, LODs and objects skipped.
    pub frame: Frame,
    /// The objects drawn, by instance.
    pub drawn: Vec<Drawn>,
    /// Clusters drawn as boxes.
    pub boxes: Vec<(u32, Stand)>,
    /// Resident segments this frame used: they move to the head of the cache (§5.2.3).
    pub touched: Vec<u32>,
    /// The eye cell's stab list segment, when the eye is in a live cell.
    pub eye_stab: Option<u32>,
    /// Seconds spent on visibility.
    pub visibility_s: f64,
    /// Seconds spent choosing.
    pub elision_s: f64,
}

impl Decision {
    /// Per candidate, the segments of its LODs the choice indexes (finest allowed first).
    pub fn segments(&self, scene: &Scene<'_>, candidate: usize) -> Vec<u32> {
        let c = &self.candidates[candidate];
        let inst = &scene.header.instances[c.id as usize];
        scene.header.lods_of(inst)[self.capped[candidate]..]
            .iter()
            .map(|l| l.segment)
            .collect()
    }

    /// The texture segments of the textured boxes drawn.
    pub fn box_textures<'h>(&'h self, h: &'h Hierarchy) -> impl Iterator<Item = u32> + 'h {
        self.boxes
            .iter()
            .filter(|(_, s)| *s == Stand::Textured)
            .map(|(n, _)| h.nodes[*n as usize].texture)
    }
}

/// The decision's frame-to-frame state: the elider (warm-started, feedback) or the cluster
/// traversal (hysteresis), the budget and the cap.
#[derive(Debug)]
pub struct Decider {
    algorithm: Algorithm,
    elider: Elider,
    traversal: Traversal,
    budget_s: f64,
    cap_px: Option<f32>,
}

impl Decider {
    /// Decides with `algorithm` at a frame budget of `budget_s` seconds; `cap_px` is the static
    /// size threshold (pixels per triangle) that caps every object's detail, as the server caps
    /// its lookahead (`None`: no cap, as the benchmark's reference runs).
    pub fn new(algorithm: Algorithm, budget_s: f64, cap_px: Option<f32>) -> Decider {
        Decider {
            algorithm,
            elider: Elider::new(algorithm, budget_s),
            traversal: Traversal::default(),
            budget_s,
            cap_px,
        }
    }

    /// The algorithm.
    pub fn algorithm(&self) -> Algorithm {
        self.algorithm
    }

    /// Forgets the previous frames (no warm start, hysteresis or feedback), e.g. after a jump.
    pub fn reset(&mut self) {
        self.elider.reset();
        self.traversal = Traversal::default();
    }

    /// Decides one frame seen from `view`, with what `resident` holds, under `cost` (the
    /// online-corrected model); `last_frame_s` feeds the feedback elider.
    pub fn decide(
        &mut self,
        scene: &Scene<'_>,
        view: &Viewpoint,
        resident: &dyn Resident,
        cost: &CostModel,
        last_frame_s: Option<f64>,
    ) -> Decision {
        let t = Instant::now();
        let stab = |cell: u32| resident.stab(cell);
        let visible = view::visible(scene.graph, &stab, scene.bounds, &view.frustum());
        let visibility_s = t.elapsed().as_secs_f64();

        let t = Instant::now();
        let has = |s: u32| resident.has(s);
        let mut candidates = view::candidates(scene.header, &visible.objects, view, &has);
        let capped = match self.cap_px {
            Some(px) => view::cap_detail(&mut candidates, px),
            None => vec![0; candidates.len()],
        };
        let (frame, boxes) = match (&scene.header.hierarchy, self.algorithm) {
            (Some(h), Algorithm::Impostors) => traverse(
                &mut self.traversal,
                h,
                &candidates,
                view,
                resident,
                cost,
                self.budget_s,
            ),
            _ => (
                self.elider.choose(&candidates, cost, last_frame_s),
                Vec::new(),
            ),
        };
        let elision_s = t.elapsed().as_secs_f64();

        let mut drawn = Vec::with_capacity(candidates.len());
        let mut touched = Vec::new();
        for ((c, ch), skip) in candidates.iter().zip(&frame.choices).zip(&capped) {
            let inst = &scene.header.instances[c.id as usize];
            let lods = scene.header.lods_of(inst);
            touched.extend(lods.iter().map(|l| l.segment).filter(|&s| resident.has(s)));
            if let Some(l) = ch.lod {
                let (texture, tint) = material_of(scene.header, c.id, l + skip, &has);
                // The texture drawn and its coarse segment stay at the head of the cache.
                if let Some(t) = texture {
                    touched.push(t);
                    let coarse = scene
                        .header
                        .texture_of(inst)
                        .and_then(|t| t.segments.first())
                        .map(|m| m.segment);
                    touched.extend(coarse.filter(|&s| s != t && resident.has(s)));
                }
                let span = scene
                    .header
                    .objects
                    .get(inst.object as usize)
                    .map_or(1.0, |o| o.uv_span);
                let wants_texture = scene
                    .header
                    .texture_of(inst)
                    .filter(|_| lods[l + skip].uv)
                    .and_then(|t| t.segments.get(t.useful_segment(c.pixels.sqrt(), span)))
                    .map(|m| m.segment);
                drawn.push(Drawn {
                    instance: c.id,
                    lod: l + skip,
                    segment: lods[l + skip].segment,
                    texture,
                    tint,
                    wants_texture,
                });
            }
        }
        let eye_stab = visible.eye_cell.and_then(|c| scene.stab_segment(c));
        let mut d = Decision {
            visible,
            candidates,
            capped,
            frame,
            drawn,
            boxes,
            touched,
            eye_stab,
            visibility_s,
            elision_s,
        };
        if let Some(h) = &scene.header.hierarchy {
            let textures: Vec<u32> = d.box_textures(h).collect();
            d.touched.extend(textures);
        }
        d.touched.extend(d.eye_stab);
        d
    }
}

/// Maciel's traversal over the clusters ([`crate::cluster`]) as an elision [`Frame`]: a stood-in
/// object is not wanted (a box represents it), a drawn one wants its finest allowed LOD, one
/// with nothing drawn and no box above is skipped.
fn traverse(
    t: &mut Traversal,
    h: &Hierarchy,
    cands: &[Candidate],
    view: &Viewpoint,
    resident: &dyn Resident,
    cost: &CostModel,
    budget_s: f64,
) -> (Frame, Vec<(u32, Stand)>) {
    let (w, ht) = view.size;
    let pixels = |n: u32| view::screen_pixels(&h.nodes[n as usize].bounds, &view.view_proj, w, ht);
    let inside = |n: u32| view.inside(&h.nodes[n as usize].bounds);
    let textured = |n: u32| {
        let s = h.nodes[n as usize].texture;
        s != u32::MAX && resident.has(s)
    };
    let f = cluster::Frame {
        pixels: &pixels,
        eye_inside: &inside,
        textured: &textured,
        cost,
        budget_s,
    };
    let cut = t.choose(h, cands, &f);
    let mut frame = Frame {
        predicted_s: cut.predicted_s,
        ..Frame::default()
    };
    for (i, c) in cands.iter().enumerate() {
        let choice = match cut.lods[i] {
            Some(l) => {
                let short = c.lods[..l].iter().filter(|o| !o.resident).count() as u32;
                frame.lods_skipped += short;
                Choice {
                    lod: Some(l),
                    desired: Some(0),
                    lods_skipped: short,
                    object_skipped: false,
                }
            }
            None if cut.stood[i] => Choice::default(),
            None => {
                frame.objects_skipped += 1;
                Choice {
                    lod: None,
                    desired: Some(0),
                    lods_skipped: 0,
                    object_skipped: true,
                }
            }
        };
        frame.choices.push(choice);
    }
    (frame, cut.boxes)
}
