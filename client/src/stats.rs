//! Per-frame statistics (Funkhouser Table 3.3) and their summary (RRB §5.2: mean, min, max,
//! mean absolute deviation, standard deviation, percentiles, frames over budget).

use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;

/// One frame's row of `frames.csv`.
#[derive(Debug, Clone, Default, Serialize)]
pub struct FrameRow {
    /// Frame index.
    pub frame: u64,
    /// Path time (seconds).
    pub t: f64,
    /// Whole frame time, visibility to finished render (seconds).
    pub frame_s: f64,
    /// Eye-to-cell and eye-to-object visibility time.
    pub visibility_s: f64,
    /// Detail elision time.
    pub elision_s: f64,
    /// Render time (submit to GPU done).
    pub render_s: f64,
    /// Render time the cost model predicted.
    pub predicted_s: f64,
    /// Cells visible from the eye.
    pub visible_cells: u32,
    /// Objects visible from the eye.
    pub visible_objects: u32,
    /// Objects drawn.
    pub drawn_objects: u32,
    /// Triangles drawn.
    pub drawn_triangles: u64,
    /// LODs skipped because finer ones were not resident (§5.2.4).
    pub lods_skipped: u32,
    /// Visible objects skipped because no LOD was resident.
    pub objects_skipped: u32,
    /// Whether the eye cell's stab list was missing (frustum culling was used instead).
    pub visibility_fallback: bool,
    /// Segments resident.
    pub resident_segments: u32,
    /// Bytes resident.
    pub resident_bytes: u64,
    /// Segments that arrived this frame.
    pub read_segments: u32,
    /// Bytes that arrived this frame.
    pub read_bytes: u64,
    /// Segments released this frame.
    pub released_segments: u32,
}

/// Summary statistics of a series.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Series {
    /// Mean.
    pub mean: f64,
    /// Minimum.
    pub min: f64,
    /// Maximum.
    pub max: f64,
    /// Mean absolute deviation from the mean (RRB eq. 5.2).
    pub mad: f64,
    /// Standard deviation.
    pub sd: f64,
    /// 50th percentile.
    pub p50: f64,
    /// 95th percentile.
    pub p95: f64,
    /// 99th percentile.
    pub p99: f64,
}

impl Series {
    /// Summarises values (all zero when empty).
    pub fn of(values: &[f64]) -> Series {
        if values.is_empty() {
            return Series::default();
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let mut sorted = values.to_vec();
        sorted.sort_by(f64::total_cmp);
        let pct = |p: f64| sorted[((p * (n - 1.0)).round() as usize).min(sorted.len() - 1)];
        Series {
            mean,
            min: sorted[0],
            max: sorted[sorted.len() - 1],
            mad: values.iter().map(|v| (v - mean).abs()).sum::<f64>() / n,
            sd: (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt(),
            p50: pct(0.5),
            p95: pct(0.95),
            p99: pct(0.99),
        }
    }
}

/// Writes rows as CSV with a header line.
pub fn write_csv(path: &Path, rows: &[FrameRow]) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(
        f,
        "frame,t,frame_s,visibility_s,elision_s,render_s,predicted_s,visible_cells,visible_objects,drawn_objects,drawn_triangles,lods_skipped,objects_skipped,visibility_fallback,resident_segments,resident_bytes,read_segments,read_bytes,released_segments"
    )?;
    for r in rows {
        writeln!(
            f,
            "{},{:.4},{:.6},{:.6},{:.6},{:.6},{:.6},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.frame,
            r.t,
            r.frame_s,
            r.visibility_s,
            r.elision_s,
            r.render_s,
            r.predicted_s,
            r.visible_cells,
            r.visible_objects,
            r.drawn_objects,
            r.drawn_triangles,
            r.lods_skipped,
            r.objects_skipped,
            r.visibility_fallback as u8,
            r.resident_segments,
            r.resident_bytes,
            r.read_segments,
            r.read_bytes,
            r.released_segments
        )?;
    }
    f.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_statistics() {
        let s = Series::of(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!((s.mean, s.min, s.max), (2.5, 1.0, 4.0));
        assert!((s.mad - 1.0).abs() < 1e-12);
        assert!((s.sd - 1.25f64.sqrt()).abs() < 1e-12);
        assert_eq!(s.p99, 4.0);
        assert_eq!(Series::of(&[]), Series::default());
    }

    #[test]
    fn csv_has_a_header_and_one_line_per_frame() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.csv");
        write_csv(
            &p,
            &[
                FrameRow::default(),
                FrameRow {
                    frame: 1,
                    ..FrameRow::default()
                },
            ],
        )
        .unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[0].split(',').count(), lines[2].split(',').count());
        assert!(lines[2].starts_with("1,"));
    }
}
