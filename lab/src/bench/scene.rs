//! The benchmark's local, fully resident model: the display database opened directly (no
//! server, no cache), every LOD of every instance uploaded once, every stab list decoded, and
//! the critical vertices and CPU triangles of every finest LOD precomputed once per geometry
//! segment (object definitions are shared by their instances, which only transform them).

use super::critical::{CriticalCounts, CriticalParams, CriticalSet, critical_vertices};
use anyhow::{Context, Result};
use glam::{Mat4, Vec3};
use portico_client::frame::material_of;
use portico_data::Database;
use portico_data::cells::{CellGraph, StabList};
use portico_data::format::{Header, LodRecord};
use portico_data::geometry::{Aabb, GeometryView, encode_geometry};
use portico_data::hierarchy::colour_box;
use portico_render::{AlphaMode, GpuImpostor, GpuMesh, GpuTexture, Renderer, Surface};
use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::path::Path;
use std::sync::Arc;

/// Triangles of a finest LOD kept on the CPU for the reference depth buffer.
#[derive(Debug, Clone, Default)]
pub struct CpuMesh {
    /// Vertex positions (object space).
    pub positions: Vec<Vec3>,
    /// Triangle list.
    pub indices: Vec<u32>,
}

/// Everything the benchmark needs about the model, resident.
pub struct Scene {
    /// The decoded header.
    pub header: Header,
    /// The cell graph, if the model has cells.
    pub graph: Option<CellGraph>,
    /// Stab list per cell (`None` for cells without one).
    pub stabs: Vec<Option<Arc<StabList>>>,
    /// World bounds per instance.
    pub bounds: Vec<Aabb>,
    /// Object-to-world matrix per instance.
    pub transforms: Vec<Mat4>,
    /// GPU meshes by geometry segment id (every LOD of every instance).
    pub meshes: HashMap<u32, GpuMesh>,
    /// CPU triangles of each finest-LOD segment.
    pub cpu: HashMap<u32, CpuMesh>,
    /// Critical vertices of each finest-LOD segment.
    pub critical: HashMap<u32, Arc<CriticalSet>>,
    /// First global critical-vertex id of each instance.
    pub cv_base: Vec<u32>,
    /// Critical-vertex counts over all instances (`critical` is RRB's `|V|`).
    pub cv_counts: CriticalCounts,
    /// `header_checksum` and `index_checksum` of the prologue, in hex (the server's database id).
    pub database_id: String,
    /// Triangles of every instance at its finest LOD.
    pub model_triangles: u64,
    /// GPU bytes of all uploaded segments.
    pub gpu_bytes: u64,
    /// Each cluster's average-colour box (Maciel §5.2), by cluster id.
    pub colour_boxes: Vec<GpuMesh>,
    /// Each cluster's textured box, where it has one.
    pub textured: HashMap<u32, GpuImpostor>,
    /// Material textures by segment (each holds a whole chain from its level down): the
    /// finest draws the full-detail frames; the coarser ones, loaded for replays only, the
    /// streamed frames.
    pub textures: HashMap<u32, GpuTexture>,
}

impl Scene {
    /// Opens `db`, uploads every LOD to `renderer` and precomputes the critical vertices; with
    /// `every_mip`, every segment of every texture (replays draw the coarser ones), else each
    /// texture's finest.
    pub fn load(
        db: &Path,
        renderer: &Renderer,
        params: &CriticalParams,
        every_mip: bool,
    ) -> Result<Scene> {
        let db = Database::open(db).with_context(|| format!("opening {}", db.display()))?;
        let header = db.header().clone();
        let graph = db.cell_graph().context("reading the cell graph")?;
        let stabs = load_stabs(&db, graph.as_ref())?;
        let p = db.prologue();
        let mut scene = Scene {
            bounds: header.instances.iter().map(|i| i.bounds).collect(),
            transforms: header
                .instances
                .iter()
                .map(|i| Mat4::from_cols_array(&i.transform))
                .collect(),
            database_id: format!("{:016x}{:016x}", p.header_checksum, p.index_checksum),
            header,
            graph,
            stabs,
            meshes: HashMap::new(),
            cpu: HashMap::new(),
            critical: HashMap::new(),
            cv_base: Vec::new(),
            cv_counts: CriticalCounts::default(),
            model_triangles: 0,
            gpu_bytes: 0,
            colour_boxes: Vec::new(),
            textured: HashMap::new(),
            textures: HashMap::new(),
        };
        scene.load_textures(&db, renderer, every_mip)?;
        scene.load_geometry(&db, renderer, params)?;
        scene.load_clusters(&db, renderer)?;
        Ok(scene)
    }

    /// Uploads every LOD once and analyses every finest LOD once.
    fn load_geometry(
        &mut self,
        db: &Database,
        renderer: &Renderer,
        params: &CriticalParams,
    ) -> Result<()> {
        let mut next_cv = 0u64;
        for (i, inst) in self.header.instances.iter().enumerate() {
            let lods = self.header.lods_of(inst);
            for lod in lods {
                if self.meshes.contains_key(&lod.segment) {
                    continue;
                }
                let bytes = db
                    .geometry(lod)
                    .with_context(|| format!("instance {i} ({})", inst.name))?;
                let mesh = renderer
                    .upload(&bytes)
                    .with_context(|| format!("uploading segment {}", lod.segment))?;
                self.gpu_bytes += mesh.gpu_bytes();
                self.meshes.insert(lod.segment, mesh);
            }
            self.cv_base
                .push(u32::try_from(next_cv).context("more than 2³² critical vertices")?);
            let Some(finest) = lods.first() else { continue };
            self.model_triangles += u64::from(finest.triangles);
            if let Entry::Vacant(slot) = self.critical.entry(finest.segment) {
                let (set, cpu) = analyse(db, finest, params)?;
                slot.insert(Arc::new(set));
                self.cpu.insert(finest.segment, cpu);
            }
            let set = &self.critical[&finest.segment];
            self.cv_counts.add(&set.counts, 1);
            next_cv += set.vertices.len() as u64;
        }
        u32::try_from(next_cv).context("more than 2³² critical vertices")?;
        Ok(())
    }

    /// Uploads each material texture's finest segment, or with `every_mip` every segment.
    fn load_textures(&mut self, db: &Database, renderer: &Renderer, every_mip: bool) -> Result<()> {
        for (i, t) in self.header.textures.iter().enumerate() {
            let skip = if every_mip {
                0
            } else {
                t.segments.len().saturating_sub(1)
            };
            for s in &t.segments[skip..] {
                let at = || format!("texture {i} ({}), segment {}", t.name, s.segment);
                let bytes = db.texture_segment(s).with_context(at)?;
                let gpu = renderer.upload_texture(&bytes, t.wrap).with_context(at)?;
                self.gpu_bytes += gpu.gpu_bytes();
                self.textures.insert(s.segment, gpu);
            }
        }
        Ok(())
    }

    /// The texture, tint, alpha mode and surface instance `i`'s LOD `lod` is drawn with when everything
    /// is resident (the client's rule, [`portico_client::frame::material_of`]).
    pub fn material(
        &self,
        i: u32,
        lod: usize,
    ) -> (Option<&GpuTexture>, [f32; 4], AlphaMode, Surface) {
        let (segment, tint) =
            material_of(&self.header, i, lod, &|s| self.textures.contains_key(&s));
        let material = self
            .header
            .instances
            .get(i as usize)
            .and_then(|inst| self.header.materials.get(inst.material as usize));
        (
            segment.and_then(|s| self.textures.get(&s)),
            tint,
            material.map_or(AlphaMode::Opaque, |m| m.alpha),
            material.map_or(Surface::default(), |m| m.surface()),
        )
    }

    /// Uploads every cluster's average-colour box and textured box.
    fn load_clusters(&mut self, db: &Database, renderer: &Renderer) -> Result<()> {
        let Some(h) = &self.header.hierarchy else {
            return Ok(());
        };
        for (id, n) in h.nodes.iter().enumerate() {
            let mesh = encode_geometry(&colour_box(&n.bounds, &n.face_colors));
            self.colour_boxes.push(renderer.upload(&mesh)?);
            if n.texture != u32::MAX {
                let png = db.segment(n.texture)?;
                let imp = renderer
                    .upload_impostor(&png, &n.bounds, n.tile)
                    .with_context(|| format!("cluster {id}'s textured box"))?;
                self.gpu_bytes += imp.gpu_bytes();
                self.textured.insert(id as u32, imp);
            }
        }
        Ok(())
    }

    /// The finest-LOD segment of instance `i`, if it has any LOD.
    pub fn finest_segment(&self, i: u32) -> Option<u32> {
        let inst = self.header.instances.get(i as usize)?;
        self.header.lods_of(inst).first().map(|l| l.segment)
    }

    /// The segment of LOD `lod` of instance `i`.
    pub fn segment(&self, i: u32, lod: usize) -> Option<u32> {
        let inst = self.header.instances.get(i as usize)?;
        self.header.lods_of(inst).get(lod).map(|l| l.segment)
    }

    /// Number of LODs of instance `i`.
    pub fn lod_count(&self, i: u32) -> usize {
        self.header
            .instances
            .get(i as usize)
            .map_or(0, |inst| self.header.lods_of(inst).len())
    }

    /// The far plane distance for cameras in this model (as the walk client uses).
    pub fn far(&self) -> f32 {
        portico_client::view::far_plane(&self.header.bounds)
    }

    /// The model as the frame decision sees it.
    pub fn frame_scene(&self) -> portico_client::frame::Scene<'_> {
        portico_client::frame::Scene {
            header: &self.header,
            graph: self.graph.as_ref(),
            bounds: &self.bounds,
        }
    }
}

/// The critical vertices and CPU triangles of one finest-LOD segment.
fn analyse(
    db: &Database,
    lod: &LodRecord,
    params: &CriticalParams,
) -> Result<(CriticalSet, CpuMesh)> {
    let bytes = db.geometry(lod)?;
    let view = GeometryView::parse(&bytes).map_err(anyhow::Error::msg)?;
    let mesh = view.to_mesh();
    let set = critical_vertices(&mesh, params);
    let cpu = CpuMesh {
        positions: mesh
            .vertices
            .iter()
            .map(|v| Vec3::from(v.position))
            .collect(),
        indices: mesh.indices,
    };
    Ok((set, cpu))
}

/// Every cell's stab list (the benchmark keeps the whole model resident).
fn load_stabs(db: &Database, graph: Option<&CellGraph>) -> Result<Vec<Option<Arc<StabList>>>> {
    let Some(graph) = graph else {
        return Ok(Vec::new());
    };
    (0..graph.cells.len() as u32)
        .map(|c| {
            if !graph.cells[c as usize].live {
                return Ok(None);
            }
            let list = db
                .stab_list(c)
                .with_context(|| format!("stab list of cell {c}"))?;
            Ok(Some(Arc::new(list)))
        })
        .collect()
}
