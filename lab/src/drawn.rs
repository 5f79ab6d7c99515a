//! What a streamed client drew, frame by frame: the load tester records its first client's
//! frames in each run ([`crate::loadtest`], `drawn/<run>.json`), and the benchmark draws them
//! again beside the full-detail frame of the same path time and scores them (`portico bench
//! --replay`, [`crate::bench`]: PSNR, Es, Et). So a run's image fidelity is measured on the
//! frames its cache and link actually allowed, textures included, not on frames with every
//! segment resident.

use anyhow::{Context, Result, bail, ensure};
use portico_client::cluster::Stand;
use portico_client::frame::Decision;
use portico_data::format::Header;
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
    /// The image size the frames were decided for (pixels): visibility, screen sizes, LODs.
    /// Logs that do not say were decided at the load tester's 640 × 480.
    #[serde(default = "load_test_size")]
    pub size: (u32, u32),
    /// The vertical field of view they were decided for (degrees; 60 where a log does not say).
    #[serde(default = "load_test_fovy")]
    pub fovy_deg: f32,
    /// The frames, in the order drawn.
    pub frames: Vec<DrawnFrame>,
}

fn load_test_size() -> (u32, u32) {
    crate::loadtest::world::SCREEN
}

fn load_test_fovy() -> f32 {
    crate::loadtest::world::FOVY_DEG
}

/// What a log must match to be drawn beside a benchmark's frames ([`DrawnLog::check`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Expected<'a> {
    /// The benchmark's database id.
    pub database_id: &'a str,
    /// Its path's hash.
    pub path_hash: &'a str,
    /// Its frame step (s).
    pub dt_s: f64,
    /// Its frame count: the log must have path frames `0..frames`.
    pub frames: u64,
    /// Its image size (pixels).
    pub size: (u32, u32),
    /// Its vertical field of view (degrees).
    pub fovy_deg: f32,
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

    /// Checks that the log was drawn from the same database, along the same path, at the same
    /// frame step, image size and field of view as `e` says, and covers path frames
    /// `0..e.frames`.
    ///
    /// # Errors
    /// The first mismatch, in a sentence naming `path` and the option that differs.
    pub fn check(&self, path: &Path, e: &Expected<'_>) -> Result<()> {
        let name = path.display();
        ensure!(
            self.database_id == e.database_id,
            "{name} was drawn from database {}, not this one ({})",
            self.database_id,
            e.database_id
        );
        ensure!(
            self.path_hash == e.path_hash,
            "{name} was drawn along path {}, not this one ({}): give the bench the load test's --path",
            self.path_hash,
            e.path_hash
        );
        ensure!(
            (self.dt_s - e.dt_s).abs() <= 1e-9,
            "{name} was drawn at a frame step of {} s, the benchmark steps {} s (--frame-step-ms must equal the load test's --budget-ms)",
            self.dt_s,
            e.dt_s
        );
        ensure!(
            self.size == e.size && (self.fovy_deg - e.fovy_deg).abs() <= 1e-3,
            "{name} was decided for {}x{} pixels and {}°, the benchmark draws {}x{} and {}° (--size, --fov)",
            self.size.0,
            self.size.1,
            self.fovy_deg,
            e.size.0,
            e.size.1,
            e.fovy_deg
        );
        let missing = (0..e.frames).find(|&f| self.at(f).is_none());
        ensure!(
            missing.is_none(),
            "{name} has no frame {} of the {} the benchmark draws (--max-frames)",
            missing.unwrap_or(0),
            e.frames
        );
        Ok(())
    }

    /// Checks every object and box against the model: the instance exists and has the LOD,
    /// the texture segment is one of its material's texture's, the cluster exists and has a
    /// textured box where one is drawn.
    ///
    /// # Errors
    /// The first entry at fault, naming `path`, the frame and the entry.
    pub fn validate(&self, path: &Path, header: &Header) -> Result<()> {
        let name = path.display();
        for f in &self.frames {
            for (i, o) in f.objects.iter().enumerate() {
                let at = format!("{name}: frame {}, object {i}", f.path_frame);
                let Some(inst) = header.instances.get(o.instance as usize) else {
                    bail!(
                        "{at}: no instance {} (the model has {})",
                        o.instance,
                        header.instances.len()
                    );
                };
                let lods = header.lods_of(inst).len();
                ensure!(
                    (o.lod as usize) < lods,
                    "{at}: instance {} has {lods} LODs, not LOD {}",
                    o.instance,
                    o.lod
                );
                if let Some(s) = o.texture {
                    let ok = header
                        .texture_of(inst)
                        .is_some_and(|t| t.segments.iter().any(|m| m.segment == s));
                    ensure!(
                        ok,
                        "{at}: segment {s} is not a segment of instance {}'s texture",
                        o.instance
                    );
                }
            }
            let nodes = header.hierarchy.as_ref().map_or(&[][..], |h| &h.nodes[..]);
            for &(n, textured) in &f.boxes {
                let at = format!("{name}: frame {}, box {n}", f.path_frame);
                let Some(node) = nodes.get(n as usize) else {
                    bail!("{at}: no cluster {n} (the model has {})", nodes.len());
                };
                ensure!(
                    !textured || node.texture != u32::MAX,
                    "{at}: cluster {n} has no textured box"
                );
            }
        }
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
            size: (640, 480),
            fovy_deg: 60.0,
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
        let same = Expected {
            database_id: "ab",
            path_hash: "cd",
            dt_s: 0.05,
            frames: 3,
            size: (640, 480),
            fovy_deg: 60.0,
        };
        assert!(l.check(p, &same).is_ok());
        for (e, says) in [
            (
                Expected {
                    database_id: "xy",
                    ..same
                },
                "not this one (xy)",
            ),
            (
                Expected {
                    path_hash: "ef",
                    ..same
                },
                "--path",
            ),
            (Expected { dt_s: 0.1, ..same }, "--frame-step-ms"),
            (Expected { frames: 4, ..same }, "no frame 3"),
            (
                Expected {
                    size: (320, 240),
                    ..same
                },
                "--size",
            ),
            (
                Expected {
                    fovy_deg: 75.0,
                    ..same
                },
                "--fov",
            ),
        ] {
            let err = l.check(p, &e).unwrap_err().to_string();
            assert!(
                err.contains("drawn/demand.json") && err.contains(says),
                "{err}"
            );
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
