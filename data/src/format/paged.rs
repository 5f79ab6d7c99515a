//! The header cut into pages (the paged manifest of [`portico_protocol::CoreManifest`] and
//! [`portico_protocol::Page`]): the server's side makes the core and each cell's page from the
//! whole header; the client's side grows a sparse header from them.
//!
//! The cut follows the stab lists (Funkhouser §3.2.3, Fig. 3.22): a cell's page holds every
//! instance its stab list names, so a client that holds a cell's stab list knows everything the
//! list lets it see, and the instances it knows nothing of are ones no list it holds names.

use super::{Header, InstanceRecord, SegmentKind};
use crate::cells::paged::GraphPart;
use crate::cells::{CellGraph, StabList};
use crate::geometry::Aabb;
use portico_protocol::SegmentInfo;

/// A cell's page of a Portico model ([`portico_protocol::Page`] with the data crate's types).
pub type CellPage = portico_protocol::Page<InstanceRecord, GraphPart>;

impl Header {
    /// The header without its instance table: what [`portico_protocol::CoreManifest`] carries.
    pub fn core(&self) -> Header {
        Header {
            name: self.name.clone(),
            sources: self.sources.clone(),
            frames: self.frames.clone(),
            flattened: self.flattened,
            bounds: self.bounds,
            origin: self.origin,
            materials: self.materials.clone(),
            textures: self.textures.clone(),
            objects: self.objects.clone(),
            instances: Vec::new(),
            cells: self.cells.clone(),
            hierarchy: self.hierarchy.clone(),
        }
    }

    /// Triangles of the whole model at each instance's finest LOD.
    pub fn finest_triangles(&self) -> u64 {
        self.instances
            .iter()
            .filter_map(|i| self.lods_of(i).first())
            .map(|l| l.triangles as u64)
            .sum()
    }

    /// The segments no instance owns (cell graph, occluders, impostor atlases, material texture
    /// mips and their parts): the core manifest carries their rows. Stab lists are not among them: each comes
    /// with its cell's page.
    pub fn unowned_segments(&self) -> Vec<u32> {
        let mut ids: Vec<u32> = self
            .cells
            .iter()
            .flat_map(|c| [c.graph_segment, c.occluder_segment])
            .chain(
                self.hierarchy
                    .iter()
                    .flat_map(|h| &h.nodes)
                    .map(|n| n.texture)
                    .filter(|&t| t != u32::MAX),
            )
            .chain(
                self.textures
                    .iter()
                    .flat_map(|t| t.segments.iter().flat_map(|s| s.ids())),
            )
            .collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    /// Cell `cell`'s page: the instances `stab` names, with the rows (`row(id)`) of their LOD
    /// segments and of the stab list's own segment `stab_segment`, and the part of `graph` the
    /// list reaches ([`CellGraph::part`]).
    pub fn page(
        &self,
        cell: u32,
        stab_segment: u32,
        stab: &StabList,
        row: &dyn Fn(u32) -> SegmentInfo,
        graph: &CellGraph,
    ) -> CellPage {
        let instances: Vec<(u32, InstanceRecord)> = stab
            .objects()
            .into_iter()
            .chain(stab.inside.iter().chain(&stab.partial).copied())
            .collect::<std::collections::BTreeSet<u32>>()
            .into_iter()
            .filter_map(|i| Some((i, self.instances.get(i as usize)?.clone())))
            .collect();
        let mut segments: Vec<u32> = instances
            .iter()
            .flat_map(|(_, inst)| self.lods_of(inst).iter().map(|l| l.segment))
            .collect();
        segments.sort_unstable();
        segments.dedup();
        CellPage {
            cell,
            stab: (stab_segment, row(stab_segment)),
            instances,
            segments: segments.into_iter().map(|s| (s, row(s))).collect(),
            graph: graph.part(stab),
        }
    }

    /// A sparse header to grow from pages: `core` (a [`Header::core`]) with `instances`
    /// placeholders ([`InstanceRecord::placeholder`]).
    pub fn sparse(core: Header, instances: u32) -> Header {
        Header {
            instances: vec![InstanceRecord::placeholder(); instances as usize],
            ..core
        }
    }

    /// Checks a page against this header (a core or a sparse one, of `instances` instances)
    /// and a segment table of `segments` rows, as [`Header::validate`] checks the whole: its
    /// stab list is the cell's, with a stab list's row; each instance exists, its object and
    /// material exist, its transform is finite, its LODs are geometry rows of the page; every
    /// row names an existing segment, and is a geometry row (a page never rewrites the core's
    /// rows). The part of the cell graph is checked by
    /// [`crate::cells::paged::GraphCore::check_part`]. A checked page can be taken without
    /// further checks ([`Header::take_page`], [`take_rows`]).
    ///
    /// # Errors
    /// One line naming the cell and the instance or segment at fault.
    pub fn check_page(
        &self,
        instances: u32,
        segments: usize,
        page: &CellPage,
    ) -> Result<(), String> {
        let at = |what: String| format!("page of cell {}: {what}", page.cell);
        for &(s, _) in page.segments.iter().chain([&page.stab]) {
            if s as usize >= segments {
                return Err(at(format!("segment {s} of {segments}")));
            }
        }
        let own = self
            .cells
            .as_ref()
            .and_then(|c| c.stab_segments.get(page.cell as usize))
            .copied()
            .filter(|&s| s != u32::MAX);
        if own != Some(page.stab.0) || page.stab.1.kind != SegmentKind::StabList as u16 {
            return Err(at(format!(
                "names stab list segment {} (kind {}), the cell's is {own:?}",
                page.stab.0, page.stab.1.kind
            )));
        }
        let geometry = SegmentKind::Geometry as u16;
        if let Some((s, r)) = page.segments.iter().find(|(_, r)| r.kind != geometry) {
            return Err(at(format!(
                "segment {s}'s row is of kind {}, not geometry",
                r.kind
            )));
        }
        let known: std::collections::HashMap<u32, SegmentInfo> =
            page.segments.iter().copied().collect();
        for (id, inst) in &page.instances {
            let what = |e: &str| at(format!("instance {id} {e}"));
            if *id >= instances {
                return Err(what(&format!("of {instances}")));
            }
            if inst.object as usize >= self.objects.len()
                || inst.material as usize >= self.materials.len()
            {
                return Err(what("names a missing object or material"));
            }
            if inst.transform.iter().any(|x| !x.is_finite()) {
                return Err(what("has a non-finite transform"));
            }
            let lods = self.lods_of(inst);
            if lods.is_empty() {
                return Err(what("has no LODs"));
            }
            if let Some(l) = lods
                .iter()
                .find(|l| known.get(&l.segment).is_none_or(|r| r.kind != geometry))
            {
                return Err(what(&format!(
                    "has LOD segment {} without a geometry row",
                    l.segment
                )));
            }
        }
        Ok(())
    }

    /// Takes a checked page ([`Header::check_page`]) into a sparse header: each of its
    /// instances replaces its placeholder. Returns the instances that were new.
    pub fn take_page(&mut self, page: &CellPage) -> Vec<u32> {
        let mut new = Vec::new();
        for (id, inst) in &page.instances {
            let Some(slot) = self.instances.get_mut(*id as usize) else {
                continue;
            };
            if slot.is_placeholder() {
                new.push(*id);
            }
            *slot = inst.clone();
        }
        new
    }
}

/// Checks a core manifest's counts before anything is sized by them: at most
/// [`MAX_PAGED_COUNT`] instances, segments, cells and portals; one stab list entry per cell of
/// the graph, each naming an existing segment; a finite graph box.
///
/// # Errors
/// One line naming the count or the entry at fault.
pub fn check_core(
    header: &Header,
    segments: u32,
    instances: u32,
    graph: Option<&crate::cells::paged::GraphCore>,
) -> Result<(), String> {
    let big = |what: &str, n: u32| {
        if n > MAX_PAGED_COUNT {
            Err(format!(
                "the core manifest claims {n} {what}, at most {MAX_PAGED_COUNT}"
            ))
        } else {
            Ok(())
        }
    };
    big("segments", segments)?;
    big("instances", instances)?;
    match (&header.cells, graph) {
        (None, None) => Ok(()),
        (Some(c), Some(g)) => {
            big("cells", g.cells)?;
            big("portals", g.portals)?;
            if c.stab_segments.len() != g.cells as usize {
                return Err(format!(
                    "the core manifest lists {} stab lists for {} cells",
                    c.stab_segments.len(),
                    g.cells
                ));
            }
            if let Some(s) = c
                .stab_segments
                .iter()
                .find(|&&s| s != u32::MAX && s >= segments)
            {
                return Err(format!(
                    "the core manifest's stab list segment {s} of {segments}"
                ));
            }
            if !g
                .bounds
                .min
                .iter()
                .chain(&g.bounds.max)
                .all(|x| x.is_finite())
            {
                return Err("the core manifest's cell graph box is not finite".into());
            }
            Ok(())
        }
        _ => Err("the core manifest has a cell index without a graph, or the reverse".into()),
    }
}

/// Most instances, segments, cells or portals a core manifest may claim (2^26: flattened
/// `mega` has 463,421 segments).
pub const MAX_PAGED_COUNT: u32 = 1 << 26;

/// Takes a checked page's rows ([`Header::check_page`]) into a client's segment table.
pub fn take_rows(rows: &mut [SegmentInfo], page: &CellPage) {
    for &(s, r) in page.segments.iter().chain([&page.stab]) {
        if let Some(slot) = rows.get_mut(s as usize) {
            *slot = r;
        }
    }
}

impl InstanceRecord {
    /// An instance a sparse header knows nothing of yet: no LODs, empty bounds (no view
    /// touches it), so it draws nothing and no list names its segments.
    pub fn placeholder() -> InstanceRecord {
        InstanceRecord {
            name: String::new(),
            object: 0,
            transform: glam::Mat4::IDENTITY.to_cols_array(),
            material: 0,
            bounds: Aabb::EMPTY,
            occluder: false,
            tags: Vec::new(),
            lods: Some(Vec::new()),
        }
    }

    /// Whether this is a [`InstanceRecord::placeholder`].
    pub fn is_placeholder(&self) -> bool {
        self.lods.as_ref().is_some_and(|l| l.is_empty()) && self.bounds.is_empty()
    }
}

/// A row no page has brought yet: zero bytes, so no segment matches it.
pub const UNKNOWN_ROW: SegmentInfo = SegmentInfo {
    kind: 0,
    bytes: 0,
    checksum: 0,
};
