//! `portico build`: imported model → LODs → (optionally flattened, baked) geometry segments →
//! header → an atomically written display database.
//!
//! LOD generation and flattening run in parallel across objects with rayon; segments are then
//! written in order, so the same input always gives the same file.

use crate::bake::bake;
use crate::cells::guard::{GuardReport, guard};
use crate::cells::occluders::{Occluders, occluder_boxes, transform_box};
use crate::cells::sight::Triangles;
use crate::cells::{CellStats, precompute};
use crate::error::Result;
use crate::format::writer::{DbWriter, WriteSummary};
use crate::format::{
    CellIndex, Header, InstanceRecord, LodRecord, ObjectRecord, SegmentKind, encode_segment,
    segment_flags,
};
use crate::geometry::{Aabb, encode_geometry};
use crate::hierarchy::{self, Hierarchy, ImpostorPainter, PaintItem};
use crate::lod::{LodMesh, complete_lods};
use crate::model::{Instance, Model};
use crate::texture::{self, TextureImage};
use glam::Mat4;
use rayon::prelude::*;
use std::path::Path;
use std::time::{Duration, Instant};

/// Instances flattened per parallel batch (bounds memory on huge flattened builds).
const FLATTEN_BATCH: usize = 512;

/// Build settings; the default compresses geometry and builds cells, visibility and the
/// hierarchy.
#[derive(Debug, Clone)]
pub struct BuildOptions {
    /// Give every instance its own world-space geometry with baked lighting (the out-of-core
    /// stress case) instead of sharing definitions.
    pub flatten: bool,
    /// Model name stored in the header (default: the first source's file stem).
    pub name: Option<String>,
    /// Skip the cell subdivision and visibility precomputation.
    pub no_cells: bool,
    /// Skip the model hierarchy of clusters and its impostors.
    pub no_hierarchy: bool,
    /// Write geometry segments quantised, meshopt-encoded and deflated ([`crate::codec`]; the
    /// default: 7.9 bytes per triangle on flattened `mega` against 44.8 plain).
    pub compress: bool,
    /// Most bytes of a texture segment or part ([`texture::PART_BYTES`] when `None`; at least
    /// [`texture::MIN_PART_BYTES`]): smaller for slower links.
    pub part_bytes: Option<usize>,
}

impl Default for BuildOptions {
    fn default() -> BuildOptions {
        BuildOptions {
            flatten: false,
            name: None,
            no_cells: false,
            no_hierarchy: false,
            compress: true,
            part_bytes: None,
        }
    }
}

/// Receives progress from long build steps (the CLI draws progress bars with it).
pub trait Observer: Sync {
    /// A step named `name` with `total` units of work starts.
    fn stage(&self, _name: &str, _total: u64) {}
    /// `n` more units are done.
    fn advance(&self, _n: u64) {}
}

/// An [`Observer`] that ignores everything.
pub struct Quiet;
impl Observer for Quiet {}

/// What a build did and how long each step took.
#[derive(Debug, Clone)]
pub struct BuildReport {
    /// The written file.
    pub written: WriteSummary,
    /// Time spent making LODs.
    pub lod_time: Duration,
    /// Time spent encoding and writing geometry and the header.
    pub write_time: Duration,
    /// Cell statistics, when cells were built.
    pub cells: Option<CellStats>,
    /// Seconds spent on the cell subdivision (0 without cells).
    pub subdivision_seconds: f64,
    /// Seconds spent on the visibility precomputation (0 without cells).
    pub visibility_seconds: f64,
    /// Seconds spent clustering and painting impostors.
    pub hierarchy_seconds: f64,
    /// The visibility guard's rays and repairs ([`crate::cells::guard`]), when cells were
    /// built.
    pub guard: Option<GuardReport>,
}

/// Builds a display database at `out` from an imported model, with average-colour boxes but
/// no textured impostors (see [`build_with`]).
pub fn build(
    model: Model,
    out: &Path,
    opts: &BuildOptions,
    obs: &dyn Observer,
) -> Result<BuildReport> {
    build_with(model, out, opts, obs, None)
}

/// Builds a display database at `out` from an imported model; `painter` renders the clusters'
/// textured boxes (Maciel §5.2.2).
pub fn build_with(
    model: Model,
    out: &Path,
    opts: &BuildOptions,
    obs: &dyn Observer,
    painter: Option<&mut dyn ImpostorPainter>,
) -> Result<BuildReport> {
    let t0 = Instant::now();
    let Model {
        materials,
        defs,
        instances,
        sources,
        frames,
        origin,
        warnings: _,
        spaces,
        textures,
    } = model;
    // Occluders come from the source meshes, before LOD optimisation reorders their triangles.
    let occluders = (!opts.no_cells).then(|| {
        // What is see-through (glass, a cut-out fence) never occludes unless its source says
        // so: a ray passes it, so its shape must not close the cells behind it.
        // Translucent vertices are looked for once per definition, not once per instance.
        let clear_vertices: Vec<bool> = defs
            .iter()
            .map(|d| d.lods.first().is_some_and(translucent))
            .collect();
        let mut occ = occluder_boxes(instances.iter().filter_map(|i| {
            let mesh = defs.get(i.def as usize)?.lods.first()?;
            let clear = clear_vertices[i.def as usize]
                || materials.get(i.material as usize).is_some_and(see_through);
            (i.occluder || !clear).then_some((mesh, i.transform, i.occluder))
        }));
        occ.rooms = spaces
            .iter()
            .filter_map(|s| transform_box(&s.bounds, &Mat4::IDENTITY))
            .collect();
        occ
    });
    obs.stage("LODs", defs.len() as u64);
    let lods: Vec<(String, u32, Vec<LodMesh>)> = defs
        .into_par_iter()
        .map(|d| {
            let l = complete_lods(d.lods);
            obs.advance(1);
            (d.name, d.material, l)
        })
        .collect();
    let lod_time = t0.elapsed();

    let t1 = Instant::now();
    let mut w = DbWriter::create(out)?;
    let part = opts
        .part_bytes
        .unwrap_or(texture::PART_BYTES)
        .max(texture::MIN_PART_BYTES);
    let texture_records = texture::write_textures(&mut w, &textures, part, obs)?;
    let objects = write_objects(&mut w, &lods, opts, obs)?;
    let records = if opts.flatten {
        write_flattened(&mut w, &lods, &instances, opts.compress, obs)?
    } else {
        instances
            .iter()
            .map(|i| instance_record(i, &lods[i.def as usize].2, None))
            .collect()
    };
    let bounds = records.iter().fold(Aabb::EMPTY, |b, r| b.union(&r.bounds));
    let t_h = Instant::now();
    let hierarchy = if opts.no_hierarchy {
        None
    } else {
        let scene = Scene {
            records: &records,
            lods: &lods,
            instances: &instances,
            materials: &materials,
            textures: &textures,
        };
        Some(write_hierarchy(&mut w, &scene, painter, obs)?)
    };
    let hierarchy_seconds = t_h.elapsed().as_secs_f64();
    let mut times = (0.0, 0.0);
    let mut guarded = None;
    let cells = match &occluders {
        Some(occ) => {
            let scene = triangles(&records, &instances, &lods);
            let (index, report) =
                write_cells(&mut w, occ, &records, &scene, &bounds, obs, &mut times)?;
            guarded = Some(report);
            Some(index)
        }
        None => None,
    };
    let cell_stats = cells.as_ref().map(|c| c.stats.clone());
    let name = opts.name.clone().unwrap_or_else(|| {
        sources
            .first()
            .and_then(|s| Path::new(s).file_stem())
            .map_or_else(|| "model".to_string(), |s| s.to_string_lossy().into_owned())
    });
    let header = Header {
        name,
        sources,
        frames,
        flattened: opts.flatten,
        bounds,
        origin,
        materials,
        textures: texture_records,
        objects,
        instances: records,
        cells,
        hierarchy,
    };
    let written = w.finish(&header)?;
    Ok(BuildReport {
        written,
        lod_time,
        write_time: t1.elapsed(),
        cells: cell_stats,
        subdivision_seconds: times.0,
        visibility_seconds: times.1,
        hierarchy_seconds,
        guard: guarded,
    })
}

/// Whether a material can be seen through: blended or cut out, or a translucent base colour.
fn see_through(m: &crate::model::Material) -> bool {
    m.alpha != crate::texture::AlphaMode::Opaque || m.base_color[3] < 0.999
}

/// Whether any vertex of a mesh is translucent (IFC glass carries its alpha there).
fn translucent(mesh: &crate::geometry::Mesh) -> bool {
    mesh.vertices.iter().any(|v| v.color[3] < 255)
}

/// Every instance's finest LOD, as shared shapes placed by the instances' transforms, for the
/// visibility guard.
fn triangles(
    records: &[InstanceRecord],
    instances: &[Instance],
    lods: &[(String, u32, Vec<LodMesh>)],
) -> Triangles {
    let shapes = lods
        .iter()
        .map(|(_, _, l)| {
            l.first().map_or_else(Vec::new, |f| {
                let p = &f.mesh.vertices;
                f.mesh
                    .indices
                    .chunks_exact(3)
                    .map(|t| [t[0], t[1], t[2]].map(|i| glam::Vec3::from(p[i as usize].position)))
                    .collect()
            })
        })
        .collect();
    Triangles::instanced(
        records.iter().map(|r| r.bounds).collect(),
        shapes,
        instances.iter().map(|i| (i.def, i.transform)).collect(),
    )
}

/// What the hierarchy build needs to see of the model.
struct Scene<'a> {
    records: &'a [InstanceRecord],
    lods: &'a [(String, u32, Vec<LodMesh>)],
    instances: &'a [Instance],
    materials: &'a [crate::model::Material],
    textures: &'a [TextureImage],
}

/// Clusters the instances (Maciel §6.3.2) and paints each cluster's impostors from the real
/// objects beneath it; writes the textured boxes' atlases as texture segments.
fn write_hierarchy(
    w: &mut DbWriter,
    scene: &Scene<'_>,
    mut painter: Option<&mut dyn ImpostorPainter>,
    obs: &dyn Observer,
) -> Result<Hierarchy> {
    let bounds: Vec<Aabb> = scene.records.iter().map(|r| r.bounds).collect();
    let mut h = Hierarchy::build(&bounds, hierarchy::FIRST_CELL);
    obs.stage("impostors", h.nodes.len() as u64);
    for n in 0..h.nodes.len() {
        let under = h.instances_under(n as u32);
        let node_bounds = h.nodes[n].bounds;
        let textured = hierarchy::tile_for(&node_bounds);
        let colors = match painter.as_deref_mut() {
            Some(p) => {
                let tile = textured.max(hierarchy::TILE_RANGE.0);
                let items = paint_items(scene, &under, &node_bounds, tile);
                let (png, colors) = p
                    .paint(&items, &node_bounds, tile)
                    .map_err(crate::DataError::Impostor)?;
                if textured > 0 {
                    h.nodes[n].texture = w.add_segment(SegmentKind::Texture, &png)?;
                    h.nodes[n].tile = tile;
                }
                colors
            }
            None => material_colors(scene, &under),
        };
        h.nodes[n].face_colors = colors;
        obs.advance(1);
    }
    Ok(h)
}

/// The objects under a cluster, each at the coarsest LOD that still shows its shape at the
/// tile's texel size (about 16 texels per triangle, as the static size threshold).
fn paint_items<'a>(
    scene: &Scene<'a>,
    under: &[u32],
    bounds: &Aabb,
    tile: u32,
) -> Vec<PaintItem<'a>> {
    let texel = bounds.size().max_element().max(1e-3) / tile.max(1) as f32;
    under
        .iter()
        .filter_map(|&i| {
            let inst = scene.instances.get(i as usize)?;
            let levels = &scene.lods.get(inst.def as usize)?.2;
            let px = scene.records[i as usize].bounds.size().max_element() / texel;
            let lod = levels
                .iter()
                .position(|l| px * px / l.mesh.triangle_count().max(1) as f32 >= 16.0)
                .unwrap_or(levels.len().saturating_sub(1));
            let mesh = &levels.get(lod)?.mesh;
            let material = scene.materials.get(inst.material as usize);
            // The base colour is in the vertex colours already.
            let color = [1.0; 4];
            let texture = material
                .and_then(|m| m.texture)
                .filter(|_| mesh.has_uvs())
                .and_then(|t| Some((t, scene.textures.get(t as usize)?)));
            Some(PaintItem {
                key: (inst.def, lod as u32),
                mesh,
                transform: inst.transform,
                color,
                texture,
                alpha: material.map_or(Default::default(), |m| m.alpha),
                surface: material.map_or(Default::default(), |m| m.surface()),
            })
        })
        .collect()
}

/// Face colours without a painter: the area-weighted mean of the materials beneath.
fn material_colors(scene: &Scene<'_>, under: &[u32]) -> [[f32; 4]; 6] {
    let mut sum = [0.0f32; 4];
    for &i in under {
        let r = &scene.records[i as usize];
        let s = r.bounds.size();
        let area = s.x * s.y + s.y * s.z + s.x * s.z;
        let (c, e) = scene
            .materials
            .get(r.material as usize)
            .map_or(([1.0; 4], [0.0; 3]), |m| (m.base_color, m.emissive));
        for k in 0..3 {
            // What an unlit viewer sees: the base colour and the light given off.
            sum[k] += (c[k] + e[k]).min(1.0) * area;
        }
        sum[3] += area;
    }
    let w = sum[3].max(1e-9);
    [[sum[0] / w, sum[1] / w, sum[2] / w, 1.0]; 6]
}

/// Subdivides into cells, precomputes visibility (Funkhouser §3.2), guards it with rays against
/// the objects' own triangles ([`crate::cells::guard`]) and writes the cell graph, the
/// occluders and one stab list per cell.
fn write_cells(
    w: &mut DbWriter,
    occluders: &Occluders,
    records: &[InstanceRecord],
    scene: &Triangles,
    bounds: &Aabb,
    obs: &dyn Observer,
    times: &mut (f64, f64),
) -> Result<(CellIndex, GuardReport)> {
    let objects: Vec<Aabb> = records.iter().map(|r| r.bounds).collect();
    obs.stage("cells", 1);
    let mut pre = precompute(
        bounds,
        occluders,
        &objects,
        &|name, n| obs.stage(name, n),
        &|| obs.advance(1),
    );
    let guarded = guard(&pre.graph, &mut pre.stabs, scene, GUARD_SEED);
    if !guarded.repaired.is_empty() {
        pre.stats = crate::cells::stats(&pre.graph, &pre.stabs, occluders.faces.len());
    }
    let graph_segment = w.add_segment(SegmentKind::CellGraph, &encode_segment(&pre.graph))?;
    let occluder_segment =
        w.add_segment(SegmentKind::Occluders, &encode_segment(&occluders.faces))?;
    let stab_segments = pre
        .stabs
        .iter()
        .zip(&pre.graph.cells)
        .map(|(s, c)| {
            if c.live {
                w.add_segment(SegmentKind::StabList, &encode_segment(s))
            } else {
                Ok(u32::MAX)
            }
        })
        .collect::<Result<Vec<_>>>()?;
    *times = (pre.subdivision_seconds, pre.visibility_seconds);
    Ok((
        CellIndex {
            graph_segment,
            occluder_segment,
            stab_segments,
            stats: pre.stats,
        },
        guarded,
    ))
}

/// The visibility guard's seed: fixed, so the same input always gives the same database.
const GUARD_SEED: u64 = 0x9047_1C0D;

/// Writes each definition's LODs (unless flattening) and returns the object records.
fn write_objects(
    w: &mut DbWriter,
    lods: &[(String, u32, Vec<LodMesh>)],
    opts: &BuildOptions,
    obs: &dyn Observer,
) -> Result<Vec<ObjectRecord>> {
    let flatten = opts.flatten;
    if !flatten {
        obs.stage("geometry", lods.len() as u64);
    }
    lods.iter()
        .map(|(name, material, levels)| {
            let records = if flatten {
                Vec::new()
            } else {
                obs.advance(1);
                levels
                    .iter()
                    .map(|l| write_lod(w, l, segment(&l.mesh, opts.compress), l.error))
                    .collect::<Result<_>>()?
            };
            Ok(ObjectRecord {
                name: name.clone(),
                bounds: levels.first().map_or(Aabb::EMPTY, |l| l.mesh.bounds()),
                material: *material,
                lods: records,
                uv_span: levels.first().map_or(0.0, |l| l.mesh.uv_span()),
            })
        })
        .collect()
}

/// Transforms, bakes and writes every instance's own copy of its LODs (in parallel batches).
fn write_flattened(
    w: &mut DbWriter,
    lods: &[(String, u32, Vec<LodMesh>)],
    instances: &[Instance],
    compress: bool,
    obs: &dyn Observer,
) -> Result<Vec<InstanceRecord>> {
    obs.stage("flatten", instances.len() as u64);
    let mut records = Vec::with_capacity(instances.len());
    for batch in instances.chunks(FLATTEN_BATCH) {
        let encoded: Vec<Vec<(Vec<u8>, &LodMesh, f32)>> = batch
            .par_iter()
            .map(|inst| {
                let scale = max_scale(&inst.transform);
                lods[inst.def as usize]
                    .2
                    .iter()
                    .map(|l| {
                        let mut m = l.mesh.transformed(&inst.transform);
                        bake(&mut m);
                        (segment(&m, compress), l, l.error * scale)
                    })
                    .collect()
            })
            .collect();
        for (inst, levels) in batch.iter().zip(encoded) {
            let own = levels
                .into_iter()
                .map(|(bytes, l, err)| write_lod(w, l, bytes, err))
                .collect::<Result<Vec<_>>>()?;
            records.push(instance_record(inst, &lods[inst.def as usize].2, Some(own)));
            obs.advance(1);
        }
    }
    Ok(records)
}

/// A mesh's geometry segment: compressed when asked for and when that is smaller and decodes
/// (a box of a dozen triangles is smaller plain: the compressed form's fixed costs), else plain.
fn segment(mesh: &crate::geometry::Mesh, compress: bool) -> Vec<u8> {
    let plain = encode_geometry(mesh);
    if !compress {
        return plain;
    }
    let packed = crate::codec::encode(mesh);
    if packed.len() < plain.len() && crate::codec::decode(&packed).is_ok() {
        packed
    } else {
        plain
    }
}

fn write_lod(w: &mut DbWriter, l: &LodMesh, bytes: Vec<u8>, error: f32) -> Result<LodRecord> {
    let (triangles, vertices) = (l.mesh.triangle_count() as u32, l.mesh.vertices.len() as u32);
    let segment = if crate::codec::is_compressed(&bytes) {
        // The index says so, with the size it decodes to: inspect and old readers see it
        // without reading the segment.
        let decoded = crate::geometry::plain_size(vertices, triangles, l.mesh.has_uvs());
        w.add_segment_flagged(
            SegmentKind::Geometry,
            &bytes,
            segment_flags::MESHOPT,
            decoded,
        )?
    } else {
        w.add_segment(SegmentKind::Geometry, &bytes)?
    };
    Ok(LodRecord {
        segment,
        triangles,
        vertices,
        error,
        uv: l.mesh.has_uvs(),
    })
}

/// The header record of an instance; flattened instances get their own LODs and identity.
fn instance_record(
    inst: &Instance,
    levels: &[LodMesh],
    own: Option<Vec<LodRecord>>,
) -> InstanceRecord {
    let local = levels.first().map_or(Aabb::EMPTY, |l| l.mesh.bounds());
    let transform = if own.is_some() {
        Mat4::IDENTITY
    } else {
        inst.transform
    };
    InstanceRecord {
        name: inst.name.clone(),
        object: inst.def,
        transform: transform.to_cols_array(),
        material: inst.material,
        bounds: local.transformed(&inst.transform),
        occluder: inst.occluder,
        tags: inst
            .tags
            .iter()
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect(),
        lods: own,
    }
}

/// Largest axis scale of a transform (turns a local geometric error into a world one).
fn max_scale(m: &Mat4) -> f32 {
    let (s, _, _) = m.to_scale_rotation_translation();
    s.abs().max_element()
}
