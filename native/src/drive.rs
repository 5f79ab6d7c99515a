//! The IO stage's pull driver: a tokio shell around the client engine's pull state machine
//! ([`portico_client::engine::pull`], Funkhouser §5.2.3 and Ch. 6), which decides every request;
//! this file only sends them and hands what comes back to the frame loop.
//!
//! [`drive`] is shared by the real client ([`crate::io`]) and the load tester's simulated
//! clients (`portico_lab::loadtest`); what differs is the [`Fetcher`] (HTTP and a GPU upload,
//! or HTTP through an emulated link) and where the need list comes from:
//! - from the server: each published frame state becomes a `POST /v1/prefetch` (one at a time),
//!   behind what the latest frame lacked ([`Ask::lacking`]);
//! - from the client itself ([`Ask::wants`]): demand fetch and the oracle of the load tester.

use portico_client::engine::pull::{self, Command, Fault, FrameState, Pull};
use portico_protocol::{Observer, Policy, PrefetchRequest, PrefetchResponse};
use std::collections::HashMap;
use std::future::Future;
use std::time::Instant;
use tokio::sync::{mpsc, watch};
use tokio::task::{JoinHandle, JoinSet};

/// What the frame loop publishes after each frame.
#[derive(Debug, Clone)]
pub struct Ask {
    /// The observer, for the server's lookahead.
    pub observer: Observer,
    /// Segments resident in the cache.
    pub held: Vec<u32>,
    /// How many events the frame loop has taken from the queue so far.
    pub consumed: u64,
    /// The client's own need list, most urgent first (demand fetch, oracle); `None` asks the
    /// server's lookahead instead.
    pub wants: Option<Vec<u32>>,
    /// What the frame lacked, most urgent first ([`portico_client::demand::lacking`]): with
    /// `wants` `None`, read ahead of the server's latest answer, which is a round trip old and
    /// may not have come yet (a cold start).
    pub lacking: Vec<u32>,
    /// The frame skipped objects (something in view had nothing to draw): read only what it
    /// lacked until it is whole ([`portico_client::engine::pull`]).
    pub incomplete: bool,
    /// When the frame loop published this.
    pub at: Instant,
}

impl Ask {
    /// The engine's view of this frame state.
    pub fn frame_state(&self) -> FrameState {
        FrameState {
            observer: self.observer,
            held: self.held.clone(),
            lacking: self.lacking.clone(),
            incomplete: self.incomplete,
            consumed: self.consumed,
        }
    }
}

/// What the driver hands the frame loop.
#[derive(Debug)]
pub enum Event<B> {
    /// A prefetch answer (its items are already scheduled; its eviction hints are for the
    /// cache).
    Answer(Box<PrefetchResponse>),
    /// A segment arrived.
    Segment {
        /// Segment id.
        id: u32,
        /// What the fetcher made of it.
        body: B,
        /// Bytes on the wire.
        bytes: u64,
        /// When a need list first asked for it (pushed: when the latest observer before it
        /// came was sent, so its latency is a lower bound).
        listed_at: Instant,
    },
    /// A request failed (the walk goes on; a later list may ask again).
    Failed(String),
    /// The server no longer serves the database this client reads (rebuilt and reloaded): the
    /// IO stage has stopped, rather than fetch another file's segments by the old ids. The walk
    /// goes on with what it holds.
    Stale(String),
}

/// How the driver talks to the server.
pub trait Fetcher: Clone + Send + Sync + 'static {
    /// A fetched segment, ready for the cache.
    type Body: Send + 'static;
    /// `POST /v1/prefetch`.
    fn prefetch(
        &self,
        req: PrefetchRequest,
    ) -> impl Future<Output = anyhow::Result<PrefetchResponse>> + Send + 'static;
    /// `GET /v1/batch`: the segments, each checked and decoded (or why not), with its size on
    /// the wire; the whole request may fail too.
    fn batch(
        &self,
        ids: Vec<u32>,
    ) -> impl Future<Output = anyhow::Result<Items<Self::Body>>> + Send + 'static;
    /// Checks and decodes one segment as it came over the wire (a pushed one; `batch` does the
    /// same for each of its own).
    fn decode(&self, id: u32, bytes: &[u8]) -> anyhow::Result<Self::Body>;
    /// The push transport's address ([`crate::net::Remote::stream_url`]); by default there is
    /// none (`Err`).
    fn stream_url(&self) -> anyhow::Result<String> {
        anyhow::bail!("no push transport")
    }
    /// Whether the client started from the core manifest, so that the server must send each
    /// cell's page with its stab list ([`portico_protocol::StreamClient::Pages`]).
    fn paged(&self) -> bool {
        false
    }
    /// Takes a pushed page ([`portico_protocol::FRAME_PAGE`]'s payload) before the segments
    /// after it are decoded.
    fn take_page(&self, deflated: &[u8]) -> anyhow::Result<()> {
        let _ = deflated;
        anyhow::bail!("a page came, but this client read the whole manifest")
    }
    /// Waits until a pushed segment can be decoded (started from the core manifest: its row has
    /// come, and a stab list's page); an [`crate::io::Unready`] error gives it back to the
    /// server.
    fn settle(&self, id: u32) -> impl Future<Output = anyhow::Result<()>> + Send + 'static {
        let _ = id;
        async { Ok(()) }
    }
    /// When a message sent now reaches the server: now, but later across an emulated link.
    fn reaches_server(&self) -> Instant {
        Instant::now()
    }
    /// When a pushed frame of `bytes` that came off the socket now is the client's: now, but
    /// later across an emulated link (its rate, then half its round trip).
    fn reaches_client(&self, bytes: u64) -> Instant {
        let _ = bytes;
        Instant::now()
    }
    /// A segment's size in bytes on the wire (from the manifest), to size the batches.
    fn bytes(&self, id: u32) -> u64;
    /// What a segment occupies once decoded (more than [`Fetcher::bytes`] for a compressed
    /// geometry segment), to keep the window.
    fn held_bytes(&self, id: u32) -> u64 {
        self.bytes(id)
    }
}

/// Runs the IO stage until the frame loop goes away: the pull engine
/// ([`portico_client::engine::pull`]) keeps up to `parallel` segment fetches busy from the
/// latest need list, with at most `window` bytes in flight or delivered and not yet taken and
/// at most what the measured link delivers within two frames past its round trip on the wire;
/// this shell sends what it asks for and hands what happens to the frame loop on `tx`.
pub async fn drive<F: Fetcher>(
    fetcher: F,
    policy: Policy,
    parallel: usize,
    window: u64,
    state: watch::Receiver<Option<Ask>>,
    tx: mpsc::Sender<Event<F::Body>>,
) {
    let never = std::future::pending();
    drive_after(0, fetcher, policy, parallel, window, state, tx, never).await;
}

/// [`drive`], after `events` already sent on `tx` by another transport (they count in what
/// the frame loop reports it has taken), until `stop` completes (another transport takes
/// over): then the events sent in all, `None` when the frame loop went away or the database
/// is stale.
#[allow(clippy::too_many_arguments)]
pub(crate) async fn drive_after<F: Fetcher>(
    events: u64,
    fetcher: F,
    policy: Policy,
    parallel: usize,
    window: u64,
    mut state: watch::Receiver<Option<Ask>>,
    tx: mpsc::Sender<Event<F::Body>>,
    stop: impl Future<Output = ()>,
) -> Option<u64> {
    let mut stop = std::pin::pin!(stop);
    let mut stopped = false;
    let mut pull = Pull::new(policy, parallel, window).resume(events);
    let mut fetches: JoinSet<Fetched<F::Body>> = JoinSet::new();
    // Each read request in flight's ticket (a task that panics must not strand its segments).
    let mut tickets: HashMap<tokio::task::Id, u64> = HashMap::new();
    let mut asking: Option<JoinHandle<Answered>> = None;
    'run: loop {
        let wire = |id| fetcher.bytes(id);
        let held = |id| fetcher.held_bytes(id);
        while let Some(cmd) = pull.poll(Instant::now(), &wire, &held) {
            match cmd {
                Command::Ask(number, req) => {
                    let f = fetcher.clone();
                    asking = Some(tokio::spawn(async move {
                        let at = Instant::now();
                        (number, at, f.prefetch(req).await)
                    }));
                }
                Command::Read(ticket, ids) => {
                    let f = fetcher.clone();
                    let task = fetches.spawn(async move { (ticket, f.batch(ids).await) });
                    tickets.insert(task.id(), ticket);
                }
            }
        }
        let (events, mut bodies) = tokio::select! {
            () = &mut stop => {
                stopped = true;
                break;
            }
            changed = state.changed() => {
                if changed.is_err() {
                    break;
                }
                let Some(ask) = state.borrow_and_update().clone() else { continue };
                match ask.wants {
                    Some(wants) => pull.want(wants, ask.consumed, ask.at),
                    None => pull.frame(ask.frame_state(), ask.at, Instant::now()),
                }
                continue;
            }
            answered = async { asking.as_mut().expect("guarded").await }, if asking.is_some() => {
                asking = None;
                let now = Instant::now();
                let event = match answered {
                    Ok((number, at, got)) => pull.answered(number, at, got.map_err(fault), now),
                    // The task panicked: the request failed.
                    Err(e) => {
                        let fault = Fault::Failed(format!("prefetch task: {e}"));
                        pull.answered(0, now, Err(fault), now)
                    }
                };
                (vec![event], HashMap::new())
            }
            Some(done) = fetches.join_next_with_id(), if !fetches.is_empty() => {
                let now = Instant::now();
                let (ticket, got) = match done {
                    Ok((task, (ticket, got))) => {
                        tickets.remove(&task);
                        (ticket, got)
                    }
                    // The task panicked (a decoder or the GPU upload): its segments failed.
                    Err(e) => {
                        let ticket = tickets.remove(&e.id()).unwrap_or_default();
                        (ticket, Err(anyhow::anyhow!("read task: {e}")))
                    }
                };
                let mut bodies = HashMap::new();
                let items = got.map_err(fault).map(|items| {
                    items
                        .into_iter()
                        .map(|(id, item)| match item {
                            Ok((body, bytes)) => {
                                bodies.insert(id, body);
                                (id, Ok(bytes))
                            }
                            Err(e) => (id, Err(format!("{e:#}"))),
                        })
                        .collect()
                });
                (pull.read(ticket, now, items), bodies)
            }
        };
        for event in events {
            let event = match event {
                pull::Event::Answer(resp) => Event::Answer(resp),
                pull::Event::Segment {
                    id,
                    bytes,
                    listed_at,
                } => match bodies.remove(&id) {
                    Some(body) => Event::Segment {
                        id,
                        body,
                        bytes,
                        listed_at,
                    },
                    None => Event::Failed(format!("segment {id}: came twice in one batch")),
                },
                pull::Event::Failed(why) => Event::Failed(why),
                pull::Event::Stale(why) => Event::Stale(why),
            };
            if tx.send(event).await.is_err() {
                break 'run;
            }
        }
        if pull.stopped() {
            break;
        }
    }
    fetches.abort_all();
    if let Some(a) = asking {
        a.abort();
    }
    stopped.then_some(pull.events())
}

/// A failed request as the engine sees it: `410 Gone` ([`crate::net::Stale`]) stops pull.
fn fault(e: anyhow::Error) -> Fault {
    if e.downcast_ref::<crate::net::Stale>().is_some() {
        Fault::Stale(format!("{e:#}"))
    } else {
        Fault::Failed(format!("{e:#}"))
    }
}

/// What one read request brings: each segment (id, then its body and size on the wire, or why
/// not).
pub type Items<B> = Vec<(u32, anyhow::Result<(B, u64)>)>;
/// A finished read request: its ticket and what came of it.
type Fetched<B> = (u64, anyhow::Result<Items<B>>);
/// A finished prefetch request: its number, when it was asked, and the answer.
type Answered = (u64, Instant, anyhow::Result<PrefetchResponse>);

#[cfg(test)]
mod tests {
    use super::*;
    use portico_protocol::{NeedItem, NeedKind, PROTOCOL_VERSION};
    use std::sync::{Arc, Mutex};
    use std::time::Duration;

    /// A server that answers every prefetch request with `answer` after `delay`, and records
    /// each read request's ids.
    #[derive(Clone)]
    struct Fake {
        answer: Vec<u32>,
        /// Listed after `answer`, needed 1,000 frames from now.
        far: Vec<u32>,
        delay: Duration,
        reads: Arc<Mutex<Vec<Vec<u32>>>>,
    }

    impl Fetcher for Fake {
        type Body = ();

        fn decode(&self, _: u32, _: &[u8]) -> anyhow::Result<()> {
            Ok(())
        }

        fn prefetch(
            &self,
            _: PrefetchRequest,
        ) -> impl Future<Output = anyhow::Result<PrefetchResponse>> + Send + 'static {
            let near = self.answer.iter().map(|&s| (s, 1));
            let items: Vec<(u32, u32)> = near.chain(self.far.iter().map(|&s| (s, 1000))).collect();
            let delay = self.delay;
            async move {
                tokio::time::sleep(delay).await;
                Ok(PrefetchResponse {
                    version: PROTOCOL_VERSION,
                    items: items
                        .into_iter()
                        .map(|(segment, frames)| NeedItem {
                            segment,
                            kind: NeedKind::Geometry,
                            lod: 0,
                            bytes: 1000,
                            frames,
                        })
                        .collect(),
                    evict: Vec::new(),
                    range_cells: 1,
                    lookahead_cells: 1,
                    lookahead_objects: 1,
                    lookahead_bytes: 0,
                    truncated: false,
                    micros: 0,
                })
            }
        }

        fn batch(
            &self,
            ids: Vec<u32>,
        ) -> impl Future<Output = anyhow::Result<Items<()>>> + Send + 'static {
            self.reads.lock().unwrap().push(ids.clone());
            async move { Ok(ids.into_iter().map(|id| (id, Ok(((), 1000)))).collect()) }
        }

        fn bytes(&self, _: u32) -> u64 {
            1000
        }
    }

    fn ask(lacking: Vec<u32>) -> Ask {
        let o = [0.0; 3];
        Ask {
            observer: Observer {
                eye: o,
                dir: [0.0, 0.0, -1.0],
                up: [0.0, 1.0, 0.0],
                velocity: o,
                half_fov_x: 0.5,
                half_fov_y: 0.4,
                max_speed: 1.0,
                max_turn: 1.0,
                turn: [0.0; 3],
            },
            held: Vec::new(),
            consumed: 0,
            wants: None,
            lacking,
            incomplete: false,
            at: Instant::now(),
        }
    }

    /// Runs the driver against `fake` with one published frame state, and returns the ids in
    /// the order the reads asked for them once `n` segments arrived and 200 ms more passed
    /// (time for reads that should not happen to show).
    async fn reads_after(fake: Fake, state: Ask, n: usize) -> Vec<u32> {
        let (state_tx, state_rx) = watch::channel(None);
        let (tx, mut rx) = mpsc::channel(64);
        let task = tokio::spawn(drive(
            fake.clone(),
            Policy::default(),
            1,
            1 << 30,
            state_rx,
            tx,
        ));
        state_tx.send(Some(state)).unwrap();
        let mut got = 0;
        while got < n {
            match tokio::time::timeout(Duration::from_secs(10), rx.recv()).await {
                Ok(Some(Event::Segment { .. })) => got += 1,
                Ok(Some(_)) => {}
                Ok(None) | Err(_) => panic!("only {got} of {n} segments arrived"),
            }
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
        drop(state_tx);
        task.abort();
        fake.reads.lock().unwrap().concat()
    }

    #[tokio::test]
    async fn a_cold_start_reads_what_the_frame_lacks_before_the_answer_comes() {
        let fake = Fake {
            answer: vec![100, 101],
            far: Vec::new(),
            delay: Duration::from_millis(300),
            reads: Arc::default(),
        };
        // The answer is 300 ms away: the frame's stab list and stand-ins are read meanwhile.
        let reads = reads_after(fake, ask(vec![7, 8, 9]), 5).await;
        assert_eq!(reads, vec![7, 8, 9, 100, 101]);
    }
}
