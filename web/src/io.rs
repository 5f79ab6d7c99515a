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
//! Which of them carries the segments, and when a session is tried again after one did not
//! open or closed (a server restart), is the engine's [`Switch`]: the first session holds pull
//! back 2 s at most, a later one opens while pull reads on, with the native client's back-off.

use crate::net::{Remote, Stale};
use crate::stream::Stream;
use portico_client::defaults;
use portico_client::engine::catalogue::{Catalogue, Kind};
use portico_client::engine::pages::{Pages, Readiness, TakenPage};
use portico_client::engine::pull::{self, Command, Fault, FrameState, Pull, Reask};
use portico_client::engine::push::{self, Push, Pushed};
use portico_client::engine::switch::{Carrier, Switch};
use portico_protocol::{Observer, Policy, PrefetchResponse};
use std::cell::RefCell;
use std::collections::{HashMap, VecDeque};
use std::rc::Rc;
use web_time::Instant;

/// Most pushed bytes taken into the cache in one frame: the rest waits for the next frames, so
/// a burst of pushes never makes one long frame.
pub const PUSHED_PER_FRAME: u64 = 4 << 20;

/// A stream session: its socket, and the engine's session state once the socket is open.
struct Session {
    socket: Stream,
    push: Option<Push>,
}

/// What a finished request left in the inbox.
enum Done {
    Answer(u64, Instant, anyhow::Result<PrefetchResponse>),
    /// A read request's segments, each checked against its row (or why not).
    Batch(u64, anyhow::Result<Vec<(u32, Result<Vec<u8>, String>)>>),
    /// A cell's page fetched for a pushed stab list that came before it.
    Page(u32, anyhow::Result<portico_data::format::CellPage>),
}

/// What the frame loop gets from the IO stage.
pub enum Arrival {
    /// A segment, its bytes checked against the manifest, when a need list first asked for it,
    /// and for a stab list of a paged start its cell's page (the instances it names and its
    /// part of the cell graph).
    Segment(u32, Vec<u8>, Instant, Option<TakenPage>),
    /// The server's eviction hints of its latest answer (§5.2.3).
    Release(Vec<u32>),
    /// A request failed; a later list may ask again.
    Failed(String),
    /// The server serves another file now: the stage has stopped.
    Stale(String),
}

/// The IO stage: the pull engine, the stream session and the inbox of finished requests.
pub struct Io {
    remote: Rc<Remote>,
    catalogue: Rc<RefCell<Catalogue>>,
    /// Started from the core manifest: the pages learnt so far.
    pages: Option<Rc<RefCell<Pages>>>,
    policy: Policy,
    /// What pull sends and when ([`portico_client::engine::pull`]).
    pull: Pull,
    inbox: Rc<RefCell<VecDeque<Done>>>,
    stopped: bool,
    /// Push or pull now, and when to try a session ([`portico_client::engine::switch`]).
    switch: Switch,
    /// The stream session, while one is opening or open.
    stream: Option<Session>,
    /// Whether the stream carried the segments at the last frame.
    was_pushing: bool,
}

impl Io {
    /// A stage reading from `remote` under `policy`, keeping at most `window` bytes in flight
    /// or delivered and not yet taken.
    /// With `push`, segments come over `/v1/stream` while it works.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        remote: Rc<Remote>,
        catalogue: Catalogue,
        pages: Option<Pages>,
        policy: Policy,
        window: u64,
        push: bool,
        reask: Reask,
    ) -> Io {
        Io {
            switch: Switch::new(push),
            stream: None,
            was_pushing: false,
            remote,
            catalogue: Rc::new(RefCell::new(catalogue)),
            pages: pages.map(|p| Rc::new(RefCell::new(p))),
            policy,
            pull: Pull::new(policy, defaults::PARALLEL, window).reasking(reask),
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
                    let mut bodies = HashMap::new();
                    let items = got.map_err(fault).map(|items| {
                        items
                            .into_iter()
                            .map(|(id, item)| match item {
                                Ok(b) => {
                                    let n = b.len() as u64;
                                    bodies.insert(id, b);
                                    (id, Ok(n))
                                }
                                Err(e) => (id, Err(e)),
                            })
                            .collect()
                    });
                    for event in self.pull.read(ticket, now, items) {
                        out.extend(self.arrival(event, &mut bodies));
                    }
                }
                Done::Page(cell, got) => {
                    if let Some(pages) = &self.pages {
                        let mut pages = pages.borrow_mut();
                        let taken = got.map_err(|e| format!("{e:#}")).and_then(|page| {
                            pages.take(&mut self.catalogue.borrow_mut(), page, Some(cell))
                        });
                        if let Err(e) = taken {
                            pages.release(cell);
                            out.push(Arrival::Failed(e));
                        }
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
        let Some(Session { socket, push }) = &mut self.stream else {
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
                        let ready = self.pages.as_ref().is_none_or(|p| {
                            p.borrow().readiness(&self.catalogue.borrow(), id) == Readiness::Ready
                        });
                        if !ready {
                            // Pushed before its page (or a stab list's cell page) came: given
                            // back, the server pushes it again; a stab list's page is read.
                            socket.send(&Push::rejected(id));
                            if let Some(p) = &self.pages
                                && let Some(cell) = p.borrow_mut().claim(id)
                            {
                                let (remote, inbox) = (self.remote.clone(), self.inbox.clone());
                                wasm_bindgen_futures::spawn_local(async move {
                                    let got = remote.page(cell).await;
                                    inbox.borrow_mut().push_back(Done::Page(cell, got));
                                });
                            }
                            continue;
                        }
                        match self.catalogue.borrow().verify(id, bytes) {
                            Ok(()) => {
                                let page =
                                    self.pages.as_ref().and_then(|p| p.borrow_mut().handed(id));
                                (
                                    Arrival::Segment(id, bytes.to_vec(), listed_at, page),
                                    Some(id),
                                )
                            }
                            Err(e) => {
                                socket.send(&Push::rejected(id));
                                (Arrival::Failed(e), None)
                            }
                        }
                    }
                    Pushed::Page(deflated) => {
                        let Some(p) = &self.pages else {
                            let why = format!("{}: a page came unasked for", socket.url());
                            out.push(Arrival::Failed(why));
                            continue;
                        };
                        let mut cat = self.catalogue.borrow_mut();
                        match p.borrow_mut().take_frame(&mut cat, deflated) {
                            Ok(()) => continue,
                            Err(e) => (Arrival::Failed(e), None),
                        }
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
                    self.switch.stale();
                    self.stopped = true;
                }
                Fault::Failed(why) => {
                    out.push(Arrival::Failed(format!("{why}; pulling over HTTP")));
                    self.switch.failed(now);
                }
            }
            self.stream = None;
        }
    }

    /// Bytes of prefetch requests and answers so far.
    pub fn prefetch_bytes(&self) -> u64 {
        self.remote.prefetch_bytes()
    }

    /// Stream sessions tried so far.
    pub fn sessions(&self) -> u64 {
        self.switch.tries()
    }

    /// Which transport brings segments now: `stream` or `pull`.
    pub fn transport(&self) -> &'static str {
        match &self.stream {
            Some(s) if s.socket.is_open() => "stream",
            _ => "pull",
        }
    }

    /// What segment `id` is, for decoding it.
    pub fn kind(&self, id: u32) -> Kind {
        self.catalogue.borrow().kind(id)
    }

    /// Keeps a stream session going when pushing; `true` while it carries the segments (or
    /// may still open), so pull stays idle. An open session hears the frame (what the cache
    /// released since the last, what the frame lacked, the observer).
    fn pushing(&mut self, state: &FrameState, now: Instant) -> bool {
        if self.stream.is_none() && self.switch.open_now(now) {
            let db = self.remote.database();
            match Stream::open(self.remote.base(), db.as_deref(), self.remote.token()) {
                Ok(socket) => self.stream = Some(Session { socket, push: None }),
                Err(_) => self.switch.failed(now),
            }
        }
        if let Some(s) = &self.stream
            && s.push.is_none()
        {
            if s.socket.is_open() {
                self.switch.opened(now);
            } else if self.switch.timed_out(now) {
                // Not open in time: pull, and try another session later.
                self.stream = None;
                self.switch.failed(now);
            }
        }
        let pushing = match (self.switch.carrier(now), &mut self.stream) {
            (Carrier::Push, Some(Session { socket, push })) => {
                let push = push.get_or_insert_with(|| {
                    // Opened: Hello, then what the cache holds (a session opened again).
                    let held = state.held.iter().copied();
                    let (p, opening) = Push::open(
                        socket.url(),
                        self.policy,
                        u64::MAX / 2,
                        socket.rtt(),
                        self.pages.is_some(),
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
            // The first session opening: pull waits a moment for it.
            (Carrier::Waiting, _) => true,
            _ => false,
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
                let bytes = bodies.remove(&id)?;
                let page = self.pages.as_ref().and_then(|p| p.borrow_mut().handed(id));
                Arrival::Segment(id, bytes, listed_at, page)
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
        self.pull.frame(state, now, now);
        let catalogue = self.catalogue.clone();
        let wire = |id: u32| catalogue.borrow().wire(id);
        let held = |id: u32| catalogue.borrow().held(id);
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
                Command::Read(ticket, ids) => {
                    let read = crate::paged::Read {
                        remote,
                        catalogue: self.catalogue.clone(),
                        pages: self.pages.clone(),
                    };
                    wasm_bindgen_futures::spawn_local(async move {
                        let got = read.batch(ids).await;
                        inbox.borrow_mut().push_back(Done::Batch(ticket, got));
                    });
                }
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
