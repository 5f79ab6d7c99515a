//! Captions drawn into rendered pictures: a scale bar and a legend for the bird's-eye view (a
//! map without them cannot be read). Text needs the font of [`crate::style`]; without it the
//! bar and the legend's swatches are drawn and the words left out.

use crate::style::fonts_available;
use anyhow::{Result, anyhow};
use image::RgbaImage;
use plotters::prelude::*;

/// The scale bar's length in metres: the largest 1, 2 or 5 × 10^k that fits in `max_m`.
pub fn nice_length(max_m: f32) -> f32 {
    if !(max_m.is_finite() && max_m > 0.0) {
        return 1.0;
    }
    let base = 10f32.powf(max_m.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|f| f * base)
        .find(|&l| l <= max_m)
        .unwrap_or(base)
}

/// `image` with a scale bar (about a fifth of its width, labelled in metres) in the lower left
/// corner and a legend of `(colour, words)` rows in the upper left, on white panels.
pub fn scale_and_legend(
    image: &RgbaImage,
    metres_per_pixel: f32,
    legend: &[([u8; 3], &str)],
) -> Result<RgbaImage> {
    let (w, h) = image.dimensions();
    let mut rgb: Vec<u8> = image::DynamicImage::ImageRgba8(image.clone())
        .into_rgb8()
        .into_raw();
    let text = fonts_available();
    {
        let err = |e: &dyn std::fmt::Display| anyhow!("captioning a picture: {e}");
        let area = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        let font = ("sans-serif", 16).into_font().color(&BLACK);
        // Scale bar.
        let metres = nice_length(w as f32 * 0.2 * metres_per_pixel.max(1e-6));
        let bar = (metres / metres_per_pixel.max(1e-6)).round() as i32;
        let (x0, y0) = (16, h as i32 - 24);
        area.draw(&Rectangle::new(
            [(x0 - 8, y0 - 26), (x0 + bar + 60, y0 + 12)],
            WHITE.mix(0.85).filled(),
        ))
        .map_err(|e| err(&e))?;
        area.draw(&Rectangle::new(
            [(x0, y0 - 3), (x0 + bar, y0 + 3)],
            BLACK.filled(),
        ))
        .map_err(|e| err(&e))?;
        for x in [x0, x0 + bar] {
            area.draw(&Rectangle::new(
                [(x - 1, y0 - 8), (x + 1, y0 + 8)],
                BLACK.filled(),
            ))
            .map_err(|e| err(&e))?;
        }
        if text {
            area.draw(&Text::new(
                format!("{metres} m"),
                (x0 + bar + 8, y0 - 8),
                font.clone(),
            ))
            .map_err(|e| err(&e))?;
        }
        // Legend.
        if !legend.is_empty() {
            let row = 22;
            let width = if text { 300 } else { 40 };
            area.draw(&Rectangle::new(
                [(8, 8), (8 + width, 14 + row * legend.len() as i32)],
                WHITE.mix(0.85).filled(),
            ))
            .map_err(|e| err(&e))?;
            for (i, (c, words)) in legend.iter().enumerate() {
                let y = 14 + row * i as i32;
                area.draw(&Rectangle::new(
                    [(16, y + 3), (30, y + 17)],
                    RGBColor(c[0], c[1], c[2]).filled(),
                ))
                .map_err(|e| err(&e))?;
                if text {
                    area.draw(&Text::new(words.to_string(), (38, y + 2), font.clone()))
                        .map_err(|e| err(&e))?;
                }
            }
        }
        area.present().map_err(|e| err(&e))?;
    }
    let rgb = image::RgbImage::from_raw(w, h, rgb).ok_or_else(|| anyhow!("picture size"))?;
    Ok(image::DynamicImage::ImageRgb8(rgb).into_rgba8())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_bars_have_round_lengths() {
        assert_eq!(nice_length(7.3), 5.0);
        assert_eq!(nice_length(19.9), 10.0);
        assert_eq!(nice_length(20.0), 20.0);
        assert_eq!(nice_length(0.3), 0.2);
        assert_eq!(nice_length(f32::NAN), 1.0);
    }

    #[test]
    fn the_bar_is_drawn_to_scale() {
        // 0.1 m per pixel on a 400-pixel picture: a fifth is 8 m, so a 5 m bar of 50 pixels.
        let img = RgbaImage::from_pixel(400, 200, image::Rgba([200, 200, 200, 255]));
        let out = scale_and_legend(&img, 0.1, &[([255, 0, 0], "path")]).unwrap();
        assert_eq!(out.dimensions(), (400, 200));
        let y = 200 - 24;
        let black = |x: u32| out.get_pixel(x, y).0[..3] == [0, 0, 0];
        assert!(black(16) && black(40) && black(66), "bar from x=16 to 66");
        assert!(!black(70), "and no further");
        // The legend's swatch is red.
        assert_eq!(out.get_pixel(20, 20).0[..3], [255, 0, 0]);
    }
}
