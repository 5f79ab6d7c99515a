//! Pacing the reads to the link: keep in flight only what the link delivers within a short
//! horizon, so the newest need order takes effect within a frame or two.
//!
//! The IO stage reads from the top of the latest need list (Funkhouser §5.2.3), several
//! requests at once. On a link slower than the read set, every byte asked for and not yet
//! delivered queues in front of whatever the next list makes urgent: with eight requests of
//! 256 KiB in flight at 10 Mbit/s the object that comes into view waits 1.6 s behind read-ahead
//! for frames that may never come (the load tester measured a first complete frame 16 frames
//! late this way). [`LinkMeter`] measures the link as the reads see it — bytes delivered per
//! second of busy time (time with a request outstanding), and the shortest round trip — and
//! [`LinkMeter::cap`] bounds the wire bytes in flight to `rate × (round trip + horizon)`: the
//! bandwidth-delay product plus what arrives within the horizon. A cap below the product
//! leaves the link idle part of each round trip, but then the measured rate is the cap over the
//! round trip, so the next cap is `(round trip + horizon) / round trip` times larger: it grows
//! to the link's rate within a few round trips and never queues more than a horizon's worth.
//!
//! Pure bookkeeping over the instants it is given: no clock, no IO.

use web_time::Instant;

/// The in-flight cap before anything has been measured (bytes on the wire).
pub const INITIAL_CAP: u64 = 256 << 10;
/// The smallest cap, however slow the link looks (bytes on the wire).
pub const MIN_CAP: u64 = 64 << 10;
/// Busy seconds over which older measurements fade (`e`-folding time).
pub const MEMORY_S: f64 = 1.0;
/// The round trip is the shortest request of the last this many seconds (as BBR keeps its
/// minimum round trip): long enough to hold a sample from before the cap filled the link (the
/// later ones include transfers), short enough to follow a link whose latency rises (a queue at
/// the server, a new route), where the best ever seen would shrink the cap each round trip.
pub const RTT_WINDOW_S: f64 = 10.0;
/// Most request durations kept for the round trip.
const RTT_SAMPLES: usize = 1024;

/// The link's measured rate and round trip, from the reads' own timings.
#[derive(Debug, Clone, Default)]
pub struct LinkMeter {
    /// Decayed sums of delivered wire bytes and of busy seconds.
    bytes: f64,
    busy_s: f64,
    /// Requests outstanding, and since when at least one has been.
    outstanding: u32,
    busy_since: Option<Instant>,
    /// The latest requests' ends and durations, send to last byte (seconds), oldest first.
    recent: std::collections::VecDeque<(Instant, f64)>,
}

impl LinkMeter {
    /// A request was sent at `at`.
    pub fn started(&mut self, at: Instant) {
        if self.outstanding == 0 {
            self.busy_since = Some(at);
        }
        self.outstanding += 1;
    }

    /// A request sent at `sent` ended at `at` with `wire_bytes` delivered (0 for a failure).
    pub fn finished(&mut self, sent: Instant, at: Instant, wire_bytes: u64) {
        let busy = self
            .busy_since
            .map_or(0.0, |b| at.saturating_duration_since(b).as_secs_f64());
        let fade = (-busy / MEMORY_S).exp();
        self.bytes = self.bytes * fade + wire_bytes as f64;
        self.busy_s = self.busy_s * fade + busy;
        self.outstanding = self.outstanding.saturating_sub(1);
        self.busy_since = (self.outstanding > 0).then_some(at);
        if wire_bytes > 0 {
            self.recent
                .push_back((at, at.saturating_duration_since(sent).as_secs_f64()));
            while self.recent.len() > RTT_SAMPLES
                || self.recent.front().is_some_and(|&(end, _)| {
                    at.saturating_duration_since(end).as_secs_f64() > RTT_WINDOW_S
                })
            {
                self.recent.pop_front();
            }
        }
    }

    /// Bytes per second delivered while busy; `None` until something arrived.
    pub fn rate(&self) -> Option<f64> {
        (self.bytes > 0.0 && self.busy_s > 0.0).then(|| self.bytes / self.busy_s)
    }

    /// The shortest request that ended in the last [`RTT_WINDOW_S`] seconds, send to last
    /// byte: the round trip plus the smallest transfer.
    pub fn rtt_s(&self) -> Option<f64> {
        self.recent.iter().map(|r| r.1).reduce(f64::min)
    }

    /// Most wire bytes to keep in flight: `rate × (round trip + horizon_s)`, at least
    /// [`MIN_CAP`]; [`INITIAL_CAP`] before the first delivery.
    pub fn cap(&self, horizon_s: f64) -> u64 {
        let (Some(rate), Some(rtt)) = (self.rate(), self.rtt_s()) else {
            return INITIAL_CAP;
        };
        let horizon = if horizon_s.is_finite() {
            horizon_s.max(0.0)
        } else {
            0.0
        };
        let cap = (rate * (rtt + horizon)).round();
        if cap.is_finite() {
            (cap as u64).max(MIN_CAP)
        } else {
            u64::MAX
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn ms(t0: Instant, ms: u64) -> Instant {
        t0 + Duration::from_millis(ms)
    }

    #[test]
    fn rate_counts_busy_time_only_and_rtt_is_the_shortest_request() {
        let t0 = Instant::now();
        let mut m = LinkMeter::default();
        assert_eq!((m.rate(), m.rtt_s()), (None, None));
        assert_eq!(m.cap(0.1), INITIAL_CAP);
        // 100 KB in 100 ms, then idle for 10 s, then 100 KB in 100 ms: 1 MB/s, not 20 KB/s.
        m.started(t0);
        m.finished(t0, ms(t0, 100), 100_000);
        m.started(ms(t0, 10_100));
        m.finished(ms(t0, 10_100), ms(t0, 10_200), 100_000);
        let rate = m.rate().unwrap();
        assert!((rate - 1.0e6).abs() < 1.0, "{rate}");
        // Two overlapping requests share the busy time.
        m.started(ms(t0, 20_000));
        m.started(ms(t0, 20_000));
        m.finished(ms(t0, 20_000), ms(t0, 20_050), 50_000);
        m.finished(ms(t0, 20_000), ms(t0, 20_100), 50_000);
        let rate = m.rate().unwrap();
        assert!((rate - 1.0e6).abs() < 1.0, "{rate}");
        assert!((m.rtt_s().unwrap() - 0.05).abs() < 1e-9);
        // A failure costs busy time and brings nothing; it is not a round trip.
        m.started(ms(t0, 30_000));
        m.finished(ms(t0, 30_000), ms(t0, 30_001), 0);
        assert!((m.rtt_s().unwrap() - 0.05).abs() < 1e-9);
    }

    #[test]
    fn the_cap_is_what_arrives_within_the_round_trip_and_the_horizon() {
        let t0 = Instant::now();
        let mut m = LinkMeter::default();
        // 1.25 MB/s (10 Mbit/s), 50 ms requests: a 100 ms horizon keeps 187.5 KB in flight.
        for i in 0..10u64 {
            m.started(ms(t0, 50 * i));
            m.finished(ms(t0, 50 * i), ms(t0, 50 * i + 50), 62_500);
        }
        assert_eq!(m.cap(0.1), 187_500);
        assert_eq!(m.cap(f64::NAN), 62_500.max(MIN_CAP));
        // A crawl never caps below MIN_CAP.
        let mut slow = LinkMeter::default();
        slow.started(t0);
        slow.finished(t0, ms(t0, 1000), 1000);
        assert_eq!(slow.cap(0.1), MIN_CAP);
    }

    #[test]
    fn the_round_trip_follows_a_link_whose_latency_rises() {
        // Cap-limited reads (one at a time) on a 12.5 MB/s link whose round trip goes from 20
        // to 150 ms: the cap must not shrink to the minimum.
        let t0 = Instant::now();
        let mut m = LinkMeter::default();
        let mut t = 0.0f64;
        let mut cap = MIN_CAP;
        for i in 0..200 {
            let rtt = if i < 20 { 0.02 } else { 0.15 };
            let took = rtt + cap as f64 / 12.5e6;
            let at = |s: f64| t0 + Duration::from_secs_f64(s);
            m.started(at(t));
            m.finished(at(t), at(t + took), cap);
            t += took;
            cap = m.cap(0.04);
        }
        assert!(m.rtt_s().unwrap() > 0.15, "{:?}", m.rtt_s());
        // With the 20 ms minimum kept for ever the cap would settle at MIN_CAP (64 KiB per
        // 150 ms); following the new round trip it holds its horizon's worth and more.
        assert!(cap > 8 * MIN_CAP, "cap {cap}");
    }

    #[test]
    fn a_cap_below_the_link_grows_to_it() {
        // A 12.5 MB/s link with a 20 ms round trip, read with the cap always full: each
        // round trip delivers min(cap, what the link carries in it).
        let t0 = Instant::now();
        let (rate, rtt, horizon) = (12.5e6, 0.02, 0.1);
        let mut m = LinkMeter::default();
        let mut t = 0.0f64;
        let mut cap = MIN_CAP;
        for _ in 0..40 {
            let bytes = cap;
            let took = rtt + bytes as f64 / rate;
            let at = |s: f64| t0 + Duration::from_secs_f64(s);
            m.started(at(t));
            m.finished(at(t), at(t + took), bytes);
            t += took;
            cap = m.cap(horizon);
        }
        let ideal = rate * (rtt + horizon);
        assert!(
            (cap as f64) > 0.5 * ideal && (cap as f64) < 1.5 * ideal,
            "cap {cap}, ideal {ideal}"
        );
    }
}
