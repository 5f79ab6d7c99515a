//! Image fidelity: RRB's spatial error Es and temporal error Et at critical vertices (RRB
//! §5.3.1–5.3.2, eq. 5.5–5.10), and whole-image PSNR (eq. 5.4).
//!
//! ## Intensity and areas of interest
//!
//! RRB gives no RGB→intensity rule. We use Rec. 601 luma on the 8-bit sRGB-encoded values read
//! back from the frame, on RRB's 0–255 grey scale:
//!
//! ```text
//! I(x, y) = 0.299·R + 0.587·G + 0.114·B        (R, G, B in 0..=255)
//! ```
//!
//! The area of interest (AOI) of a critical vertex is the square of `side × side` pixels centred
//! on the pixel its position projects to in the *reference* frame (pixels `x − ⌊(side−1)/2⌋ ..=
//! x + ⌊side/2⌋`, clipped to the image), and its intensity is the mean `I` over the square. RRB
//! allows 1–10 px (§5.3.4, default 1); our default side is [`DEFAULT_PATCH`] = 5.
//!
//! ## Es and Et
//!
//! Positions and visibility come only from the reference (Regular) frame with the same index
//! (§5.3.1, the `OrgInfo` step). For vertex `v` visible in reference frame `i` (depth test, see
//! [`super::depth`]) let `I0_i(v)` and `I_i(v)` be its AOI intensities in the reference and the
//! test frame and `e_i(v) = I0_i(v) − I_i(v)` (signed, eq. 5.9). `V_i` is the set of critical
//! vertices visible in reference frame `i`, `n` the number of frames, `V` every critical vertex
//! of the model (all instances). We report:
//!
//! ```text
//! Es_i = (1/|V_i|) Σ_{v∈V_i} |e_i(v)|                      (eq. 5.5–5.6, n_v = visible AOIs)
//! Es   = (1/n) Σ_i Es_i                                      (eq. 5.7)
//! Et_i = (1/|V_i ∩ V_{i−1}|) Σ_{v∈V_i∩V_{i−1}} |e_i(v) − e_{i−1}(v)|,   i ≥ 1
//! Et   = (1/(n−1)) Σ_{i=1}^{n−1} Et_i
//! ```
//!
//! (an empty set gives 0), and, exactly as printed in RRB with `n_v = |V|`:
//!
//! ```text
//! Es_rrb = (1/n) Σ_i (1/|V|) Σ_{v∈V_i} |e_i(v)|
//! Et_rrb = (1/|V|) Σ_v (1/n) Σ_{i: v∈V_i∩V_{i−1}} |e_i(v) − e_{i−1}(v)|        (eq. 5.8–5.10)
//! ```
//!
//! The RRB variants are diluted by every invisible vertex (in a building, most of them), so the
//! per-frame visible-only forms are the headline numbers and give the per-frame curves. Both
//! are 0 when the test frames equal the reference frames. Frames are never dropped in a
//! frame-indexed run, so RRB's "repeat the previous frame" rule never applies.
//!
//! ## PSNR
//!
//! `PSNR = 10·log10(255² / MSE)`, MSE over all pixels and the R, G, B channels (eq. 5.4);
//! identical images have MSE 0 and PSNR ∞ (reported as `null`).

use image::RgbaImage;
use serde::Serialize;

/// Default side of the area of interest, in pixels (RRB §5.3.4 allows 1–10).
pub const DEFAULT_PATCH: u32 = 5;
/// Largest area-of-interest side RRB allows.
pub const MAX_PATCH: u32 = 10;
/// Luma weights of [`intensity`] (Rec. 601).
pub const LUMA: [f32; 3] = [0.299, 0.587, 0.114];
/// The intensity formula, as written in reports.
pub const INTENSITY_FORMULA: &str = "I = 0.299 R + 0.587 G + 0.114 B (8-bit sRGB-encoded, 0-255)";

/// Intensity of one pixel, 0–255.
pub fn intensity(p: &image::Rgba<u8>) -> f32 {
    LUMA[0] * f32::from(p[0]) + LUMA[1] * f32::from(p[1]) + LUMA[2] * f32::from(p[2])
}

/// Mean intensity of the `side`×`side` square centred on `(x, y)`, clipped to the image.
pub fn patch_intensity(img: &RgbaImage, x: u32, y: u32, side: u32) -> f32 {
    let side = side.clamp(1, MAX_PATCH);
    let (w, h) = img.dimensions();
    let x0 = x.saturating_sub((side - 1) / 2);
    let y0 = y.saturating_sub((side - 1) / 2);
    let x1 = (x + side / 2).min(w.saturating_sub(1));
    let y1 = (y + side / 2).min(h.saturating_sub(1));
    let (mut sum, mut count) = (0.0f32, 0u32);
    for yy in y0..=y1 {
        for xx in x0..=x1 {
            sum += intensity(img.get_pixel(xx, yy));
            count += 1;
        }
    }
    if count == 0 { 0.0 } else { sum / count as f32 }
}

/// Mean squared error over all pixels and the R, G, B channels (0 for different sizes: callers
/// compare frames of one renderer).
pub fn mse(a: &RgbaImage, b: &RgbaImage) -> f64 {
    if a.dimensions() != b.dimensions() || a.as_raw().is_empty() {
        return 0.0;
    }
    let sum: u64 = a
        .pixels()
        .zip(b.pixels())
        .map(|(p, q)| {
            (0..3)
                .map(|c| (i32::from(p[c]) - i32::from(q[c])).pow(2) as u64)
                .sum::<u64>()
        })
        .sum();
    sum as f64 / (3 * a.pixels().len()) as f64
}

/// PSNR in dB of an 8-bit image against a reference; `None` when they are identical (∞).
pub fn psnr(reference: &RgbaImage, test: &RgbaImage) -> Option<f64> {
    psnr_of_mse(mse(reference, test))
}

/// `10·log10(255²/mse)`; `None` for `mse = 0`.
pub fn psnr_of_mse(mse: f64) -> Option<f64> {
    (mse > 0.0).then(|| 10.0 * (255.0f64 * 255.0 / mse).log10())
}

/// One critical vertex visible in a reference frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefPoint {
    /// Global critical-vertex id (stable across frames; ascending within a frame).
    pub id: u32,
    /// Pixel the vertex projects to.
    pub x: u32,
    /// See `x`.
    pub y: u32,
    /// AOI intensity in the reference frame, `I0`.
    pub i0: f32,
}

/// The reference points of a frame: `(id, x, y)` sorted by id, with `I0` measured in `img`.
pub fn reference_points(img: &RgbaImage, visible: &[(u32, u32, u32)], side: u32) -> Vec<RefPoint> {
    visible
        .iter()
        .map(|&(id, x, y)| RefPoint {
            id,
            x,
            y,
            i0: patch_intensity(img, x, y, side),
        })
        .collect()
}

/// Es and Et of one test frame (`et` is `None` for the first frame).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameFidelity {
    /// `Es_i`.
    pub es: f64,
    /// `Et_i`.
    pub et: Option<f64>,
}

/// Es/Et of a whole run (see the module docs for the formulas).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Fidelity {
    /// Es, visible-only per-frame form.
    pub es: f64,
    /// Et, visible-only per-frame form.
    pub et: f64,
    /// Es with RRB's `n_v = |V|`.
    pub es_rrb: f64,
    /// Et exactly per RRB eq. 5.8–5.10 (`n_v = |V|`, normalised by `n`).
    pub et_rrb: f64,
}

/// Accumulates Es and Et frame by frame for one test sequence against the reference sequence.
#[derive(Debug, Clone)]
pub struct FidelityAccumulator {
    side: u32,
    previous: Vec<(u32, f32)>,
    frames: u64,
    es_sum: f64,
    et_sum: f64,
    abs_error_sum: f64,
    abs_change_sum: f64,
}

impl FidelityAccumulator {
    /// An accumulator with AOI side `side` pixels (clamped to 1..=10).
    pub fn new(side: u32) -> Self {
        FidelityAccumulator {
            side: side.clamp(1, MAX_PATCH),
            previous: Vec::new(),
            frames: 0,
            es_sum: 0.0,
            et_sum: 0.0,
            abs_error_sum: 0.0,
            abs_change_sum: 0.0,
        }
    }

    /// Adds test frame `i` given reference frame `i`'s points (sorted by id).
    pub fn frame(&mut self, reference: &[RefPoint], test: &RgbaImage) -> FrameFidelity {
        let errors: Vec<(u32, f32)> = reference
            .iter()
            .map(|r| (r.id, r.i0 - patch_intensity(test, r.x, r.y, self.side)))
            .collect();
        let abs_sum: f64 = errors.iter().map(|e| f64::from(e.1.abs())).sum();
        let es = if errors.is_empty() {
            0.0
        } else {
            abs_sum / errors.len() as f64
        };
        let et = (self.frames > 0).then(|| {
            let (sum, count) = changes(&self.previous, &errors);
            self.abs_change_sum += sum;
            if count == 0 { 0.0 } else { sum / count as f64 }
        });
        self.frames += 1;
        self.es_sum += es;
        self.et_sum += et.unwrap_or(0.0);
        self.abs_error_sum += abs_sum;
        self.previous = errors;
        FrameFidelity { es, et }
    }

    /// The run's Es and Et; `total_critical` is `|V|`, every critical vertex of the model.
    pub fn finish(&self, total_critical: u64) -> Fidelity {
        let n = self.frames as f64;
        let v = total_critical.max(1) as f64;
        if self.frames == 0 {
            return Fidelity::default();
        }
        Fidelity {
            es: self.es_sum / n,
            et: if self.frames > 1 {
                self.et_sum / (n - 1.0)
            } else {
                0.0
            },
            es_rrb: self.abs_error_sum / (n * v),
            et_rrb: self.abs_change_sum / (n * v),
        }
    }
}

/// `Σ |e_i(v) − e_{i−1}(v)|` over the ids in both sorted lists, and how many there were.
fn changes(previous: &[(u32, f32)], current: &[(u32, f32)]) -> (f64, u64) {
    let (mut i, mut j, mut sum, mut count) = (0, 0, 0.0f64, 0u64);
    while i < previous.len() && j < current.len() {
        match previous[i].0.cmp(&current[j].0) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                sum += f64::from((current[j].1 - previous[i].1).abs());
                count += 1;
                i += 1;
                j += 1;
            }
        }
    }
    (sum, count)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grey(w: u32, h: u32, level: u8) -> RgbaImage {
        RgbaImage::from_pixel(w, h, image::Rgba([level, level, level, 255]))
    }

    /// RRB Fig. 5.4 (b): a white square on a 155 background.
    fn with_square(level: u8) -> RgbaImage {
        let mut img = grey(32, 32, level);
        for y in 8..16 {
            for x in 8..16 {
                img.put_pixel(x, y, image::Rgba([255, 255, 255, 255]));
            }
        }
        img
    }

    fn points(img: &RgbaImage, at: &[(u32, u32)], side: u32) -> Vec<RefPoint> {
        let ids: Vec<(u32, u32, u32)> = at
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| (i as u32, x, y))
            .collect();
        reference_points(img, &ids, side)
    }

    #[test]
    fn intensity_weights_sum_to_one_on_grey() {
        assert!((intensity(&image::Rgba([155, 155, 155, 255])) - 155.0).abs() < 1e-3);
        assert!((intensity(&image::Rgba([255, 0, 0, 255])) - 76.245).abs() < 1e-3);
        let img = with_square(155);
        // A 5x5 patch centred on the square's corner (8, 8) has 3x3 white pixels of 25.
        let want = (9.0 * 255.0 + 16.0 * 155.0) / 25.0;
        assert!((patch_intensity(&img, 8, 8, 5) - want).abs() < 1e-3);
        // Clipped at the image corner: 3x3 pixels remain.
        assert!((patch_intensity(&img, 0, 0, 5) - 155.0).abs() < 1e-3);
    }

    #[test]
    fn identical_sequences_give_zero_errors_and_infinite_psnr() {
        let img = with_square(155);
        let refs = points(&img, &[(10, 10), (20, 20), (0, 31)], DEFAULT_PATCH);
        let mut acc = FidelityAccumulator::new(DEFAULT_PATCH);
        for _ in 0..3 {
            let f = acc.frame(&refs, &img);
            assert_eq!(f.es, 0.0);
            assert!(f.et.is_none_or(|e| e == 0.0));
        }
        assert_eq!(acc.finish(3), Fidelity::default());
        assert_eq!(psnr(&img, &img), None);
    }

    #[test]
    fn uniform_offset_of_one_level_has_es_one_and_known_psnr() {
        let (a, b) = (grey(16, 16, 155), grey(16, 16, 154));
        let refs = points(&a, &[(3, 3), (8, 8)], 3);
        let mut acc = FidelityAccumulator::new(3);
        assert!((acc.frame(&refs, &b).es - 1.0).abs() < 1e-4);
        let want = 10.0 * (255.0f64 * 255.0).log10();
        assert!((psnr(&a, &b).unwrap() - want).abs() < 1e-9);
        assert!((want - 48.1308).abs() < 1e-3);
    }

    #[test]
    fn a_local_error_is_seen_only_where_the_aoi_is() {
        // RRB Fig. 5.4: (a) uniform 155, (b) with a white square. An AOI on the square sees
        // the whole 100-level error, one elsewhere sees none: Es = (100 + 0) / 2.
        let (a, b) = (grey(32, 32, 155), with_square(155));
        let refs = points(&a, &[(11, 11), (25, 25)], 3);
        let mut acc = FidelityAccumulator::new(3);
        let f = acc.frame(&refs, &b);
        assert!((f.es - 50.0).abs() < 1e-3, "{f:?}");
        assert!(psnr(&a, &b).is_some_and(|p| p.is_finite() && p > 0.0));
    }

    #[test]
    fn constant_error_has_no_temporal_error_but_popping_does() {
        let reference = grey(8, 8, 100);
        let refs = points(&reference, &[(4, 4)], 1);
        // A steady error of 10 levels: Es = 10, Et = 0.
        let mut steady = FidelityAccumulator::new(1);
        for _ in 0..4 {
            steady.frame(&refs, &grey(8, 8, 90));
        }
        let s = steady.finish(1);
        assert!((s.es - 10.0).abs() < 1e-4 && s.et == 0.0, "{s:?}");
        // Errors 0, 10, 10, 0: |Δe| = 10, 0, 10 → Et = 20/3 per frame pair, RRB 20/4 over n.
        let mut popping = FidelityAccumulator::new(1);
        let levels = [100u8, 90, 90, 100];
        let per_frame: Vec<FrameFidelity> = levels
            .iter()
            .map(|&l| popping.frame(&refs, &grey(8, 8, l)))
            .collect();
        assert_eq!(per_frame[0].et, None);
        assert!((per_frame[1].et.unwrap() - 10.0).abs() < 1e-4);
        let p = popping.finish(1);
        assert!((p.et - 20.0 / 3.0).abs() < 1e-4, "{p:?}");
        assert!((p.et_rrb - 5.0).abs() < 1e-4, "{p:?}");
        assert!((p.es - 5.0).abs() < 1e-4 && (p.es_rrb - 5.0).abs() < 1e-4);
        // With |V| = 4 vertices in the model (three never visible), RRB dilutes by 4.
        assert!((popping.finish(4).et_rrb - 1.25).abs() < 1e-4);
    }

    #[test]
    fn et_pairs_only_vertices_visible_in_both_frames() {
        let reference = grey(8, 8, 100);
        let both = [
            RefPoint {
                id: 1,
                x: 2,
                y: 2,
                i0: 100.0,
            },
            RefPoint {
                id: 2,
                x: 5,
                y: 5,
                i0: 100.0,
            },
        ];
        let only_second = [
            RefPoint {
                id: 2,
                x: 5,
                y: 5,
                i0: 100.0,
            },
            RefPoint {
                id: 3,
                x: 1,
                y: 1,
                i0: 100.0,
            },
        ];
        let mut acc = FidelityAccumulator::new(1);
        acc.frame(&both, &reference);
        let f = acc.frame(&only_second, &grey(8, 8, 80));
        // Vertex 2 changes by 20; vertex 3 was not visible before and does not count.
        assert!((f.et.unwrap() - 20.0).abs() < 1e-4);
        assert!((f.es - 20.0).abs() < 1e-4);
    }
}
