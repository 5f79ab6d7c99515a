//! `portico serve FILE.portico|MODEL [--listen ADDR] [--token T] [limits]`: the streaming server
//! (a model file is built first, into a cache reused while it is unchanged: [`super::built`]).
//! Binds to loopback unless told otherwise; on Ctrl-C or SIGTERM stops accepting and drains for
//! at most 10 s; on SIGHUP reopens the file (a rebuild renamed a new file over it) and serves it
//! to new connections at once, while the old connections finish on the old map (valid until its
//! last reader is done, never remapped under them) and are closed after 10 s.

use anyhow::{Context, Result};
use portico_server::{AppState, Config};
use portico_server::{Control, Drained};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// Arguments of `portico serve`.
#[derive(clap::Args)]
pub struct Args {
    /// The display database (memory-mapped read-only; replace it by renaming a new file over it
    /// and sending SIGHUP or restarting, never by writing into it), or a model (.glb, .gltf,
    /// .obj, .ifc) to build with `portico build`'s defaults into a cache beside it (reused
    /// while the model and the files beside it are unchanged) and serve.
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
    /// Deadline of one prefetch answer, milliseconds (past it the request gets a 503).
    #[arg(long, default_value_t = 250)]
    prefetch_deadline_ms: u64,
    /// Compute each observer's own need list (stream and `/v1/prefetch`) instead of sharing
    /// one per place (the baseline the shared answers are measured against; exact, costly).
    #[arg(long)]
    exact_answers: bool,
    /// The built browser viewer to serve at `/` (default: `target/viewer` under the current
    /// folder, where `web/build.sh` puts it, else beside the binary's folder).
    #[arg(long, value_name = "DIR")]
    viewer: Option<PathBuf>,
    /// The share of the compute slots observers' own answers may take before answers are
    /// shared by place (a few clients get their own, a crowd shares; 0: always shared).
    #[arg(long, default_value_t = 0.3, value_name = "FRACTION")]
    exact_share: f64,
    /// Memory for the stream sessions' shared need lists, MB.
    #[arg(long, default_value_t = 256)]
    shared_cache_mb: usize,
    /// After SIGTERM or SIGHUP, seconds the requests in flight have to finish before their
    /// connections are closed.
    #[arg(long, default_value_t = 10)]
    drain_secs: u64,
}

impl Args {
    /// `portico serve FILE` with every other argument at its default (and the token from
    /// `PORTICO_TOKEN`, if set).
    pub fn for_file(file: &std::path::Path) -> Args {
        #[derive(clap::Parser)]
        struct One {
            #[command(flatten)]
            a: Args,
        }
        <One as clap::Parser>::parse_from([std::ffi::OsStr::new("serve"), file.as_os_str()]).a
    }
}

/// The viewer folder: the one given (which must hold a built viewer), else `target/viewer`
/// under the current folder (a checkout), else next to the binary's folder
/// (`target/release/portico` → `target/viewer`).
pub(crate) fn viewer_dir(given: Option<PathBuf>) -> Result<Option<PathBuf>> {
    if let Some(d) = given {
        if !portico_server::viewer_is_built(&d) {
            anyhow::bail!(
                "--viewer {0}: no built viewer there (index.html, {1}); build one with `bash web/build.sh {0}`",
                d.display(),
                portico_server::VIEWER_FILES.join(", ")
            );
        }
        return Ok(Some(d));
    }
    let beside = std::env::current_exe()
        .ok()
        .and_then(|e| Some(e.parent()?.parent()?.join("viewer")));
    Ok(std::iter::once(PathBuf::from("target/viewer"))
        .chain(beside)
        .find(|d| portico_server::viewer_is_built(d)))
}

/// Opens the database and serves until interrupted.
pub fn run(mut a: Args) -> Result<()> {
    if super::built::is_model(&a.file) {
        a.file = super::built::database_for(&a.file)?;
    }
    let config = Config {
        token: a.token.filter(|t| !t.is_empty()),
        max_sessions: a.max_sessions.max(1),
        max_session_rate: (a.session_rate_mb * 1e6).max(1.0) as u64,
        max_body_bytes: a.max_body_kb.max(1) << 10,
        request_timeout: Duration::from_secs(a.timeout.max(1)),
        compute_deadline: Duration::from_millis(a.prefetch_deadline_ms.max(1)),
        drain: Duration::from_secs(a.drain_secs),
        shared_answers: !a.exact_answers,
        exact_share: a.exact_share,
        shared_cache_bytes: a.shared_cache_mb << 20,
        viewer: viewer_dir(a.viewer)?,
        ..Config::default()
    };
    let state = AppState::open(&a.file, config.clone())?;
    let mut rt = tokio::runtime::Builder::new_multi_thread();
    if let Some(n) = a.threads {
        rt.worker_threads(n.max(1));
    }
    let rt = rt
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let listener = std::net::TcpListener::bind(a.listen).with_context(|| {
        let mut other = a.listen;
        other.set_port(a.listen.port().wrapping_add(1).max(1));
        format!(
            "cannot listen on {} (another server there? give another port: --listen {other})",
            a.listen
        )
    })?;
    listener.set_nonblocking(true)?;
    let addr = listener.local_addr()?;
    announce(&state, addr);
    match &config.viewer {
        Some(d) => eprintln!(
            "browser viewer (from {}): open {}",
            d.display(),
            page_url(addr, config.token.is_some())
        ),
        None => eprintln!(
            "no browser viewer at / (build it with `bash web/build.sh` in Portico's checkout, then \
             serve from there or give its target/viewer folder with --viewer DIR)"
        ),
    }
    if !config.shared_answers {
        eprintln!("stream sessions: exact answers (every observer its own need list, not shared)");
    }
    tracing::info!(
        "limits: {} connections, {} s to send headers, {} compute slots with a {} ms deadline",
        config.max_connections,
        config.header_timeout.as_secs(),
        config.compute_slots,
        config.compute_deadline.as_millis()
    );
    let drain = config.drain;
    rt.block_on(async move {
        // Signals are watched once for the whole life of the process and queued, so one that
        // arrives while a reload drains or reopens is not lost.
        let mut signals = watch_signals()?;
        let (control, rx) = tokio::sync::mpsc::unbounded_channel();
        let listener = tokio::net::TcpListener::from_std(listener)?;
        let mut serving = state.clone();
        let server = tokio::spawn(portico_server::serve_with_control(listener, state, rx, move |reload, d: Drained| {
            let what = if reload { "reload" } else { "stop" };
            if d.closed == 0 && d.sessions_left == 0 {
                eprintln!("{what}: {} connections finished their requests", d.finished);
            } else {
                eprintln!(
                    "{what}: {} connections finished; {} still busy after {} s were closed; {} stream sessions left",
                    d.finished, d.closed, drain.as_secs(), d.sessions_left
                );
            }
        }));
        while let Some(signal) = signals.recv().await {
            match signal {
                Stop::Quit => break,
                // SIGHUP: a rebuild renamed a new file over the old one. New connections get it
                // at once; the old map stays valid until its last request is done. If it does
                // not open, say why and keep serving the old one.
                Stop::Reload => match AppState::open_after(&a.file, config.clone(), &serving) {
                    Ok(new) => {
                        let (swapped, done) = tokio::sync::oneshot::channel();
                        let _ = control.send(Control::Reload(new.clone(), swapped));
                        if done.await.is_ok() {
                            announce(&new, addr);
                        }
                        serving = new;
                    }
                    Err(e) => eprintln!("reload failed, still serving the previous file: {e}"),
                },
            }
        }
        let _ = control.send(Control::Stop);
        server.await??;
        anyhow::Ok(())
    })?;
    eprintln!("stopped");
    Ok(())
}

/// The viewer's address for a browser on this machine (a server listening on every interface
/// is opened on loopback), with the token's place when the server wants one.
fn page_url(addr: SocketAddr, token: bool) -> String {
    let mut addr = addr;
    if addr.ip().is_unspecified() {
        addr.set_ip(std::net::Ipv4Addr::LOCALHOST.into());
    }
    if token {
        format!("http://{addr}/?token=TOKEN (TOKEN: the one given with --token)")
    } else {
        format!("http://{addr}/")
    }
}

/// Says what is served where.
fn announce(state: &AppState, addr: SocketAddr) {
    let db = state.db();
    let m = &state.manifest_bincode;
    eprintln!(
        "serving {} ({} segments, {:.1} MB, id {}; manifest {:.2} MB, {:.2} MB gzip-coded) on http://{addr}",
        db.header().name,
        db.segments().len(),
        db.file_len() as f64 / 1e6,
        state.database_id,
        m.identity.len() as f64 / 1e6,
        m.gzip.len() as f64 / 1e6,
    );
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
