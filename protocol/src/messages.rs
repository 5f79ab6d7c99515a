//! The messages of the HTTP and WebSocket API.
//!
//! - [`Manifest`]: what `/v1/manifest` answers: the segment table and the model header.
//! - [`PrefetchRequest`] / [`PrefetchResponse`]: `POST /v1/prefetch`, Funkhouser §5.2's lookahead
//!   for one observer, answered as a need-ordered list of segments cut at a byte budget.
//! - [`StreamClient`] / [`StreamServer`]: the `/v1/stream` WebSocket's control messages.
//! - [`ApiError`]: the JSON body of every 4xx/5xx answer.

use serde::{Deserialize, Serialize};

/// `/v1/manifest`: everything a client needs before it asks for geometry.
///
/// `H` is the model header type; the server and the client both use `portico_data::Header`, but
/// this crate stays free of the data crate (the dependency arrows point one way).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest<H> {
    /// [`crate::PROTOCOL_VERSION`] of the server.
    pub protocol_version: u32,
    /// A strong identifier of the database file's contents (hex), changing on every rebuild.
    pub database_id: String,
    /// Size of the database file in bytes.
    pub file_bytes: u64,
    /// The segment table: index = segment id.
    pub segments: Vec<SegmentInfo>,
    /// The model header: materials, objects with their LOD tables, instances, cell index.
    pub header: H,
}

/// One row of the manifest's segment table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SegmentInfo {
    /// Segment kind (1 geometry, 2 cell graph, 3 stab list, 4 impostor atlas, 5 occluders, 6
    /// material texture mips).
    pub kind: u16,
    /// Length in bytes as served.
    pub bytes: u64,
    /// xxh3-64 of the bytes: the segment's strong ETag. In JSON a 16-digit hex string
    /// (JavaScript numbers cannot hold it), in bincode a `u64`.
    #[serde(with = "crate::hex")]
    pub checksum: u64,
}

/// Checks segment `id`'s bytes against its manifest row, if it has one ([`SegmentInfo::check`]).
///
/// # Errors
/// One line naming the segment: not in the manifest, or corrupt.
pub fn verify_segment(info: Option<&SegmentInfo>, id: u32, bytes: &[u8]) -> Result<(), String> {
    info.ok_or_else(|| format!("segment {id}: not in the manifest"))?
        .check(id, bytes)
}

impl SegmentInfo {
    /// Checks a segment's bytes against this row (length and xxh3, the strong ETag), so a
    /// segment damaged on the way is rejected before anything decodes or uploads it.
    ///
    /// # Errors
    /// One line naming segment `id`, what arrived and what the manifest says.
    pub fn check(&self, id: u32, bytes: &[u8]) -> Result<(), String> {
        let sum = xxhash_rust::xxh3::xxh3_64(bytes);
        if bytes.len() as u64 != self.bytes || sum != self.checksum {
            return Err(format!(
                "segment {id}: corrupt ({} bytes, xxh3 {sum:016x}; the manifest says {} bytes, {:016x})",
                bytes.len(),
                self.bytes,
                self.checksum
            ));
        }
        Ok(())
    }
}

/// Where the observer is and how fast it may move (Funkhouser §5.2.1: the observer range).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Observer {
    /// Eye position (metres, model coordinates).
    pub eye: [f32; 3],
    /// View direction (need not be normalised).
    pub dir: [f32; 3],
    /// Up vector.
    pub up: [f32; 3],
    /// Current velocity (metres per second).
    pub velocity: [f32; 3],
    /// Horizontal half field of view (radians).
    pub half_fov_x: f32,
    /// Vertical half field of view (radians).
    pub half_fov_y: f32,
    /// Maximum positional speed v_p (metres per second).
    pub max_speed: f32,
    /// Maximum rotational speed v_r (radians per second).
    pub max_turn: f32,
    /// How the view direction turns now: the angular velocity (radians per second about the
    /// axis it points along; zero when not turning). The predicted lookahead turns the view by
    /// it ([`LookaheadCull::Predicted`]); JSON may leave it out.
    #[serde(default)]
    pub turn: [f32; 3],
}

/// Which observer-range cells to keep (Funkhouser §5.2.2, the range cull algorithm).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RangeCull {
    /// Every cell the observer can reach in N frames.
    Any,
    /// Cells at least partly in front of the observer.
    Plane,
    /// Cells at least partly inside the (widened) observer frustum.
    Frustum,
    /// Cells hit by a ray along the view direction.
    Direction,
}

/// Which cells visible from the range cells to keep (Funkhouser §5.2.2, the lookahead cull).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LookaheadCull {
    /// Every visible cell.
    Any,
    /// Visible cells at least partly in front of the observer.
    Plane,
    /// Visible cells at least partly inside the (widened) observer frustum.
    Frustum,
    /// Not the range cells' visibility but what is seen, looking all around, from the eye and
    /// from where its velocity takes it within the lookahead depth (eye-to-object visibility,
    /// §4.1.2, at predicted eye positions; `portico_data::prefetch::predicted`).
    Predicted,
}

/// Whether a visible cell contributes the objects visible from the range cell or all of its
/// incident objects (Funkhouser §5.2.2, the lookahead granularity).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Granularity {
    /// Only the objects in the range cell's cell-to-object visibility.
    Object,
    /// Every object incident upon a visible cell.
    Cell,
}

/// The prefetch policy: Funkhouser's lookahead parameters plus the client's budgets.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Policy {
    /// Lookahead depth N in frames.
    pub depth_frames: u32,
    /// Frame time in seconds (turns speeds into per-frame steps).
    pub frame_time_s: f32,
    /// Range cull algorithm.
    pub range_cull: RangeCull,
    /// Lookahead cull algorithm.
    pub lookahead_cull: LookaheadCull,
    /// Lookahead granularity.
    pub granularity: Granularity,
    /// Static size threshold (pixels per polygon) that caps each object's LOD at the nearest
    /// point of the observer range (§5.2.2).
    pub size_threshold_px: f32,
    /// Screen size in pixels (for projected sizes).
    pub screen: [u32; 2],
    /// Bytes the answer's read set may hold (Funkhouser's maximum bytes read per frame).
    pub read_bytes: u64,
    /// Bytes the client can hold: the lookahead set stops growing here (§5.2.2, condition 2).
    pub cache_bytes: u64,
    /// The client draws clusters as impostors: list their textured boxes before geometry.
    pub impostors: bool,
    /// The client's GPU holds textures block-compressed (BC1 opaque, BC3 with alpha: half a
    /// byte or one byte per texel) rather than RGBA8: texture segments count that much
    /// against [`Policy::cache_bytes`]. Optional in JSON (default `false`).
    #[serde(default)]
    pub block_textures: bool,
}

impl Default for Policy {
    fn default() -> Self {
        Policy {
            depth_frames: 16,
            frame_time_s: 0.05,
            range_cull: RangeCull::Direction,
            lookahead_cull: LookaheadCull::Predicted,
            granularity: Granularity::Object,
            size_threshold_px: 16.0,
            screen: [640, 480],
            read_bytes: 4 << 20,
            cache_bytes: 64 << 20,
            impostors: false,
            block_textures: false,
        }
    }
}

/// `POST /v1/prefetch`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PrefetchRequest {
    /// The client's [`crate::PROTOCOL_VERSION`].
    pub version: u32,
    /// The observer.
    pub observer: Observer,
    /// The policy.
    pub policy: Policy,
    /// Segments the client holds: see [`encode_held`].
    pub held: Vec<u32>,
}

/// What a segment is needed for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NeedKind {
    /// A cell's stab list (visibility data the geometry depends on).
    Stab,
    /// One LOD of an object's geometry.
    Geometry,
    /// A cluster's impostor texture (its textured box).
    Texture,
    /// A material's texture: one mip level and every coarser one (`lod` is the index into the
    /// texture's segments, coarsest first).
    Mips,
}

/// One entry of the lookahead list.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NeedItem {
    /// Segment id.
    pub segment: u32,
    /// What it is.
    pub kind: NeedKind,
    /// For geometry, the LOD index (0 = finest); for stab lists, 0.
    pub lod: u8,
    /// Bytes.
    pub bytes: u64,
    /// Frames until it can first be needed (0 = visible now).
    pub frames: u32,
}

/// The answer to a prefetch request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PrefetchResponse {
    /// The server's [`crate::PROTOCOL_VERSION`].
    pub version: u32,
    /// The read set: segments not held, in need order, cut at `read_bytes`.
    pub items: Vec<NeedItem>,
    /// Held segments outside the lookahead set, least needed first: release these first.
    pub evict: Vec<u32>,
    /// Cells in the observer range.
    pub range_cells: u32,
    /// Cells contributing lookahead objects.
    pub lookahead_cells: u32,
    /// Objects in the lookahead set.
    pub lookahead_objects: u32,
    /// Bytes of the lookahead set (every LOD up to each object's maximum).
    pub lookahead_bytes: u64,
    /// True when the read set was cut at the byte budget.
    pub truncated: bool,
    /// Server time spent computing the answer, in microseconds.
    pub micros: u32,
}

/// Client → server control messages on `/v1/stream` (binary frames, bincode).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum StreamClient {
    /// Start or change the session: policy and the per-session byte rate wanted.
    Hello {
        /// The client's [`crate::PROTOCOL_VERSION`].
        version: u32,
        /// Prefetch policy.
        policy: Policy,
        /// Bytes per second the client wants at most (the server may cap it lower); the
        /// session's pushes are paced to it and its deadlines counted at it.
        rate_bytes_per_s: u64,
        /// The client's round trip to the server in milliseconds, as it measured it (the
        /// WebSocket handshake), for the push deadlines; 0: not known (counted as none).
        rtt_ms: u32,
    },
    /// This frame's observer.
    Observer(Observer),
    /// Segments the client dropped from its cache (the server's mirror forgets them).
    Evicted(Vec<u32>),
    /// What the client's latest frame lacked, most urgent first (what it had nothing to draw
    /// for, then what it drew coarser: `portico_client::demand`): pushed ahead of the need
    /// list, which the server made for an observer that may have moved on or mispredicted.
    /// Replaces the previous one; empty clears it. At most [`MAX_LACKING`] ids.
    Lacking(Vec<u32>),
    /// The client started from the [`crate::CoreManifest`]: from now on the server sends each
    /// cell's [`crate::Page`] (a [`crate::FRAME_PAGE`]) before that cell's stab list, once.
    Pages,
    /// What the client's cache already holds when the session opens (a session reopened after
    /// the last one ended), delta-coded as [`encode_held`] codes it: the server's mirror starts
    /// from it, so nothing the client holds is pushed again.
    Holding(Vec<u32>),
}

/// WebSocket close code of a stream session whose URL names a database the server no longer
/// serves (rebuilt and reloaded): like HTTP's `410 Gone`, the client must read the manifest
/// again; reopening the same URL cannot help. (4000–4999 are the application's codes,
/// RFC 6455 §7.4.2.)
pub const CLOSE_STALE: u16 = 4410;

/// Most segment ids in one [`StreamClient::Lacking`].
pub const MAX_LACKING: usize = 4096;

/// Server → client control messages on `/v1/stream`. Segment bytes do not go through this
/// type: they travel as [`segment_frame`]s so the payload is not re-encoded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum StreamServer {
    /// The need list changed: these queued segments will not come (their need vanished).
    Dropped(Vec<u32>),
    /// A problem with the last message; the session continues.
    Error(ApiError),
}

/// First byte of a binary WebSocket frame carrying a bincode [`StreamServer`].
pub const FRAME_CONTROL: u8 = 0;
/// First byte of a binary WebSocket frame carrying a segment: then the id (`u32` LE), then the
/// segment's bytes exactly as `/v1/segments/{id}` serves them.
pub const FRAME_SEGMENT: u8 = 1;

/// Builds a segment frame (see [`FRAME_SEGMENT`]).
pub fn segment_frame(id: u32, bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(5 + bytes.len());
    out.push(FRAME_SEGMENT);
    out.extend_from_slice(&id.to_le_bytes());
    out.extend_from_slice(bytes);
    out
}

/// A decoded server frame.
#[derive(Debug, Clone, PartialEq)]
pub enum ServerFrame<'a> {
    /// A segment's id and bytes.
    Segment(u32, &'a [u8]),
    /// A control message.
    Control(StreamServer),
    /// A cell's page, deflated ([`crate::inflate_page`]).
    Page(&'a [u8]),
}

/// Decodes a binary frame from the server.
pub fn parse_server_frame(frame: &[u8]) -> Result<ServerFrame<'_>, crate::CodecError> {
    match frame.split_first() {
        Some((&FRAME_SEGMENT, rest)) if rest.len() >= 4 => {
            let id = u32::from_le_bytes([rest[0], rest[1], rest[2], rest[3]]);
            Ok(ServerFrame::Segment(id, &rest[4..]))
        }
        Some((&FRAME_CONTROL, rest)) => Ok(ServerFrame::Control(crate::from_bincode(rest)?)),
        Some((&crate::FRAME_PAGE, rest)) => Ok(ServerFrame::Page(rest)),
        _ => Err(crate::CodecError::Bincode("unknown frame tag".into())),
    }
}

/// The JSON (or bincode) body of every error answer.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ApiError {
    /// HTTP status code.
    pub status: u16,
    /// Short machine-readable code (`bad_request`, `not_found`, `too_large`, ...).
    pub code: String,
    /// What was wrong, for a person.
    pub message: String,
}

/// Encodes a set of segment ids compactly: sorted, deduplicated, delta-coded (bincode's varints
/// make each small gap one byte).
pub fn encode_held(ids: impl IntoIterator<Item = u32>) -> Vec<u32> {
    let mut v: Vec<u32> = ids.into_iter().collect();
    v.sort_unstable();
    v.dedup();
    let mut prev = 0u32;
    for x in v.iter_mut() {
        let cur = *x;
        *x = cur - prev;
        prev = cur;
    }
    v
}

/// Decodes [`encode_held`]'s output; `None` when the gaps overflow `u32` (hostile input).
pub fn decode_held(deltas: &[u32]) -> Option<Vec<u32>> {
    let mut out = Vec::with_capacity(deltas.len());
    let mut acc = 0u32;
    for (i, &d) in deltas.iter().enumerate() {
        if i > 0 && d == 0 {
            return None; // duplicates are not allowed
        }
        acc = acc.checked_add(d)?;
        out.push(acc);
    }
    Some(out)
}
