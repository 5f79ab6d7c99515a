//! The accept loop: hyper connections under limits that `axum::serve` does not offer.
//!
//! - A client has [`Config::header_timeout`] to send a request's headers (and an idle keep-alive
//!   connection to start its next request): slow or silent sockets are closed, not kept.
//! - At most [`Config::max_connections`] connections are open, below the process's
//!   file-descriptor limit, so the server never runs out of descriptors. At the cap, the oldest
//!   connection that has not yet sent a whole request head (a slow or silent socket) is closed
//!   to make room; only when every connection is a real client is a new one answered 503
//!   (JSON, `Retry-After`) and closed.
//! - A reload swaps the database for new connections at once (no pause in accepting); the
//!   connections of the old generation finish their requests, are asked to close, and after
//!   [`Config::drain`] are closed. Stream sessions of the old generation are told to end. A stop
//!   does the same for every generation and returns. Both report what they really did.

use crate::config::Config;
use crate::state::AppState;
use crate::timed::{Stall, Timed};
use hyper_util::rt::{TokioExecutor, TokioIo, TokioTimer};
use hyper_util::server::conn::auto::Builder;
use hyper_util::server::graceful::GracefulShutdown;
use hyper_util::service::TowerToHyperService;
use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering::Relaxed;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::AsyncWriteExt;
use tokio::net::TcpListener;
use tokio::sync::{Semaphore, mpsc};
use tokio::task::{AbortHandle, JoinSet};

/// Descriptors kept free for the map, logs, and the answers that refuse connections.
const RESERVED_FDS: u64 = 64;

/// After a reload, how long the old generation's connections may start a request before idle
/// ones are closed (one accepted just before the swap has not sent its request yet).
const SETTLE: Duration = Duration::from_secs(1);

/// At the connection cap, a connection whose writes have been stuck this long may be closed to
/// make room: most likely a client that stopped reading, though a client whose link stalls
/// this long while the server is full loses its connection too (it may reconnect).
const STUCK: Duration = Duration::from_secs(2);

/// Largest buffer for one request's head (bytes): larger heads get hyper's own 431.
const MAX_HEAD_BUFFER: usize = 64 << 10;

/// The default connection cap: the file-descriptor limit (raised to its hard limit where the
/// system allows) less 64 reserved for files and the listener, between 64 and 16,384.
pub fn default_max_connections() -> usize {
    let limit = raise_fd_limit().unwrap_or(1024);
    limit.saturating_sub(RESERVED_FDS).clamp(64, 16_384) as usize
}

/// Raises the soft limit on open files to the hard limit; returns the soft limit now in force.
#[cfg(unix)]
#[allow(unsafe_code)] // libc's rlimit calls: see the SAFETY note.
fn raise_fd_limit() -> Option<u64> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit and setrlimit only read and write the struct we pass, which lives for
    // the whole call.
    unsafe {
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) != 0 {
            return None;
        }
        if lim.rlim_cur < lim.rlim_max {
            let raised = libc::rlimit {
                rlim_cur: lim.rlim_max,
                rlim_max: lim.rlim_max,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &raised) == 0 {
                lim = raised;
            }
        }
    }
    Some(lim.rlim_cur)
}

#[cfg(not(unix))]
fn raise_fd_limit() -> Option<u64> {
    None
}

/// What the accept loop is told.
#[derive(Debug)]
pub enum Control {
    /// Serve this database to new connections; drain the old generation. The sender hears
    /// when every connection accepted from then on gets the new database.
    Reload(Arc<AppState>, tokio::sync::oneshot::Sender<()>),
    /// Stop accepting, drain everything, return.
    Stop,
}

/// What a drain did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Drained {
    /// Connections that finished their requests and closed within the drain time.
    pub finished: usize,
    /// Connections still open at the end of the drain time, closed by the server.
    pub closed: usize,
    /// Stream sessions still open at the end of the drain time.
    pub sessions_left: u64,
}

/// One database's connections.
struct Generation {
    state: Arc<AppState>,
    router: axum::Router,
    graceful: GracefulShutdown,
    tasks: JoinSet<()>,
    /// Connections in the order they were accepted, with whether they have sent a whole
    /// request head yet and since when their writes are stuck (ended ones pruned when they
    /// are most of it, and at each shedding).
    waiting: VecDeque<(AbortHandle, Arc<AtomicBool>, Stall)>,
}

impl Generation {
    fn new(state: Arc<AppState>) -> Generation {
        Generation {
            router: crate::router(state.clone()),
            state,
            graceful: GracefulShutdown::new(),
            tasks: JoinSet::new(),
            waiting: VecDeque::new(),
        }
    }

    /// Closes the oldest open connection that has not sent a whole request head, else the one
    /// whose writes have been stuck longest (at least [`STUCK`]); false if there is none.
    /// Slowloris sockets and clients that stopped reading go first; clients that send their
    /// head at once and keep reading their answers are never shed.
    fn shed_one(&mut self, epoch: std::time::Instant) -> bool {
        self.waiting.retain(|(task, ..)| !task.is_finished());
        let idle = self
            .waiting
            .iter()
            .position(|(_, started, _)| !started.load(Relaxed));
        let stuck = || {
            let stuck_for = |i: usize| self.waiting[i].2.stuck_for(epoch);
            (0..self.waiting.len())
                .filter(|&i| stuck_for(i).is_some_and(|d| d >= STUCK))
                .max_by_key(|&i| stuck_for(i))
        };
        match idle.or_else(stuck).and_then(|i| self.waiting.remove(i)) {
            Some((task, ..)) => {
                task.abort();
                self.state.metrics.shed_connections.fetch_add(1, Relaxed);
                true
            }
            None => false,
        }
    }

    /// Asks every connection to close after its request in flight and every stream session to
    /// end, waits up to `drain`, then closes what is left.
    async fn drain(mut self, drain: Duration, settle: Duration) -> Drained {
        let start = tokio::time::Instant::now();
        let _ = self.state.shutdown.send(true);
        while self.tasks.try_join_next().is_some() {}
        let open = self.tasks.len();
        let graceful = self.graceful;
        let tasks = &mut self.tasks;
        let done = tokio::time::timeout(drain, async {
            // A connection accepted just before the swap may not have sent its request yet;
            // closing it as idle would fail that request. Let such requests start first.
            tokio::time::sleep(settle.min(drain / 2)).await;
            graceful.shutdown().await;
            while tasks.join_next().await.is_some() {}
        })
        .await;
        let closed = if done.is_ok() { 0 } else { self.tasks.len() };
        self.tasks.abort_all();
        // Sessions have their own tasks (after the upgrade); they watch `shutdown` and end at
        // once, or within their write timeout. Give them what is left of the drain time.
        let sessions = || self.state.sessions_open();
        while sessions() > 0 && start.elapsed() < drain {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        Drained {
            finished: open.saturating_sub(closed),
            closed,
            sessions_left: sessions(),
        }
    }
}

/// Serves `state` on `listener` until [`Control::Stop`]; `on_drain` hears about each drain
/// (`true` for a reload). Returns when everything has drained.
pub async fn run(
    listener: TcpListener,
    state: Arc<AppState>,
    mut control: mpsc::UnboundedReceiver<Control>,
    on_drain: impl Fn(bool, Drained) + Send + Sync + 'static,
) -> std::io::Result<()> {
    let config: Config = state.config.clone();
    let slots = Arc::new(Semaphore::new(config.max_connections.max(1)));
    let builder = Builder::new(TokioExecutor::new());
    // HTTP/1.1 only: over h2c a client could hold an answer for ever with a zero flow-control
    // window, without a single stuck write for the write timeout to see (TLS and HTTP/2 belong
    // to the proxy in front).
    let mut builder = builder.http1_only();
    builder
        .http1()
        .timer(TokioTimer::new())
        .header_read_timeout(config.header_timeout)
        .max_buf_size(MAX_HEAD_BUFFER);
    let mut current = Generation::new(state);
    let epoch = std::time::Instant::now();
    let on_drain = Arc::new(on_drain);
    let mut draining = JoinSet::new();
    loop {
        tokio::select! {
            accepted = listener.accept() => {
                let (stream, _) = match accepted {
                    Ok(s) => s,
                    Err(e) => {
                        // Out of descriptors or a transient error: wait a little instead of
                        // spinning; the connections in flight go on.
                        tracing::warn!("accept: {e}");
                        tokio::time::sleep(Duration::from_millis(50)).await;
                        continue;
                    }
                };
                let _ = stream.set_nodelay(true);
                // A stream session's socket outlives its connection task (the upgrade hands it
                // over): open sessions count against the cap too.
                let sessions = current.state.metrics.sessions.load(Relaxed).max(0) as usize;
                let free = slots.available_permits() > sessions;
                let permit = match slots.clone().try_acquire_owned().ok().filter(|_| free) {
                    Some(p) => Some(p),
                    // Full: make room by closing the oldest connection that has not sent one
                    // whole request head (a slow or silent socket), else refuse this one.
                    None if current.shed_one(epoch) => tokio::time::timeout(
                        Duration::from_millis(50),
                        slots.clone().acquire_owned(),
                    )
                    .await
                    .ok()
                    .and_then(Result::ok),
                    None => None,
                };
                let Some(permit) = permit else {
                    current.state.metrics.refused_connections.fetch_add(1, Relaxed);
                    tokio::spawn(refuse(stream));
                    continue;
                };
                let started = Arc::new(AtomicBool::new(false));
                let stall = Stall::default();
                let io = Timed::new(stream, config.write_timeout, stall.clone(), epoch)
                    .counting(current.state.metrics.clone());
                let service = TowerToHyperService::new(Started {
                    inner: current.router.clone(),
                    started: started.clone(),
                });
                let watcher = current.graceful.watcher();
                let builder = builder.clone();
                let task = current.tasks.spawn(async move {
                    let _slot = permit;
                    let conn = builder.serve_connection_with_upgrades(TokioIo::new(io), service);
                    let _ = watcher.watch(conn).await;
                });
                current.waiting.push_back((task, started, stall));
                // Reap finished connection tasks so the set does not grow, and their entries in
                // `waiting` once they are most of it (amortised: each entry is looked at a
                // bounded number of times).
                while current.tasks.try_join_next().is_some() {}
                if current.waiting.len() > 2 * current.tasks.len() + 64 {
                    current.waiting.retain(|(task, ..)| !task.is_finished());
                }
            }
            c = control.recv() => {
                match c {
                    Some(Control::Reload(state, swapped)) => {
                        let old = std::mem::replace(&mut current, Generation::new(state));
                        let _ = swapped.send(());
                        let report = on_drain.clone();
                        let drain = config.drain;
                        draining.spawn(async move { report(true, old.drain(drain, SETTLE).await) });
                    }
                    Some(Control::Stop) | None => break,
                }
            }
        }
    }
    drop(listener);
    let last = current.drain(config.drain, Duration::ZERO).await;
    while draining.join_next().await.is_some() {}
    on_drain(false, last);
    Ok(())
}

/// The router, noting that its connection has sent a whole request head.
#[derive(Clone)]
struct Started<S> {
    inner: S,
    started: Arc<AtomicBool>,
}

impl<S, R> tower::Service<R> for Started<S>
where
    S: tower::Service<R>,
{
    type Response = S::Response;
    type Error = S::Error;
    type Future = S::Future;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), S::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, req: R) -> S::Future {
        self.started.store(true, Relaxed);
        self.inner.call(req)
    }
}

/// Answers a connection over the cap with a 503 and closes it.
async fn refuse(mut stream: tokio::net::TcpStream) {
    const BODY: &str = r#"{"status":503,"code":"connections","message":"too many open connections; retry shortly"}"#;
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\nretry-after: {}\r\nconnection: close\r\ncontent-length: {}\r\n\r\n{BODY}",
        crate::error::RETRY_AFTER_S,
        BODY.len()
    );
    let _ = tokio::time::timeout(Duration::from_secs(1), stream.write_all(answer.as_bytes())).await;
}
