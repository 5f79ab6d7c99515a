//! Block compression on the client: a decoded mip chain re-coded as BC1 (opaque textures,
//! half a byte per texel) or BC3 (with alpha, one byte per texel), the formats desktop GPUs
//! sample directly, or as ETC2 RGB8 (opaque, half a byte) for phones' GPUs, so a texture holds
//! a quarter or an eighth of its RGBA8 bytes in GPU memory and in the cache budget.
//!
//! The wire stays a compact image codec ([`super::decode_segment`]: JPEG at 40 dB is a fifth
//! of a byte per texel, less than any block format) and the client transcodes on its IO stage:
//! the approach of J.M.P. van Waveren, *Real-Time DXT Compression* (Intel/id Software, 2006).
//! The BC encoder is libsquish's range fit (the `texpresso` crate, pure Rust: the browser runs
//! it too), chosen over cluster fit for speed: it runs once per arriving segment. The ETC2
//! encoder is Basis Universal's real-time ETC1 packer (the `basisu` crate's, pure Rust): ETC1
//! blocks are ETC2 RGB8 blocks.
//!
//! A GPU takes a block-compressed texture only when its finest level is a whole number of
//! 4 × 4 blocks; other sizes stay RGBA8 ([`block_format`]). Levels below 4 texels are stored
//! as one partial block, as the GPU expects.

use super::{TextureChain, level_size};

/// How a client's GPU holds texture texels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum TexelFormat {
    /// Four bytes per texel: every GPU can (those with neither BC nor ETC2, such as WebGL2
    /// without all of the S3TC, S3TC sRGB, RGTC and BPTC extensions wgpu asks for).
    #[default]
    Rgba8,
    /// BC1 for opaque textures, BC3 for those with alpha, where the size allows
    /// ([`block_format`]: a finest level of whole 4 × 4 blocks): adapters with BC texture
    /// compression (desktop GPUs, llvmpipe, WebGPU on desktops, WebGL2 with S3TC, RGTC and
    /// BPTC).
    Block,
    /// ETC2 (RGB8) for opaque textures where the size allows, RGBA8 for those with alpha:
    /// mobile GPUs (OpenGL ES 3 and Vulkan on phones take ETC2, few take BC).
    Etc2,
}

/// A block-compressed texel format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BlockFormat {
    /// 8 bytes per 4 × 4 block: colour only (opaque textures).
    Bc1,
    /// 16 bytes per 4 × 4 block: colour and interpolated alpha.
    Bc3,
    /// 8 bytes per 4 × 4 block: ETC2's RGB8 (ETC1 blocks, which every ETC2 GPU reads).
    Etc2Rgb,
}

impl BlockFormat {
    /// Bytes of one 4 × 4 block.
    pub fn block_bytes(self) -> u64 {
        match self {
            BlockFormat::Bc1 | BlockFormat::Etc2Rgb => 8,
            BlockFormat::Bc3 => 16,
        }
    }

    /// The BC encoder of a BC format (`None` for ETC2).
    fn encoder(self) -> Option<texpresso::Format> {
        match self {
            BlockFormat::Bc1 => Some(texpresso::Format::Bc1),
            BlockFormat::Bc3 => Some(texpresso::Format::Bc3),
            BlockFormat::Etc2Rgb => None,
        }
    }
}

/// The block format a `width × height` texture is held in by a GPU of `texels`: `None` for
/// RGBA8 (that GPU, or a finest level that is not whole 4 × 4 blocks).
pub fn block_format(
    texels: TexelFormat,
    width: u32,
    height: u32,
    opaque: bool,
) -> Option<BlockFormat> {
    let whole = width > 0 && height > 0 && width.is_multiple_of(4) && height.is_multiple_of(4);
    match texels {
        TexelFormat::Block if whole && opaque => Some(BlockFormat::Bc1),
        TexelFormat::Block if whole => Some(BlockFormat::Bc3),
        TexelFormat::Etc2 if whole && opaque => Some(BlockFormat::Etc2Rgb),
        _ => None,
    }
}

/// Bytes of `levels` levels from `width × height` down in `format` (partial blocks count
/// whole; more than 32 levels count as 32).
pub fn block_chain_bytes(width: u32, height: u32, levels: u32, format: BlockFormat) -> u64 {
    (0..levels.min(32))
        .map(|i| {
            let (w, h) = level_size(width, height, i);
            w.div_ceil(4) as u64 * h.div_ceil(4) as u64 * format.block_bytes()
        })
        .fold(0u64, u64::saturating_add)
}

/// A mip chain in a block format: each level's blocks row by row, finest level first.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockChain {
    /// The format of every level.
    pub format: BlockFormat,
    /// Width of the finest level (texels; a multiple of 4).
    pub width: u32,
    /// Height of the finest level (texels; a multiple of 4).
    pub height: u32,
    /// Number of levels.
    pub levels: u32,
    /// The blocks ([`block_chain_bytes`] long).
    pub bytes: Vec<u8>,
}

/// Whether every texel of an RGBA8 chain has alpha 255 (BC1 then loses nothing of it).
pub fn is_opaque(texels: &[u8]) -> bool {
    texels.chunks_exact(4).all(|p| p[3] == 255)
}

/// Compresses a decoded chain into `format`; `None` when its finest level is not whole 4 × 4
/// blocks (the caller keeps it RGBA8).
pub fn compress(chain: &TextureChain, format: BlockFormat) -> Option<BlockChain> {
    if !chain.width.is_multiple_of(4) || !chain.height.is_multiple_of(4) || chain.levels == 0 {
        return None;
    }
    let total = block_chain_bytes(chain.width, chain.height, chain.levels, format) as usize;
    let mut bytes = vec![0u8; total];
    let mut at = 0;
    for i in 0..chain.levels {
        let (w, h, texels) = chain.level(i);
        let size = (w.div_ceil(4) * h.div_ceil(4)) as usize * format.block_bytes() as usize;
        let out = &mut bytes[at..at + size];
        match format.encoder() {
            Some(encoder) => {
                let params = texpresso::Params {
                    algorithm: texpresso::Algorithm::RangeFit,
                    weights: texpresso::COLOUR_WEIGHTS_UNIFORM,
                    weigh_colour_by_alpha: false,
                };
                encoder.compress(texels, w as usize, h as usize, params, out);
            }
            None => etc2_level(texels, w, h, out),
        }
        at += size;
    }
    Some(BlockChain {
        format,
        width: chain.width,
        height: chain.height,
        levels: chain.levels,
        bytes,
    })
}

/// One level as ETC2 RGB8 blocks, row by row: Basis Universal's real-time ETC1 packer
/// (`basisu::fastenc`), each block's texels row-major, a partial block's repeating its edge.
fn etc2_level(texels: &[u8], w: u32, h: u32, out: &mut [u8]) {
    let mut state = basisu::fastenc::etc1f::PackEtc1State::new();
    let (bw, bh) = (w.div_ceil(4), h.div_ceil(4));
    for by in 0..bh {
        for bx in 0..bw {
            let mut pixels = [[0u8; 4]; 16];
            for (k, p) in pixels.iter_mut().enumerate() {
                let x = (bx * 4 + k as u32 % 4).min(w - 1);
                let y = (by * 4 + k as u32 / 4).min(h - 1);
                let o = ((y * w + x) * 4) as usize;
                p.copy_from_slice(&texels[o..o + 4]);
            }
            let b = ((by * bw + bx) * 8) as usize;
            let block: &mut [u8; 8] = (&mut out[b..b + 8]).try_into().expect("8 bytes");
            basisu::fastenc::etc1f::pack_etc1(block, &pixels, &mut state);
        }
    }
}

/// Decodes level 0 of a BC chain back to RGBA8 (to measure what the GPU samples); `None` for
/// ETC2, which this build only encodes.
pub fn decompress_finest(chain: &BlockChain) -> Option<Vec<u8>> {
    let encoder = chain.format.encoder()?;
    let (w, h) = (chain.width as usize, chain.height as usize);
    let mut out = vec![0u8; w * h * 4];
    let size = encoder.compressed_size(w, h);
    encoder.decompress(&chain.bytes[..size], w, h, &mut out);
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::{mip_chain, psnr};

    fn chain_of(w: u32, h: u32, rgba: &[u8]) -> TextureChain {
        let levels = mip_chain(w, h, rgba);
        TextureChain {
            width: w,
            height: h,
            levels: levels.len() as u32,
            texels: levels.concat(),
        }
    }

    fn picture(w: u32, h: u32, alpha: bool) -> Vec<u8> {
        (0..w * h)
            .flat_map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let r = 128.0 + 90.0 * (x / 13.0).sin();
                let g = 128.0 + 80.0 * (y / 17.0).cos();
                let b = 100.0 + 60.0 * ((x + y) / 29.0).sin();
                let a = if alpha {
                    (x * 255.0 / w as f32) as u8
                } else {
                    255
                };
                [r as u8, g as u8, b as u8, a]
            })
            .collect()
    }

    #[test]
    fn formats_follow_the_gpu_alpha_and_whole_blocks() {
        use BlockFormat::*;
        use TexelFormat::*;
        assert_eq!(block_format(Block, 256, 128, true), Some(Bc1));
        assert_eq!(block_format(Block, 256, 128, false), Some(Bc3));
        assert_eq!(block_format(Etc2, 256, 128, true), Some(Etc2Rgb));
        assert_eq!(block_format(Etc2, 256, 128, false), None);
        assert_eq!(block_format(Rgba8, 256, 128, true), None);
        assert_eq!(block_format(Block, 250, 128, true), None);
        // A 256² chain of 9 levels: 4096 + 1024 + ... blocks, the last three one block each.
        assert_eq!(
            block_chain_bytes(256, 256, 9, Bc1),
            8 * (4096 + 1024 + 256 + 64 + 16 + 4 + 1 + 1 + 1)
        );
        assert_eq!(block_chain_bytes(256, 256, 9, Bc3), 2 * 8 * 5463);
    }

    #[test]
    fn compressed_chains_hold_at_most_a_byte_per_texel_and_keep_the_picture() {
        let (w, h) = (128, 64);
        for (alpha, format, per_texel) in [
            (false, BlockFormat::Bc1, 0.5),
            (true, BlockFormat::Bc3, 1.0),
        ] {
            let img = picture(w, h, alpha);
            assert_eq!(is_opaque(&img), !alpha);
            let chain = chain_of(w, h, &img);
            let blocks = compress(&chain, format).expect("whole blocks");
            assert_eq!(blocks.levels, chain.levels);
            assert_eq!(
                blocks.bytes.len() as u64,
                block_chain_bytes(w, h, chain.levels, format)
            );
            // The finest level at `per_texel`, the coarser ones under a half of it more.
            let finest = (w * h) as f64 * per_texel;
            let held = blocks.bytes.len() as f64;
            assert!(held >= finest && held <= finest * 1.4, "{held} bytes");
            let back = decompress_finest(&blocks).unwrap();
            let p = psnr(&img, &back);
            assert!(p > 32.0, "{format:?}: {p:.1} dB");
            if alpha {
                let err = img
                    .chunks_exact(4)
                    .zip(back.chunks_exact(4))
                    .map(|(a, b)| (a[3] as i32 - b[3] as i32).abs())
                    .max()
                    .unwrap();
                assert!(err <= 4, "alpha off by {err}");
            }
        }
        // ETC2: half a byte per texel, every block written (none left zero on a picture).
        let chain = chain_of(w, h, &picture(w, h, false));
        let etc = compress(&chain, BlockFormat::Etc2Rgb).unwrap();
        assert_eq!(
            etc.bytes.len() as u64,
            block_chain_bytes(w, h, chain.levels, BlockFormat::Etc2Rgb)
        );
        assert!(etc.bytes.chunks_exact(8).all(|b| b != [0; 8]));
        assert!(decompress_finest(&etc).is_none());
        let odd = chain_of(6, 4, &picture(6, 4, false));
        assert!(compress(&odd, BlockFormat::Bc1).is_none());
    }
}
