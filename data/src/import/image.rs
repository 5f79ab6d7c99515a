//! Material images decoded into textures: every format the `image` crate reads with a pure-Rust
//! decoder (PNG, JPEG, TGA, BMP, GIF, TIFF, WebP, QOI, PNM, ICO, HDR, DDS), and KTX2 with Basis
//! Universal supercompression (glTF's `KHR_texture_basisu`, what gltfpack and gltf-transform
//! write: ETC1S or UASTC, transcoded to RGBA8 by the pure-Rust `basisu` transcoder), as sRGB
//! RGBA8.
//!
//! - The format comes from the content where it has a magic number, else from the name: TGA
//!   has none, so a `.tga` is read as TGA first (Crytek's Sponza and 3ds Max use it).
//! - Any size is read (up to [`MAX_DECODED_SIDE`] and [`MAX_DECODED_BYTES`], the size refused
//!   before anything is allocated when a header claims more) and scaled to at most
//!   [`MAX_SIZE`] texels on a side.
//! - One **texture budget per model** ([`MODEL_TEXELS`]): an importer first reads every image's
//!   size ([`dimensions`]), then [`fit`] gives the one scale that brings them all within the
//!   budget, and each image is decoded and scaled in turn ([`decode`]), so a build holds the
//!   budget plus one decoded image, never the sum of the images; every texture shrinks by the
//!   same factor and none is dropped.

use crate::texture::{MAX_SIZE, TextureImage, Wrap};
use std::io::Cursor;

/// Largest image side read (texels): more is a broken or hostile header.
pub const MAX_DECODED_SIDE: u32 = 1 << 15;
/// Most bytes one image may decode into before it is scaled (1 GiB: 16,384² RGBA8).
pub const MAX_DECODED_BYTES: u64 = 1 << 30;
/// Texels (finest levels) all of a model's textures may hold together: 64 M, 256 MiB as
/// RGBA8. Past it every texture is scaled by one factor ([`fit`]).
pub const MODEL_TEXELS: u64 = 64 << 20;

/// The names of the formats read, for messages.
const FORMATS: &str = "PNG, JPEG, TGA, BMP, GIF, TIFF, WebP, QOI, PNM, ICO, HDR, DDS or KTX2";

/// The first bytes of every KTX2 file.
const KTX2_MAGIC: [u8; 12] = [
    0xAB, b'K', b'T', b'X', b' ', b'2', b'0', 0xBB, b'\r', b'\n', 0x1A, b'\n',
];

/// A KTX2 file opened for transcoding (its base level's size checked), or `None` for other
/// bytes.
fn ktx2(bytes: &[u8]) -> Option<Result<(basisu::Transcoder<'_>, u32, u32), String>> {
    if !bytes.starts_with(&KTX2_MAGIC) {
        return None;
    }
    let what = "KTX2 (KHR_texture_basisu)";
    Some(
        basisu::Transcoder::new(bytes)
            .map_err(|e| {
                format!("{what}: not a Basis Universal texture this build transcodes ({e:?})")
            })
            .and_then(|t| {
                let (w, h) = t.base_dimensions();
                if w == 0 || h == 0 || w > MAX_DECODED_SIDE || h > MAX_DECODED_SIDE {
                    return Err(format!(
                        "{what}: a {w}x{h} image is beyond what is read ({MAX_DECODED_SIDE} a side)"
                    ));
                }
                if w as u64 * h as u64 * 4 > MAX_DECODED_BYTES {
                    return Err(format!(
                        "{what}: a {w}x{h} image decodes past {} MiB",
                        MAX_DECODED_BYTES >> 20
                    ));
                }
                Ok((t, w, h))
            }),
    )
}

/// A KTX2 file's base level as RGBA8 ([`ktx2`]).
fn decode_ktx2(bytes: &[u8]) -> Option<Result<image::DynamicImage, String>> {
    let opened = ktx2(bytes)?;
    Some(opened.and_then(|(t, w, h)| {
        let rgba = t
            .transcode(0, basisu::TargetFormat::Rgba32, basisu::DecodeFlags::NONE)
            .map_err(|e| format!("KTX2 (KHR_texture_basisu): {e:?}"))?;
        image::RgbaImage::from_raw(w, h, rgba)
            .map(image::DynamicImage::ImageRgba8)
            .ok_or_else(|| "KTX2 (KHR_texture_basisu): its base level is short".to_string())
    }))
}

/// A reader of `bytes` in the format the content says, else the name's extension (TGA, which
/// has no magic number, by its extension first unless `content_first`).
fn reader<'a>(
    name: &str,
    bytes: &'a [u8],
    content_first: bool,
) -> Result<image::ImageReader<Cursor<&'a [u8]>>, String> {
    let by_name = image::ImageFormat::from_path(name.replace('\\', "/")).ok();
    let mut reader = image::ImageReader::new(Cursor::new(bytes));
    if by_name == Some(image::ImageFormat::Tga) && !content_first {
        reader.set_format(image::ImageFormat::Tga);
    } else {
        reader = reader.with_guessed_format().map_err(|e| e.to_string())?;
        if reader.format().is_none() {
            match by_name {
                Some(f) => reader.set_format(f),
                None => return Err(format!("not an image this build reads ({FORMATS})")),
            }
        }
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_DECODED_SIDE);
    limits.max_image_height = Some(MAX_DECODED_SIDE);
    limits.max_alloc = Some(MAX_DECODED_BYTES);
    reader.limits(limits);
    Ok(reader)
}

/// The size of image `bytes` named `name` (texels), read from its header without decoding.
/// Errors say what is wrong in one line, without the name.
pub fn dimensions(name: &str, bytes: &[u8]) -> Result<(u32, u32), String> {
    if let Some(k) = ktx2(bytes) {
        return k.map(|(_, w, h)| (w, h));
    }
    // A `.tga` that is another format after all is read by its content.
    let (w, h) = reader(name, bytes, false)?
        .into_dimensions()
        .map_err(|e| e.to_string())
        .or_else(|e| reader(name, bytes, true)?.into_dimensions().map_err(|_| e))?;
    if w == 0 || h == 0 || w > MAX_DECODED_SIDE || h > MAX_DECODED_SIDE {
        return Err(format!(
            "a {w}x{h} image is beyond what is read ({MAX_DECODED_SIDE} a side)"
        ));
    }
    Ok((w, h))
}

/// The size an image of `width × height` is stored at under `scale` (from [`fit`]; 1 for
/// none): at most [`MAX_SIZE`] a side, then scaled, at least one texel.
pub fn fitted(width: u32, height: u32, scale: f64) -> (u32, u32) {
    let side = width.max(height).max(1) as f64;
    let s = (MAX_SIZE as f64 / side).min(1.0) * scale.clamp(0.0, 1.0);
    let f = |x: u32| ((x as f64 * s).round() as u32).clamp(1, MAX_SIZE);
    (f(width), f(height))
}

/// A warning naming image `name` when its `size` is stored smaller than read because of the
/// side limit ([`MAX_SIZE`]; the budget's scale is warned of once, by [`fit`]).
pub fn limit_warning(name: &str, size: (u32, u32)) -> Option<String> {
    let stored = fitted(size.0, size.1, 1.0);
    (stored != size).then(|| {
        format!(
            "image '{name}' is {}x{} texels: stored at {}x{} (at most {MAX_SIZE} a side)",
            size.0, size.1, stored.0, stored.1
        )
    })
}

/// The one scale (0..=1) that brings images of these sizes within `budget` texels once each is
/// [`fitted`], and a warning saying so when it is below 1.
pub fn fit(sizes: &[(u32, u32)], budget: u64) -> (f64, Option<String>) {
    let texels = |s: f64| -> u64 {
        sizes
            .iter()
            .map(|&(w, h)| {
                let (w, h) = fitted(w, h, s);
                w as u64 * h as u64
            })
            .sum()
    };
    let full = texels(1.0);
    if full <= budget {
        return (1.0, None);
    }
    let mut s = (budget as f64 / full as f64).sqrt();
    // Rounding each side can overshoot by a texel row: step down until the sum fits.
    while s > 1e-4 && texels(s) > budget {
        s *= 0.99;
    }
    let warning = format!(
        "the model's {} textures hold {:.1} M texels, past its texture budget of {} M: \
         each is scaled to {:.0} % of its side",
        sizes.len(),
        full as f64 / (1u64 << 20) as f64,
        budget >> 20,
        s * 100.0
    );
    (s, Some(warning))
}

/// Decodes image bytes named `name` (for the format and the texture's name) and scales it to
/// its [`fitted`] size under `scale`. Errors say what is wrong in one line, without the name.
pub fn decode(
    name: &str,
    bytes: &[u8],
    wrap: [Wrap; 2],
    scale: f64,
) -> Result<TextureImage, String> {
    let img = match decode_ktx2(bytes) {
        Some(k) => k?,
        None => reader(name, bytes, false)?
            .decode()
            .map_err(|e| e.to_string())
            .or_else(|e| reader(name, bytes, true)?.decode().map_err(|_| e))?,
    };
    let (w, h) = (img.width(), img.height());
    let (nw, nh) = fitted(w, h, scale);
    let img = if (nw, nh) != (w, h) {
        // Area averaging: each texel the mean of what it covers (the box filter the mip chain
        // uses), and fast on huge images.
        img.thumbnail_exact(nw, nh).into_rgba8()
    } else {
        img.into_rgba8()
    };
    Ok(TextureImage {
        name: name.to_string(),
        width: img.width(),
        height: img.height(),
        rgba: img.into_raw(),
        wrap,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn encoded(w: u32, h: u32, format: image::ImageFormat) -> Vec<u8> {
        let img = image::RgbaImage::from_pixel(w, h, image::Rgba([200, 100, 50, 255]));
        let mut out = Vec::new();
        img.write_to(&mut Cursor::new(&mut out), format).unwrap();
        out
    }

    #[test]
    fn images_decode_and_large_ones_shrink() {
        let png = encoded(8, 4, image::ImageFormat::Png);
        let t = decode("a.png", &png, [Wrap::Repeat; 2], 1.0).unwrap();
        assert_eq!((t.width, t.height, t.rgba.len()), (8, 4, 128));
        assert_eq!(&t.rgba[..4], &[200, 100, 50, 255]);
        let big = encoded(MAX_SIZE * 2, 16, image::ImageFormat::Png);
        assert_eq!(dimensions("big.png", &big).unwrap(), (MAX_SIZE * 2, 16));
        let t = decode("big.png", &big, [Wrap::Clamp; 2], 1.0).unwrap();
        assert_eq!((t.width, t.height), (MAX_SIZE, 8));
        let t = decode("big.png", &big, [Wrap::Clamp; 2], 0.25).unwrap();
        assert_eq!((t.width, t.height), (MAX_SIZE / 4, 2));
    }

    #[test]
    fn formats_come_from_the_content_then_the_name() {
        // TGA has no magic number: read by its name.
        let tga = encoded(4, 4, image::ImageFormat::Tga);
        let t = decode("textures\\wall.TGA", &tga, [Wrap::Repeat; 2], 1.0).unwrap();
        assert_eq!(&t.rgba[..4], &[200, 100, 50, 255]);
        // A PNG named .jpg is a PNG, and so is one named .tga.
        let png = encoded(2, 2, image::ImageFormat::Png);
        assert!(decode("wrong.jpg", &png, [Wrap::Repeat; 2], 1.0).is_ok());
        assert_eq!(dimensions("wrong.tga", &png).unwrap(), (2, 2));
        assert!(decode("wrong.tga", &png, [Wrap::Repeat; 2], 1.0).is_ok());
        for format in [
            image::ImageFormat::Bmp,
            image::ImageFormat::Gif,
            image::ImageFormat::Tiff,
        ] {
            let bytes = encoded(3, 2, format);
            let t = decode("noname", &bytes, [Wrap::Repeat; 2], 1.0).unwrap();
            assert_eq!((t.width, t.height), (3, 2), "{format:?}");
        }
    }

    #[test]
    fn other_bytes_are_refused() {
        let err = decode("x", b"hello", [Wrap::Repeat; 2], 1.0).unwrap_err();
        assert!(err.contains("not an image this build reads"), "{err}");
        assert!(decode("x", b"GIF89a....", [Wrap::Repeat; 2], 1.0).is_err());
        let mut truncated = encoded(8, 8, image::ImageFormat::Png);
        truncated.truncate(40);
        assert!(decode("x", &truncated, [Wrap::Repeat; 2], 1.0).is_err());
    }

    #[test]
    fn the_budget_shrinks_every_texture_by_one_factor() {
        let sizes = vec![(4096, 4096); 24];
        let (s, warning) = fit(&sizes, MODEL_TEXELS);
        let each = fitted(4096, 4096, s);
        assert!(24 * each.0 as u64 * each.1 as u64 <= MODEL_TEXELS);
        assert!(each.0 > 1600 && each.0 < 1700, "{each:?}");
        assert!(warning.unwrap().contains("24 textures"));
        // A 16k strip counts at its stored size (4096 a side), within the budget.
        assert_eq!(
            fit(&[(16384, 512), (8192, 8192)], MODEL_TEXELS),
            (1.0, None)
        );
        assert_eq!(fitted(16384, 512, 1.0), (4096, 128));
    }
}
