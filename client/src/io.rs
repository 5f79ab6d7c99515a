//! The lookahead/IO stage (Funkhouser Ch. 6 and §5.2.3), on its own thread with its own tokio
//! runtime: it takes the latest observer the render stage published, asks the server for the
//! read set, fetches those segments a few at a time, uploads geometry to the GPU (the upload
//! stage) and hands the results to the render stage through a bounded queue. The render stage
//! never waits for it.

use crate::net::Remote;
use crate::render::{GpuMesh, Uploader};
use futures_util::StreamExt;
use portico_data::cells::StabList;
use portico_protocol::{NeedKind, Observer, PROTOCOL_VERSION, Policy, PrefetchRequest};
use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::time::Instant;
use tokio::sync::{mpsc, watch};

/// What the render stage publishes after each frame.
#[derive(Debug, Clone)]
pub struct FrameState {
    /// Frame index.
    pub frame: u64,
    /// The observer.
    pub observer: Observer,
    /// Segments resident in the cache.
    pub held: Vec<u32>,
    /// How many arrivals the render stage has taken from the queue so far.
    pub consumed: u64,
}

/// A segment's contents, ready for the cache.
pub enum Payload {
    /// Geometry already on the GPU.
    Mesh(GpuMesh),
    /// A decoded stab list.
    Stab(Arc<StabList>),
}

/// One message from the IO stage.
pub enum Arrival {
    /// A segment arrived.
    Segment {
        /// Segment id.
        id: u32,
        /// Its contents.
        payload: Payload,
        /// Bytes on the wire.
        bytes: u64,
        /// Seconds from the prefetch request that listed it to its arrival.
        latency_s: f64,
    },
    /// Segments the server says are outside the lookahead set: release them first.
    Hints(Vec<u32>),
    /// Something failed (logged and counted; the walk goes on).
    Failed(String),
}

/// Settings of the IO stage.
#[derive(Debug, Clone, Copy)]
pub struct IoConfig {
    /// Prefetch policy sent to the server.
    pub policy: Policy,
    /// Concurrent segment fetches.
    pub parallel: usize,
}

/// A running IO stage.
pub struct IoStage {
    /// Publish the latest frame state here.
    pub state: watch::Sender<Option<FrameState>>,
    /// Arrivals come out here.
    pub arrivals: mpsc::Receiver<Arrival>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl IoStage {
    /// Starts the stage on its own thread.
    pub fn start(remote: Remote, uploader: Uploader, cfg: IoConfig) -> std::io::Result<IoStage> {
        let (state_tx, state_rx) = watch::channel(None);
        let (tx, rx) = mpsc::channel(1024);
        let thread = std::thread::Builder::new()
            .name("portico-io".into())
            .spawn(move || {
                let rt = match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(rt) => rt,
                    Err(e) => {
                        let _ = tx.blocking_send(Arrival::Failed(format!("IO runtime: {e}")));
                        return;
                    }
                };
                rt.block_on(run(remote, uploader, cfg, state_rx, tx));
            })?;
        Ok(IoStage {
            state: state_tx,
            arrivals: rx,
            thread: Some(thread),
        })
    }

    /// Stops the stage and waits for its thread.
    pub fn stop(mut self) {
        drop(self.state);
        self.arrivals.close();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

async fn run(
    remote: Remote,
    uploader: Uploader,
    cfg: IoConfig,
    mut state: watch::Receiver<Option<FrameState>>,
    tx: mpsc::Sender<Arrival>,
) {
    // Delivered but maybe not yet seen in a published held set: id → arrival sequence number.
    let mut delivered: HashMap<u32, u64> = HashMap::new();
    let mut seq = 0u64;
    while state.changed().await.is_ok() {
        let Some(st) = state.borrow_and_update().clone() else {
            continue;
        };
        delivered.retain(|_, s| *s >= st.consumed);
        let held: HashSet<u32> = st
            .held
            .iter()
            .copied()
            .chain(delivered.keys().copied())
            .collect();
        let req = PrefetchRequest {
            version: PROTOCOL_VERSION,
            observer: st.observer,
            policy: cfg.policy,
            held: portico_protocol::encode_held(held),
        };
        let t0 = Instant::now();
        let resp = match remote.prefetch(&req).await {
            Ok(r) => r,
            Err(e) => {
                if send(&tx, &mut seq, Arrival::Failed(format!("{e:#}")))
                    .await
                    .is_err()
                {
                    return;
                }
                continue;
            }
        };
        if !resp.evict.is_empty()
            && send(&tx, &mut seq, Arrival::Hints(resp.evict))
                .await
                .is_err()
        {
            return;
        }
        let mut fetches = futures_util::stream::iter(resp.items)
            .map(|item| {
                let remote = &remote;
                async move { (item, remote.segment(item.segment).await) }
            })
            .buffered(cfg.parallel.max(1));
        while let Some((item, got)) = fetches.next().await {
            let arrival = match got {
                Err(e) => Arrival::Failed(format!("{e:#}")),
                Ok(bytes) => decode(item.kind, item.segment, &bytes, &uploader, t0),
            };
            if matches!(arrival, Arrival::Segment { .. }) {
                delivered.insert(item.segment, seq);
            }
            if send(&tx, &mut seq, arrival).await.is_err() {
                return;
            }
        }
    }
}

/// Sends one arrival; every message counts in the sequence the render stage acknowledges with
/// [`FrameState::consumed`].
async fn send(tx: &mpsc::Sender<Arrival>, seq: &mut u64, a: Arrival) -> Result<(), ()> {
    *seq += 1;
    tx.send(a).await.map_err(|_| ())
}

fn decode(kind: NeedKind, id: u32, bytes: &[u8], uploader: &Uploader, t0: Instant) -> Arrival {
    let payload = match kind {
        NeedKind::Geometry => uploader
            .upload(bytes)
            .map(Payload::Mesh)
            .map_err(|e| e.to_string()),
        NeedKind::Stab => portico_data::format::decode_segment::<StabList>(bytes)
            .map(|s| Payload::Stab(Arc::new(s))),
    };
    match payload {
        Ok(payload) => Arrival::Segment {
            id,
            payload,
            bytes: bytes.len() as u64,
            latency_s: t0.elapsed().as_secs_f64(),
        },
        Err(e) => Arrival::Failed(format!("segment {id}: {e}")),
    }
}
