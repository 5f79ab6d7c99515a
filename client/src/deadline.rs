//! Deadline-ordered reads: what of the server's need list to read now, and what can wait for a
//! later answer.
//!
//! Funkhouser's IO process (§5.2.3) reads the whole read set from its top. Every item of a
//! prefetch answer says when it can first be needed (`frames` until visible, counted from the
//! observer the answer was computed for), and the link's rate and round trip are measured
//! ([`crate::pacing::LinkMeter`]): an item whose deadline a later answer can still meet need
//! not be read now, and by then the observer has walked on and the later answer may no longer
//! list it. [`ReadPlan::list`] keeps an item when waiting for the next answer would make it
//! late:
//!
//! `now + period + rtt + (queued + bytes) / rate + margin ≥ asked + frames · Δt`
//! ([`portico_data::deadline`], which the server's push sessions apply too),
//!
//! where `asked` is when the answer's observer was sent, `period` how long until the next answer
//! can change the list (a round trip, at least a frame, plus the wait before the pull engine
//! asks again: [`Link::wait_s`]), `queued` the wire bytes in flight and
//! of the items kept before it, and `margin` [`MARGIN_FRAMES`]. Items the view needs now
//! (`frames` 0) are always kept. Before the link is measured, only items within
//! [`UNMEASURED_FRAMES`] are. Ahead of every item goes what the last frame lacked
//! ([`crate::demand`]), alone while the frame had objects with nothing to draw (§5.2.4: a
//! coarse LOD of everything visible before anything else).

use crate::demand::ahead_of;
use portico_data::deadline::cannot_wait;
pub use portico_data::deadline::{MARGIN_FRAMES, UNMEASURED_FRAMES};
use portico_protocol::NeedItem;
use web_time::Instant;

/// The link as the reads measured it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Link {
    /// Wire bytes per second (`None`: not measured yet).
    pub rate: Option<f64>,
    /// Round trip in seconds (`None`: not measured yet).
    pub rtt_s: Option<f64>,
    /// Wire bytes in flight now.
    pub in_flight: u64,
    /// How long (seconds) past a round trip the next answer may be in coming: the pull
    /// engine's wait before it asks again ([`crate::engine::pull::Reask::wait_s`]; 0 when it
    /// asks after every answer).
    pub wait_s: f64,
}

/// The read list's inputs: the latest answer and what the latest frame lacked.
#[derive(Debug, Clone, Default)]
pub struct ReadPlan {
    answer: Vec<NeedItem>,
    /// When the latest answer's observer was sent.
    asked: Option<Instant>,
    lacking: Vec<u32>,
    incomplete: bool,
}

impl ReadPlan {
    /// A new answer whose observer was sent at `asked`.
    pub fn answered(&mut self, items: Vec<NeedItem>, asked: Instant) {
        self.answer = items;
        self.asked = Some(asked);
    }

    /// What the latest frame lacked, and whether it skipped objects.
    pub fn frame(&mut self, lacking: Vec<u32>, incomplete: bool) {
        self.lacking = lacking;
        self.incomplete = incomplete;
    }

    /// Forgets the answer and the frame (another transport took over).
    pub fn clear(&mut self) {
        *self = ReadPlan::default();
    }

    /// The segments to read, most urgent first, at `now` with frames of `frame_s` seconds
    /// (see the module).
    pub fn list(&self, now: Instant, frame_s: f64, link: Link) -> Vec<u32> {
        if self.incomplete {
            return ahead_of(&self.lacking, []);
        }
        let asked = self.asked.unwrap_or(now);
        let dt = frame_s.max(1e-3);
        let age = now.saturating_duration_since(asked).as_secs_f64();
        let due = match (link.rate, link.rtt_s) {
            (Some(rate), Some(rtt)) if rate > 0.0 => {
                let lead = age + rtt.max(dt) + link.wait_s + rtt + MARGIN_FRAMES * dt;
                let mut queued = link.in_flight as f64;
                let mut out = Vec::new();
                for i in &self.answer {
                    if cannot_wait(i.frames, dt, lead, queued, i.bytes as f64, rate) {
                        queued += i.bytes as f64;
                        out.push(i.segment);
                    }
                }
                out
            }
            _ => {
                let elapsed = (age / dt).floor() as u32;
                self.answer
                    .iter()
                    .filter(|i| i.frames <= UNMEASURED_FRAMES + elapsed)
                    .map(|i| i.segment)
                    .collect()
            }
        };
        ahead_of(&self.lacking, due)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use portico_protocol::NeedKind;
    use std::time::Duration;

    fn item(segment: u32, frames: u32, bytes: u64) -> NeedItem {
        NeedItem {
            segment,
            kind: NeedKind::Geometry,
            lod: 0,
            bytes,
            frames,
        }
    }

    fn plan(items: Vec<NeedItem>, t0: Instant) -> ReadPlan {
        let mut p = ReadPlan::default();
        p.answered(items, t0);
        p
    }

    const MEASURED: Link = Link {
        rate: Some(1e6),
        rtt_s: Some(0.05),
        in_flight: 0,
        wait_s: 0.0,
    };

    #[test]
    fn what_a_later_answer_can_still_bring_in_time_waits() {
        let t0 = Instant::now();
        // 50 ms frames, 50 ms round trip, 1 MB/s: the lead is 50 + 50 + 100 = 200 ms, so an
        // item of 10 kB (10 ms) is read now up to 4 frames ahead.
        let p = plan(
            vec![item(1, 0, 10_000), item(2, 4, 10_000), item(3, 5, 10_000)],
            t0,
        );
        assert_eq!(p.list(t0, 0.05, MEASURED), vec![1, 2]);
        // Two frames later the third is due too.
        assert_eq!(
            p.list(t0 + Duration::from_millis(100), 0.05, MEASURED),
            vec![1, 2, 3]
        );
    }

    #[test]
    fn bytes_ahead_on_the_wire_bring_deadlines_forward() {
        let t0 = Instant::now();
        let p = plan(vec![item(1, 6, 10_000)], t0);
        assert!(p.list(t0, 0.05, MEASURED).is_empty());
        // 100 kB in flight take 100 ms more: six frames ahead is due now.
        let busy = Link {
            in_flight: 100_000,
            ..MEASURED
        };
        assert_eq!(p.list(t0, 0.05, busy), vec![1]);
        // A slower link brings it forward by itself; so does a big item before it.
        let slow = Link {
            rate: Some(9e4),
            ..MEASURED
        };
        assert_eq!(p.list(t0, 0.05, slow), vec![1]);
        let p = plan(vec![item(2, 0, 200_000), item(1, 6, 10_000)], t0);
        assert_eq!(p.list(t0, 0.05, MEASURED), vec![2, 1]);
    }

    #[test]
    fn a_wait_before_the_next_ask_brings_deadlines_forward() {
        let t0 = Instant::now();
        let p = plan(vec![item(1, 6, 10_000)], t0);
        assert!(p.list(t0, 0.05, MEASURED).is_empty());
        // Two frames more before a later answer can come: six frames ahead is due now.
        let waiting = Link {
            wait_s: 0.1,
            ..MEASURED
        };
        assert_eq!(p.list(t0, 0.05, waiting), vec![1]);
    }

    #[test]
    fn the_frame_lacks_go_first_and_alone_while_it_is_incomplete() {
        let t0 = Instant::now();
        let mut p = plan(vec![item(1, 0, 10), item(2, 0, 10)], t0);
        p.frame(vec![7, 2], false);
        assert_eq!(p.list(t0, 0.05, MEASURED), vec![7, 2, 1]);
        p.frame(vec![7], true);
        assert_eq!(p.list(t0, 0.05, MEASURED), vec![7]);
    }

    #[test]
    fn before_the_link_is_measured_a_few_frames_are_read_ahead() {
        let t0 = Instant::now();
        let p = plan(vec![item(1, 4, 10), item(2, 5, 10)], t0);
        let unknown = Link {
            rate: None,
            rtt_s: None,
            in_flight: 0,
            wait_s: 0.0,
        };
        assert_eq!(p.list(t0, 0.05, unknown), vec![1]);
        assert_eq!(
            p.list(t0 + Duration::from_millis(50), 0.05, unknown),
            vec![1, 2]
        );
    }
}
