//! Counters and latency histograms, rendered as Prometheus text on `/metrics`. Lock-free:
//! every field is an atomic, so recording costs a few relaxed adds on the hot path.

use std::fmt::Write;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering::Relaxed};

/// The routes we count separately.
pub const ROUTES: [&str; 13] = [
    "healthz", "metrics", "manifest", "core", "page", "cells", "segment", "batch", "prefetch",
    "stream", "viewer", "other", "denied",
];

/// Upper bounds (seconds) of the latency histogram buckets.
pub const BUCKETS: [f64; 12] = [
    0.000_1, 0.000_25, 0.000_5, 0.001, 0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.5, 2.0,
];

/// One route's numbers.
#[derive(Debug, Default)]
struct RouteStats {
    requests: AtomicU64,
    client_errors: AtomicU64,
    server_errors: AtomicU64,
    latency_buckets: [AtomicU64; BUCKETS.len()],
    latency_sum_us: AtomicU64,
}

/// All server metrics.
#[derive(Debug, Default)]
pub struct Metrics {
    routes: [RouteStats; ROUTES.len()],
    /// Response body bytes handed to the network (segments, batches, stream pushes).
    pub bytes_sent: AtomicU64,
    /// Segments sent (single, batched or pushed).
    pub segments_sent: AtomicU64,
    /// Stream sessions open now.
    pub sessions: AtomicI64,
    /// Stream sessions ever opened.
    pub sessions_total: AtomicU64,
    /// Queued stream items dropped because their need vanished.
    pub stream_dropped: AtomicU64,
    /// Prefetch answers computed (HTTP and stream).
    pub prefetch_answers: AtomicU64,
    /// Observers received on stream sessions.
    pub stream_updates: AtomicU64,
    /// Need lists stream sessions started computing for their own observer, shared with
    /// nobody: an eye outside the live cells, a model without cells or `--exact-answers` has
    /// no shared place.
    pub stream_own_lists: AtomicU64,
    /// Stream updates by seconds from arrival to the need list in place (0 when the observer
    /// stayed in its place), bucketed by [`BUCKETS`].
    update_buckets: [AtomicU64; BUCKETS.len()],
    update_sum_us: AtomicU64,
    update_count: AtomicU64,
    /// Connections over the cap, answered 503 and closed.
    pub refused_connections: AtomicU64,
    /// Connections closed at the cap to make room: the oldest that had not sent a request,
    /// else the one whose write has been stuck longest.
    pub shed_connections: AtomicU64,
    /// Connections closed because the client took no bytes of an answer for the write timeout.
    pub write_timeouts: AtomicU64,
    /// Stream sessions refused because their URL named a database no longer served.
    pub stream_stale: AtomicU64,
    /// Stream need lists stopped at their deadline (the session waits as long before its next).
    pub stream_overdue: AtomicU64,
}

/// Index of a route name in [`ROUTES`] (`other` when unknown).
pub fn route_index(name: &str) -> usize {
    ROUTES
        .iter()
        .position(|r| *r == name)
        .unwrap_or(ROUTES.len() - 2)
}

impl Metrics {
    /// Records one finished request.
    pub fn record(&self, route: usize, status: u16, seconds: f64) {
        let r = &self.routes[route.min(ROUTES.len() - 1)];
        r.requests.fetch_add(1, Relaxed);
        if (400..500).contains(&status) {
            r.client_errors.fetch_add(1, Relaxed);
        } else if status >= 500 {
            r.server_errors.fetch_add(1, Relaxed);
        }
        if let Some(b) = BUCKETS.iter().position(|&ub| seconds <= ub) {
            r.latency_buckets[b].fetch_add(1, Relaxed);
        }
        r.latency_sum_us.fetch_add((seconds * 1e6) as u64, Relaxed);
    }

    /// Records `updates` stream updates served after `seconds` (arrival of the oldest to its
    /// need list in place, or to the end of a computation that failed or was stale).
    pub fn update(&self, seconds: f64, updates: u64) {
        if let Some(b) = BUCKETS.iter().position(|&ub| seconds <= ub) {
            self.update_buckets[b].fetch_add(updates, Relaxed);
        }
        self.update_sum_us
            .fetch_add((seconds * 1e6) as u64 * updates, Relaxed);
        self.update_count.fetch_add(updates, Relaxed);
    }

    /// Counts bytes of one segment sent.
    pub fn sent(&self, bytes: u64) {
        self.bytes_sent.fetch_add(bytes, Relaxed);
        self.segments_sent.fetch_add(1, Relaxed);
    }

    /// Requests recorded for a route (tests and reports).
    pub fn requests(&self, route: &str) -> u64 {
        self.routes[route_index(route)].requests.load(Relaxed)
    }

    /// Prometheus text exposition format.
    pub fn render(&self) -> String {
        let mut s = String::with_capacity(8 << 10);
        let _ = writeln!(s, "# HELP portico_requests_total HTTP requests by route.");
        let _ = writeln!(s, "# TYPE portico_requests_total counter");
        for (name, r) in ROUTES.iter().zip(&self.routes) {
            let _ = writeln!(
                s,
                "portico_requests_total{{route=\"{name}\"}} {}",
                r.requests.load(Relaxed)
            );
        }
        let _ = writeln!(
            s,
            "# HELP portico_errors_total Error answers by route and class."
        );
        let _ = writeln!(s, "# TYPE portico_errors_total counter");
        for (name, r) in ROUTES.iter().zip(&self.routes) {
            let c = r.client_errors.load(Relaxed);
            let e = r.server_errors.load(Relaxed);
            let _ = writeln!(
                s,
                "portico_errors_total{{route=\"{name}\",class=\"4xx\"}} {c}"
            );
            let _ = writeln!(
                s,
                "portico_errors_total{{route=\"{name}\",class=\"5xx\"}} {e}"
            );
        }
        let _ = writeln!(
            s,
            "# HELP portico_request_seconds Request latency by route."
        );
        let _ = writeln!(s, "# TYPE portico_request_seconds histogram");
        for (name, r) in ROUTES.iter().zip(&self.routes) {
            let mut cum = 0;
            for (ub, b) in BUCKETS.iter().zip(&r.latency_buckets) {
                cum += b.load(Relaxed);
                let _ = writeln!(
                    s,
                    "portico_request_seconds_bucket{{route=\"{name}\",le=\"{ub}\"}} {cum}"
                );
            }
            let n = r.requests.load(Relaxed);
            let _ = writeln!(
                s,
                "portico_request_seconds_bucket{{route=\"{name}\",le=\"+Inf\"}} {n}"
            );
            let sum = r.latency_sum_us.load(Relaxed) as f64 / 1e6;
            let _ = writeln!(s, "portico_request_seconds_sum{{route=\"{name}\"}} {sum}");
            let _ = writeln!(s, "portico_request_seconds_count{{route=\"{name}\"}} {n}");
        }
        let _ = writeln!(
            s,
            "# HELP portico_stream_update_seconds Stream observer to need list in place."
        );
        let _ = writeln!(s, "# TYPE portico_stream_update_seconds histogram");
        let mut cum = 0;
        for (ub, b) in BUCKETS.iter().zip(&self.update_buckets) {
            cum += b.load(Relaxed);
            let _ = writeln!(
                s,
                "portico_stream_update_seconds_bucket{{le=\"{ub}\"}} {cum}"
            );
        }
        let n = self.update_count.load(Relaxed);
        let _ = writeln!(s, "portico_stream_update_seconds_bucket{{le=\"+Inf\"}} {n}");
        let sum = self.update_sum_us.load(Relaxed) as f64 / 1e6;
        let _ = writeln!(s, "portico_stream_update_seconds_sum {sum}");
        let _ = writeln!(s, "portico_stream_update_seconds_count {n}");
        let gauges: [(&str, &str, &str, i64); 13] = [
            (
                "portico_stream_updates_total",
                "counter",
                "Observers received on stream sessions (a newer one may replace one waiting).",
                self.stream_updates.load(Relaxed) as i64,
            ),
            (
                "portico_stream_own_lists_total",
                "counter",
                "Need lists stream sessions computed for their own observer (not shared).",
                self.stream_own_lists.load(Relaxed) as i64,
            ),
            (
                "portico_bytes_sent_total",
                "counter",
                "Segment bytes sent.",
                self.bytes_sent.load(Relaxed) as i64,
            ),
            (
                "portico_segments_sent_total",
                "counter",
                "Segments sent.",
                self.segments_sent.load(Relaxed) as i64,
            ),
            (
                "portico_sessions",
                "gauge",
                "Open stream sessions.",
                self.sessions.load(Relaxed),
            ),
            (
                "portico_sessions_total",
                "counter",
                "Stream sessions opened.",
                self.sessions_total.load(Relaxed) as i64,
            ),
            (
                "portico_stream_dropped_total",
                "counter",
                "Queued pushes dropped as stale.",
                self.stream_dropped.load(Relaxed) as i64,
            ),
            (
                "portico_prefetch_answers_total",
                "counter",
                "Prefetch answers computed, and need lists stream sessions took.",
                self.prefetch_answers.load(Relaxed) as i64,
            ),
            (
                "portico_refused_connections_total",
                "counter",
                "Connections over the cap, answered 503.",
                self.refused_connections.load(Relaxed) as i64,
            ),
            (
                "portico_shed_connections_total",
                "counter",
                "Connections without a request, or stuck writing, closed at the cap to make room.",
                self.shed_connections.load(Relaxed) as i64,
            ),
            (
                "portico_write_timeouts_total",
                "counter",
                "Connections closed because the client took nothing for the write timeout.",
                self.write_timeouts.load(Relaxed) as i64,
            ),
            (
                "portico_stream_stale_total",
                "counter",
                "Stream sessions refused: their URL named a database no longer served.",
                self.stream_stale.load(Relaxed) as i64,
            ),
            (
                "portico_stream_overdue_total",
                "counter",
                "Stream need lists stopped at the prefetch deadline.",
                self.stream_overdue.load(Relaxed) as i64,
            ),
        ];
        for (name, kind, help, v) in gauges {
            let _ = writeln!(s, "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {v}");
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_buckets_are_cumulative_and_counts_add_up() {
        let m = Metrics::default();
        m.record(route_index("prefetch"), 200, 0.0004);
        m.record(route_index("prefetch"), 400, 0.003);
        m.record(route_index("segment"), 500, 10.0);
        let text = m.render();
        assert!(text.contains("portico_requests_total{route=\"prefetch\"} 2"));
        assert!(
            text.contains("portico_request_seconds_bucket{route=\"prefetch\",le=\"0.0005\"} 1")
        );
        assert!(text.contains("portico_request_seconds_bucket{route=\"prefetch\",le=\"0.005\"} 2"));
        assert!(text.contains("portico_errors_total{route=\"prefetch\",class=\"4xx\"} 1"));
        assert!(text.contains("portico_errors_total{route=\"segment\",class=\"5xx\"} 1"));
        // Slower than every bucket: only in +Inf.
        assert!(text.contains("portico_request_seconds_bucket{route=\"segment\",le=\"2\"} 0"));
        assert!(text.contains("portico_request_seconds_bucket{route=\"segment\",le=\"+Inf\"} 1"));
    }
}
