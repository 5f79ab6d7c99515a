//! Textures streamed coarse to fine: mip chains cut into segments a client can draw alone.
//!
//! A texture is a chain of RGBA8 (sRGB) mip levels, finest first, each level half the one
//! above (at least one texel). Its levels are cut into segments:
//!
//! * the **coarse segment** gives every level at most [`COARSE_SIZE`] texels on a side — a few
//!   kilobytes, fetched with the first geometry that needs it;
//! * each finer level gets a segment of its own that **also gives every coarser level**, so any
//!   one segment is a complete mip chain the GPU can sample without the others.
//!
//! The second rule departs from "one segment per level": a client that needs level `L` fetches
//! the coarse segment and `L`'s, never the levels between, and may evict any segment without
//! breaking another; a viewer far away never pays for the levels it cannot see (Funkhouser
//! §5.2.2's "maximum LOD" applied to texels). It costs nothing on the wire: a segment holds an
//! image of its finest level only, and the client builds the coarser levels from it
//! ([`code_segments`], [`decode_segment`]: PNG, or JPEG within [`MIN_PSNR`]).

mod block;
mod mips;
mod segment;
#[cfg(feature = "native")]
mod store;

pub use block::{
    BlockChain, BlockFormat, TexelFormat, block_chain_bytes, block_format, compress,
    decompress_finest, is_opaque,
};

pub use mips::{average_color, mip_chain, to_linear, to_srgb};
pub use segment::{
    Codec, CodedSegment, MIN_PSNR, TEXTURE_HEADER, TextureChain, code_segments, cut_segments,
    decode_segment, psnr,
};
#[cfg(feature = "native")]
pub(crate) use store::write_textures;

use serde::{Deserialize, Serialize};

/// First four bytes of every texture segment.
pub const TEXTURE_MAGIC: u32 = u32::from_le_bytes(*b"PTEX");
/// Levels at most this many texels on a side go into the one coarse segment.
pub const COARSE_SIZE: u32 = 64;
/// Largest texture side accepted (texels); larger images are scaled down on import.
pub const MAX_SIZE: u32 = 4096;
/// Most bytes a texture segment is stored and sent in: a longer one is cut into parts of at
/// most this many bytes, each a segment of its own, so that no one of them holds a 10 Mbit/s
/// link for more than about 52 ms (two frames at 40 Hz, one at the default 20 Hz) and what a
/// frame lacks can be read between them. A client draws the texture segment once all its
/// parts have come ([`MipSegment::parts`]).
pub const PART_BYTES: usize = 64 << 10;
/// The least a build may cut parts to ([`crate::build::BuildOptions::part_bytes`]).
pub const MIN_PART_BYTES: usize = 1 << 10;

/// How a material's texture repeats past 0..1 on one axis (glTF sampler wrap modes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub enum Wrap {
    /// Tile the image (glTF's default).
    #[default]
    Repeat,
    /// Mirror every other tile.
    Mirror,
    /// Hold the edge texel.
    Clamp,
}

/// How a material's alpha is used (glTF `alphaMode`).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub enum AlphaMode {
    /// Alpha is ignored: the surface is opaque.
    #[default]
    Opaque,
    /// Texels below the cutoff are not drawn, the rest are opaque (foliage, grilles).
    Mask(f32),
    /// The surface is blended over what is behind it (glass).
    Blend,
}

/// A decoded image as importers give it: sRGB RGBA8, rows top to bottom.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureImage {
    /// Name (the file name, or the glTF image's name or index).
    pub name: String,
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `width × height × 4` bytes.
    pub rgba: Vec<u8>,
    /// Wrap mode along u and v.
    pub wrap: [Wrap; 2],
}

/// One texture segment: a mip level and every coarser one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct MipSegment {
    /// Segment id.
    pub segment: u32,
    /// Width of the segment's finest level (texels).
    pub width: u32,
    /// Height of the segment's finest level (texels).
    pub height: u32,
    /// Levels in the segment.
    pub levels: u32,
    /// Every texel's alpha is 255: a GPU with block compression holds it as BC1, else BC3.
    pub opaque: bool,
    /// Further parts its bytes were cut into ([`PART_BYTES`]): segments `segment + 1` to
    /// `segment + parts`, whose bytes follow `segment`'s in that order; 0 for most.
    pub parts: u32,
}

impl MipSegment {
    /// Bytes its levels take decoded (RGBA8): what it holds on a GPU that takes no compressed
    /// textures.
    pub fn texel_bytes(&self) -> u64 {
        chain_bytes(self.width, self.height, self.levels)
    }

    /// Its segment ids: `segment`, then its parts, in the order their bytes join.
    pub fn ids(&self) -> impl Iterator<Item = u32> + use<> {
        let first = self.segment;
        (0..=self.parts).map(move |i| first.saturating_add(i))
    }

    /// Bytes its levels take on a GPU that holds texels as `texels` (RGBA8, or BC1 / BC3 where
    /// [`block_format`] allows): what a client's cache is charged for it.
    pub fn gpu_bytes(&self, texels: TexelFormat) -> u64 {
        match block_format(texels, self.width, self.height, self.opaque) {
            Some(f) => block_chain_bytes(self.width, self.height, self.levels, f),
            None => self.texel_bytes(),
        }
    }

    /// Whether the record describes a chain [`decode_segment`] would accept: each side
    /// 1..=[`MAX_SIZE`], 1..=[`full_levels`] levels.
    pub fn is_valid(&self) -> bool {
        let side = 1..=MAX_SIZE;
        side.contains(&self.width)
            && side.contains(&self.height)
            && (1..=full_levels(self.width, self.height)).contains(&self.levels)
    }
}

/// A texture in the database header.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TextureRecord {
    /// Name from the source.
    pub name: String,
    /// Width of the finest level (texels).
    pub width: u32,
    /// Height of the finest level (texels).
    pub height: u32,
    /// Segments, coarsest first (the coarse segment, then one per finer level).
    pub segments: Vec<MipSegment>,
    /// The image's average colour (linear RGBA): what an object is drawn with before any of
    /// its texture's segments is resident.
    pub average: [f32; 4],
    /// Wrap mode along u and v.
    pub wrap: [Wrap; 2],
    /// The lowest PSNR (dB) of its segments' finest levels against the texels they were coded
    /// from; `None` when every segment is lossless.
    pub psnr: Option<f32>,
}

impl TextureRecord {
    /// Index into [`TextureRecord::segments`] of the coarsest segment that gives an object
    /// `pixels` across, over which the texture repeats `uv_span` times, at least one texel per
    /// pixel ([`useful_width`]); the finest segment when none does.
    pub fn useful_segment(&self, pixels: f32, uv_span: f32) -> usize {
        let want = useful_width(pixels, uv_span);
        let side = |s: &MipSegment| s.width.max(s.height) as f32;
        self.segments
            .iter()
            .position(|s| side(s) >= want)
            .unwrap_or(self.segments.len().saturating_sub(1))
    }
}

/// Texels across a texture that an object `pixels` across shows when the texture repeats
/// `uv_span` times over it: finer levels than this are minified away by the mip filter.
pub fn useful_width(pixels: f32, uv_span: f32) -> f32 {
    if uv_span > 0.0 && uv_span.is_finite() {
        pixels.max(0.0) / uv_span
    } else {
        pixels.max(0.0)
    }
}

/// Number of levels of a full chain from `width × height` down to 1 × 1.
pub fn full_levels(width: u32, height: u32) -> u32 {
    32 - width.max(height).max(1).leading_zeros()
}

/// Size of level `i` of a chain whose finest level is `width × height`.
pub fn level_size(width: u32, height: u32, i: u32) -> (u32, u32) {
    let half = |x: u32| x.checked_shr(i).unwrap_or(0).max(1);
    (half(width), half(height))
}

/// Bytes of `levels` levels from `width × height` down (a chain has at most 32 levels; more
/// count as 32, so an absurd record cannot loop or overflow).
pub fn chain_bytes(width: u32, height: u32, levels: u32) -> u64 {
    (0..levels.min(32))
        .map(|i| {
            let (w, h) = level_size(width, height, i);
            (w as u64 * h as u64).saturating_mul(4)
        })
        .fold(0u64, u64::saturating_add)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absurd_records_neither_panic_nor_loop() {
        let s = MipSegment {
            segment: 0,
            width: u32::MAX,
            height: u32::MAX,
            levels: u32::MAX,
            opaque: true,
            parts: 0,
        };
        assert!(!s.is_valid());
        assert!(s.texel_bytes() > 0);
        assert_eq!(level_size(8, 8, 40), (1, 1));
        let ok = MipSegment {
            segment: 0,
            width: 64,
            height: 16,
            levels: 7,
            opaque: false,
            parts: 0,
        };
        assert!(ok.is_valid());
        assert!(!MipSegment { levels: 8, ..ok }.is_valid());
    }

    #[test]
    fn the_useful_segment_follows_screen_size_and_repeats() {
        let rec = TextureRecord {
            name: "t".into(),
            width: 512,
            height: 512,
            segments: [64u32, 128, 256, 512]
                .iter()
                .enumerate()
                .map(|(i, &s)| MipSegment {
                    segment: i as u32,
                    width: s,
                    height: s,
                    levels: full_levels(s, s),
                    opaque: true,
                    parts: 0,
                })
                .collect(),
            average: [0.5; 4],
            wrap: [Wrap::Repeat; 2],
            psnr: None,
        };
        assert_eq!(rec.useful_segment(10.0, 1.0), 0);
        assert_eq!(rec.useful_segment(200.0, 1.0), 2);
        assert_eq!(rec.useful_segment(2000.0, 1.0), 3);
        // Repeated 8 times across 800 pixels: 100 texels are enough.
        assert_eq!(rec.useful_segment(800.0, 8.0), 1);
    }
}
