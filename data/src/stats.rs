//! Database statistics for `portico inspect`, including Funkhouser's Table 3.1 (multi-resolution
//! modelling statistics: per LOD level, how many object instances have it and how many polygons
//! they use — min, mean and max per object).

use crate::format::reader::Database;
use crate::format::{SegmentKind, segment_flags};
use serde::Serialize;

/// One row of the Table 3.1-style LOD table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LodRow {
    /// "1 (lowest)", "2", ..., or the summary rows "lowest", "highest", "all".
    pub level: String,
    /// Object instances that have this level.
    pub objects: u64,
    /// Polygons (triangles) over those instances.
    pub polygons: u64,
    /// Fewest polygons of one instance at this level.
    pub min_per_object: u64,
    /// Mean polygons per instance at this level.
    pub mean_per_object: f64,
    /// Most polygons of one instance at this level.
    pub max_per_object: u64,
}

/// Everything `portico inspect --json` prints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DbStats {
    /// Model name.
    pub name: String,
    /// Format version.
    pub format_version: u32,
    /// Whether instances carry their own geometry.
    pub flattened: bool,
    /// Object definitions.
    pub objects: u64,
    /// Object instances.
    pub instances: u64,
    /// Instances tagged as structural occluders.
    pub occluders: u64,
    /// Materials.
    pub materials: u64,
    /// Triangles over all instances at their highest LOD.
    pub triangles_highest: u64,
    /// Triangles over all instances and all their LODs.
    pub triangles_all_lods: u64,
    /// Table 3.1: levels from the lowest up, then lowest / highest / all.
    pub lod_table: Vec<LodRow>,
    /// Number of segments.
    pub segments: u64,
    /// Bytes of geometry segments.
    pub geometry_bytes: u64,
    /// Triangles stored in geometry segments, every LOD once (a shared definition counts once).
    pub triangles_stored: u64,
    /// Geometry segments stored meshopt-compressed (`portico build --compress`).
    pub compressed_segments: u64,
    /// Bytes the geometry segments occupy decoded (equal to `geometry_bytes` when none is
    /// compressed).
    pub geometry_decoded_bytes: u64,
    /// Total file size.
    pub file_bytes: u64,
    /// Bounds (min, max) in metres, relative to `origin`.
    pub bounds: [[f32; 3]; 2],
    /// The local origin (metres, Y up): add it to place the model back in the world (survey
    /// coordinates); zero for models built near their own origin.
    pub origin: [f64; 3],
    /// Each source file with its unit and up axis ([`crate::frame`]), converted from at import.
    pub frames: Vec<(String, crate::frame::SourceFrame)>,
    /// Leaf cells (0 without cells).
    pub cells: u64,
    /// Portals.
    pub portals: u64,
    /// Funkhouser Table 3.2 and precomputation times, when the database has cells.
    pub cell_stats: Option<crate::cells::CellStats>,
    /// Clusters of the model hierarchy (Maciel §6.3; 0 without one).
    pub clusters: u64,
    /// Clusters with a textured box.
    pub textured_clusters: u64,
    /// Depth of the hierarchy (clusters from the root down to the deepest leaf).
    pub hierarchy_depth: u64,
    /// Bytes of texture segments (the textured boxes' atlases).
    pub texture_bytes: u64,
    /// Material textures.
    pub textures: u64,
    /// Bytes of the material textures' mip segments as stored and sent (coded: PNG or JPEG).
    pub mip_bytes: u64,
    /// What those segments give decoded (RGBA8; every segment a whole chain).
    pub mip_texel_bytes: u64,
    /// What they hold on a GPU with BC textures (BC1 opaque, BC3 with alpha, RGBA8 where the
    /// size is not whole 4 × 4 blocks): [`crate::texture::MipSegment::gpu_bytes`].
    pub mip_block_bytes: u64,
    /// Bytes of the material textures' coarse segments: what a first view of every textured
    /// object costs.
    pub coarse_mip_bytes: u64,
    /// The longest texture segment or part on the wire (bytes; [`crate::texture::PART_BYTES`]
    /// at most): what one of them holds a link for.
    pub largest_mip_piece: u64,
    /// The lowest PSNR (dB) of any coded texture segment against its texels; `None` when all
    /// are lossless.
    pub texture_psnr: Option<f32>,
    /// Each material texture: its name, stored size (texels), segments and their coded bytes.
    pub texture_list: Vec<TextureStat>,
}

/// One material texture in [`DbStats::texture_list`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TextureStat {
    /// Name from the source (file name or glTF image).
    pub name: String,
    /// Width of its finest level (texels).
    pub width: u32,
    /// Height of its finest level (texels).
    pub height: u32,
    /// Segments (coarse first).
    pub segments: u32,
    /// Their bytes as stored and sent.
    pub bytes: u64,
    /// The lowest PSNR of its coded segments (dB); `None` when lossless.
    pub psnr: Option<f32>,
}

/// Computes the statistics of an open database (header only; no segment is read).
pub fn stats(db: &Database) -> DbStats {
    let h = db.header();
    let per_instance: Vec<Vec<u64>> = h
        .instances
        .iter()
        .map(|i| {
            h.lods_of(i)
                .iter()
                .rev()
                .map(|l| l.triangles as u64)
                .collect()
        })
        .collect();
    let levels = per_instance.iter().map(Vec::len).max().unwrap_or(0);
    let mut lod_table: Vec<LodRow> = (0..levels)
        .map(|k| {
            let label = if k == 0 {
                "1 (lowest)".to_string()
            } else {
                (k + 1).to_string()
            };
            row(label, per_instance.iter().filter_map(|l| l.get(k).copied()))
        })
        .collect();
    lod_table.push(row(
        "lowest".into(),
        per_instance.iter().filter_map(|l| l.first().copied()),
    ));
    lod_table.push(row(
        "highest".into(),
        per_instance.iter().filter_map(|l| l.last().copied()),
    ));
    lod_table.push(row(
        "all".into(),
        per_instance.iter().map(|l| l.iter().sum()),
    ));
    let geometry = db
        .segments()
        .iter()
        .filter(|s| s.kind == SegmentKind::Geometry as u16);
    let geometry_bytes = geometry.clone().map(|s| s.length).sum();
    let stored: std::collections::BTreeMap<u32, u64> = h
        .objects
        .iter()
        .flat_map(|o| &o.lods)
        .chain(h.instances.iter().flat_map(|i| i.lods.iter().flatten()))
        .map(|l| (l.segment, l.triangles as u64))
        .collect();
    let kind_bytes = |k: SegmentKind| -> u64 {
        db.segments()
            .iter()
            .filter(|s| s.kind == k as u16)
            .map(|s| s.length)
            .sum()
    };
    let (clusters, textured_clusters, hierarchy_depth) =
        h.hierarchy.as_ref().map_or((0, 0, 0), |hy| {
            let textured = hy.nodes.iter().filter(|n| n.texture != u32::MAX).count() as u64;
            let mut depth = vec![0u64; hy.nodes.len()];
            for i in (0..hy.nodes.len()).rev() {
                let p = hy.nodes[i].parent as usize;
                depth[i] = if p < hy.nodes.len() { depth[p] + 1 } else { 1 };
            }
            (
                hy.nodes.len() as u64,
                textured,
                depth.into_iter().max().unwrap_or(0),
            )
        });
    DbStats {
        clusters,
        textured_clusters,
        hierarchy_depth,
        texture_bytes: kind_bytes(SegmentKind::Texture),
        textures: h.textures.len() as u64,
        mip_bytes: kind_bytes(SegmentKind::Mips) + kind_bytes(SegmentKind::MipPart),
        mip_texel_bytes: h
            .textures
            .iter()
            .flat_map(|t| &t.segments)
            .map(|s| s.texel_bytes())
            .sum(),
        mip_block_bytes: h
            .textures
            .iter()
            .flat_map(|t| &t.segments)
            .map(|s| s.gpu_bytes(crate::texture::TexelFormat::Block))
            .sum(),
        coarse_mip_bytes: h
            .textures
            .iter()
            .filter_map(|t| t.segments.first())
            .flat_map(|s| s.ids())
            .filter_map(|id| db.segments().get(id as usize))
            .map(|e| e.length)
            .sum(),
        largest_mip_piece: db
            .segments()
            .iter()
            .filter(|e| {
                matches!(
                    SegmentKind::from_u16(e.kind),
                    Some(SegmentKind::Mips | SegmentKind::MipPart)
                )
            })
            .map(|e| e.length)
            .max()
            .unwrap_or(0),
        texture_psnr: h
            .textures
            .iter()
            .filter_map(|t| t.psnr)
            .min_by(f32::total_cmp),
        texture_list: h
            .textures
            .iter()
            .map(|t| TextureStat {
                name: t.name.clone(),
                width: t.width,
                height: t.height,
                segments: t.segments.len() as u32,
                bytes: t
                    .segments
                    .iter()
                    .flat_map(|s| s.ids())
                    .filter_map(|id| db.segments().get(id as usize))
                    .map(|e| e.length)
                    .sum(),
                psnr: t.psnr,
            })
            .collect(),
        name: h.name.clone(),
        format_version: db.prologue().version,
        flattened: h.flattened,
        objects: h.objects.len() as u64,
        instances: h.instances.len() as u64,
        occluders: h.instances.iter().filter(|i| i.occluder).count() as u64,
        materials: h.materials.len() as u64,
        triangles_highest: lod_table[lod_table.len() - 2].polygons,
        triangles_all_lods: lod_table[lod_table.len() - 1].polygons,
        lod_table,
        segments: db.segments().len() as u64,
        geometry_bytes,
        triangles_stored: stored.values().sum(),
        compressed_segments: geometry
            .clone()
            .filter(|s| s.flags & segment_flags::MESHOPT != 0)
            .count() as u64,
        geometry_decoded_bytes: geometry.map(|s| s.raw_length).sum(),
        file_bytes: db.file_len(),
        bounds: [h.bounds.min, h.bounds.max],
        origin: h.origin,
        frames: h
            .sources
            .iter()
            .cloned()
            .zip(h.frames.iter().cloned())
            .collect(),
        cells: h.cells.as_ref().map_or(0, |c| c.stats.cells),
        portals: h.cells.as_ref().map_or(0, |c| c.stats.portals),
        cell_stats: h.cells.as_ref().map(|c| c.stats.clone()),
    }
}

fn row(level: String, counts: impl Iterator<Item = u64>) -> LodRow {
    let (mut n, mut sum, mut min, mut max) = (0u64, 0u64, u64::MAX, 0u64);
    for c in counts {
        n += 1;
        sum += c;
        min = min.min(c);
        max = max.max(c);
    }
    LodRow {
        level,
        objects: n,
        polygons: sum,
        min_per_object: if n == 0 { 0 } else { min },
        mean_per_object: if n == 0 { 0.0 } else { sum as f64 / n as f64 },
        max_per_object: max,
    }
}

impl DbStats {
    /// A human-readable summary with the LOD table laid out like Funkhouser's Table 3.1.
    pub fn to_text(&self) -> String {
        let mut s = format!(
            "{} (format v{}{})\n  objects {}  instances {}  occluders {}  materials {}\n  triangles: highest LOD {}  all LODs {}\n  segments {}  geometry {:.1} MB ({:.1} B per stored triangle{})  file {:.1} MB\n",
            self.name,
            self.format_version,
            if self.flattened { ", flattened" } else { "" },
            self.objects,
            self.instances,
            self.occluders,
            self.materials,
            self.triangles_highest,
            self.triangles_all_lods,
            self.segments,
            self.geometry_bytes as f64 / 1e6,
            self.geometry_bytes as f64 / self.triangles_stored.max(1) as f64,
            if self.compressed_segments > 0 {
                format!(
                    "; {} segments meshopt-compressed, {:.1} MB decoded",
                    self.compressed_segments,
                    self.geometry_decoded_bytes as f64 / 1e6
                )
            } else {
                String::new()
            },
            self.file_bytes as f64 / 1e6,
        );
        let [lo, hi] = self.bounds;
        s.push_str(&format!(
            "  bounds ({:.2}, {:.2}, {:.2}) to ({:.2}, {:.2}, {:.2}) m",
            lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
        ));
        if self.origin != [0.0; 3] {
            let o = self.origin;
            s.push_str(&format!(
                " from the local origin ({:.3}, {:.3}, {:.3}) (metres, Y up)",
                o[0], o[1], o[2]
            ));
        }
        for (source, frame) in &self.frames {
            let file = std::path::Path::new(source)
                .file_name()
                .map_or(source.clone(), |f| f.to_string_lossy().into_owned());
            s.push_str(&format!("\n  {file}: {}", frame.describe()));
        }
        s.push_str("\n\n");
        s.push_str(&format!(
            "  {:<12} {:>10} {:>12} {:>8} {:>10} {:>8}\n",
            "LOD", "objects", "polygons", "min", "mean", "max"
        ));
        for r in &self.lod_table {
            s.push_str(&format!(
                "  {:<12} {:>10} {:>12} {:>8} {:>10.2} {:>8}\n",
                r.level,
                r.objects,
                r.polygons,
                r.min_per_object,
                r.mean_per_object,
                r.max_per_object
            ));
        }
        if let Some(c) = &self.cell_stats {
            s.push_str(&format!(
                "\n  cells {} ({} live), portals {}, occluder faces {}{}\n",
                c.cells,
                c.live_cells,
                c.portals,
                c.occluder_boxes,
                if c.grid_fallback {
                    " (grid fallback)"
                } else {
                    ""
                },
            ));
            s.push_str(&format!(
                "\n  {:<28} {:>10} {:>8}\n",
                "per live cell", "mean", "max"
            ));
            for (name, (mean, max)) in [
                ("portals", c.portals_per_cell),
                ("objects completely inside", c.objects_inside),
                ("objects partially inside", c.objects_partial),
                ("cells visible", c.cells_visible),
                ("objects visible", c.objects_visible),
            ] {
                s.push_str(&format!("  {name:<28} {mean:>10.2} {max:>8}\n"));
            }
        }
        if self.textures > 0 {
            s.push_str(&format!(
                "\n  textures {}: {:.1} MB of mip segments ({:.0} % of the file; {:.1} MB decoded as RGBA8, {:.1} MB block-compressed, every segment a whole chain), {:.2} MB of them coarse, the longest piece on the wire {:.1} KB, {}\n",
                self.textures,
                self.mip_bytes as f64 / 1e6,
                100.0 * self.mip_bytes as f64 / self.file_bytes.max(1) as f64,
                self.mip_texel_bytes as f64 / 1e6,
                self.mip_block_bytes as f64 / 1e6,
                self.coarse_mip_bytes as f64 / 1e6,
                self.largest_mip_piece as f64 / 1e3,
                self.texture_psnr.map_or("all lossless".to_string(), |p| format!("PSNR at least {p:.1} dB")),
            ));
            const LISTED: usize = 12;
            for t in self.texture_list.iter().take(LISTED) {
                s.push_str(&format!(
                    "    {:<32} {:>5}x{:<5} {:>2} segments {:>9.1} KB  {}\n",
                    t.name,
                    t.width,
                    t.height,
                    t.segments,
                    t.bytes as f64 / 1e3,
                    t.psnr
                        .map_or("lossless".to_string(), |p| format!("{p:.1} dB"))
                ));
            }
            if self.texture_list.len() > LISTED {
                s.push_str(&format!(
                    "    ... and {} more\n",
                    self.texture_list.len() - LISTED
                ));
            }
        }
        if self.clusters > 0 {
            s.push_str(&format!(
                "\n  clusters {} ({} with textured boxes, {:.1} MB of atlases), depth {}\n",
                self.clusters,
                self.textured_clusters,
                self.texture_bytes as f64 / 1e6,
                self.hierarchy_depth
            ));
        }
        s
    }
}
