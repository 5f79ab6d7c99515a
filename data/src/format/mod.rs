//! The `.portico` display database file (Funkhouser §5.1 made into one memory-mappable file).
//!
//! ```text
//! offset 0     Prologue (128 bytes): magic, version, flags, file length, offsets of the header
//!              and the segment index, their checksums, and a checksum of the prologue itself
//! 128 ...      segments, each aligned to 64 bytes (4096 for those ≥ 4096 bytes), laid out for
//!              direct GPU upload (see `geometry`), optionally compressed (flag per segment)
//! ...          header: bincode 2 of [`Header`] (materials, definitions with their LOD tables,
//!              instances, bounds)
//! ...          segment index: `SegmentEntry` × n (48 bytes each: id, kind, flags, offset,
//!              length, raw length, xxh3 checksum)
//! ```
//! Every number is little-endian. A served file is immutable: rebuilds write a new file and
//! rename it over the old one ([`writer`]), and readers validate everything they touch
//! ([`reader`]), so a truncated, corrupt or foreign file is a clear error, never a panic.

mod header;
mod paged;
#[cfg(feature = "native")]
pub mod reader;
#[cfg(feature = "native")]
pub mod writer;

pub use header::{CellIndex, Header, InstanceRecord, LodRecord, ObjectRecord};
pub use paged::{CellPage, MAX_PAGED_COUNT, UNKNOWN_ROW, check_core, take_rows};

use bytemuck::{Pod, Zeroable};

/// First eight bytes of every display database.
pub const MAGIC: [u8; 8] = *b"PORTICO\0";
/// The format version this build writes and reads.
pub const FORMAT_VERSION: u32 = 8;
/// Size of the prologue; the first segment starts here.
pub const PROLOGUE_SIZE: usize = 128;
/// Minimum alignment of every segment.
pub const SEGMENT_ALIGN: u64 = 64;
/// Alignment of segments of at least this many bytes (page-aligned for the mmap).
pub const PAGE_ALIGN: u64 = 4096;
/// Largest header we agree to decode (guards bincode against absurd lengths).
pub const MAX_HEADER_BYTES: u64 = 1 << 30;

/// What a segment holds.
#[repr(u16)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum SegmentKind {
    /// One LOD of one object: see [`crate::geometry`].
    Geometry = 1,
    /// The compact cell graph (reserved for the cell subdivision).
    CellGraph = 2,
    /// One cell's stab list (reserved for the visibility precomputation).
    StabList = 3,
    /// A texture: a cluster's impostor atlas, PNG-encoded (see [`crate::hierarchy`]).
    Texture = 4,
    /// The occluder faces the cells were built from (used by `portico verify`).
    Occluders = 5,
    /// A material's texture: one mip level and every coarser one, coded as a PNG or JPEG of the finest
    /// ([`crate::texture`]).
    Mips = 6,
    /// A further part of a texture segment longer than [`crate::texture::PART_BYTES`]: its
    /// bytes follow the segment before it ([`crate::texture::MipSegment::parts`]).
    MipPart = 7,
}

impl SegmentKind {
    /// Decodes the on-disk number.
    pub fn from_u16(v: u16) -> Option<Self> {
        Some(match v {
            1 => SegmentKind::Geometry,
            2 => SegmentKind::CellGraph,
            3 => SegmentKind::StabList,
            4 => SegmentKind::Texture,
            5 => SegmentKind::Occluders,
            6 => SegmentKind::Mips,
            7 => SegmentKind::MipPart,
            _ => return None,
        })
    }
}

/// Segment flag bits.
pub mod segment_flags {
    /// The payload is zstd-compressed (reserved: not written yet; readers reject it).
    pub const ZSTD: u16 = 1;
    /// A geometry segment quantised and meshopt-encoded (`codec`); its `raw_length` is the
    /// size it decodes to. Readers from before compression refuse the file by this flag,
    /// with a clear message, rather than misreading the segment.
    pub const MESHOPT: u16 = 2;
    /// Every flag this build understands.
    pub const KNOWN: u16 = MESHOPT;
}

/// The fixed prologue at offset 0.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct Prologue {
    /// [`MAGIC`].
    pub magic: [u8; 8],
    /// [`FORMAT_VERSION`].
    pub version: u32,
    /// Whole-file flags (bit 0: flattened).
    pub flags: u32,
    /// Total file length in bytes.
    pub file_len: u64,
    /// Offset of the bincode header.
    pub header_offset: u64,
    /// Length of the bincode header.
    pub header_len: u64,
    /// Offset of the segment index.
    pub index_offset: u64,
    /// Number of segment index entries.
    pub index_count: u64,
    /// xxh3-64 of the header bytes.
    pub header_checksum: u64,
    /// xxh3-64 of the index bytes.
    pub index_checksum: u64,
    /// xxh3-64 of the prologue bytes before this field.
    pub prologue_checksum: u64,
    /// Zero padding to [`PROLOGUE_SIZE`].
    pub reserved: [u64; 6],
}

/// Prologue flag: instances carry their own (flattened, baked) geometry.
pub const FLAG_FLATTENED: u32 = 1;

impl Prologue {
    /// Checksum of everything before the `prologue_checksum` field.
    pub fn compute_checksum(&self) -> u64 {
        let bytes = bytemuck::bytes_of(self);
        xxhash_rust::xxh3::xxh3_64(&bytes[..72])
    }
}

/// One entry of the segment index.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct SegmentEntry {
    /// Segment id (its position in the index).
    pub id: u32,
    /// [`SegmentKind`] as a number.
    pub kind: u16,
    /// [`segment_flags`] bits.
    pub flags: u16,
    /// Byte offset in the file.
    pub offset: u64,
    /// Stored length in bytes.
    pub length: u64,
    /// Length once decompressed (equal to `length` when uncompressed).
    pub raw_length: u64,
    /// xxh3-64 of the stored bytes.
    pub checksum: u64,
    /// Zero.
    pub reserved: u64,
}

/// The checksum used everywhere in the file.
pub fn checksum(bytes: &[u8]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(bytes)
}

/// Alignment for a segment of `len` bytes.
pub fn alignment_for(len: u64) -> u64 {
    if len >= PAGE_ALIGN {
        PAGE_ALIGN
    } else {
        SEGMENT_ALIGN
    }
}

/// The bincode configuration of the header and of structured segments.
pub(crate) fn bincode_config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<{ MAX_HEADER_BYTES as usize }>()
}

/// Encodes a structured segment (cell graph, stab list, occluders) with bincode 2.
pub fn encode_segment<T: serde::Serialize>(value: &T) -> Vec<u8> {
    // Encoding plain data structures into a Vec cannot fail short of running out of memory.
    bincode::serde::encode_to_vec(value, bincode_config()).unwrap_or_default()
}

/// Decodes a structured segment, rejecting trailing bytes.
pub fn decode_segment<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, String> {
    let (v, used) = bincode::serde::decode_from_slice(bytes, bincode_config())
        .map_err(|e| format!("does not decode: {e}"))?;
    if used != bytes.len() {
        return Err("has trailing bytes".into());
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_layout_sizes() {
        assert_eq!(std::mem::size_of::<Prologue>(), PROLOGUE_SIZE);
        assert_eq!(std::mem::size_of::<SegmentEntry>(), 48);
        assert_eq!(std::mem::offset_of!(Prologue, prologue_checksum), 72);
    }
}
