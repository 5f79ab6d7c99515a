//! `portico serve FILE.portico [--listen ADDR] [--token T] [limits]`: the streaming server
//! (DESIGN §4). Binds to loopback unless told otherwise; stops cleanly on Ctrl-C or SIGTERM;
//! on SIGHUP drains the requests in flight and reopens the file (a rebuild renamed a new file
//! over it: the old map stays valid until its last reader is done, never remapped under them).

use anyhow::{Context, Result};
use portico_server::{AppState, Config};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// Arguments of `portico serve`.
#[derive(clap::Args)]
pub struct Args {
    /// The display database (memory-mapped read-only; replace it by renaming a new file over it
    /// and sending SIGHUP or restarting, never by writing into it).
    file: PathBuf,
    /// Address to listen on.
    #[arg(long, default_value = "127.0.0.1:7878")]
    listen: SocketAddr,
    /// Require `Authorization: Bearer TOKEN` on /v1/* (also read from PORTICO_TOKEN).
    #[arg(long, env = "PORTICO_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Most concurrent /v1/stream sessions.
    #[arg(long, default_value_t = 1024)]
    max_sessions: usize,
    /// Cap on each stream session's push rate, MB/s.
    #[arg(long, default_value_t = 256.0)]
    session_rate_mb: f64,
    /// Largest request body, KiB.
    #[arg(long, default_value_t = 1024)]
    max_body_kb: usize,
    /// Time limit for one HTTP request, seconds.
    #[arg(long, default_value_t = 30)]
    timeout: u64,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
}

/// Opens the database and serves until interrupted.
pub fn run(a: Args) -> Result<()> {
    let config = Config {
        token: a.token.filter(|t| !t.is_empty()),
        max_sessions: a.max_sessions.max(1),
        max_session_rate: (a.session_rate_mb * 1e6).max(1.0) as u64,
        max_body_bytes: a.max_body_kb.max(1) << 10,
        request_timeout: Duration::from_secs(a.timeout.max(1)),
        ..Config::default()
    };
    let mut state = AppState::open(&a.file, config.clone())?;
    let mut rt = tokio::runtime::Builder::new_multi_thread();
    if let Some(n) = a.threads {
        rt.worker_threads(n.max(1));
    }
    let rt = rt
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let listener = std::net::TcpListener::bind(a.listen)
        .with_context(|| format!("cannot listen on {}", a.listen))?;
    listener.set_nonblocking(true)?;
    let addr = listener.local_addr()?;
    // Signals are watched once for the whole life of the process and queued, so one that
    // arrives while a reload drains or reopens is not lost.
    let mut signals = rt.block_on(async { watch_signals() })?;
    loop {
        let db = state.db();
        eprintln!(
            "serving {} ({} segments, {:.1} MB, id {}) on http://{addr}",
            db.header().name,
            db.segments().len(),
            db.file_len() as f64 / 1e6,
            state.database_id
        );
        let l = listener.try_clone()?;
        let stop = rt.block_on(serve_until_signal(state.clone(), l, &mut signals))?;
        if stop == Stop::Quit {
            break;
        }
        // SIGHUP: the requests in flight have drained against the old map; open the file
        // again (a rebuild renamed a new inode over it) and go on. If it does not open, say
        // why and keep serving the old one.
        match AppState::open(&a.file, config.clone()) {
            Ok(new) => state = new,
            Err(e) => eprintln!("reload failed, still serving the previous file: {e}"),
        }
    }
    eprintln!("stopped");
    Ok(())
}

/// How long requests in flight may take to finish after a stop or reload signal before their
/// connections are dropped (a slow client must not hold a reload up for ever).
const DRAIN: Duration = Duration::from_secs(10);

/// Serves `state` on `listener` until a signal arrives, then drains for at most [`DRAIN`].
async fn serve_until_signal(
    state: std::sync::Arc<AppState>,
    listener: std::net::TcpListener,
    signals: &mut tokio::sync::mpsc::UnboundedReceiver<Stop>,
) -> Result<Stop> {
    let listener = tokio::net::TcpListener::from_std(listener)?;
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let mut server = tokio::spawn(portico_server::serve(state, listener, async move {
        let _ = stop_rx.await;
    }));
    let stop = tokio::select! {
        s = signals.recv() => s.unwrap_or(Stop::Quit),
        done = &mut server => {
            done??;
            return Ok(Stop::Quit);
        }
    };
    let _ = stop_tx.send(());
    match tokio::time::timeout(DRAIN, &mut server).await {
        Ok(done) => done??,
        Err(_) => {
            eprintln!("requests still running after {DRAIN:?}: closing their connections");
            server.abort();
        }
    }
    Ok(stop)
}

/// What a signal asks the server to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stop {
    /// Ctrl-C or SIGTERM: drain and exit.
    Quit,
    /// SIGHUP: drain and reopen the file.
    Reload,
}

/// Forwards Ctrl-C and SIGTERM (stop) and SIGHUP (reload) into a queue, for the whole life of
/// the process.
fn watch_signals() -> Result<tokio::sync::mpsc::UnboundedReceiver<Stop>> {
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    let quit = tx.clone();
    tokio::spawn(async move {
        while tokio::signal::ctrl_c().await.is_ok() {
            if quit.send(Stop::Quit).is_err() {
                break;
            }
        }
    });
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        for (kind, what) in [
            (SignalKind::terminate(), Stop::Quit),
            (SignalKind::hangup(), Stop::Reload),
        ] {
            let mut stream = signal(kind).context("installing a signal handler")?;
            let tx = tx.clone();
            tokio::spawn(async move {
                while stream.recv().await.is_some() {
                    if tx.send(what).is_err() {
                        break;
                    }
                }
            });
        }
    }
    Ok(rx)
}
