//! What a streamed client drew, frame by frame: the load tester records its first client's
//! frames in each run ([`crate::loadtest`], `drawn/<run>.json`), and the benchmark draws them
//! again beside the full-detail frame of the same path time and scores them (`portico bench
//! --replay`, [`crate::bench`]: PSNR, Es, Et). So a run's image fidelity is measured on the
//! frames its cache and link actually allowed, textures included, not on frames with every
//! segment resident.

use anyhow::{Context, Result, ensure};
use portico_client::cluster::Stand;
use portico_client::frame::Decision;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One object drawn: which LOD, with which texture segment and tint ([`portico_client::frame::Drawn`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DrawnObject {
    /// The instance.
    pub instance: u32,
    /// LOD index into the instance's full LOD table, finest first.
    pub lod: u32,
    /// The texture segment it was drawn with, if any.
    pub texture: Option<u32>,
    /// The colour multiplied in (linear RGBA).
    pub tint: [f32; 4],
}

/// One frame as drawn.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DrawnFrame {
    /// The path frame shown (the benchmark's frame index: path time `path_frame · dt_s`).
    pub path_frame: usize,
    /// The objects drawn.
    pub objects: Vec<DrawnObject>,
    /// Cluster boxes drawn in place of objects: `(cluster, textured)`.
    pub boxes: Vec<(u32, bool)>,
    /// Objects the visibility stage passed.
    pub visible: u32,
}

impl DrawnFrame {
    /// What `d` drew at path frame `path_frame`.
    pub fn of(d: &Decision, path_frame: usize) -> DrawnFrame {
        DrawnFrame {
            path_frame,
            objects: d
                .drawn
                .iter()
                .map(|o| DrawnObject {
                    instance: o.instance,
                    lod: o.lod as u32,
                    texture: o.texture,
                    tint: o.tint,
                })
                .collect(),
            boxes: d
                .boxes
                .iter()
                .map(|&(n, s)| (n, s == Stand::Textured))
                .collect(),
            visible: d.visible.objects.len() as u32,
        }
    }
}

/// A run's recorded frames (`drawn/<run>.json`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DrawnLog {
    /// The run that drew them (a policy's name, `demand` or `oracle`).
    pub run: String,
    /// The database id (content hash) the frames index into.
    pub database_id: String,
    /// The path's hash.
    pub path_hash: String,
    /// Path time between frames (s).
    pub dt_s: f64,
    /// The frames, in the order drawn.
    pub frames: Vec<DrawnFrame>,
}

impl DrawnLog {
    /// Writes the log as JSON to `path`.
    pub fn write(&self, path: &Path) -> Result<()> {
        let bytes = serde_json::to_vec(self)?;
        std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
    }

    /// Reads a log written by [`DrawnLog::write`].
    ///
    /// # Errors
    /// The file unreadable or not a drawn-frames log, naming the file.
    pub fn read(path: &Path) -> Result<DrawnLog> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        serde_json::from_slice(&bytes).with_context(|| {
            format!(
                "{} is not a load test's drawn-frames log (drawn/<run>.json)",
                path.display()
            )
        })
    }

    /// The frame drawn at path frame `f`, if the log has it.
    pub fn at(&self, f: u64) -> Option<&DrawnFrame> {
        let i = usize::try_from(f).ok()?;
        match self.frames.get(i) {
            Some(x) if x.path_frame == i => Some(x),
            _ => self.frames.iter().find(|x| x.path_frame == i),
        }
    }

    /// Checks that the log was drawn from database `database_id` at frame step `dt_s` and
    /// covers path frames `0..frames`.
    ///
    /// # Errors
    /// The first mismatch, in a sentence naming `path`.
    pub fn check(&self, path: &Path, database_id: &str, dt_s: f64, frames: u64) -> Result<()> {
        let name = path.display();
        ensure!(
            self.database_id == database_id,
            "{name} was drawn from database {}, not this one ({database_id})",
            self.database_id
        );
        ensure!(
            (self.dt_s - dt_s).abs() <= 1e-9,
            "{name} was drawn at a frame step of {} s, the benchmark steps {dt_s} s (--frame-step-ms)",
            self.dt_s
        );
        let missing = (0..frames).find(|&f| self.at(f).is_none());
        ensure!(
            missing.is_none(),
            "{name} has no frame {} of the {frames} the benchmark draws (--max-frames)",
            missing.unwrap_or(0)
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log() -> DrawnLog {
        DrawnLog {
            run: "demand".into(),
            database_id: "ab".into(),
            path_hash: "cd".into(),
            dt_s: 0.05,
            frames: (0..3)
                .map(|f| DrawnFrame {
                    path_frame: f,
                    ..DrawnFrame::default()
                })
                .collect(),
        }
    }

    #[test]
    fn frames_are_found_by_path_frame_and_mismatches_named() {
        let mut l = log();
        assert_eq!(l.at(2).map(|f| f.path_frame), Some(2));
        assert!(l.at(3).is_none());
        l.frames.swap(0, 2);
        assert_eq!(l.at(0).map(|f| f.path_frame), Some(0), "found out of order");
        let p = Path::new("drawn/demand.json");
        assert!(l.check(p, "ab", 0.05, 3).is_ok());
        for (id, dt, frames, says) in [
            ("xy", 0.05, 3, "not this one (xy)"),
            ("ab", 0.1, 3, "frame step"),
            ("ab", 0.05, 4, "no frame 3"),
        ] {
            let e = l.check(p, id, dt, frames).unwrap_err().to_string();
            assert!(e.contains("drawn/demand.json") && e.contains(says), "{e}");
        }
    }

    #[test]
    fn logs_round_trip_and_bad_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("l.json");
        log().write(&f).unwrap();
        assert_eq!(DrawnLog::read(&f).unwrap(), log());
        std::fs::write(&f, b"{}").unwrap();
        let e = format!("{:#}", DrawnLog::read(&f).unwrap_err());
        assert!(
            e.contains("l.json") && e.contains("drawn-frames log"),
            "{e}"
        );
    }
}
