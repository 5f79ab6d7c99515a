//! The header: everything about the model except the geometry bytes (Funkhouser Fig. 3.23:
//! object definitions, instances and their LOD tables), bincode-encoded.

use super::{SegmentEntry, SegmentKind};
use crate::geometry::Aabb;
use crate::model::Material;
use crate::texture::TextureRecord;
use serde::{Deserialize, Serialize};

/// The decoded header of a display database.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Model name (the first source file's stem).
    pub name: String,
    /// The model files it was built from.
    pub sources: Vec<String>,
    /// Each source's unit and up axis ([`crate::frame`]), in the order of `sources`: the
    /// model was converted from it to metres, Y up.
    pub frames: Vec<crate::frame::SourceFrame>,
    /// Whether instances carry their own baked geometry (`portico build --flatten`).
    pub flattened: bool,
    /// Bounds of the whole model, relative to `origin`.
    pub bounds: Aabb,
    /// Where the model's local origin lies (metres, Y up, double precision): add it to any
    /// position to place the model back in the world (survey coordinates), then undo the
    /// source's frame (`frames`) for the file's own numbers. Zero for models built near their
    /// own origin.
    pub origin: [f64; 3],
    /// Materials (index 0 is the default).
    pub materials: Vec<Material>,
    /// Base-colour textures, their mip segments coarsest first ([`crate::texture`]).
    pub textures: Vec<TextureRecord>,
    /// Object definitions.
    pub objects: Vec<ObjectRecord>,
    /// Object instances.
    pub instances: Vec<InstanceRecord>,
    /// Cells, portals and precomputed visibility, when built.
    pub cells: Option<CellIndex>,
    /// The model hierarchy of clusters with their impostors (Maciel §6.3), when built.
    pub hierarchy: Option<crate::hierarchy::Hierarchy>,
}

/// Where the cell data lives (Funkhouser Fig. 3.23: cells, portals, stab lists).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellIndex {
    /// Segment holding the bincode [`crate::cells::CellGraph`].
    pub graph_segment: u32,
    /// Segment holding the occluder faces (`Vec<Aabb>`).
    pub occluder_segment: u32,
    /// Per cell, the segment of its [`crate::cells::StabList`] (`u32::MAX` for dead cells).
    pub stab_segments: Vec<u32>,
    /// Table 3.2 statistics and precomputation times.
    pub stats: crate::cells::CellStats,
}

impl CellIndex {
    /// The segment of cell `cell`'s stab list; `None` for a dead cell or one that does not
    /// exist.
    pub fn stab_segment(&self, cell: u32) -> Option<u32> {
        self.stab_segments
            .get(cell as usize)
            .copied()
            .filter(|&s| s != u32::MAX)
    }

    /// Every live cell's stab-list segment, with the cell: `(segment, cell)`.
    pub fn stab_lists(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        (0..self.stab_segments.len() as u32).filter_map(|c| Some((self.stab_segment(c)?, c)))
    }

    /// The cell of each stab-list segment.
    pub fn stab_cells(&self) -> std::collections::HashMap<u32, u32> {
        self.stab_lists().collect()
    }
}

/// One LOD of an object: where its geometry is and what it costs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LodRecord {
    /// Geometry segment id.
    pub segment: u32,
    /// Triangle count.
    pub triangles: u32,
    /// Vertex count.
    pub vertices: u32,
    /// Geometric error (metres) against the finest LOD: the benefit's accuracy term uses it.
    pub error: f32,
    /// Whether the segment carries texture coordinates ([`crate::geometry::GEOMETRY_UV`]).
    pub uv: bool,
}

/// An object definition.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectRecord {
    /// Name from the source.
    pub name: String,
    /// Bounds of the finest LOD in the definition's coordinates.
    pub bounds: Aabb,
    /// Default material.
    pub material: u32,
    /// LODs, finest first.
    pub lods: Vec<LodRecord>,
    /// How many times the texture repeats across the object ([`crate::geometry::Mesh::uv_span`]
    /// of its finest LOD; 0 without texture coordinates).
    pub uv_span: f32,
}

/// A placed object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstanceRecord {
    /// Name from the source.
    pub name: String,
    /// Index into [`Header::objects`].
    pub object: u32,
    /// Column-major object-to-world matrix (identity when `lods` holds world-space geometry).
    pub transform: [f32; 16],
    /// Material index.
    pub material: u32,
    /// World-space bounds.
    pub bounds: Aabb,
    /// Structural occluder (wall, floor, ceiling).
    pub occluder: bool,
    /// Tags from the source (`kind`, `room`, `storey`, ...), sorted by key.
    pub tags: Vec<(String, String)>,
    /// This instance's own LODs (world space, e.g. baked lighting), overriding the definition's
    /// (Funkhouser §3.1: instances may store their own geometry). `None` = inherit.
    pub lods: Option<Vec<LodRecord>>,
}

impl InstanceRecord {
    /// The value of a tag, if present.
    pub fn tag(&self, key: &str) -> Option<&str> {
        self.tags
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

impl Header {
    /// Every LOD's geometry segment and every texture segment with the bytes it occupies
    /// decoded on a GPU that holds texels as `texels` ([`crate::geometry::plain_size`],
    /// [`crate::texture::MipSegment::gpu_bytes`]): a compressed segment's wire length says
    /// less, and a cache is charged what it decodes to.
    pub fn decoded_sizes(
        &self,
        texels: crate::texture::TexelFormat,
    ) -> impl Iterator<Item = (u32, u64)> + '_ {
        self.objects
            .iter()
            .flat_map(|o| &o.lods)
            .chain(self.instances.iter().flat_map(|i| i.lods.iter().flatten()))
            .map(|l| {
                (
                    l.segment,
                    crate::geometry::plain_size(l.vertices, l.triangles, l.uv),
                )
            })
            .chain(
                self.textures
                    .iter()
                    .flat_map(|t| &t.segments)
                    .map(move |s| (s.segment, s.gpu_bytes(texels))),
            )
    }

    /// What each segment costs a client's cache on a GPU that holds texels as `texels`, by
    /// id, from the segments' `wire` lengths: a texture segment its GPU bytes (the coded image
    /// is dropped once decoded; its parts nothing), a geometry segment the larger of its wire
    /// and decoded sizes, anything else its wire length. The server's lookahead and the load tester both count
    /// with it, so that their geometry and textures agree with the clients' (impostor atlases
    /// are counted at their wire length here, at their GPU bytes by the clients).
    pub fn cache_charges(&self, wire: &[u64], texels: crate::texture::TexelFormat) -> Vec<u64> {
        let mut charges = wire.to_vec();
        for (seg, plain) in self.decoded_sizes(texels) {
            if let Some(c) = charges.get_mut(seg as usize) {
                *c = (*c).max(plain);
            }
        }
        for s in self.textures.iter().flat_map(|t| &t.segments) {
            // The head holds the texture once its parts have joined it; they hold nothing.
            for (k, id) in s.ids().enumerate() {
                if let Some(c) = charges.get_mut(id as usize) {
                    *c = if k == 0 { s.gpu_bytes(texels) } else { 0 };
                }
            }
        }
        charges
    }

    /// The LODs an instance draws with: its own, else its definition's (finest first).
    pub fn lods_of<'a>(&'a self, inst: &'a InstanceRecord) -> &'a [LodRecord] {
        match &inst.lods {
            Some(l) => l,
            None => self
                .objects
                .get(inst.object as usize)
                .map_or(&[], |o| &o.lods),
        }
    }

    /// The texture an instance is drawn with, if its material has one.
    pub fn texture_of(&self, inst: &InstanceRecord) -> Option<&TextureRecord> {
        let m = self.materials.get(inst.material as usize)?;
        self.textures.get(m.texture? as usize)
    }

    /// Checks every cross-reference against the segment index, so later lookups cannot fail.
    pub fn validate(&self, segments: &[SegmentEntry]) -> Result<(), String> {
        let check_lods = |lods: &[LodRecord], what: &dyn Fn() -> String| -> Result<(), String> {
            if lods.is_empty() {
                return Err(format!("{} has no LODs", what()));
            }
            for l in lods {
                let seg = segments
                    .get(l.segment as usize)
                    .ok_or_else(|| format!("{} refers to missing segment {}", what(), l.segment))?;
                if SegmentKind::from_u16(seg.kind) != Some(SegmentKind::Geometry) {
                    return Err(format!(
                        "{} refers to non-geometry segment {}",
                        what(),
                        l.segment
                    ));
                }
            }
            Ok(())
        };
        for (i, m) in self.materials.iter().enumerate() {
            if let Some(t) = m.texture.filter(|&t| t as usize >= self.textures.len()) {
                return Err(format!(
                    "material {i} has texture {t} of {}",
                    self.textures.len()
                ));
            }
        }
        // Every texture segment and part belongs to one record only (a client joins parts by
        // these ids).
        let mut claimed = std::collections::HashSet::new();
        for (i, t) in self.textures.iter().enumerate() {
            if t.segments.is_empty() {
                return Err(format!("texture {i} has no segments"));
            }
            for s in &t.segments {
                if !s.is_valid() {
                    return Err(format!(
                        "texture {i}'s segment {} claims {}x{} texels in {} levels",
                        s.segment, s.width, s.height, s.levels
                    ));
                }
                // Coded segments are at most their raw form (the build keeps the smaller),
                // head and parts together; the parts follow the head, each of their kind.
                let most = crate::texture::TEXTURE_HEADER as u64 + s.texel_bytes();
                if u64::from(s.parts) > most / crate::texture::MIN_PART_BYTES as u64 + 1 {
                    return Err(format!(
                        "texture {i}'s segment {} claims {} parts",
                        s.segment, s.parts
                    ));
                }
                if s.segment.checked_add(s.parts).is_none() {
                    return Err(format!(
                        "texture {i}'s segment {} claims {} parts",
                        s.segment, s.parts
                    ));
                }
                let mut total = 0u64;
                for (k, id) in s.ids().enumerate() {
                    if !claimed.insert(id) {
                        return Err(format!(
                            "texture {i}'s segment {id} belongs to another texture segment too"
                        ));
                    }
                    let seg = segments
                        .get(id as usize)
                        .ok_or_else(|| format!("texture {i} refers to missing segment {id}"))?;
                    let kind = if k == 0 {
                        SegmentKind::Mips
                    } else {
                        SegmentKind::MipPart
                    };
                    if SegmentKind::from_u16(seg.kind) != Some(kind) {
                        return Err(format!("texture {i}'s segment {id} has the wrong kind"));
                    }
                    total = total.saturating_add(seg.raw_length);
                }
                if !(crate::texture::TEXTURE_HEADER as u64..=most).contains(&total) {
                    return Err(format!(
                        "texture {i}'s segment {} has the wrong size",
                        s.segment
                    ));
                }
            }
        }
        for (i, o) in self.objects.iter().enumerate() {
            // A flattened database may leave definitions without shared geometry.
            if !o.lods.is_empty() {
                check_lods(&o.lods, &|| format!("object {i}"))?;
            }
            if o.material as usize >= self.materials.len() {
                return Err(format!(
                    "object {i} has material {} of {}",
                    o.material,
                    self.materials.len()
                ));
            }
        }
        if let Some(c) = &self.cells {
            let kind = |id: u32, want: SegmentKind, what: &str| -> Result<(), String> {
                let seg = segments
                    .get(id as usize)
                    .ok_or_else(|| format!("{what} refers to missing segment {id}"))?;
                if SegmentKind::from_u16(seg.kind) != Some(want) {
                    return Err(format!("{what} segment {id} has the wrong kind"));
                }
                Ok(())
            };
            kind(c.graph_segment, SegmentKind::CellGraph, "cell graph")?;
            kind(c.occluder_segment, SegmentKind::Occluders, "occluders")?;
            for &s in c.stab_segments.iter().filter(|&&s| s != u32::MAX) {
                kind(s, SegmentKind::StabList, "stab list")?;
            }
        }
        if let Some(h) = &self.hierarchy {
            let bounds: Vec<crate::geometry::Aabb> =
                self.instances.iter().map(|i| i.bounds).collect();
            h.check(&bounds).map_err(|e| format!("hierarchy: {e}"))?;
            for (n, c) in h.nodes.iter().enumerate() {
                if c.texture == u32::MAX {
                    continue;
                }
                let seg = segments.get(c.texture as usize).ok_or_else(|| {
                    format!("cluster {n} refers to missing segment {}", c.texture)
                })?;
                if SegmentKind::from_u16(seg.kind) != Some(SegmentKind::Texture) {
                    return Err(format!("cluster {n}'s texture segment has the wrong kind"));
                }
            }
        }
        for (i, inst) in self.instances.iter().enumerate() {
            if inst.object as usize >= self.objects.len() {
                return Err(format!(
                    "instance {i} refers to missing object {}",
                    inst.object
                ));
            }
            if inst.material as usize >= self.materials.len() {
                return Err(format!(
                    "instance {i} has material {} of {}",
                    inst.material,
                    self.materials.len()
                ));
            }
            if inst.transform.iter().any(|x| !x.is_finite()) {
                return Err(format!("instance {i} has a non-finite transform"));
            }
            check_lods(self.lods_of(inst), &|| format!("instance {i}"))?;
        }
        Ok(())
    }
}
