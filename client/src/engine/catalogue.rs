//! What a client knows of the model before it draws: the segment table (each segment's size and
//! checksum, to size reads and reject damaged bytes), what kind each segment is (to decode it)
//! and what it occupies decoded (to keep the IO window), made once from the whole manifest or
//! from the core manifest ([`Start`]), and grown page by page ([`crate::engine::pages`]).
//!
//! Funkhouser §3.1 and Fig. 3.23: the display database's header and index; the paged start
//! cuts it along the stab lists (§5.2: a client needs only what its observer range sees).

use portico_data::cells::CellGraph;
use portico_data::cells::StabList;
use portico_data::cells::paged::GraphCore;
use portico_data::format::{CellPage, Header, UNKNOWN_ROW, take_rows};
use portico_data::geometry::Aabb;
use portico_data::texture::{TexelFormat, Wrap};
use portico_protocol::{CoreManifest, Manifest, SegmentInfo};
use std::borrow::Cow;
use std::collections::{HashMap, HashSet};

/// Each segment's row and kind, and what it occupies decoded.
#[derive(Debug, Clone, Default)]
pub struct Catalogue {
    /// The manifest's segment table, by id (started from the core manifest: the rows the pages
    /// have brought so far, the rest [`UNKNOWN_ROW`]).
    pub segments: Vec<SegmentInfo>,
    /// Ids of the stab-list segments.
    pub stabs: HashSet<u32>,
    /// Impostor atlas segments: the box and atlas tile of the cluster each belongs to (Maciel
    /// & Shirley's textured clusters).
    pub textures: HashMap<u32, (Aabb, u32)>,
    /// Material texture segments (mip chains) and how their texture wraps.
    pub mips: HashMap<u32, [Wrap; 2]>,
    /// Geometry and texture segments by the bytes they occupy decoded (geometry: more than its
    /// wire length when compressed; textures: what the GPU holds in the client's texel format).
    pub decoded: HashMap<u32, u64>,
}

/// What a segment is, for decoding it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Kind {
    /// A cell's stab list.
    Stab,
    /// A cluster's textured box: its bounds and atlas tile.
    Impostor(Aabb, u32),
    /// A material texture's mip chain and how it wraps.
    Texture([Wrap; 2]),
    /// An LOD's geometry, with its decoded size by its LOD record when known.
    Geometry(Option<u64>),
}

impl Catalogue {
    /// The catalogue of `header` with the segment table `segments`, for a client holding
    /// textures as `texels`.
    pub fn new(header: &Header, segments: Vec<SegmentInfo>, texels: TexelFormat) -> Catalogue {
        Catalogue {
            segments,
            stabs: header
                .cells
                .as_ref()
                .map(|c| c.stab_lists().map(|(s, _)| s).collect())
                .unwrap_or_default(),
            textures: header
                .hierarchy
                .iter()
                .flat_map(|h| &h.nodes)
                .filter(|n| n.texture != u32::MAX)
                .map(|n| (n.texture, (n.bounds, n.tile)))
                .collect(),
            mips: header
                .textures
                .iter()
                .flat_map(|t| t.segments.iter().map(move |s| (s.segment, t.wrap)))
                .collect(),
            decoded: header.decoded_sizes(texels).collect(),
        }
    }

    /// Segment `id`'s bytes on the wire (0 when unknown).
    pub fn wire(&self, id: u32) -> u64 {
        self.segments.get(id as usize).map_or(0, |s| s.bytes)
    }

    /// What segment `id` occupies once decoded, at least its wire bytes (the IO window counts
    /// this).
    pub fn held(&self, id: u32) -> u64 {
        let wire = self.wire(id);
        self.decoded.get(&id).map_or(wire, |&d| d.max(wire))
    }

    /// Whether segment `id`'s row is known (a paged client learns rows page by page).
    pub fn known(&self, id: u32) -> bool {
        self.segments.get(id as usize).is_some_and(|r| r.kind != 0)
    }

    /// Checks a segment's bytes against its row (size and xxh3, the strong ETag): a segment
    /// damaged on the way is rejected, never decoded.
    ///
    /// # Errors
    /// One line naming the segment: not in the manifest (or its row not known yet), truncated
    /// or corrupt.
    pub fn verify(&self, id: u32, bytes: &[u8]) -> Result<(), String> {
        let row = self.segments.get(id as usize).filter(|r| r.kind != 0);
        portico_protocol::verify_segment(row, id, bytes)
    }

    /// What segment `id` is.
    pub fn kind(&self, id: u32) -> Kind {
        if let Some(&(bounds, tile)) = self.textures.get(&id) {
            Kind::Impostor(bounds, tile)
        } else if let Some(&wrap) = self.mips.get(&id) {
            Kind::Texture(wrap)
        } else if self.stabs.contains(&id) {
            Kind::Stab
        } else {
            Kind::Geometry(self.decoded.get(&id).copied())
        }
    }

    /// Takes a page's rows, and its instances' LODs' decoded sizes (`core`: the header the
    /// page was checked against).
    pub fn take_page(&mut self, core: &Header, page: &CellPage) {
        take_rows(&mut self.segments, page);
        for (_, inst) in &page.instances {
            for l in core.lods_of(inst) {
                let size = portico_data::geometry::plain_size(l.vertices, l.triangles, l.uv);
                self.decoded.insert(l.segment, size);
            }
        }
    }
}

/// A stab-list segment decoded.
///
/// # Errors
/// One line naming the segment: it does not decode.
pub fn decode_stab(id: u32, bytes: &[u8]) -> Result<StabList, String> {
    portico_data::format::decode_segment::<StabList>(bytes)
        .map_err(|e| format!("segment {id}: {e}"))
}

/// A geometry segment in the layout GPUs bind: a compressed one decoded (after its counts are
/// checked against its LOD record's `expected` size), a plain one as it is.
///
/// # Errors
/// One line naming the segment: it does not decode, or not to the expected size.
pub fn plain_geometry(
    id: u32,
    bytes: &[u8],
    expected: Option<u64>,
) -> Result<Cow<'_, [u8]>, String> {
    portico_data::codec::to_gpu_layout_as(id, bytes, expected)
}

/// What a client starts a walkthrough from: the header (sparse when paged: placeholders until
/// pages bring the instances), the cell graph (likewise), the instances' bounds and the
/// catalogue.
#[derive(Debug)]
pub struct Start {
    /// The model header.
    pub header: Header,
    /// The cell graph, when the model has cells.
    pub graph: Option<CellGraph>,
    /// Every instance's bounds (placeholders' until their page comes).
    pub bounds: Vec<Aabb>,
    /// The segments.
    pub catalogue: Catalogue,
    /// The database the manifest describes.
    pub database_id: String,
    /// Triangles of the whole model at its finest LODs.
    pub model_triangles: u64,
    /// Started from the core manifest: the pages to learn (and the core they are checked
    /// against).
    pub pages: Option<crate::engine::pages::Pages>,
}

impl Start {
    /// From the whole manifest and cell graph.
    ///
    /// # Errors
    /// One line: the manifest's hierarchy names what does not exist.
    pub fn whole(
        manifest: Manifest<Header>,
        graph: Option<CellGraph>,
        texels: TexelFormat,
    ) -> Result<Start, String> {
        let triangles = manifest.header.finest_triangles();
        Start::of(
            manifest.header,
            graph,
            manifest.segments,
            texels,
            manifest.database_id,
            triangles,
            None,
        )
    }

    /// From the core manifest: a sparse header and graph, the rows no instance owns, and the
    /// pages to learn the rest from.
    ///
    /// # Errors
    /// One line: the core does not fit together ([`portico_data::format::check_core`]).
    pub fn paged(
        core: CoreManifest<Header, GraphCore>,
        texels: TexelFormat,
    ) -> Result<Start, String> {
        portico_data::format::check_core(
            &core.header,
            core.segment_count,
            core.instance_count,
            core.graph.as_ref(),
        )?;
        // The cell graph grows page by page too: its cells and portals come with the stab lists.
        let graph = core.graph.as_ref().map(CellGraph::sparse);
        let mut rows = vec![UNKNOWN_ROW; core.segment_count as usize];
        for &(s, r) in &core.rows {
            if let Some(slot) = rows.get_mut(s as usize) {
                *slot = r;
            }
        }
        let pages =
            crate::engine::pages::Pages::new(core.header.core(), core.instance_count, core.graph);
        let header = Header::sparse(core.header, core.instance_count);
        Start::of(
            header,
            graph,
            rows,
            texels,
            core.database_id,
            core.triangles,
            Some(pages),
        )
    }

    fn of(
        header: Header,
        graph: Option<CellGraph>,
        segments: Vec<SegmentInfo>,
        texels: TexelFormat,
        database_id: String,
        model_triangles: u64,
        pages: Option<crate::engine::pages::Pages>,
    ) -> Result<Start, String> {
        let bounds: Vec<Aabb> = header.instances.iter().map(|i| i.bounds).collect();
        // Indices from the manifest are used as they are from here on: check them once.
        if let Some(h) = &header.hierarchy {
            h.check(&bounds)
                .map_err(|e| format!("the manifest's hierarchy: {e}"))?;
        }
        let catalogue = Catalogue::new(&header, segments, texels);
        Ok(Start {
            header,
            graph,
            bounds,
            catalogue,
            database_id,
            model_triangles,
            pages,
        })
    }

    /// Takes a page the IO stage handed on with its stab list: its instances into the header
    /// and their bounds, its part of the cell graph into the graph. Returns the instances it
    /// brought.
    pub fn learn(
        header: &mut Header,
        graph: Option<&mut CellGraph>,
        bounds: &mut [Aabb],
        page: &CellPage,
    ) -> Vec<u32> {
        let new = header.take_page(page);
        for &i in &new {
            if let (Some(b), Some(inst)) =
                (bounds.get_mut(i as usize), header.instances.get(i as usize))
            {
                *b = inst.bounds;
            }
        }
        if let Some(g) = graph {
            g.take_part(&page.graph);
        }
        new
    }
}
