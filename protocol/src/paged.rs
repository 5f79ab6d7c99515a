//! The paged manifest: what a client needs before its first frame, split so that a cold start
//! costs one small document and then, with each cell's stab list, the part of the model that
//! cell sees (Funkhouser §5.2: the client only ever needs what is visible from the cells in its
//! observer range; Fig. 3.23's instance table, cut along the stab lists).
//!
//! - [`CoreManifest`] (`GET /v1/manifest/core`): the header without its instance table (materials,
//!   textures, object definitions, cell index, hierarchy), the counts, the cell graph's frame,
//!   and the rows of the segments no instance owns (cell graph, occluders, impostor atlases,
//!   texture mips). Flattened `mega`: 31 KB gzip-coded, where the whole manifest is 9.6 MB and
//!   the cell graph 0.9 MB: a client needs neither before its first frame.
//! - [`Page`] (`GET /v1/db/{db}/pages/{cell}`, and on the push stream as a [`FRAME_PAGE`]
//!   before the cell's stab list): the instance records the cell's stab list names and the
//!   segment rows of their LODs, the stab list's own row, and the cells the list reaches with
//!   their portals. Immutable under the database id.
//!
//! A client holding the core and some pages knows a sparse header: instances it has no page
//! for are placeholders that draw nothing, and are never asked for (nothing it holds names
//! them).

use crate::SegmentInfo;
use serde::{Deserialize, Serialize};

/// `GET /v1/manifest/core`: the manifest less its per-instance and per-segment tables, and the
/// cell graph less its cells, portals and tree.
///
/// `H` is the model header type (`portico_data::format::Header`) with its `instances` empty;
/// `G` the cell graph's frame (`portico_data::cells::paged::GraphCore`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoreManifest<H, G> {
    /// [`crate::PROTOCOL_VERSION`] of the server.
    pub protocol_version: u32,
    /// The same strong identifier as [`crate::Manifest::database_id`].
    pub database_id: String,
    /// Size of the database file in bytes.
    pub file_bytes: u64,
    /// How many segments the database has (the length of the full manifest's table).
    pub segment_count: u32,
    /// How many instances the model has (the length of the full header's table).
    pub instance_count: u32,
    /// Triangles of the whole model at its finest LODs (the walk's drawn fraction divides by
    /// it).
    pub triangles: u64,
    /// Rows of the segments no instance owns: cell graph, occluders, impostor atlases,
    /// material texture mips (stab lists' rows come in their pages), by id.
    pub rows: Vec<(u32, SegmentInfo)>,
    /// The header, its instance table empty.
    pub header: H,
    /// The cell graph's frame (its box and counts), when the model has cells.
    pub graph: Option<G>,
}

/// One cell's page: the part of the instance table its stab list names, and the part of the
/// cell graph it reaches.
///
/// `I` is the instance record type (`portico_data::format::InstanceRecord`); `G` the graph's
/// part (`portico_data::cells::paged::GraphPart`: the cells the stab list reaches, their
/// portals).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Page<I, G> {
    /// The cell.
    pub cell: u32,
    /// Its stab list's segment, and that segment's row.
    pub stab: (u32, SegmentInfo),
    /// Every instance the stab list names (cell-to-object visibility) and those inside or
    /// partly inside the cell, by instance id, ascending.
    pub instances: Vec<(u32, I)>,
    /// The rows of those instances' LOD segments, by segment id, ascending.
    pub segments: Vec<(u32, SegmentInfo)>,
    /// The cells the stab list reaches and their portals.
    pub graph: G,
}

/// First byte of a binary WebSocket frame carrying a cell's [`Page`]: then the page's bincode,
/// deflated (RFC 1951, [`deflate_page`]). Sent to a session that asked with
/// [`crate::StreamClient::Pages`], before the cell's stab list, once per cell.
pub const FRAME_PAGE: u8 = 2;

/// A page's bincode, deflated for a [`FRAME_PAGE`] (the page of flattened `mega`'s median
/// cell: 31 KB → 9 KB).
pub fn deflate_page(bincode: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(1 + bincode.len() / 3);
    out.push(FRAME_PAGE);
    out.extend_from_slice(&miniz_oxide::deflate::compress_to_vec(bincode, 6));
    out
}

/// Decodes a [`FRAME_PAGE`]'s payload (after the tag byte): inflates it (at most
/// [`crate::MAX_MESSAGE_BYTES`]) and decodes the page.
///
/// # Errors
/// One line: the deflate stream is damaged or too large, or the page does not decode.
pub fn inflate_page<I: serde::de::DeserializeOwned, G: serde::de::DeserializeOwned>(
    deflated: &[u8],
) -> Result<Page<I, G>, crate::CodecError> {
    let raw =
        miniz_oxide::inflate::decompress_to_vec_with_limit(deflated, crate::MAX_MESSAGE_BYTES)
            .map_err(|e| {
                crate::CodecError::Bincode(format!("page frame does not inflate: {e:?}"))
            })?;
    crate::from_bincode(&raw)
}
