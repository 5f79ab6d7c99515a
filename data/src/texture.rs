//! Textures streamed coarse to fine: mip chains cut into segments a client can draw alone.
//!
//! A texture is stored as RGBA8 (sRGB) mip levels, finest first, each level half the one
//! above (at least one texel). Its levels are cut into segments:
//!
//! * the **coarse segment** holds every level at most [`COARSE_SIZE`] texels on a side — a few
//!   kilobytes, fetched with the first geometry that needs it;
//! * each finer level gets a segment of its own that **also holds every coarser level**, so any
//!   one segment is a complete mip chain the GPU can sample without the others.
//!
//! The second rule departs from "one segment per level": it costs a third more bytes per
//! segment, but a client that needs level `L` fetches the coarse segment and `L`'s, never the
//! levels between, and may evict any segment without breaking another; a viewer far away never
//! pays for the levels it cannot see (Funkhouser §5.2.2's "maximum LOD" applied to texels).
//!
//! ```text
//! 0   magic "PTEX", width, height, levels (u32 each): the segment's finest level and how many
//!     levels follow it
//! 16  level 0 (width × height × 4 bytes), level 1, ... down to `levels - 1`
//! ```

use serde::{Deserialize, Serialize};

/// First four bytes of every texture segment.
pub const TEXTURE_MAGIC: u32 = u32::from_le_bytes(*b"PTEX");
/// Levels at most this many texels on a side go into the one coarse segment.
pub const COARSE_SIZE: u32 = 64;
/// Largest texture side accepted (texels); larger images are scaled down on import.
pub const MAX_SIZE: u32 = 4096;
/// Bytes of a texture segment's header.
pub const TEXTURE_HEADER: usize = 16;

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
}

impl MipSegment {
    /// Bytes of the segment (header and levels).
    pub fn bytes(&self) -> u64 {
        (TEXTURE_HEADER as u64).saturating_add(chain_bytes(self.width, self.height, self.levels))
    }

    /// Whether the record describes a chain [`TextureView::parse`] would accept: each side
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

/// The full mip chain of an image, finest first: each level a 2 × 2 box filter of the one above,
/// averaged in linear light (sRGB decoded and re-encoded) with alpha-weighted colour, so dark
/// fringes do not grow around cut-out edges.
pub fn mip_chain(width: u32, height: u32, rgba: &[u8]) -> Vec<Vec<u8>> {
    let mut levels = vec![rgba.to_vec()];
    let (mut w, mut h) = (width, height);
    while w > 1 || h > 1 {
        let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
        let src = levels.last().expect("one level");
        let mut dst = vec![0u8; (nw * nh * 4) as usize];
        for y in 0..nh {
            for x in 0..nw {
                let mut acc = [0.0f32; 4];
                let mut n = 0.0;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (sx, sy) = ((x * 2 + dx).min(w - 1), (y * 2 + dy).min(h - 1));
                    let p = &src[((sy * w + sx) * 4) as usize..][..4];
                    let a = p[3] as f32 / 255.0;
                    for c in 0..3 {
                        acc[c] += to_linear(p[c]) * a;
                    }
                    acc[3] += a;
                    n += 1.0;
                }
                let out = &mut dst[((y * nw + x) * 4) as usize..][..4];
                for c in 0..3 {
                    out[c] = if acc[3] > 0.0 {
                        to_srgb(acc[c] / acc[3])
                    } else {
                        0
                    };
                }
                out[3] = (acc[3] / n * 255.0).round() as u8;
            }
        }
        levels.push(dst);
        (w, h) = (nw, nh);
    }
    levels
}

/// The average colour of an RGBA8 sRGB image, linear RGBA: colour weighted by alpha (as the
/// mip filter does, so transparent texels do not darken a cut-out's stand-in), alpha the mean.
pub fn average_color(rgba: &[u8]) -> [f32; 4] {
    let mut acc = [0.0f64; 4];
    let n = (rgba.len() / 4).max(1) as f64;
    for p in rgba.chunks_exact(4) {
        let a = p[3] as f64 / 255.0;
        for c in 0..3 {
            acc[c] += to_linear(p[c]) as f64 * a;
        }
        acc[3] += a;
    }
    let w = acc[3].max(1e-12);
    [
        (acc[0] / w) as f32,
        (acc[1] / w) as f32,
        (acc[2] / w) as f32,
        (acc[3] / n) as f32,
    ]
}

/// sRGB byte to linear light.
pub fn to_linear(c: u8) -> f32 {
    let c = c as f32 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear light to an sRGB byte.
pub fn to_srgb(l: f32) -> u8 {
    let l = l.clamp(0.0, 1.0);
    let c = if l <= 0.003_130_8 {
        l * 12.92
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    };
    (c * 255.0).round() as u8
}

/// Cuts a mip chain (finest first, full down to 1 × 1) into segments' bytes, coarsest first:
/// the coarse segment, then one per finer level holding it and every coarser level (see the
/// module docs). Returns each segment's `(width, height, levels, bytes)`.
pub fn cut_segments(width: u32, height: u32, chain: &[Vec<u8>]) -> Vec<(u32, u32, u32, Vec<u8>)> {
    let n = chain.len() as u32;
    // The first level that fits in the coarse segment.
    let coarse = (0..n)
        .find(|&i| {
            let (w, h) = level_size(width, height, i);
            w.max(h) <= COARSE_SIZE
        })
        .unwrap_or(n - 1);
    (0..=coarse)
        .rev()
        .map(|first| {
            let (w, h) = level_size(width, height, first);
            let levels = n - first;
            let mut out = Vec::with_capacity(TEXTURE_HEADER + chain_bytes(w, h, levels) as usize);
            for x in [TEXTURE_MAGIC, w, h, levels] {
                out.extend_from_slice(&x.to_le_bytes());
            }
            for level in &chain[first as usize..] {
                out.extend_from_slice(level);
            }
            (w, h, levels, out)
        })
        .collect()
}

/// A validated, borrowed view of a texture segment.
#[derive(Debug, Clone, Copy)]
pub struct TextureView<'a> {
    /// Width of the finest level (texels).
    pub width: u32,
    /// Height of the finest level (texels).
    pub height: u32,
    /// Number of levels.
    pub levels: u32,
    /// The levels' texels, finest first, tightly packed (what a GPU upload takes mip by mip).
    pub texels: &'a [u8],
}

impl<'a> TextureView<'a> {
    /// Parses a texture segment: magic, a size within [`MAX_SIZE`], a level count no longer
    /// than the chain, and exactly the bytes those levels need.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, String> {
        let head = bytes
            .get(..TEXTURE_HEADER)
            .ok_or_else(|| format!("texture segment of {} bytes is too short", bytes.len()))?;
        let word = |i: usize| u32::from_le_bytes(head[i * 4..i * 4 + 4].try_into().unwrap());
        let (magic, width, height, levels) = (word(0), word(1), word(2), word(3));
        if magic != TEXTURE_MAGIC {
            return Err("texture segment has a bad magic".into());
        }
        if width == 0 || height == 0 || width > MAX_SIZE || height > MAX_SIZE {
            return Err(format!("texture segment is {width}x{height} texels"));
        }
        if levels == 0 || levels > full_levels(width, height) {
            return Err(format!(
                "texture segment of {width}x{height} claims {levels} levels"
            ));
        }
        let want = chain_bytes(width, height, levels);
        let texels = &bytes[TEXTURE_HEADER..];
        if texels.len() as u64 != want {
            return Err(format!(
                "texture segment holds {} texel bytes, its {levels} levels need {want}",
                texels.len()
            ));
        }
        Ok(TextureView {
            width,
            height,
            levels,
            texels,
        })
    }

    /// Level `i`'s size and texels.
    pub fn level(&self, i: u32) -> (u32, u32, &'a [u8]) {
        let start = chain_bytes(self.width, self.height, i) as usize;
        let (w, h) = level_size(self.width, self.height, i);
        (w, h, &self.texels[start..start + (w * h * 4) as usize])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker(w: u32, h: u32) -> Vec<u8> {
        (0..w * h)
            .flat_map(|i| {
                let on = ((i % w) + (i / w)).is_multiple_of(2);
                if on {
                    [255, 0, 0, 255]
                } else {
                    [0, 0, 255, 255]
                }
            })
            .collect()
    }

    #[test]
    fn chains_halve_to_one_texel() {
        let chain = mip_chain(8, 2, &checker(8, 2));
        let sizes: Vec<usize> = chain.iter().map(Vec::len).collect();
        assert_eq!(sizes, vec![64, 16, 8, 4]);
        assert_eq!(full_levels(8, 2), 4);
        // Red and blue average in linear light: 0.5 each, sRGB 188.
        assert_eq!(&chain[3][..], &[188, 0, 188, 255]);
    }

    #[test]
    fn cut_out_edges_keep_their_colour() {
        // A white texel beside a transparent black one: the average stays white, half covered.
        let img = [255, 255, 255, 255, 0, 0, 0, 0];
        let chain = mip_chain(2, 1, &img);
        assert_eq!(&chain[1][..], &[255, 255, 255, 128]);
    }

    #[test]
    fn segments_are_coarse_first_and_each_a_whole_chain() {
        let (w, h) = (256, 128);
        let chain = mip_chain(w, h, &checker(w, h));
        let segs = cut_segments(w, h, &chain);
        let shapes: Vec<(u32, u32, u32)> = segs.iter().map(|s| (s.0, s.1, s.2)).collect();
        assert_eq!(shapes, vec![(64, 32, 7), (128, 64, 8), (256, 128, 9)]);
        for (sw, sh, levels, bytes) in &segs {
            let v = TextureView::parse(bytes).expect("parses");
            assert_eq!((v.width, v.height, v.levels), (*sw, *sh, *levels));
            let (lw, lh, last) = v.level(levels - 1);
            assert_eq!((lw, lh, last), (1, 1, &chain[8][..]));
            let seg = MipSegment {
                segment: 0,
                width: *sw,
                height: *sh,
                levels: *levels,
            };
            assert_eq!(seg.bytes(), bytes.len() as u64);
        }
        // A small image is one coarse segment.
        let small = cut_segments(16, 16, &mip_chain(16, 16, &checker(16, 16)));
        assert_eq!(small.len(), 1);
        assert_eq!(small[0].2, 5);
    }

    #[test]
    fn absurd_records_neither_panic_nor_loop() {
        let s = MipSegment {
            segment: 0,
            width: u32::MAX,
            height: u32::MAX,
            levels: u32::MAX,
        };
        assert!(!s.is_valid());
        assert!(s.bytes() > 0);
        assert_eq!(level_size(8, 8, 40), (1, 1));
        let ok = MipSegment {
            segment: 0,
            width: 64,
            height: 16,
            levels: 7,
        };
        assert!(ok.is_valid());
        assert!(!MipSegment { levels: 8, ..ok }.is_valid());
        // Transparent black texels do not darken the average colour.
        let avg = average_color(&[255, 0, 0, 255, 0, 0, 0, 0]);
        assert_eq!((avg[0], avg[1], avg[3]), (1.0, 0.0, 0.5));
    }

    #[test]
    fn bad_segments_are_refused() {
        let segs = cut_segments(4, 4, &mip_chain(4, 4, &checker(4, 4)));
        let good = &segs[0].3;
        assert!(TextureView::parse(good).is_ok());
        assert!(TextureView::parse(&good[..good.len() - 1]).is_err());
        let mut bad = good.clone();
        bad[12] = 9; // more levels than a 4x4 chain has
        assert!(TextureView::parse(&bad).unwrap_err().contains("levels"));
        let mut bad = good.clone();
        bad[4..8].copy_from_slice(&0u32.to_le_bytes());
        assert!(TextureView::parse(&bad).is_err());
        let mut bad = good.clone();
        bad[0] = b'X';
        assert!(TextureView::parse(&bad).unwrap_err().contains("magic"));
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
                })
                .collect(),
            average: [0.5; 4],
            wrap: [Wrap::Repeat; 2],
        };
        assert_eq!(rec.useful_segment(10.0, 1.0), 0);
        assert_eq!(rec.useful_segment(200.0, 1.0), 2);
        assert_eq!(rec.useful_segment(2000.0, 1.0), 3);
        // Repeated 8 times across 800 pixels: 100 texels are enough.
        assert_eq!(rec.useful_segment(800.0, 8.0), 1);
    }
}
