//! Push, without IO: one `/v1/stream` session (one WebSocket) as a state machine that takes
//! frames, the socket's frames and the time, and says which messages to send.
//!
//! The session opens with `Hello` (the policy, the byte rate, the round trip as far as it is
//! known), `Pages` when the client started from the core manifest, and `Holding` with what the
//! cache holds (a session opened again after one ended), so nothing held is pushed again. From
//! then on the client sends each frame's observer, what the frame lacked (`Lacking`, when it
//! changes: pushed ahead of the server's list, as pull reads it ahead of the answer) and what
//! its cache released (`Evicted`, so the server's mirror of the cache stays true). The server
//! pushes the observer's need list in need order, each item when it can no longer wait for a
//! later list (Funkhouser §5.2.3 with deadlines: `portico_data::deadline`).
//!
//! What the cache released is found by comparing each frame's held set with the last one's and
//! with the segments handed on since ([`Push::handed`]): a segment the frame loop took and then
//! evicted before the next frame is told too. A pushed segment the client rejects (damaged, or
//! not yet decodable) is given back ([`Push::rejected`]), or the server's mirror would count it
//! held and never send it again.

use super::pull::{Fault, FrameState};
use portico_protocol::{
    CLOSE_STALE, MAX_LACKING, PROTOCOL_VERSION, Policy, ServerFrame, StreamClient, StreamServer,
    parse_server_frame,
};
use std::collections::HashSet;
use std::time::Duration;
use web_time::Instant;

/// What came off the socket, for the front end.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Pushed<'a> {
    /// A segment (not yet checked against the manifest), and when the latest observer before
    /// it was sent (its latency counted from then is a lower bound).
    Segment {
        /// Segment id.
        id: u32,
        /// Its bytes.
        bytes: &'a [u8],
        /// When the latest observer before it was sent.
        listed_at: Instant,
    },
    /// A cell's page (deflated), to take before the segments after it.
    Page(&'a [u8]),
    /// The server reported a problem with a message, or a frame does not decode; the session
    /// goes on.
    Failed(String),
    /// Nothing for the frame loop (the server dropped queued items whose need vanished).
    Nothing,
}

/// One push session's state.
#[derive(Debug)]
pub struct Push {
    policy: Policy,
    rate: u64,
    /// The address, for messages (never the token).
    shown: String,
    /// What the frame loop held at its last frame.
    held: HashSet<u32>,
    /// The last `Lacking` sent.
    lacking: Vec<u32>,
    /// Events handed to the frame loop so far, and the (event number, segment) of segments not
    /// yet known taken.
    events: u64,
    handed: Vec<(u64, u32)>,
    /// When the latest observer was sent.
    observed: Option<Instant>,
}

impl Push {
    /// A session on `shown` (its address, for messages) that opened at `now`, after `events`
    /// handed to the frame loop by another transport; returns it and the messages that open
    /// it. `rtt`: the round trip as far as known (zero: not known; [`Push::measured`] tells it
    /// later); `paged`: the client started from the core manifest and needs each cell's page
    /// with its stab list; `held`: what the cache holds now.
    pub fn open(
        shown: &str,
        policy: Policy,
        rate_bytes_per_s: u64,
        rtt: Duration,
        paged: bool,
        held: impl IntoIterator<Item = u32>,
        events: u64,
    ) -> (Push, Vec<StreamClient>) {
        let push = Push {
            policy,
            rate: rate_bytes_per_s,
            shown: shown.to_string(),
            held: held.into_iter().collect(),
            lacking: Vec::new(),
            events,
            handed: Vec::new(),
            observed: None,
        };
        // Hello at once (the first observer must not wait for a round trip).
        let mut out = vec![push.hello(rtt)];
        if paged {
            out.push(StreamClient::Pages);
        }
        if !push.held.is_empty() {
            let held = portico_protocol::encode_held(push.held.iter().copied());
            out.push(StreamClient::Holding(held));
        }
        (push, out)
    }

    fn hello(&self, rtt: Duration) -> StreamClient {
        StreamClient::Hello {
            version: PROTOCOL_VERSION,
            policy: self.policy,
            rate_bytes_per_s: self.rate,
            rtt_ms: rtt.as_millis().min(10_000) as u32,
        }
    }

    /// The round trip was measured (a ping's pong): the server counts its deadlines with it.
    pub fn measured(&self, rtt: Duration) -> StreamClient {
        self.hello(rtt)
    }

    /// Events handed to the frame loop so far (counting [`Push::open`]'s).
    pub fn events(&self) -> u64 {
        self.events
    }

    /// One event was handed to the frame loop: `segment` when it was a pushed segment.
    pub fn handed(&mut self, segment: Option<u32>) {
        if let Some(s) = segment {
            self.handed.push((self.events, s));
        }
        self.events += 1;
    }

    /// A frame at `now`: what the cache released, what the frame lacked when it changed, and
    /// the observer.
    pub fn frame(&mut self, f: &FrameState, now: Instant) -> Vec<StreamClient> {
        let mut out = Vec::new();
        let held: HashSet<u32> = f.held.iter().copied().collect();
        let consumed = f.consumed;
        let (taken, rest): (Vec<_>, Vec<_>) = self.handed.iter().partition(|(n, _)| *n < consumed);
        self.handed = rest;
        let mut evicted: Vec<u32> = self
            .held
            .iter()
            .copied()
            .chain(taken.into_iter().map(|(_, s)| s))
            .filter(|s| !held.contains(s))
            .collect::<HashSet<u32>>()
            .into_iter()
            .collect();
        evicted.sort_unstable();
        self.held = held;
        if !evicted.is_empty() {
            out.push(StreamClient::Evicted(evicted));
        }
        let mut lacking = f.lacking.clone();
        lacking.truncate(MAX_LACKING);
        if lacking != self.lacking {
            out.push(StreamClient::Lacking(lacking.clone()));
            self.lacking = lacking;
        }
        out.push(StreamClient::Observer(f.observer));
        self.observed = Some(now);
        out
    }

    /// What a binary frame from the server is; `now` is when it became the client's.
    pub fn incoming<'a>(&self, frame: &'a [u8], now: Instant) -> Pushed<'a> {
        match parse_server_frame(frame) {
            Ok(ServerFrame::Segment(id, bytes)) => Pushed::Segment {
                id,
                bytes,
                listed_at: self.observed.unwrap_or(now),
            },
            Ok(ServerFrame::Page(bytes)) => Pushed::Page(bytes),
            Ok(ServerFrame::Control(StreamServer::Dropped(_))) => Pushed::Nothing,
            Ok(ServerFrame::Control(StreamServer::Error(e))) => {
                Pushed::Failed(format!("{}: {}: {}", self.shown, e.code, e.message))
            }
            Err(e) => Pushed::Failed(format!("{}: a frame does not decode: {e}", self.shown)),
        }
    }

    /// A pushed segment the client rejected or cannot decode yet: given back, so the server's
    /// mirror does not count it held (it pushes it again when a list still wants it).
    pub fn rejected(id: u32) -> StreamClient {
        StreamClient::Evicted(vec![id])
    }

    /// Why the session ended, from the server's close frame (`None`: no close frame): stale
    /// when the server serves another database now ([`CLOSE_STALE`]), where opening it again
    /// cannot help.
    pub fn closed(&self, close: Option<(u16, &str)>) -> Fault {
        ended(&self.shown, close)
    }
}

/// Why a session on `shown` ended, from its close frame (see [`Push::closed`]).
pub fn ended(shown: &str, close: Option<(u16, &str)>) -> Fault {
    let why = match close {
        Some((code, "")) => format!(" ({code})"),
        Some((code, reason)) => format!(" ({code}: {reason})"),
        None => String::new(),
    };
    let why = format!("{shown}: the server ended the session{why}");
    match close {
        Some((CLOSE_STALE, _)) => Fault::Stale(why),
        _ => Fault::Failed(why),
    }
}

#[cfg(test)]
mod tests;
