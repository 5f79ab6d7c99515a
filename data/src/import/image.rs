//! Material images (PNG, JPEG, through the `image` crate) decoded into textures: sRGB RGBA8 at
//! most [`MAX_SIZE`] texels on a side (larger images are scaled down), the size refused before
//! anything is allocated when the header claims an absurd one.

use crate::texture::{MAX_SIZE, TextureImage, Wrap};
use std::io::Cursor;

/// Largest image side accepted before scaling (texels): more is a broken or hostile header.
const MAX_DECODED_SIDE: u32 = 8_192;

/// Decodes image bytes named `name` (for messages and the texture's name). Errors say what is
/// wrong in one line, without the name.
pub fn decode(name: &str, bytes: &[u8], wrap: [Wrap; 2]) -> Result<TextureImage, String> {
    let mut reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    if reader.format().is_none() {
        return Err("not a PNG or JPEG image".into());
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_DECODED_SIDE);
    limits.max_image_height = Some(MAX_DECODED_SIDE);
    reader.limits(limits);
    let img = reader.decode().map_err(|e| e.to_string())?.to_rgba8();
    let (w, h) = img.dimensions();
    let img = if w.max(h) > MAX_SIZE {
        let scale = MAX_SIZE as f32 / w.max(h) as f32;
        let (nw, nh) = (
            ((w as f32 * scale).round() as u32).max(1),
            ((h as f32 * scale).round() as u32).max(1),
        );
        image::imageops::resize(&img, nw, nh, image::imageops::FilterType::Triangle)
    } else {
        img
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

    fn png(w: u32, h: u32) -> Vec<u8> {
        let img = image::RgbaImage::from_pixel(w, h, image::Rgba([200, 100, 50, 255]));
        let mut out = Vec::new();
        img.write_to(&mut Cursor::new(&mut out), image::ImageFormat::Png)
            .unwrap();
        out
    }

    #[test]
    fn images_decode_and_large_ones_shrink() {
        let t = decode("a.png", &png(8, 4), [Wrap::Repeat; 2]).unwrap();
        assert_eq!((t.width, t.height, t.rgba.len()), (8, 4, 128));
        assert_eq!(&t.rgba[..4], &[200, 100, 50, 255]);
        let t = decode("big.png", &png(MAX_SIZE * 2, 16), [Wrap::Clamp; 2]).unwrap();
        assert_eq!((t.width, t.height), (MAX_SIZE, 8));
    }

    #[test]
    fn other_bytes_are_refused() {
        let err = decode("x", b"GIF89a....", [Wrap::Repeat; 2]).unwrap_err();
        assert!(!err.is_empty());
        assert!(decode("x", b"hello", [Wrap::Repeat; 2]).is_err());
        let mut truncated = png(8, 8);
        truncated.truncate(40);
        assert!(decode("x", &truncated, [Wrap::Repeat; 2]).is_err());
    }
}
