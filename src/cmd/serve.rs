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
        let serving = state.clone();
        let stop = rt.block_on(async move {
            let (tx, rx) = tokio::sync::oneshot::channel();
            let l = tokio::net::TcpListener::from_std(l)?;
            portico_server::serve(serving, l, async move {
                let _ = tx.send(stop_signal().await);
            })
            .await?;
            Ok::<_, anyhow::Error>(rx.await.unwrap_or(Stop::Quit))
        })?;
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

/// Why [`stop_signal`] returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stop {
    /// Ctrl-C or SIGTERM: drain and exit.
    Quit,
    /// SIGHUP: drain and reopen the file.
    Reload,
}

/// Waits for Ctrl-C, SIGTERM or SIGHUP.
async fn stop_signal() -> Stop {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let (term, hup) = {
        use tokio::signal::unix::{SignalKind, signal};
        let wait = |kind| async move {
            match signal(kind) {
                Ok(mut s) => {
                    s.recv().await;
                }
                Err(_) => std::future::pending::<()>().await,
            }
        };
        (wait(SignalKind::terminate()), wait(SignalKind::hangup()))
    };
    #[cfg(not(unix))]
    let (term, hup) = (std::future::pending::<()>(), std::future::pending::<()>());
    tokio::select! {
        _ = ctrl_c => Stop::Quit,
        _ = term => Stop::Quit,
        _ = hup => Stop::Reload,
    }
}
