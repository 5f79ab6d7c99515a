//! Pull, without IO: the IO stage's reads over `POST /v1/prefetch` and `GET /v1/batch`
//! (Funkhouser §5.2.3 and Ch. 6) as a state machine that takes frames, answers, read results
//! and the time, and says which request to send next ([`Pull::poll`]).
//!
//! - One prefetch request at a time: a newer frame waits for the answer in flight, then asks
//!   with the latest observer — once the answer in hand has aged or the observer has moved,
//!   turned or changed pace enough to change it ([`Reask`]): a walker's answers would
//!   otherwise cost more bytes than the geometry they bring. After a failed request,
//!   [`BACKOFF`] passes before the next (a server that is down is not asked sixty times a
//!   second).
//! - Up to `parallel` read requests from the top of the latest read list: what the latest frame
//!   lacked, then what of the server's answer cannot wait for a later one
//!   ([`crate::deadline::ReadPlan`]), or the client's own list ([`Pull::want`]: demand fetch,
//!   the load tester's oracle).
//! - No more bytes in flight or delivered and not taken than the window
//!   ([`crate::schedule::Schedule::with_window`]), and no more on the wire than the measured
//!   link delivers within two frames past its round trip ([`crate::pacing::LinkMeter::cap`]).
//!
//! Every [`Event`] it returns is numbered in order (from [`Pull::resume`]'s count, when push
//! handed over): a front end hands them to its frame loop in that order, and the frame loop
//! says how many it has taken ([`FrameState::consumed`]), which frees the window.

use crate::deadline::{Link, ReadPlan};
use crate::pacing::LinkMeter;
use crate::schedule::Schedule;
use portico_protocol::{Observer, PROTOCOL_VERSION, Policy, PrefetchRequest, PrefetchResponse};
use std::collections::{HashMap, HashSet};
use std::time::Duration;
use web_time::Instant;

/// How long after a failed prefetch request the next may go.
pub const BACKOFF: Duration = Duration::from_millis(500);

/// When the answer in hand no longer stands and a new prefetch request is worth its bytes.
/// The server's answer follows the observer's place (the predicted lookahead shares one list
/// per cell, 1 m cube, view bucket of about 11° and velocity bucket) and the cache's contents;
/// what the cache took meanwhile is read past anyway (the read list skips what is held), so
/// asking again pays only once the observer has moved on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reask {
    /// The eye has moved this far (metres) from where the last request stood...
    pub moved_m: f32,
    /// ...or the view has turned this far (radians)...
    pub turned_rad: f32,
    /// ...or the velocity has changed this much (m/s)...
    pub velocity: f32,
    /// ...or the turn rate this much (rad/s)...
    pub turn: f32,
    /// ...or the last request is this old (seconds).
    pub age_s: f32,
}

impl Reask {
    /// After every answer, whatever changed (every front end before #43).
    pub const ALWAYS: Reask = Reask {
        moved_m: 0.0,
        turned_rad: 0.0,
        velocity: 0.0,
        turn: 0.0,
        age_s: 0.0,
    };

    /// The server's own grain: its place cube (1 m), about its view bucket (0.2 rad), a speed
    /// band's width (a quarter of a walking pace), its turn band (0.25 rad/s); two seconds.
    pub const DEFAULT: Reask = Reask {
        moved_m: 1.0,
        turned_rad: 0.2,
        velocity: 0.4,
        turn: 0.25,
        age_s: 2.0,
    };

    /// Whether `now` an observer `o` is worth a new request, the last having gone for `last`
    /// at `at`.
    pub fn due(&self, last: &Observer, at: Instant, o: &Observer, now: Instant) -> bool {
        let v = |a: [f32; 3]| glam::Vec3::from(a);
        let turned = v(last.dir)
            .normalize_or_zero()
            .angle_between(v(o.dir).normalize_or_zero());
        now.saturating_duration_since(at).as_secs_f32() >= self.age_s
            || v(o.eye).distance(v(last.eye)) >= self.moved_m
            || turned >= self.turned_rad
            || v(o.velocity).distance(v(last.velocity)) >= self.velocity
            || v(o.turn).distance(v(last.turn)) >= self.turn
    }

    /// How long (seconds) the next request may wait for `o` moving as it does now: until it
    /// has moved or turned past the thresholds, at most the age.
    pub fn wait_s(&self, o: &Observer) -> f64 {
        let v = |a: [f32; 3]| glam::Vec3::from(a).length();
        let until = |limit: f32, rate: f32| {
            if rate > 1e-6 {
                limit / rate
            } else {
                f32::INFINITY
            }
        };
        let s = self
            .age_s
            .min(until(self.moved_m, v(o.velocity)))
            .min(until(self.turned_rad, v(o.turn)));
        f64::from(s.max(0.0))
    }
}

impl Default for Reask {
    fn default() -> Self {
        Reask::DEFAULT
    }
}

/// What the frame loop publishes after each frame, for the server's lookahead.
#[derive(Debug, Clone)]
pub struct FrameState {
    /// The observer.
    pub observer: Observer,
    /// Segments resident in the cache.
    pub held: Vec<u32>,
    /// What the frame lacked, most urgent first ([`crate::demand::lacking`]): read ahead of the
    /// server's latest answer, which is a round trip old and may not have come yet.
    pub lacking: Vec<u32>,
    /// The frame skipped objects (something in view had nothing to draw): only what it lacked
    /// is read until it is whole.
    pub incomplete: bool,
    /// How many events the frame loop has taken so far.
    pub consumed: u64,
}

/// A request to send.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// `POST /v1/prefetch` with this body; its answer goes to [`Pull::answered`] with the
    /// number.
    Ask(u64, PrefetchRequest),
    /// `GET /v1/batch` of these segments; what comes goes to [`Pull::read`] with the ticket.
    Read(u64, Vec<u32>),
}

/// Why a request failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Fault {
    /// The server serves another database now (`410 Gone`): pull stops, rather than read
    /// another file's segments by the old ids.
    Stale(String),
    /// Anything else (the walk goes on; a later list may ask again).
    Failed(String),
}

/// What the front end hands its frame loop, in this order.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A prefetch answer (its items are already scheduled; its eviction hints are for the
    /// cache).
    Answer(Box<PrefetchResponse>),
    /// A segment of a read request came (the front end attaches what it made of it).
    Segment {
        /// Segment id.
        id: u32,
        /// Bytes on the wire.
        bytes: u64,
        /// When a need list first asked for it.
        listed_at: Instant,
    },
    /// A request, or one segment of it, failed.
    Failed(String),
    /// The server serves another database now: pull has stopped.
    Stale(String),
}

/// One segment of a finished read request: its bytes on the wire, or why it did not come
/// (damaged, not decodable).
pub type Item = (u32, Result<u64, String>);

/// The pull state machine (see the module).
#[derive(Debug)]
pub struct Pull {
    policy: Policy,
    parallel: usize,
    schedule: Schedule,
    meter: LinkMeter,
    plan: ReadPlan,
    /// A prefetch request is in flight.
    asking: bool,
    /// No prefetch request before this (after a failure).
    ask_after: Option<Instant>,
    /// The latest frame the server has not been asked about: its observer and held set.
    unasked: Option<(Observer, Vec<u32>)>,
    /// When to ask again, and the observer of the last request that was answered and when it
    /// went.
    reask: Reask,
    last_asked: Option<(Observer, Instant)>,
    /// The observer of the request in flight and when it went.
    in_flight_ask: Option<(Observer, Instant)>,
    /// Read requests in flight: what each asked for and when it was sent.
    reads: HashMap<u64, (Vec<u32>, Instant)>,
    tickets: u64,
    /// Events returned so far.
    events: u64,
    stopped: bool,
}

impl Pull {
    /// Pull under `policy` with up to `parallel` read requests in flight and at most `window`
    /// bytes in flight or delivered and not yet taken.
    pub fn new(policy: Policy, parallel: usize, window: u64) -> Pull {
        Pull {
            policy,
            parallel: parallel.max(1),
            schedule: Schedule::with_window(window),
            meter: LinkMeter::default(),
            plan: ReadPlan::default(),
            asking: false,
            ask_after: None,
            unasked: None,
            reask: Reask::DEFAULT,
            last_asked: None,
            in_flight_ask: None,
            reads: HashMap::new(),
            tickets: 0,
            events: 0,
            stopped: false,
        }
    }

    /// Pull asking again as `reask` says ([`Reask::ALWAYS`]: after every answer).
    pub fn reasking(mut self, reask: Reask) -> Pull {
        self.reask = reask;
        self
    }

    /// Pull taking over after another transport handed `events` to the frame loop (they count
    /// in what it reports it has taken).
    pub fn resume(mut self, events: u64) -> Pull {
        self.events = events;
        self
    }

    /// Events returned so far (counting [`Pull::resume`]'s).
    pub fn events(&self) -> u64 {
        self.events
    }

    /// Whether pull has stopped (the database is stale).
    pub fn stopped(&self) -> bool {
        self.stopped
    }

    /// Requests in flight (prefetch and read).
    pub fn in_flight(&self) -> usize {
        self.reads.len() + usize::from(self.asking)
    }

    /// A frame published at `at`, heard at `now`: what the frame loop took frees the window,
    /// what it lacked goes to the top of the read list (listed from `at`), and the next
    /// prefetch request asks about its observer.
    pub fn frame(&mut self, f: FrameState, at: Instant, now: Instant) {
        self.schedule.acknowledge(f.consumed, true);
        self.plan.frame(f.lacking, f.incomplete);
        self.unasked = Some((f.observer, f.held));
        // Every frame: deadlines come nearer as the answer ages (and the wait for the next
        // follows this frame's pace).
        self.refresh(now, at);
    }

    /// The client's own need list, most urgent first (demand fetch, the load tester's oracle),
    /// instead of the server's: no prefetch request is sent.
    pub fn want(&mut self, wants: Vec<u32>, consumed: u64, at: Instant) {
        self.schedule.acknowledge(consumed, false);
        self.schedule.refresh(wants, at);
    }

    /// The frame loop took every event returned so far (a front end that takes them all each
    /// frame, as a page does).
    pub fn taken_all(&mut self) {
        self.schedule.acknowledge(self.events, true);
    }

    /// Forgets the read list (another transport carries the segments now); requests in flight
    /// still finish.
    pub fn clear(&mut self, now: Instant) {
        self.plan.clear();
        self.schedule.refresh(Vec::new(), now);
    }

    /// The next request to send at `now`, if any: call until `None` after every change. `wire`
    /// gives a segment's bytes on the wire, `held` what it occupies once decoded (the window
    /// counts the larger).
    pub fn poll(
        &mut self,
        now: Instant,
        wire: &impl Fn(u32) -> u64,
        held: &impl Fn(u32) -> u64,
    ) -> Option<Command> {
        if self.stopped {
            return None;
        }
        let due = |(o, _): &(Observer, Vec<u32>)| {
            self.last_asked
                .as_ref()
                .is_none_or(|(last, at)| self.reask.due(last, *at, o, now))
        };
        if !self.asking
            && self.ask_after.is_none_or(|t| now >= t)
            && self.unasked.as_ref().is_some_and(due)
            && let Some((observer, cached)) = self.unasked.take()
        {
            self.asking = true;
            self.ask_after = None;
            self.in_flight_ask = Some((observer, now));
            let held: HashSet<u32> = cached.into_iter().chain(self.schedule.pending()).collect();
            let number = self.schedule.asked();
            let req = PrefetchRequest {
                version: PROTOCOL_VERSION,
                observer,
                policy: self.policy,
                held: portico_protocol::encode_held(held),
            };
            return Some(Command::Ask(number, req));
        }
        if self.reads.len() >= self.parallel {
            return None;
        }
        let horizon_s = 2.0 * f64::from(self.policy.frame_time_s);
        self.schedule.set_wire_cap(Some(self.meter.cap(horizon_s)));
        let ids = self.schedule.next_batch_sized(now, wire, held);
        if ids.is_empty() {
            return None;
        }
        self.tickets += 1;
        self.meter.started(now);
        self.reads.insert(self.tickets, (ids.clone(), now));
        Some(Command::Read(self.tickets, ids))
    }

    /// The answer to prefetch request `number`, sent at `at`, came at `now` (or failed).
    pub fn answered(
        &mut self,
        number: u64,
        at: Instant,
        answer: Result<PrefetchResponse, Fault>,
        now: Instant,
    ) -> Event {
        self.asking = false;
        let event = match answer {
            Ok(resp) => {
                self.last_asked = self.in_flight_ask.take();
                self.schedule.answered(number);
                self.plan.answered(resp.items.clone(), at);
                self.refresh(now, at);
                Event::Answer(Box::new(resp))
            }
            Err(fault) => {
                self.in_flight_ask = None;
                self.ask_after = Some(now + BACKOFF);
                self.fault(fault)
            }
        };
        self.events += 1;
        event
    }

    /// Read request `ticket` finished at `now`: each segment that came (in the order given),
    /// or why the whole request failed. Returns one event per item (one for a request that
    /// failed whole); a segment asked for and not among the items failed.
    pub fn read(&mut self, ticket: u64, now: Instant, got: Result<Vec<Item>, Fault>) -> Vec<Event> {
        let Some((ids, sent)) = self.reads.remove(&ticket) else {
            return Vec::new();
        };
        let wire: u64 = got.as_ref().map_or(0, |items| {
            items.iter().filter_map(|(_, r)| r.as_ref().ok()).sum()
        });
        self.meter.finished(sent, now, wire);
        let items = match got {
            Ok(items) => items,
            Err(fault) => {
                for id in ids {
                    self.schedule.finished(id, Err(()), now);
                }
                self.events += 1;
                return vec![self.fault(fault)];
            }
        };
        let mut out = Vec::with_capacity(items.len());
        let mut answered = HashSet::new();
        for (id, item) in items {
            if !answered.insert(id) {
                continue;
            }
            self.events += 1;
            out.push(match item {
                Ok(bytes) => Event::Segment {
                    id,
                    bytes,
                    listed_at: self.schedule.finished(id, Ok(self.events), now),
                },
                Err(e) => {
                    self.schedule.finished(id, Err(()), now);
                    Event::Failed(e)
                }
            });
        }
        for id in ids.into_iter().filter(|id| !answered.contains(id)) {
            self.schedule.finished(id, Err(()), now);
        }
        out
    }

    fn fault(&mut self, fault: Fault) -> Event {
        match fault {
            Fault::Stale(why) => {
                self.stopped = true;
                Event::Stale(why)
            }
            Fault::Failed(why) => Event::Failed(why),
        }
    }

    /// The read list from the plan at `now`, for need lists first listed at `at`.
    fn refresh(&mut self, now: Instant, at: Instant) {
        // The latest observer heard of: how long the next request may wait depends on its pace.
        let latest =
            (self.unasked.as_ref().map(|(o, _)| o)).or(self.last_asked.as_ref().map(|(o, _)| o));
        let link = Link {
            rate: self.meter.rate(),
            rtt_s: self.meter.rtt_s(),
            in_flight: self.schedule.wire_bytes(),
            wait_s: latest.map_or(0.0, |o| self.reask.wait_s(o)),
        };
        let list = self
            .plan
            .list(now, f64::from(self.policy.frame_time_s), link);
        self.schedule.refresh(list, at);
    }
}

#[cfg(test)]
mod tests;
