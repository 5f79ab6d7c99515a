//! Opens a display database read-only through a memory map and validates everything it touches:
//! the prologue (magic, version, its checksum, the file length), the segment index (checksum,
//! bounds, alignment, kinds), the header (checksum, decoding, cross-references). Segment payloads
//! are checked against their checksum the first time they are handed out, and the result is
//! remembered, so a server pays for each segment's check once.
//!
//! Segments come out as `bytes::Bytes` slices of the map: zero-copy, cheap to clone, and safe to
//! send to a socket. The file must not be truncated in place while mapped (SIGBUS); rebuilds
//! rename a new file over it instead (see `writer`).

use super::decode_segment;
use super::{
    FORMAT_VERSION, Header, LodRecord, MAGIC, PROLOGUE_SIZE, Prologue, SEGMENT_ALIGN, SegmentEntry,
    SegmentKind, bincode_config, checksum, segment_flags,
};
use crate::cells::{CellGraph, StabList};
use crate::error::{DataError, Result};
use crate::geometry::{Aabb, GeometryView};
use bytes::Bytes;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

/// An open, validated display database.
pub struct Database {
    path: PathBuf,
    map: Bytes,
    prologue: Prologue,
    index: Vec<SegmentEntry>,
    header: Header,
    verified: Vec<AtomicBool>,
}

impl std::fmt::Debug for Database {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Database")
            .field("path", &self.path)
            .field("bytes", &self.map.len())
            .field("segments", &self.index.len())
            .finish()
    }
}

impl Database {
    /// Maps and validates the file at `path`.
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| DataError::io(path, e))?;
        // SAFETY: the map is read-only and Portico never modifies a served file in place (a
        // rebuild renames a new file over it). Another process truncating the file would be a
        // SIGBUS, which docs/how-it-works.md warns about; nothing in this process writes to it.
        #[allow(unsafe_code)]
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| DataError::io(path, e))?;
        Self::from_bytes(path, Bytes::from_owner(map))
    }

    /// Validates a database held in memory (tests and fuzzing use this; `open` maps a file).
    pub fn from_bytes(path: &Path, map: Bytes) -> Result<Self> {
        let corrupt = |what: String| DataError::corrupt(path, what);
        let prologue = read_prologue(path, &map)?;
        let index = read_index(&map, &prologue).map_err(corrupt)?;
        let header = read_header(&map, &prologue).map_err(corrupt)?;
        header.validate(&index).map_err(corrupt)?;
        let verified = index.iter().map(|_| AtomicBool::new(false)).collect();
        Ok(Database {
            path: path.to_path_buf(),
            map,
            prologue,
            index,
            header,
            verified,
        })
    }

    /// The file this was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The decoded header (materials, objects, instances).
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The prologue.
    pub fn prologue(&self) -> &Prologue {
        &self.prologue
    }

    /// File size in bytes.
    pub fn file_len(&self) -> u64 {
        self.map.len() as u64
    }

    /// The segment index.
    pub fn segments(&self) -> &[SegmentEntry] {
        &self.index
    }

    /// Segment `id`'s manifest row (kind, bytes, xxh3); [`super::UNKNOWN_ROW`] for an id the
    /// file does not have.
    pub fn row(&self, id: u32) -> portico_protocol::SegmentInfo {
        self.index
            .get(id as usize)
            .map_or(super::UNKNOWN_ROW, |e| portico_protocol::SegmentInfo {
                kind: e.kind,
                bytes: e.length,
                checksum: e.checksum,
            })
    }

    /// The manifest's segment table: every segment's row, by id.
    pub fn rows(&self) -> Vec<portico_protocol::SegmentInfo> {
        (0..self.index.len() as u32)
            .map(|id| self.row(id))
            .collect()
    }

    /// A texture segment's whole bytes: its head's and its parts', joined in order (each
    /// checksum-verified as [`Database::segment`] does).
    ///
    /// # Errors
    /// As [`Database::segment`], for the head or any part.
    pub fn texture_segment(&self, s: &crate::texture::MipSegment) -> Result<Vec<u8>> {
        let mut out = Vec::new();
        for id in s.ids() {
            out.extend_from_slice(&self.segment(id)?);
        }
        Ok(out)
    }

    /// A segment's bytes as a zero-copy slice of the map, checksum-verified on first access.
    pub fn segment(&self, id: u32) -> Result<Bytes> {
        let entry = self
            .index
            .get(id as usize)
            .ok_or_else(|| DataError::NotFound(format!("segment {id} does not exist")))?;
        let bytes = self
            .map
            .slice(entry.offset as usize..(entry.offset + entry.length) as usize);
        if !self.verified[id as usize].load(Ordering::Relaxed) {
            if checksum(&bytes) != entry.checksum {
                return Err(DataError::corrupt(
                    &self.path,
                    format!("segment {id} checksum mismatch"),
                ));
            }
            self.verified[id as usize].store(true, Ordering::Relaxed);
        }
        Ok(bytes)
    }

    /// The bytes of one LOD's geometry segment in the layout GPUs bind (decoded first when the
    /// segment is compressed, [`crate::codec`]), checked to parse (every index in range) and to
    /// agree with its LOD record; borrow its streams with [`GeometryView::parse`].
    pub fn geometry(&self, lod: &LodRecord) -> Result<Bytes> {
        let raw = self.segment(lod.segment)?;
        let disagrees = || {
            DataError::corrupt(
                &self.path,
                format!("segment {} disagrees with its LOD record", lod.segment),
            )
        };
        if let Some(h) = crate::codec::compressed_header(&raw) {
            // Checked before decoding: the record bounds what decoding may allocate.
            if h.vertex_count != lod.vertices || h.index_count as u64 != lod.triangles as u64 * 3 {
                return Err(disagrees());
            }
        }
        let bytes = if crate::codec::is_compressed(&raw) {
            Bytes::from(crate::codec::decode(&raw).map_err(|e| {
                DataError::corrupt(&self.path, format!("segment {}: {e}", lod.segment))
            })?)
        } else {
            raw
        };
        let view = GeometryView::parse(&bytes)
            .map_err(|e| DataError::corrupt(&self.path, format!("segment {}: {e}", lod.segment)))?;
        if view.header.vertex_count != lod.vertices
            || view.header.index_count as u64 != lod.triangles as u64 * 3
        {
            return Err(disagrees());
        }
        Ok(bytes)
    }

    /// The cell graph, if the database has cells.
    pub fn cell_graph(&self) -> Result<Option<CellGraph>> {
        let Some(c) = &self.header.cells else {
            return Ok(None);
        };
        let graph: CellGraph = self.structured(c.graph_segment)?;
        if graph.cells.len() != c.stab_segments.len() {
            return Err(DataError::corrupt(
                &self.path,
                "cell graph and cell index disagree",
            ));
        }
        graph.validate().map_err(|e| {
            DataError::corrupt(
                &self.path,
                format!("cell graph (segment {}): {e}", c.graph_segment),
            )
        })?;
        Ok(Some(graph))
    }

    /// The stab list of one cell (empty for dead cells), if the database has cells.
    pub fn stab_list(&self, cell: u32) -> Result<StabList> {
        let seg = self
            .header
            .cells
            .as_ref()
            .and_then(|c| c.stab_segments.get(cell as usize))
            .ok_or_else(|| DataError::NotFound(format!("cell {cell} does not exist")))?;
        if *seg == u32::MAX {
            return Ok(StabList::default());
        }
        let list: StabList = self.structured(*seg)?;
        let cells = self
            .header
            .cells
            .as_ref()
            .map_or(0, |c| c.stab_segments.len());
        list.validate(cells, self.header.instances.len())
            .map_err(|e| {
                DataError::corrupt(
                    &self.path,
                    format!("stab list of cell {cell} (segment {seg}): {e}"),
                )
            })?;
        Ok(list)
    }

    /// The occluder faces the cells were built from.
    pub fn occluders(&self) -> Result<Vec<Aabb>> {
        match &self.header.cells {
            Some(c) => self.structured(c.occluder_segment),
            None => Ok(Vec::new()),
        }
    }

    fn structured<T: serde::de::DeserializeOwned>(&self, id: u32) -> Result<T> {
        let bytes = self.segment(id)?;
        decode_segment(&bytes)
            .map_err(|e| DataError::corrupt(&self.path, format!("segment {id} {e}")))
    }

    /// Verifies every segment's checksum (and parses every geometry segment).
    pub fn verify_all(&self) -> Result<()> {
        for e in &self.index {
            let bytes = self.segment(e.id)?;
            if SegmentKind::from_u16(e.kind) == Some(SegmentKind::Geometry) {
                crate::codec::to_gpu_layout(&bytes).map_err(|err| {
                    DataError::corrupt(&self.path, format!("segment {}: {err}", e.id))
                })?;
            }
        }
        Ok(())
    }
}

fn read_prologue(path: &Path, map: &[u8]) -> Result<Prologue> {
    if map.len() < MAGIC.len() || map[..MAGIC.len()] != MAGIC {
        return Err(DataError::NotPortico {
            path: path.to_path_buf(),
            model: crate::error::sniff_model(map),
        });
    }
    let Some(head) = map.get(..PROLOGUE_SIZE) else {
        return Err(DataError::Truncated {
            path: path.to_path_buf(),
            expected: PROLOGUE_SIZE as u64,
            actual: map.len() as u64,
        });
    };
    let p: Prologue = bytemuck::pod_read_unaligned(head);
    if p.version != FORMAT_VERSION {
        return Err(DataError::Version {
            path: path.to_path_buf(),
            found: p.version,
            expected: FORMAT_VERSION,
        });
    }
    if p.prologue_checksum != p.compute_checksum() {
        return Err(DataError::corrupt(path, "prologue checksum mismatch"));
    }
    // The padding is outside the checksum (which covers the fields), and is written as zeros:
    // anything else is damage.
    if p.reserved != [0; 6] {
        return Err(DataError::corrupt(path, "prologue padding is not zero"));
    }
    if p.file_len != map.len() as u64 {
        return Err(DataError::Truncated {
            path: path.to_path_buf(),
            expected: p.file_len,
            actual: map.len() as u64,
        });
    }
    Ok(p)
}

fn read_index(map: &[u8], p: &Prologue) -> Result<Vec<SegmentEntry>, String> {
    let entry = std::mem::size_of::<SegmentEntry>() as u64;
    let len = p
        .index_count
        .checked_mul(entry)
        .ok_or("segment index size overflows")?;
    let bytes = slice(map, p.index_offset, len).ok_or("segment index lies outside the file")?;
    if checksum(bytes) != p.index_checksum {
        return Err("segment index checksum mismatch".into());
    }
    let index: Vec<SegmentEntry> = bytes
        .chunks_exact(entry as usize)
        .map(bytemuck::pod_read_unaligned)
        .collect();
    for (i, e) in index.iter().enumerate() {
        if e.id as usize != i {
            return Err(format!("segment index entry {i} has id {}", e.id));
        }
        if SegmentKind::from_u16(e.kind).is_none() {
            return Err(format!("segment {i} has unknown kind {}", e.kind));
        }
        if e.flags & !segment_flags::KNOWN != 0 {
            return Err(format!("segment {i} uses unsupported flags {:#x}", e.flags));
        }
        if e.offset % SEGMENT_ALIGN != 0 || e.offset < PROLOGUE_SIZE as u64 {
            return Err(format!("segment {i} is misplaced at offset {}", e.offset));
        }
        if slice(map, e.offset, e.length).is_none() {
            return Err(format!("segment {i} lies outside the file"));
        }
    }
    Ok(index)
}

fn read_header(map: &[u8], p: &Prologue) -> Result<Header, String> {
    let bytes = slice(map, p.header_offset, p.header_len).ok_or("header lies outside the file")?;
    if checksum(bytes) != p.header_checksum {
        return Err("header checksum mismatch".into());
    }
    let (header, used): (Header, usize) =
        bincode::serde::decode_from_slice(bytes, bincode_config())
            .map_err(|e| format!("header does not decode: {e}"))?;
    if used != bytes.len() {
        return Err("header has trailing bytes".into());
    }
    Ok(header)
}

fn slice(map: &[u8], offset: u64, len: u64) -> Option<&[u8]> {
    let end = offset.checked_add(len)?;
    map.get(usize::try_from(offset).ok()?..usize::try_from(end).ok()?)
}
