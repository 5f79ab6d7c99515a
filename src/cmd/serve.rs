//! `portico serve FILE.portico [--listen ADDR] [--token T] [limits]`: the streaming server
//! (DESIGN §4). Binds to loopback unless told otherwise; stops cleanly on Ctrl-C or SIGTERM.

use anyhow::{Context, Result};
use portico_server::{AppState, Config};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// Arguments of `portico serve`.
#[derive(clap::Args)]
pub struct Args {
    /// The display database (memory-mapped read-only; replace it by renaming a new file over it
    /// and restarting, never by writing into it).
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
    let state = AppState::open(&a.file, config)?;
    let mut rt = tokio::runtime::Builder::new_multi_thread();
    if let Some(n) = a.threads {
        rt.worker_threads(n.max(1));
    }
    let rt = rt
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    rt.block_on(async move {
        let listener = tokio::net::TcpListener::bind(a.listen)
            .await
            .with_context(|| format!("cannot listen on {}", a.listen))?;
        let addr = listener.local_addr()?;
        let db = state.db();
        eprintln!(
            "serving {} ({} segments, {:.1} MB) on http://{addr}",
            db.header().name,
            db.segments().len(),
            db.file_len() as f64 / 1e6
        );
        portico_server::serve(state, listener, shutdown_signal()).await?;
        eprintln!("stopped");
        Ok(())
    })
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}
