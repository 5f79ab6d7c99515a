//! Texture segments as they are stored and sent: a header, then the segment's levels either as
//! raw RGBA8 or as one image file of its finest level from which the client builds the coarser
//! levels itself ([`mip_chain`], the filter the build uses).
//!
//! ```text
//! 0   magic "PTEX", width, height, levels, codec (u32 each): the segment's finest level, how
//!     many levels it gives, and how they are coded
//! 20  raw:       level 0 (width × height × 4 bytes), level 1, ... down to `levels - 1`
//!     PNG, JPEG: an image file of level 0, exactly width × height
//! ```
//!
//! The build codes each segment as the smaller of a lossless PNG and the lowest JPEG quality
//! whose finest level keeps [`MIN_PSNR`] against the texels it came from (opaque textures only:
//! JPEG has no alpha). Decoding is pure Rust (the `image` crate's PNG and JPEG decoders), so
//! the browser decodes as the native client does, on its IO stage.

use super::{
    COARSE_SIZE, MAX_SIZE, TEXTURE_MAGIC, chain_bytes, full_levels, level_size, mip_chain,
};
use image::ImageEncoder;

/// Bytes of a texture segment's header.
pub const TEXTURE_HEADER: usize = 20;
/// The least picture quality a lossy segment keeps: PSNR (dB, over RGB) of its finest level
/// decoded against the texels it was coded from.
pub const MIN_PSNR: f64 = 40.0;
/// JPEG qualities tried, lowest first: the first that keeps [`MIN_PSNR`] is used.
const QUALITIES: [u8; 4] = [80, 88, 94, 98];

/// How a texture segment's levels are coded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Codec {
    /// Every level's RGBA8 texels, finest first.
    Raw = 0,
    /// A PNG of the finest level (lossless).
    Png = 1,
    /// A JPEG of the finest level (opaque textures; at least [`MIN_PSNR`]).
    Jpeg = 2,
}

impl Codec {
    fn of(word: u32) -> Option<Codec> {
        [Codec::Raw, Codec::Png, Codec::Jpeg]
            .into_iter()
            .find(|c| *c as u32 == word)
    }
}

/// The first level of each segment of a `width × height` chain of `n` levels, coarsest
/// segment first: the coarse segment starts at the first level at most [`COARSE_SIZE`] a
/// side, then one segment per finer level (see the module docs of [`crate::texture`]).
fn segment_starts(width: u32, height: u32, n: u32) -> Vec<u32> {
    let coarse = (0..n)
        .find(|&i| {
            let (w, h) = level_size(width, height, i);
            w.max(h) <= COARSE_SIZE
        })
        .unwrap_or(n.saturating_sub(1));
    (0..=coarse).rev().collect()
}

fn header(out: &mut Vec<u8>, w: u32, h: u32, levels: u32, codec: Codec) {
    for x in [TEXTURE_MAGIC, w, h, levels, codec as u32] {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

/// Cuts a mip chain (finest first, full down to 1 × 1) into raw segments' bytes, coarsest
/// first: the coarse segment, then one per finer level holding it and every coarser level.
/// Returns each segment's `(width, height, levels, bytes)`. (Uncoded: for tests and for
/// textures made on the client; a build codes its segments with [`code_segments`].)
pub fn cut_segments(width: u32, height: u32, chain: &[Vec<u8>]) -> Vec<(u32, u32, u32, Vec<u8>)> {
    let n = chain.len() as u32;
    segment_starts(width, height, n)
        .into_iter()
        .map(|first| {
            let (w, h) = level_size(width, height, first);
            let levels = n - first;
            let mut out = Vec::with_capacity(TEXTURE_HEADER + chain_bytes(w, h, levels) as usize);
            header(&mut out, w, h, levels, Codec::Raw);
            for level in &chain[first as usize..] {
                out.extend_from_slice(level);
            }
            (w, h, levels, out)
        })
        .collect()
}

/// One coded texture segment ([`code_segments`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CodedSegment {
    /// Width of its finest level (texels).
    pub width: u32,
    /// Height of its finest level (texels).
    pub height: u32,
    /// Levels it gives (down to 1 × 1).
    pub levels: u32,
    /// The segment's bytes (header and image file).
    pub bytes: Vec<u8>,
    /// How its finest level was coded.
    pub codec: Codec,
    /// PSNR of its finest level decoded (dB; infinite when lossless).
    pub psnr: f64,
}

/// Cuts a mip chain (finest first, full down to 1 × 1) into coded segments, coarsest first,
/// each the smaller of a PNG and the lowest JPEG quality that keeps [`MIN_PSNR`].
pub fn code_segments(width: u32, height: u32, chain: &[Vec<u8>]) -> Vec<CodedSegment> {
    let n = chain.len() as u32;
    segment_starts(width, height, n)
        .into_iter()
        .map(|first| {
            let (w, h) = level_size(width, height, first);
            let (codec, file, psnr) = code_level(w, h, &chain[first as usize..]);
            let mut bytes = Vec::with_capacity(TEXTURE_HEADER + file.len());
            header(&mut bytes, w, h, n - first, codec);
            bytes.extend_from_slice(&file);
            CodedSegment {
                width: w,
                height: h,
                levels: n - first,
                bytes,
                codec,
                psnr,
            }
        })
        .collect()
}

/// Codes the finest of `levels` (a segment's chain, finest first): PNG (RGB when opaque), or
/// the first JPEG quality that keeps [`MIN_PSNR`] when it is smaller; the raw levels when even
/// the PNG is no smaller. Returns the codec, the payload and its PSNR.
fn code_level(w: u32, h: u32, levels: &[Vec<u8>]) -> (Codec, Vec<u8>, f64) {
    let rgba = &levels[0];
    let opaque = rgba.chunks_exact(4).all(|p| p[3] == 255);
    let rgb: Vec<u8> = if opaque {
        rgba.chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect()
    } else {
        Vec::new()
    };
    let mut png = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new(&mut png);
    let written = if opaque {
        encoder.write_image(&rgb, w, h, image::ExtendedColorType::Rgb8)
    } else {
        encoder.write_image(rgba, w, h, image::ExtendedColorType::Rgba8)
    };
    if written.is_err() {
        return (Codec::Raw, levels.concat(), f64::INFINITY);
    }
    if opaque {
        for q in QUALITIES {
            let mut jpeg = Vec::new();
            let coded = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, q).encode(
                &rgb,
                w,
                h,
                image::ExtendedColorType::Rgb8,
            );
            if coded.is_err() || jpeg.len() >= png.len() {
                break;
            }
            let Ok(back) = decode_image(&jpeg, image::ImageFormat::Jpeg, w, h) else {
                break;
            };
            let p = psnr(rgba, &back);
            if p >= MIN_PSNR {
                return (Codec::Jpeg, jpeg, p);
            }
        }
    }
    if png.len() as u64 >= chain_bytes(w, h, full_levels(w, h)) {
        // Noise: the raw levels are no larger.
        return (Codec::Raw, levels.concat(), f64::INFINITY);
    }
    (Codec::Png, png, f64::INFINITY)
}

/// PSNR (dB) of `b` against `a`, two RGBA8 images of one size, over RGB; infinite when equal.
pub fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0u64);
    for (p, q) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for c in 0..3 {
            let d = p[c] as f64 - q[c] as f64;
            sum += d * d;
        }
        n += 3;
    }
    if sum == 0.0 || n == 0 {
        return f64::INFINITY;
    }
    10.0 * (255.0f64 * 255.0 / (sum / n as f64)).log10()
}

/// Decodes an image file that must be exactly `w × h` into RGBA8.
fn decode_image(
    file: &[u8],
    format: image::ImageFormat,
    w: u32,
    h: u32,
) -> Result<Vec<u8>, String> {
    let reader = || {
        let mut r = image::ImageReader::with_format(std::io::Cursor::new(file), format);
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(w);
        limits.max_image_height = Some(h);
        // The image decoded (16-bit RGBA at most) and its RGBA8 copy.
        limits.max_alloc = Some(w as u64 * h as u64 * 12 + (1 << 20));
        r.limits(limits);
        r
    };
    // The size first, from the file's header: nothing is decoded that the segment's header
    // does not allow.
    let size = reader()
        .into_dimensions()
        .map_err(|e| format!("texture segment: {e}"))?;
    if size != (w, h) {
        return Err(format!(
            "texture segment says {w}x{h} texels, its image is {}x{}",
            size.0, size.1
        ));
    }
    let img = reader()
        .decode()
        .map_err(|e| format!("texture segment: {e}"))?;
    Ok(img.into_rgba8().into_raw())
}

/// A texture segment decoded: its levels' RGBA8 texels, finest first, tightly packed (what a
/// GPU upload takes mip by mip).
#[derive(Debug, Clone, PartialEq)]
pub struct TextureChain {
    /// Width of the finest level (texels).
    pub width: u32,
    /// Height of the finest level (texels).
    pub height: u32,
    /// Number of levels.
    pub levels: u32,
    /// The levels' texels.
    pub texels: Vec<u8>,
}

impl TextureChain {
    /// Level `i`'s size and texels.
    pub fn level(&self, i: u32) -> (u32, u32, &[u8]) {
        let start = chain_bytes(self.width, self.height, i) as usize;
        let (w, h) = level_size(self.width, self.height, i);
        (w, h, &self.texels[start..start + (w * h * 4) as usize])
    }
}

/// Decodes a texture segment of any codec: the header checked (magic, a size within
/// [`MAX_SIZE`], a level count no longer than the chain, a known codec), raw texels exactly
/// as long as their levels need, an image file exactly the size the header says. Errors are
/// one line; nothing is allocated beyond what the header's size allows.
pub fn decode_segment(bytes: &[u8]) -> Result<TextureChain, String> {
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
    let codec = Codec::of(word(4))
        .ok_or_else(|| format!("texture segment codec {} is unknown", word(4)))?;
    let payload = &bytes[TEXTURE_HEADER..];
    let texels = match codec {
        Codec::Raw => {
            let want = chain_bytes(width, height, levels);
            if payload.len() as u64 != want {
                return Err(format!(
                    "texture segment holds {} texel bytes, its {levels} levels need {want}",
                    payload.len()
                ));
            }
            payload.to_vec()
        }
        Codec::Png | Codec::Jpeg => {
            let format = if codec == Codec::Png {
                image::ImageFormat::Png
            } else {
                image::ImageFormat::Jpeg
            };
            let finest = decode_image(payload, format, width, height)?;
            let mut texels = Vec::with_capacity(chain_bytes(width, height, levels) as usize);
            for l in mip_chain(width, height, &finest)
                .into_iter()
                .take(levels as usize)
            {
                texels.extend_from_slice(&l);
            }
            texels
        }
    };
    Ok(TextureChain {
        width,
        height,
        levels,
        texels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checker(w: u32, h: u32) -> Vec<u8> {
        (0..w * h)
            .flat_map(|i| {
                if ((i % w) + (i / w)).is_multiple_of(2) {
                    [255, 0, 0, 255]
                } else {
                    [0, 0, 255, 255]
                }
            })
            .collect()
    }

    /// A smooth, photograph-like image with a little grain.
    fn picture(w: u32, h: u32, alpha: bool) -> Vec<u8> {
        (0..w * h)
            .flat_map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let grain = ((i.wrapping_mul(2_654_435_761) >> 28) & 7) as f32;
                let r = 128.0 + 90.0 * (x / 13.0).sin() + grain;
                let g = 128.0 + 80.0 * (y / 17.0).cos();
                let b = 100.0 + 60.0 * ((x + y) / 29.0).sin();
                let a = if alpha && x < w as f32 / 2.0 {
                    0.0
                } else {
                    255.0
                };
                [r as u8, g as u8, b as u8, a as u8]
            })
            .collect()
    }

    #[test]
    fn raw_segments_are_coarse_first_and_each_a_whole_chain() {
        let (w, h) = (256, 128);
        let chain = mip_chain(w, h, &checker(w, h));
        let segs = cut_segments(w, h, &chain);
        let shapes: Vec<(u32, u32, u32)> = segs.iter().map(|s| (s.0, s.1, s.2)).collect();
        assert_eq!(shapes, vec![(64, 32, 7), (128, 64, 8), (256, 128, 9)]);
        for (sw, sh, levels, bytes) in &segs {
            let c = decode_segment(bytes).expect("decodes");
            assert_eq!((c.width, c.height, c.levels), (*sw, *sh, *levels));
            assert_eq!(c.level(levels - 1), (1, 1, &chain[8][..]));
        }
        // A small image is one coarse segment.
        let small = cut_segments(16, 16, &mip_chain(16, 16, &checker(16, 16)));
        assert_eq!(small.len(), 1);
        assert_eq!(small[0].2, 5);
    }

    #[test]
    fn coded_segments_keep_the_stated_quality_and_are_smaller() {
        let (w, h) = (256, 256);
        let img = picture(w, h, false);
        let chain = mip_chain(w, h, &img);
        let segs = code_segments(w, h, &chain);
        let raw = cut_segments(w, h, &chain);
        assert_eq!(segs.len(), raw.len());
        for (s, r) in segs.iter().zip(&raw) {
            let c = decode_segment(&s.bytes).unwrap();
            assert_eq!((c.width, c.height, c.levels), (r.0, r.1, r.2));
            let (_, _, finest) = c.level(0);
            let p = psnr(&chain[(8 - (c.levels - 1)) as usize], finest);
            assert!(
                p >= MIN_PSNR && (p - s.psnr).abs() < 1e-6 || p.is_infinite(),
                "{p}"
            );
            assert!(
                s.bytes.len() * 3 < r.3.len(),
                "{} coded, {} raw",
                s.bytes.len(),
                r.3.len()
            );
        }
        // The finest: a JPEG of this picture keeps 40 dB for well under a PNG's bytes.
        assert_eq!(segs.last().unwrap().codec, Codec::Jpeg);
        // A cut-out keeps its alpha: lossless.
        let cut = picture(w, h, true);
        let segs = code_segments(w, h, &mip_chain(w, h, &cut));
        let c = decode_segment(&segs.last().unwrap().bytes).unwrap();
        assert_eq!(segs.last().unwrap().codec, Codec::Png);
        assert_eq!(c.level(0).2, &cut[..]);
    }

    #[test]
    fn bad_segments_are_refused() {
        let segs = cut_segments(4, 4, &mip_chain(4, 4, &checker(4, 4)));
        let good = &segs[0].3;
        assert!(decode_segment(good).is_ok());
        assert!(decode_segment(&good[..good.len() - 1]).is_err());
        let mut bad = good.clone();
        bad[12] = 9; // more levels than a 4x4 chain has
        assert!(decode_segment(&bad).unwrap_err().contains("levels"));
        let mut bad = good.clone();
        bad[4..8].copy_from_slice(&0u32.to_le_bytes());
        assert!(decode_segment(&bad).is_err());
        let mut bad = good.clone();
        bad[0] = b'X';
        assert!(decode_segment(&bad).unwrap_err().contains("magic"));
        let mut bad = good.clone();
        bad[16] = 7;
        assert!(decode_segment(&bad).unwrap_err().contains("codec"));
        // An image of another size than the header says.
        let coded = code_segments(64, 64, &mip_chain(64, 64, &picture(64, 64, false)));
        let mut bad = coded[0].bytes.clone();
        bad[4..8].copy_from_slice(&32u32.to_le_bytes());
        bad[12..16].copy_from_slice(&6u32.to_le_bytes());
        // Refused from the file's header, before its texels are decoded.
        let err = decode_segment(&bad).unwrap_err();
        assert!(err.contains("64x64") || err.contains("limit"), "{err}");
    }
}
