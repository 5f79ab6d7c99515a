//! The lookahead/IO stage in a page (Funkhouser Ch. 6 and §5.2.3), on the page's one thread.
//! What it brings waits in an inbox until the next frame takes it, so a frame never waits for
//! the network. Two transports:
//!
//! - **push** (the default): one `/v1/stream` session ([`crate::stream`]) run by the client
//!   engine's push session ([`portico_client::engine::push`]): the observer and what the frame
//!   lacked go every frame, the server pushes in need order what the cache lacks;
//! - **pull** (the fallback, and `?transport=pull`): the engine's pull state machine
//!   ([`portico_client::engine::pull`], as the native client) over HTTP — one prefetch request
//!   in flight at a time and up to [`portico_client::defaults::PARALLEL`] segment batches from the top of the latest
//!   list: what the last frame lacked, then what of the answer cannot wait.
//!
//! A stream that does not open within [`OPEN_WAIT`], or closes (a server restart), hands over
//! to pull at once and is tried again after [`RETRY`].

use crate::net::{Remote, Stale};
use crate::stream::Stream;
use portico_client::defaults;
use portico_client::engine::pull::{self, Command, Fault, FrameState, Pull};
use portico_client::engine::push::{self, Push, Pushed};
use portico_protocol::{Observer, Policy, PrefetchResponse};
use std::cell::RefCell;
use std::collections::{HashMap, VecDeque};
use std::rc::Rc;
use std::time::Duration;
use web_time::Instant;

/// How long a stream may take to open before pull takes over.
pub const OPEN_WAIT: Duration = Duration::from_secs(2);
/// How long after a stream failed another is tried.
pub const RETRY: Duration = Duration::from_secs(5);
/// Most pushed bytes taken into the cache in one frame: the rest waits for the next frames, so
/// a burst of pushes never makes one long frame.
pub const PUSHED_PER_FRAME: u64 = 4 << 20;

/// A stream session: its socket, when it was opened, and the engine's session state once the
/// socket is open.
struct Session {
    socket: Stream,
    since: Instant,
    push: Option<Push>,
}

/// What a finished request left in the inbox.
enum Done {
    Answer(u64, Instant, anyhow::Result<PrefetchResponse>),
    Batch(u64, anyhow::Result<Vec<(u32, anyhow::Result<Vec<u8>>)>>),
}

/// What the frame loop gets from the IO stage.
pub enum Arrival {
    /// A segment, its bytes checked against the manifest, and when a need list first asked for
    /// it.
    Segment(u32, Vec<u8>, Instant),
    /// The server's eviction hints of its latest answer (§5.2.3).
    Release(Vec<u32>),
    /// A request failed; a later list may ask again.
    Failed(String),
    /// The server serves another file now: the stage has stopped.
    Stale(String),
}

/// Each segment's size and checksum (the manifest's table) and what it occupies decoded.
pub struct Catalogue {
    /// The manifest's segment table, by id.
    pub segments: Vec<portico_protocol::SegmentInfo>,
    /// Geometry segments by their decoded size.
    pub decoded: HashMap<u32, u64>,
}

/// The IO stage: the pull engine, the stream session and the inbox of finished requests.
pub struct Io {
    remote: Rc<Remote>,
    catalogue: Rc<Catalogue>,
    policy: Policy,
    /// What pull sends and when ([`portico_client::engine::pull`]).
    pull: Pull,
    inbox: Rc<RefCell<VecDeque<Done>>>,
    stopped: bool,
    /// Whether to push (else pull only), the session, when it was opened, and when the next
    /// one may be.
    push: bool,
    stream: Option<Session>,
    retry_at: Option<Instant>,
    /// Stream sessions opened so far.
    pub sessions: u64,
    /// Whether the stream carried the segments at the last frame.
    was_pushing: bool,
}

impl Io {
    /// A stage reading from `remote` under `policy`, keeping at most `window` bytes in flight
    /// or delivered and not yet taken.
    /// With `push`, segments come over `/v1/stream` while it works.
    pub fn new(
        remote: Rc<Remote>,
        catalogue: Catalogue,
        policy: Policy,
        window: u64,
        push: bool,
    ) -> Io {
        Io {
            push,
            stream: None,
            retry_at: None,
            sessions: 0,
            was_pushing: false,
            remote,
            catalogue: Rc::new(catalogue),
            policy,
            pull: Pull::new(policy, defaults::PARALLEL, window),
            inbox: Rc::new(RefCell::new(VecDeque::new())),
            stopped: false,
        }
    }

    /// Takes what the finished requests brought: answers become the read list, segments are
    /// checked against the manifest. Everything returned counts as taken by the frame loop.
    pub fn take(&mut self) -> Vec<Arrival> {
        let mut out = Vec::new();
        let now = Instant::now();
        let done: Vec<Done> = self.inbox.borrow_mut().drain(..).collect();
        for d in done {
            match d {
                Done::Answer(number, at, answer) => {
                    let event = self.pull.answered(number, at, answer.map_err(fault), now);
                    out.extend(self.arrival(event, &mut HashMap::new()));
                }
                Done::Batch(ticket, got) => {
                    // Checked against the manifest here; the engine hears what came.
                    let mut bodies = HashMap::new();
                    let items = got.map_err(fault).map(|items| {
                        items
                            .into_iter()
                            .map(|(id, item)| {
                                let checked = item.and_then(|b| {
                                    let info = self.catalogue.segments.get(id as usize);
                                    portico_protocol::verify_segment(info, id, &b)
                                        .map(|()| b)
                                        .map_err(anyhow::Error::msg)
                                });
                                match checked {
                                    Ok(b) => {
                                        let n = b.len() as u64;
                                        bodies.insert(id, b);
                                        (id, Ok(n))
                                    }
                                    Err(e) => (id, Err(format!("{e:#}"))),
                                }
                            })
                            .collect()
                    });
                    for event in self.pull.read(ticket, now, items) {
                        out.extend(self.arrival(event, &mut bodies));
                    }
                }
            }
        }
        // The frame loop takes every arrival at once.
        self.pull.taken_all();
        self.take_pushed(&mut out);
        out
    }

    /// What the stream pushed, checked like pulled segments (a rejected one is given back to
    /// the server); a closed stream hands over to pull.
    fn take_pushed(&mut self, out: &mut Vec<Arrival>) {
        let Some(Session { socket, push, .. }) = &mut self.stream else {
            return;
        };
        let now = Instant::now();
        if let Some(push) = push {
            for frame in socket.take(PUSHED_PER_FRAME) {
                let (arrival, segment) = match push.incoming(&frame, now) {
                    Pushed::Segment {
                        id,
                        bytes,
                        listed_at,
                    } => {
                        let info = self.catalogue.segments.get(id as usize);
                        match portico_protocol::verify_segment(info, id, bytes) {
                            Ok(()) => (Arrival::Segment(id, bytes.to_vec(), listed_at), Some(id)),
                            Err(e) => {
                                socket.send(&Push::rejected(id));
                                (Arrival::Failed(e), None)
                            }
                        }
                    }
                    // This client reads the whole manifest and never asks for pages.
                    Pushed::Page(_) => {
                        let why = format!("{}: a page came unasked for", socket.url());
                        (Arrival::Failed(why), None)
                    }
                    Pushed::Failed(why) => (Arrival::Failed(why), None),
                    Pushed::Nothing => continue,
                };
                out.push(arrival);
                push.handed(segment);
            }
        }
        if let Some((code, reason)) = socket.closed() {
            let close = (code != 0).then_some((code, reason.as_str()));
            match push::ended(socket.url(), close) {
                Fault::Stale(why) => {
                    out.push(Arrival::Stale(why));
                    self.stopped = true;
                }
                Fault::Failed(why) => {
                    out.push(Arrival::Failed(format!("{why}; pulling over HTTP")));
                    self.retry_at = Some(now + RETRY);
                }
            }
            self.stream = None;
        }
    }

    /// Which transport brings segments now: `stream` or `pull`.
    pub fn transport(&self) -> &'static str {
        match &self.stream {
            Some(s) if s.socket.is_open() => "stream",
            _ => "pull",
        }
    }

    /// What geometry segment `id` occupies decoded, by its LOD record (bytes).
    pub fn decoded_size(&self, id: u32) -> Option<u64> {
        self.catalogue.decoded.get(&id).copied()
    }

    /// Keeps a stream session going when pushing; `true` while it carries the segments (or
    /// may still open), so pull stays idle. An open session hears the frame (what the cache
    /// released since the last, what the frame lacked, the observer).
    fn pushing(&mut self, state: &FrameState, now: Instant) -> bool {
        if !self.push {
            return false;
        }
        if self.stream.is_none() && self.retry_at.is_none_or(|t| now >= t) {
            let db = self.remote.database();
            match Stream::open(self.remote.base(), db.as_deref(), self.remote.token()) {
                Ok(socket) => {
                    self.stream = Some(Session {
                        socket,
                        since: now,
                        push: None,
                    });
                    self.sessions += 1;
                }
                Err(_) => self.retry_at = Some(now + RETRY),
            }
        }
        let pushing = match &mut self.stream {
            Some(Session { socket, push, .. }) if socket.is_open() => {
                let push = push.get_or_insert_with(|| {
                    // Opened: Hello, then what the cache holds (a session opened again).
                    let held = state.held.iter().copied();
                    let (p, opening) = Push::open(
                        socket.url(),
                        self.policy,
                        u64::MAX / 2,
                        socket.rtt(),
                        false,
                        held,
                        0,
                    );
                    for m in &opening {
                        socket.send(m);
                    }
                    p
                });
                // The frame loop took everything handed on.
                let f = FrameState {
                    consumed: push.events(),
                    ..state.clone()
                };
                for m in push.frame(&f, now) {
                    socket.send(&m);
                }
                true
            }
            Some(s) if s.push.is_none() && now.duration_since(s.since) < OPEN_WAIT => true,
            // Not open in time: pull, and try another session later.
            Some(_) => {
                self.stream = None;
                self.retry_at = Some(now + RETRY);
                false
            }
            None => false,
        };
        if pushing && !self.was_pushing {
            // The stream takes over: what pull still meant to read is the stream's now.
            self.pull.clear(now);
        }
        self.was_pushing = pushing;
        pushing
    }

    /// What the frame loop gets of one of the engine's events (a segment with its checked
    /// bytes from `bodies`).
    fn arrival(
        &mut self,
        event: pull::Event,
        bodies: &mut HashMap<u32, Vec<u8>>,
    ) -> Option<Arrival> {
        Some(match event {
            pull::Event::Answer(resp) => Arrival::Release(resp.evict),
            pull::Event::Segment { id, listed_at, .. } => {
                Arrival::Segment(id, bodies.remove(&id)?, listed_at)
            }
            pull::Event::Failed(why) => Arrival::Failed(why),
            pull::Event::Stale(why) => {
                self.stopped = true;
                Arrival::Stale(why)
            }
        })
    }

    /// After a frame: asks the server about `observer` unless an answer is pending, and keeps
    /// up to [`portico_client::defaults::PARALLEL`] batches in flight from the top of the latest read list, no more on
    /// the wire than the measured link delivers within two frames past its round trip. `held`:
    /// the segments resident in the cache; `lacking`: what the frame lacked, read first, and
    /// alone while the frame was `incomplete` ([`portico_client::deadline::ReadPlan`]).
    pub fn pump(
        &mut self,
        observer: Observer,
        held: impl Iterator<Item = u32>,
        lacking: Vec<u32>,
        incomplete: bool,
    ) {
        if self.stopped {
            return;
        }
        let now = Instant::now();
        let mut state = FrameState {
            observer,
            held: held.collect(),
            lacking,
            incomplete,
            consumed: 0,
        };
        if self.pushing(&state, now) {
            return;
        }
        state.consumed = self.pull.events();
        self.pull.frame(state, now);
        let catalogue = self.catalogue.clone();
        let wire = |id: u32| catalogue.segments.get(id as usize).map_or(0, |s| s.bytes);
        let held = |id: u32| {
            catalogue
                .decoded
                .get(&id)
                .map_or(wire(id), |&d| d.max(wire(id)))
        };
        while let Some(cmd) = self.pull.poll(now, &wire, &held) {
            let (remote, inbox) = (self.remote.clone(), self.inbox.clone());
            match cmd {
                Command::Ask(number, req) => wasm_bindgen_futures::spawn_local(async move {
                    let at = Instant::now();
                    let answer = remote.prefetch(&req).await;
                    inbox
                        .borrow_mut()
                        .push_back(Done::Answer(number, at, answer));
                }),
                Command::Read(ticket, ids) => wasm_bindgen_futures::spawn_local(async move {
                    let got = remote.batch(&ids).await;
                    inbox.borrow_mut().push_back(Done::Batch(ticket, got));
                }),
            }
        }
    }
}

/// A failed request as the engine sees it: `410 Gone` ([`Stale`]) stops pull.
fn fault(e: anyhow::Error) -> Fault {
    if e.downcast_ref::<Stale>().is_some() {
        Fault::Stale(format!("{e:#}"))
    } else {
        Fault::Failed(format!("{e:#}"))
    }
}
