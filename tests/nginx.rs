//! The scaled-out deployment of `docker/`, without Docker: Debian's nginx with
//! `docker/nginx.conf.template` in front of three `portico serve` processes on loopback ports.
//! A client walks through nginx while one replica is killed mid-run; segments come from
//! nginx's cache on the second read; the WebSocket stream and the browser viewer's files pass
//! the proxy; a short load test runs through the proxy on the replicas left.
//!
//! Needs `nginx` on the PATH or in /usr/sbin (`.ci/run` installs it). Without it the test
//! prints why and passes, unless `CI` is set, where a missing nginx is a failure.

use futures_util::{SinkExt, StreamExt};
use portico_client::elision::Algorithm;
use portico_client::policy::policy_spec;
use portico_data::path::{PathKind, generate};
use portico_lab::loadtest::{Link, LoadtestConfig, run as run_loadtest};
use portico_native::walk::{WalkConfig, walk};
use portico_protocol::{PROTOCOL_VERSION, Policy, ServerFrame, StreamClient};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

fn nginx_binary() -> Option<PathBuf> {
    ["/usr/sbin/nginx", "/usr/local/sbin/nginx", "/usr/bin/nginx"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
}

/// Kills the child when dropped, so a failing test leaves no processes behind.
struct Proc(Child);
impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// nginx's master process, stopped with SIGTERM when dropped: the master then stops its
/// workers. (SIGKILL would orphan the workers, which hold the test harness's output pipe open
/// and keep `cargo test | tee` waiting for ever.)
struct Nginx(Child);
impl Drop for Nginx {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status();
        let _ = self.0.wait();
    }
}

fn portico(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_portico"));
    c.args(args);
    c
}

fn build_tiny(dir: &Path) -> PathBuf {
    let glb = dir.join("tiny.glb");
    let db = dir.join("tiny.portico");
    let gen_ok = portico(&["generate", "--preset", "tiny", "-o", glb.to_str().unwrap()])
        .status()
        .unwrap();
    assert!(gen_ok.success());
    let build_ok = portico(&["build", glb.to_str().unwrap(), "-o", db.to_str().unwrap()])
        .status()
        .unwrap();
    assert!(build_ok.success());
    db
}

/// Starts a replica on a free port with these `serve` flags; returns it, its address (read from
/// its start-up line) and its log lines (stderr) as they come.
fn replica_with(db: &Path, flags: &[&str]) -> (Proc, String, std::sync::mpsc::Receiver<String>) {
    let mut args = vec!["serve", db.to_str().unwrap(), "--listen", "127.0.0.1:0"];
    args.extend(flags);
    let mut child = portico(&args)
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let line = lines.next().unwrap().unwrap();
    let addr = line.rsplit("http://").next().unwrap().trim().to_string();
    assert!(
        addr.starts_with("127.0.0.1:"),
        "unexpected start-up line {line:?}"
    );
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for l in lines.map_while(Result::ok) {
            let _ = tx.send(l);
        }
    });
    (Proc(child), addr, rx)
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn start_nginx(nginx: &Path, dir: &Path, replicas: &[String]) -> (Nginx, String) {
    let template = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/docker/nginx.conf.template"
    ))
    .unwrap();
    let port = free_port();
    let tmp = dir.join("nginx");
    std::fs::create_dir_all(&tmp).unwrap();
    let upstreams: String = replicas
        .iter()
        .map(|a| format!("server {a} max_fails=1 fail_timeout=30s; "))
        .collect();
    let conf = template
        .replace("${PORTICO_UPSTREAMS}", &upstreams)
        .replace("${PORTICO_LISTEN}", &format!("127.0.0.1:{port}"))
        .replace("${PORTICO_CACHE_DIR}", tmp.join("cache").to_str().unwrap())
        .replace("${PORTICO_TMP}", tmp.to_str().unwrap());
    let conf_path = tmp.join("nginx.conf");
    std::fs::write(&conf_path, conf).unwrap();
    let child = Command::new(nginx)
        .args([
            "-p",
            tmp.to_str().unwrap(),
            "-c",
            conf_path.to_str().unwrap(),
            "-g",
            "daemon off;",
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let child = Nginx(child);
    let base = format!("http://127.0.0.1:{port}");
    // Wait until nginx answers (a readiness poll: bounded, no fixed sleep).
    assert!(
        wait_healthy(&base),
        "nginx never answered on {base}; see {}",
        tmp.join("error.log").display()
    );
    (child, base)
}

/// Polls `/healthz` through a plain socket until it answers 200 (bounded: about 5 s).
fn wait_healthy(base: &str) -> bool {
    use std::io::{Read, Write};
    let addr = base.trim_start_matches("http://");
    for _ in 0..500 {
        if let Ok(mut s) = std::net::TcpStream::connect(addr) {
            let _ =
                s.write_all(b"GET /healthz HTTP/1.1\r\nHost: portico\r\nConnection: close\r\n\r\n");
            let mut buf = [0u8; 12];
            if s.read_exact(&mut buf).is_ok() && buf.starts_with(b"HTTP/1.1 200") {
                return true;
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    false
}

#[test]
fn three_replicas_behind_nginx_survive_losing_one() {
    let Some(nginx) = nginx_binary() else {
        assert!(
            std::env::var_os("CI").is_none(),
            "nginx is not installed but CI is set"
        );
        eprintln!("skipping: nginx is not installed (apt-get install nginx-light)");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let db = build_tiny(dir.path());
    // The browser viewer, where `web/build.sh` built it (CI does).
    let viewer = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/viewer");
    let viewer = portico_server::viewer_is_built(&viewer).then_some(viewer);
    assert!(
        viewer.is_some() || std::env::var_os("CI").is_none(),
        "no built viewer in target/viewer, but CI is set"
    );
    let flags: Vec<&str> = match &viewer {
        Some(v) => vec!["--viewer", v.to_str().unwrap()],
        None => Vec::new(),
    };
    let mut replicas: Vec<(Proc, String)> = (0..3)
        .map(|_| {
            let (p, addr, _) = replica_with(&db, &flags);
            (p, addr)
        })
        .collect();
    let addrs: Vec<String> = replicas.iter().map(|(_, a)| a.clone()).collect();
    let (_nginx, base) = start_nginx(&nginx, dir.path(), &addrs);
    let rt = tokio::runtime::Runtime::new().unwrap();

    // The browser viewer's page and module pass the proxy: gzipped where the browser accepts
    // it, revalidated (no-cache) and marked as varying by encoding for nginx and CDNs.
    if viewer.is_some() {
        rt.block_on(async {
            // No automatic decoding: the test sees the coding on the wire.
            let http = reqwest::Client::builder().no_gzip().build().unwrap();
            let page = http.get(format!("{base}/")).send().await.unwrap();
            assert_eq!(page.status(), 200);
            assert_eq!(page.headers()["cache-control"], "no-cache");
            assert!(page.text().await.unwrap().contains("portico_web.js"));
            let module = http
                .get(format!("{base}/portico_web_bg.wasm"))
                .header("accept-encoding", "gzip")
                .send()
                .await
                .unwrap();
            assert_eq!(module.status(), 200);
            let h = module.headers();
            assert_eq!(h["content-type"], "application/wasm");
            assert_eq!(h["content-encoding"], "gzip");
            assert_eq!(h["vary"], "accept-encoding");
            let body = module.bytes().await.unwrap();
            assert_eq!(&body[..2], &[0x1f, 0x8b], "a gzip stream");
        });
    }

    // Content-named segments are served from nginx's cache the second time.
    rt.block_on(async {
        let http = reqwest::Client::new();
        let m: serde_json::Value = http
            .get(format!("{base}/v1/manifest"))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        let url = format!(
            "{base}/v1/db/{}/segments/1",
            m["database_id"].as_str().unwrap()
        );
        let first = http.get(&url).send().await.unwrap();
        assert_eq!(first.status(), 200);
        let bytes = first.bytes().await.unwrap();
        let second = http.get(&url).send().await.unwrap();
        assert_eq!(second.headers()["x-cache-status"], "HIT");
        assert_eq!(second.bytes().await.unwrap(), bytes);
    });

    // The WebSocket stream passes the proxy.
    rt.block_on(async {
        let ws_url = base.replace("http://", "ws://") + "/v1/stream";
        let (mut ws, _) = tokio_tungstenite::connect_async(&ws_url).await.unwrap();
        let d = portico_data::Database::open(&db).unwrap();
        let g = d.cell_graph().unwrap().unwrap();
        let c = g.cells.iter().find(|c| c.live).unwrap();
        let eye = [
            (c.bounds.min[0] + c.bounds.max[0]) / 2.0,
            1.5,
            (c.bounds.min[2] + c.bounds.max[2]) / 2.0,
        ];
        let hello = StreamClient::Hello {
            version: PROTOCOL_VERSION,
            policy: Policy::default(),
            rate_bytes_per_s: 50 << 20,
            rtt_ms: 0,
        };
        let obs = StreamClient::Observer(portico_protocol::Observer {
            eye,
            dir: [1.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            velocity: [0.0; 3],
            half_fov_x: 0.6,
            half_fov_y: 0.45,
            max_speed: 1.5,
            max_turn: 1.0,
            turn: [0.0; 3],
        });
        for m in [hello, obs] {
            let bytes = portico_protocol::to_bincode(&m).unwrap();
            ws.send(tokio_tungstenite::tungstenite::Message::Binary(
                bytes.into(),
            ))
            .await
            .unwrap();
        }
        let first_segment = async {
            loop {
                let msg = ws.next().await.expect("stream open").unwrap();
                if let tokio_tungstenite::tungstenite::Message::Binary(b) = msg
                    && let Ok(ServerFrame::Segment(id, bytes)) =
                        portico_protocol::parse_server_frame(&b)
                {
                    assert_eq!(bytes, &d.segment(id).unwrap()[..]);
                    break;
                }
            }
        };
        tokio::time::timeout(std::time::Duration::from_secs(20), first_segment)
            .await
            .expect("no segment pushed through nginx within 20 s");
    });

    // A walk through nginx carries on when a replica is killed a third of the way in.
    let graph = portico_data::Database::open(&db)
        .unwrap()
        .cell_graph()
        .unwrap()
        .unwrap();
    let path = generate(&graph, PathKind::Tour, 2, 3, 1.5, 1.5).unwrap();
    let cfg = WalkConfig {
        server: base.clone(),
        token: None,
        path,
        budget_s: 0.02,
        cache_bytes: 32 << 20,
        size: (64, 48),
        elision: Algorithm::Optimize,
        policy: Policy::default(),
        out: None,
        png_every: 0,
        max_frames: Some(90),
        pace: true,
        fovy: 1.0,
        max_speed: 2.0,
        max_turn: 2.0,
        transport: portico_native::stream::Transport::Pull,
        paged: true,
    };
    let mut killed = None;
    let s = walk(&cfg, &mut |done, _| {
        if done == 30 && killed.is_none() {
            let (mut p, addr) = replicas.remove(0);
            let _ = p.0.kill();
            let _ = p.0.wait();
            killed = Some(addr);
        }
    })
    .unwrap();
    assert!(killed.is_some());
    assert_eq!(s.frames, 90);
    assert_eq!(s.io_failures, 0, "nginx retried on the surviving replicas");
    assert!(s.segments_read > 0 && s.drawn_triangles.max > 0.0);
    eprintln!(
        "nginx fan-out: {} frames, {} segments ({} bytes) read through nginx, fetch latency p50 {:.1} ms p99 {:.1} ms, replica {} killed at frame 30",
        s.frames,
        s.segments_read,
        s.bytes_read,
        s.fetch_latency_s.p50 * 1e3,
        s.fetch_latency_s.p99 * 1e3,
        killed.unwrap_or_default()
    );

    // A short load test through the proxy, on the two replicas left.
    let out = dir.path().join("loadtest");
    let policy = Policy::default();
    let lt = LoadtestConfig {
        server: base.clone(),
        token: None,
        clients: 4,
        path: cfg.path.clone(),
        policies: vec![(policy_spec(&policy), policy)],
        transports: vec![portico_lab::loadtest::Transport::Pull],
        baselines: false,
        link: Link::parse("rtt=10ms,rate=100mbit").unwrap(),
        cache_bytes: 16 << 20,
        budget_s: 0.02,
        max_frames: Some(40),
        out: out.clone(),
    };
    let summary = run_loadtest(&lt, &mut |_, _| {}).unwrap();
    let p = &summary.policies[0];
    assert_eq!(summary.clients, 4);
    assert!(p.bytes_fetched > 0, "{p:?}");
    assert!(out.join("summary.json").exists());
    eprintln!(
        "nginx loadtest: 4 clients x 40 frames, {:.2} LODs skipped/frame, {:.1} MB fetched, request->resident p50 {:.1} ms p99 {:.1} ms",
        p.lods_skipped_mean,
        p.bytes_fetched as f64 / 1e6,
        p.latency_p50_s * 1e3,
        p.latency_p99_s * 1e3
    );
}

/// A rebuild behind the documented nginx: segment URLs name their database, so after the
/// rebuild and SIGHUP no cache serves the old bytes under the new names, and a walk that was
/// reading the old database stops cleanly (no checksum failures, no refetch loop). With
/// `--token`, nginx's cache never answers a request that lacks the token.
#[test]
fn a_rebuild_and_a_token_behind_nginx_serve_no_stale_or_unauthorised_byte() {
    let Some(nginx) = nginx_binary() else {
        assert!(
            std::env::var_os("CI").is_none(),
            "nginx is not installed but CI is set"
        );
        eprintln!("skipping: nginx is not installed (apt-get install nginx-light)");
        return;
    };
    const TOKEN: &str = "s3cret";
    let dir = tempfile::tempdir().unwrap();
    let db = build_tiny(dir.path());
    let replicas: Vec<_> = (0..2)
        .map(|_| replica_with(&db, &["--token", TOKEN]))
        .collect();
    let addrs: Vec<String> = replicas.iter().map(|(_, a, _)| a.clone()).collect();
    let (_nginx, base) = start_nginx(&nginx, dir.path(), &addrs);
    let rt = tokio::runtime::Runtime::new().unwrap();
    let http = reqwest::Client::new();
    let manifest_id = |http: &reqwest::Client| {
        let m: serde_json::Value = rt
            .block_on(async {
                http.get(format!("{base}/v1/manifest"))
                    .bearer_auth(TOKEN)
                    .send()
                    .await
                    .unwrap()
                    .json()
                    .await
            })
            .unwrap();
        m["database_id"].as_str().unwrap().to_string()
    };
    let old_id = manifest_id(&http);
    let seg_url = |id: &str| format!("{base}/v1/db/{id}/segments/1");
    rt.block_on(async {
        for expect in ["MISS", "HIT"] {
            let r = http
                .get(seg_url(&old_id))
                .bearer_auth(TOKEN)
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), 200);
            assert_eq!(r.headers()["x-cache-status"], expect);
        }
        // The cached answer is not served without the token, nor with a query token.
        assert_eq!(
            http.get(seg_url(&old_id)).send().await.unwrap().status(),
            401
        );
        let q = format!("{}?token={TOKEN}", seg_url(&old_id));
        assert_eq!(http.get(&q).send().await.unwrap().status(), 401);
    });

    // A walk reads through nginx while the file is rebuilt and the replicas reload.
    let graph = portico_data::Database::open(&db)
        .unwrap()
        .cell_graph()
        .unwrap()
        .unwrap();
    let cfg = WalkConfig {
        server: base.clone(),
        token: Some(TOKEN.into()),
        path: generate(&graph, PathKind::Tour, 3, 3, 1.5, 1.5).unwrap(),
        budget_s: 0.02,
        cache_bytes: 32 << 20,
        size: (64, 48),
        elision: Algorithm::Optimize,
        policy: Policy::default(),
        out: None,
        png_every: 0,
        // Long enough after the rebuild for the pull engine, which asks again only once the
        // observer has moved on, to ask through a connection that reaches the new file.
        max_frames: Some(300),
        pace: true,
        fovy: 1.0,
        max_speed: 2.0,
        max_turn: 2.0,
        transport: portico_native::stream::Transport::Pull,
        paged: true,
    };
    let mut rebuilt = false;
    let s = walk(&cfg, &mut |done, _| {
        if done == 20 && !rebuilt {
            rebuilt = true;
            let glb = dir.path().join("other.glb");
            assert!(
                portico(&[
                    "generate",
                    "--preset",
                    "tiny",
                    "--seed",
                    "9",
                    "-o",
                    glb.to_str().unwrap()
                ])
                .status()
                .unwrap()
                .success()
            );
            assert!(
                portico(&["build", glb.to_str().unwrap(), "-o", db.to_str().unwrap()])
                    .status()
                    .unwrap()
                    .success()
            );
            for (p, _, log) in &replicas {
                assert!(
                    Command::new("kill")
                        .args(["-HUP", &p.0.id().to_string()])
                        .status()
                        .unwrap()
                        .success()
                );
                // The replica says when it serves the new file (bounded wait).
                let reloaded = std::iter::from_fn(|| {
                    log.recv_timeout(std::time::Duration::from_secs(10)).ok()
                })
                .find(|l| l.starts_with("serving "));
                assert!(reloaded.is_some(), "no reload line");
            }
        }
    })
    .unwrap();
    assert!(rebuilt);
    assert!(
        s.database_changed,
        "the walk did not notice the new database"
    );
    assert!(
        s.io_failures <= 3,
        "{} IO failures: a refetch loop",
        s.io_failures
    );

    // The new database under its own names: fresh bytes, never the cached old ones.
    let new_id = manifest_id(&http);
    assert_ne!(new_id, old_id);
    let fresh = portico_data::Database::open(&db)
        .unwrap()
        .segment(1)
        .unwrap();
    rt.block_on(async {
        let r = http
            .get(seg_url(&new_id))
            .bearer_auth(TOKEN)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 200);
        assert_eq!(r.bytes().await.unwrap(), fresh);
        // The old name is gone at the replicas (410), whatever an old cache entry holds.
        let direct = format!("http://{}/v1/db/{old_id}/segments/2", addrs[0]);
        assert_eq!(
            http.get(&direct)
                .bearer_auth(TOKEN)
                .send()
                .await
                .unwrap()
                .status(),
            410
        );
    });
    // And a new walk reads the new database without a failure.
    let s = walk(
        &WalkConfig {
            max_frames: Some(30),
            ..cfg
        },
        &mut |_, _| {},
    )
    .unwrap();
    assert_eq!(s.io_failures, 0);
    assert!(!s.database_changed && s.segments_read > 0);
    // No token in nginx's access log, whatever the query strings held.
    let log = std::fs::read_to_string(dir.path().join("nginx/access.log")).unwrap();
    assert!(!log.contains(TOKEN), "a token reached the access log");
}
