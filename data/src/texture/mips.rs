//! Mip levels and colours: the box-filtered chain of an image (built at import for the
//! stand-in colours, and by the client from each decoded texture segment), its average colour,
//! and sRGB ↔ linear light.

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

/// sRGB byte to linear light (a table: the client builds mip chains from decoded segments).
pub fn to_linear(c: u8) -> f32 {
    static TABLE: std::sync::LazyLock<[f32; 256]> = std::sync::LazyLock::new(|| {
        std::array::from_fn(|i| {
            let c = i as f32 / 255.0;
            if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            }
        })
    });
    TABLE[c as usize]
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chains_halve_to_one_texel() {
        let checker: Vec<u8> = (0..16u32)
            .flat_map(|i| {
                if ((i % 8) + (i / 8)).is_multiple_of(2) {
                    [255, 0, 0, 255]
                } else {
                    [0, 0, 255, 255]
                }
            })
            .collect();
        let chain = mip_chain(8, 2, &checker);
        let sizes: Vec<usize> = chain.iter().map(Vec::len).collect();
        assert_eq!(sizes, vec![64, 16, 8, 4]);
        // Red and blue average in linear light: 0.5 each, sRGB 188.
        assert_eq!(&chain[3][..], &[188, 0, 188, 255]);
    }

    #[test]
    fn cut_out_edges_keep_their_colour() {
        // A white texel beside a transparent black one: the average stays white, half covered.
        let img = [255, 255, 255, 255, 0, 0, 0, 0];
        let chain = mip_chain(2, 1, &img);
        assert_eq!(&chain[1][..], &[255, 255, 255, 128]);
        // Transparent black texels do not darken the average colour.
        let avg = average_color(&[255, 0, 0, 255, 0, 0, 0, 0]);
        assert_eq!((avg[0], avg[1], avg[3]), (1.0, 0.0, 0.5));
    }

    #[test]
    fn srgb_round_trips() {
        for c in 0..=255u8 {
            assert_eq!(to_srgb(to_linear(c)), c);
        }
    }
}
