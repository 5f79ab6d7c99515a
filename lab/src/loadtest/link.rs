//! The emulated network link between one simulated client and the server: every
//! request pays the round-trip time — half before it is sent, half after its answer — and every
//! response body is paced through a per-client token bucket so that the client never receives
//! more than `rate` bytes per second, however many requests it has in flight.
//!
//! The spec language is `rtt=20ms,rate=100mbit`: durations in `us`, `ms` or `s` (a bare number
//! is milliseconds), rates in `bit`, `kbit`, `mbit`, `gbit` (SI, bits per second), `b`, `kb`,
//! `mb`, `gb` (SI bytes per second), `kib`, `mib`, `gib` (binary bytes per second), or `inf`.
//!
//! `Linked` is a simulated client's [`Fetcher`]: the real HTTP requests through its pipe.

use super::world::World;
use portico_native::drive::{Fetcher, Items};
use portico_native::net::Remote;
use portico_protocol::{PrefetchRequest, PrefetchResponse};
use serde::Serialize;
use std::fmt;
use std::future::Future;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::time::Instant;

/// Latency and bandwidth of one client's link.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Link {
    /// Round-trip time in seconds, paid once per request.
    pub rtt_s: f64,
    /// Bytes per second each client may receive (`f64::INFINITY` = unlimited).
    pub rate_bytes_per_s: f64,
}

impl Default for Link {
    /// The default link: 20 ms round trip, 100 Mbit/s.
    fn default() -> Self {
        Link {
            rtt_s: 0.020,
            rate_bytes_per_s: 100e6 / 8.0,
        }
    }
}

/// A `--link` spec that does not parse; the message names the part that was wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LinkError {
    /// Nothing was given.
    #[error("empty link spec (expected e.g. rtt=20ms,rate=100mbit)")]
    Empty,
    /// A part is not `key=value`.
    #[error("link item {0:?} is not key=value (expected e.g. rtt=20ms,rate=100mbit)")]
    NotKeyValue(String),
    /// A key other than `rtt` and `rate`.
    #[error("unknown link key {0:?} (expected rtt or rate)")]
    UnknownKey(String),
    /// The round-trip time is not a duration.
    #[error("link rtt={0:?} is not a duration ≥ 0 (e.g. 20ms, 0.5s, 800us)")]
    BadRtt(String),
    /// The rate is not a positive rate.
    #[error("link rate={0:?} is not a rate > 0 (e.g. 100mbit, 12.5mb, 4mib, inf)")]
    BadRate(String),
}

impl Link {
    /// Parses `rtt=20ms,rate=100mbit` (either key may be left out: no delay, no rate limit).
    pub fn parse(spec: &str) -> Result<Link, LinkError> {
        let mut link = Link {
            rtt_s: 0.0,
            rate_bytes_per_s: f64::INFINITY,
        };
        let parts: Vec<&str> = spec
            .split(',')
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .collect();
        if parts.is_empty() {
            return Err(LinkError::Empty);
        }
        for part in parts {
            let (k, v) = part
                .split_once('=')
                .ok_or_else(|| LinkError::NotKeyValue(part.to_string()))?;
            match k.trim() {
                "rtt" | "latency" => {
                    link.rtt_s = parse_seconds(v).ok_or_else(|| LinkError::BadRtt(v.into()))?
                }
                "rate" | "bw" | "bandwidth" => {
                    link.rate_bytes_per_s =
                        parse_rate(v).ok_or_else(|| LinkError::BadRate(v.into()))?
                }
                other => return Err(LinkError::UnknownKey(other.to_string())),
            }
        }
        Ok(link)
    }

    /// Seconds to deliver `bytes` at this link's rate (0 when unlimited).
    pub fn transfer_s(&self, bytes: u64) -> f64 {
        if self.rate_bytes_per_s.is_finite() {
            bytes as f64 / self.rate_bytes_per_s
        } else {
            0.0
        }
    }
}

impl fmt::Display for Link {
    /// The spec form, e.g. `rtt=20ms,rate=100mbit` (parses back to the same link).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "rtt={}ms,rate=", trim_float(self.rtt_s * 1e3))?;
        if self.rate_bytes_per_s.is_finite() {
            write!(f, "{}mbit", trim_float(self.rate_bytes_per_s * 8.0 / 1e6))
        } else {
            f.write_str("inf")
        }
    }
}

fn trim_float(x: f64) -> String {
    let s = format!("{x:.6}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// `20ms`, `0.5s`, `800us`, `20` (milliseconds) → seconds.
fn parse_seconds(v: &str) -> Option<f64> {
    let v = v.trim().to_ascii_lowercase();
    let (num, scale) = split_unit(&v, &[("us", 1e-6), ("ms", 1e-3), ("s", 1.0), ("", 1e-3)])?;
    let x = num.parse::<f64>().ok()? * scale;
    (x.is_finite() && x >= 0.0).then_some(x)
}

/// `100mbit`, `12.5mb`, `4mib`, `inf` → bytes per second.
fn parse_rate(v: &str) -> Option<f64> {
    let v = v.trim().to_ascii_lowercase();
    if matches!(v.as_str(), "inf" | "unlimited" | "none") {
        return Some(f64::INFINITY);
    }
    let units = [
        ("gbit", 1e9 / 8.0),
        ("mbit", 1e6 / 8.0),
        ("kbit", 1e3 / 8.0),
        ("bit", 1.0 / 8.0),
        ("gib", (1u64 << 30) as f64),
        ("mib", (1u64 << 20) as f64),
        ("kib", 1024.0),
        ("gb", 1e9),
        ("mb", 1e6),
        ("kb", 1e3),
        ("b", 1.0),
    ];
    let (num, scale) = split_unit(v.trim_end_matches("/s").trim_end_matches("ps"), &units)?;
    let x = num.parse::<f64>().ok()? * scale;
    (x.is_finite() && x > 0.0).then_some(x)
}

/// The first unit (in the given order) that `v` ends with, and the number before it.
fn split_unit<'a>(v: &'a str, units: &[(&str, f64)]) -> Option<(&'a str, f64)> {
    units
        .iter()
        .find_map(|(u, s)| v.strip_suffix(u).map(|n| (n.trim(), *s)))
        .filter(|(n, _)| !n.is_empty())
}

/// One client's end of the emulated link: its token bucket (a FIFO pipe at `rate`) is shared by
/// all of the client's requests in flight.
#[derive(Debug)]
pub struct Pipe {
    link: Link,
    free_at: Mutex<Instant>,
}

impl Pipe {
    /// A pipe with nothing queued.
    pub fn new(link: Link) -> Pipe {
        Pipe {
            link,
            free_at: Mutex::new(Instant::now()),
        }
    }

    /// The link it emulates.
    pub fn link(&self) -> Link {
        self.link
    }

    /// Half the round trip: the request travelling to the server.
    pub async fn send(&self) {
        self.half_rtt().await;
    }

    /// Delivers a response body of `bytes`: waits until the pipe has carried it at the link's
    /// rate after everything queued before it, then for the answer's half of the round trip.
    pub async fn deliver(&self, bytes: u64) {
        tokio::time::sleep_until(self.stamp(bytes)).await;
    }

    /// Queues `bytes` on the pipe now and says when they are in the client's hands: once the
    /// pipe has carried them at the link's rate after everything queued before them, and half
    /// the round trip later.
    pub fn stamp(&self, bytes: u64) -> Instant {
        let transfer = Duration::from_secs_f64(self.link.transfer_s(bytes));
        let done = {
            let mut free = self.free_at.lock().unwrap_or_else(|e| e.into_inner());
            let start = (*free).max(Instant::now());
            *free = start + transfer;
            *free
        };
        done + self.half_rtt_duration()
    }

    /// Half the round trip.
    pub fn half_rtt_duration(&self) -> Duration {
        Duration::from_secs_f64(self.link.rtt_s.max(0.0) / 2.0)
    }

    async fn half_rtt(&self) {
        if self.link.rtt_s > 0.0 {
            tokio::time::sleep(self.half_rtt_duration()).await;
        }
    }
}

/// A simulated client's [`Fetcher`]: the real HTTP requests, through its emulated link.
#[derive(Clone)]
pub(super) struct Linked {
    pub(super) remote: Remote,
    pub(super) pipe: Arc<Pipe>,
    pub(super) world: Arc<World>,
}

impl Fetcher for Linked {
    /// What the segment occupies once decoded (a compressed geometry segment is decoded here,
    /// as the real client's IO thread does, and charged its plain size).
    type Body = u64;

    fn prefetch(
        &self,
        req: PrefetchRequest,
    ) -> impl Future<Output = anyhow::Result<PrefetchResponse>> + Send + 'static {
        let me = self.clone();
        async move {
            me.pipe.send().await;
            let resp = me.remote.prefetch(&req).await?;
            let body = portico_protocol::to_bincode(&resp).map_or(0, |b| b.len() as u64);
            me.pipe.deliver(body).await;
            Ok(resp)
        }
    }

    fn batch(
        &self,
        ids: Vec<u32>,
    ) -> impl Future<Output = anyhow::Result<Items<u64>>> + Send + 'static {
        let me = self.clone();
        async move {
            me.pipe.send().await;
            let got = me.remote.batch(&ids).await?;
            let total = got
                .iter()
                .map(|(_, b)| 12 + b.as_ref().map_or(0, |b| b.len() as u64))
                .sum();
            me.pipe.deliver(total).await;
            Ok(got
                .into_iter()
                .map(|(id, b)| {
                    let item = b.and_then(|b| Ok((me.decode(id, &b)?, b.len() as u64)));
                    (id, item)
                })
                .collect())
        }
    }

    fn decode(&self, id: u32, bytes: &[u8]) -> anyhow::Result<u64> {
        if portico_data::codec::is_compressed(bytes) {
            portico_data::codec::decode(bytes).map_err(|e| anyhow::anyhow!("segment {id}: {e}"))?;
        }
        // What the real client's cache is charged for it (a texture: what its GPU holds).
        Ok(self.world.decoded(id))
    }

    fn stream_url(&self) -> anyhow::Result<String> {
        self.remote.stream_url()
    }

    fn reaches_server(&self) -> std::time::Instant {
        (Instant::now() + self.pipe.half_rtt_duration()).into_std()
    }

    fn reaches_client(&self, bytes: u64) -> std::time::Instant {
        self.pipe.stamp(bytes).into_std()
    }

    fn bytes(&self, id: u32) -> u64 {
        self.world.bytes(id)
    }

    /// What the IO window is charged, as the real clients charge it: the larger of the wire
    /// and decoded sizes.
    fn held_bytes(&self, id: u32) -> u64 {
        self.world.decoded(id).max(self.world.bytes(id))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_with_units_and_print_back() {
        let l = Link::parse("rtt=20ms,rate=100mbit").unwrap();
        assert!((l.rtt_s - 0.02).abs() < 1e-12);
        assert!((l.rate_bytes_per_s - 12.5e6).abs() < 1e-6);
        assert_eq!(Link::parse(&l.to_string()).unwrap(), l);
        assert_eq!(l, Link::default());
        let l = Link::parse(" rate=4MiB , rtt=0.5s ").unwrap();
        assert_eq!((l.rtt_s, l.rate_bytes_per_s), (0.5, 4.0 * 1048576.0));
        let l = Link::parse("rtt=800us").unwrap();
        assert!((l.rtt_s - 0.0008).abs() < 1e-12 && l.rate_bytes_per_s.is_infinite());
        assert_eq!(Link::parse("rtt=5").unwrap().rtt_s, 0.005);
        assert_eq!(
            Link::parse("rate=inf").unwrap().to_string(),
            "rtt=0ms,rate=inf"
        );
        assert!((Link::parse("rate=1gbit").unwrap().rate_bytes_per_s - 1.25e8).abs() < 1e-3);
    }

    #[test]
    fn bad_specs_name_what_was_wrong() {
        assert_eq!(Link::parse(""), Err(LinkError::Empty));
        assert_eq!(
            Link::parse("rtt"),
            Err(LinkError::NotKeyValue("rtt".into()))
        );
        assert_eq!(
            Link::parse("jitter=3ms"),
            Err(LinkError::UnknownKey("jitter".into()))
        );
        assert_eq!(
            Link::parse("rtt=fast"),
            Err(LinkError::BadRtt("fast".into()))
        );
        assert_eq!(
            Link::parse("rtt=-1ms"),
            Err(LinkError::BadRtt("-1ms".into()))
        );
        assert_eq!(
            Link::parse("rate=0mbit"),
            Err(LinkError::BadRate("0mbit".into()))
        );
        assert_eq!(
            Link::parse("rate=mbit"),
            Err(LinkError::BadRate("mbit".into()))
        );
        assert!(
            Link::parse("rate=lots")
                .unwrap_err()
                .to_string()
                .contains("rate=\"lots\"")
        );
    }

    #[tokio::test]
    async fn the_pipe_never_exceeds_its_rate() {
        let pipe = std::sync::Arc::new(Pipe::new(Link {
            rtt_s: 0.010,
            rate_bytes_per_s: 100_000.0,
        }));
        let t0 = Instant::now();
        pipe.send().await;
        pipe.deliver(2_000).await;
        // 5 ms out, 20 ms on the wire, 5 ms back (timers only ever fire late).
        assert!(
            t0.elapsed() >= Duration::from_millis(30),
            "{:?}",
            t0.elapsed()
        );
        // Two bodies at once share the bucket: together they take two transfers.
        let t1 = Instant::now();
        let (a, b) = (pipe.clone(), pipe.clone());
        let ha = tokio::spawn(async move { a.deliver(2_000).await });
        let hb = tokio::spawn(async move { b.deliver(2_000).await });
        ha.await.unwrap();
        hb.await.unwrap();
        assert!(
            t1.elapsed() >= Duration::from_millis(45),
            "{:?}",
            t1.elapsed()
        );
    }
}
