//! The measuring commands as a user runs them: `portico loadtest` (policies against both
//! baselines, and `--stress`) and `portico bench` against a `portico serve` process, on the tiny
//! building, each writing what its help promises.

use std::io::BufRead;
use std::path::Path;
use std::process::{Child, Command, Stdio};

mod common;
use common::{ok, s};

/// `portico serve` on a free port; the child (killed on drop) and its base URL.
struct Server(Child, String);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn serve(db: &Path, extra: &[&str]) -> Server {
    let mut child = Command::new(env!("CARGO_BIN_EXE_portico"))
        .args(["serve", s(db), "--listen", "127.0.0.1:0"])
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("serve");
    let mut lines = std::io::BufReader::new(child.stderr.take().expect("stderr")).lines();
    let first = lines.next().expect("a line").expect("utf-8");
    let url = format!(
        "http://{}",
        first.rsplit("http://").next().unwrap_or("").trim()
    );
    // Keep draining the log so the server never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines.map_while(Result::ok) {});
    Server(child, url)
}

fn tiny_database(dir: &Path) -> std::path::PathBuf {
    let glb = dir.join("tiny.glb");
    let db = dir.join("tiny.portico");
    ok(&["generate", "--preset", "tiny", "--seed", "5", "-o", s(&glb)]);
    ok(&["build", s(&glb), "-o", s(&db)]);
    db
}

fn json(path: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).expect("JSON")
}

#[test]
fn loadtest_stress_and_bench_run_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let db = tiny_database(dir.path());
    let server = serve(&db, &[]);

    let lt = dir.path().join("lt");
    let said = ok(&[
        "loadtest",
        "--server",
        &server.1,
        "--clients",
        "2",
        "--path-kind",
        "tour",
        "--max-frames",
        "30",
        "--policy",
        "depth=8,gran=object,range=frustum,look=any",
        "--link",
        "rtt=20ms,rate=50mbit",
        "-o",
        s(&lt),
    ]);
    let summary = json(&lt.join("summary.json"));
    let names: Vec<&str> = summary["policies"]
        .as_array()
        .expect("policies")
        .iter()
        .filter_map(|p| p["name"].as_str())
        .collect();
    assert_eq!(
        names,
        [
            "depth=8,gran=object,range=frustum,look=any",
            "depth=8,gran=object,range=frustum,look=any+push",
            "demand",
            "oracle"
        ],
        "by default each policy runs over both transports, pull then push"
    );
    assert_eq!(summary["clients"], 2);
    assert!(lt.join("report.md").is_file());
    assert!(
        said.contains("met: ") || said.contains("NOT met: "),
        "{said}"
    );

    let st = dir.path().join("stress");
    let said = ok(&[
        "loadtest",
        "--server",
        &server.1,
        "--path-kind",
        "tour",
        "--stress",
        "1,4",
        "--stress-seconds",
        "0.5",
        "-o",
        s(&st),
    ]);
    let stress = json(&st.join("stress.json"));
    let levels = stress["levels"].as_array().expect("levels");
    assert_eq!(levels.len(), 2, "{said}");
    for (l, clients) in levels.iter().zip([1, 4]) {
        assert_eq!(l["clients"], clients);
        assert!(l["requests"].as_u64().is_some_and(|n| n > 0), "{l}");
        assert_eq!(l["errors"], 0, "{l}");
    }

    // The push transport under a crowd, measured from the server's /metrics, on a server that
    // shares answers whatever its load (by default a few clients get their own): under the
    // range lookahead one place's list serves every observer in it, so four walkers compute
    // far fewer lists than they send updates (each session changes lists only when it changes
    // place), and the server's CPU per update is measured, not zero.
    let sharing = serve(&db, &["--exact-share", "0"]);
    let ss = dir.path().join("stream-stress");
    let said = ok(&[
        "loadtest",
        "--server",
        &sharing.1,
        "--path-kind",
        "tour",
        "--policy",
        "depth=8,gran=object,range=frustum,look=any",
        "--stress",
        "1,4",
        "--stream",
        "--stress-seconds",
        "2",
        "--link",
        "rtt=0ms,rate=1mbit",
        "-o",
        s(&ss),
    ]);
    let stress = json(&ss.join("stress.json"));
    assert_eq!(stress["transport"], "stream");
    let levels = stress["levels"].as_array().expect("levels");
    assert_eq!(levels.len(), 2, "{said}");
    for (l, clients) in levels.iter().zip([1u64, 4]) {
        assert_eq!(l["connected"], clients, "{l}");
        let updates = l["updates"].as_u64().unwrap();
        // 20 updates per second per client for 2 s; at least half of them on a loaded machine.
        assert!(updates >= 20 * clients, "{l}");
        let taken = l["lists_taken"].as_u64().unwrap();
        assert!(taken < updates / 2, "{l}");
        // A computation started in the window may end after it.
        assert!(
            l["lists_computed"].as_u64().unwrap() <= taken + clients,
            "{l}"
        );
        assert!(l["server_cpu_s"].as_f64().unwrap() > 0.0, "{l}");
        assert!(l["ping_s"]["max"].as_f64().unwrap() > 0.0, "{l}");
    }
    assert!(ss.join("scaling.png").is_file());
    assert!(
        levels.iter().all(|l| l["shared_answers"] == true),
        "{stress}"
    );
    // Drawn against an earlier run; an HTTP stress result is refused as a baseline.
    let again = dir.path().join("stream-stress-2");
    let base = [
        "loadtest",
        "--server",
        &server.1,
        "--path-kind",
        "tour",
        "--stress",
        "2",
    ];
    let tail = [
        "--stream",
        "--stress-seconds",
        "0.5",
        "-o",
        s(&again),
        "--baseline",
    ];
    ok(&[&base[..], &tail[..], &[s(&ss)]].concat());
    assert!(again.join("scaling.png").is_file());
    // The default policy, the predicted lookahead, depends on each observer's motion: every
    // list a session takes was computed for it alone (one per session may have started before
    // the window), and the report counts them.
    let own = json(&again.join("stress.json"));
    let level = &own["levels"][0];
    let (mine, computed, taken) = (
        level["own_lists"].as_u64().unwrap(),
        level["lists_computed"].as_u64().unwrap(),
        level["lists_taken"].as_u64().unwrap(),
    );
    assert!(taken > 0 && mine + 2 >= taken && computed >= mine, "{own}");
    // Refused before any level runs: nothing is written.
    let never = dir.path().join("never");
    let tail = ["--stream", "-o", s(&never), "--baseline", s(&st)];
    let refused = common::portico(&[&base[..], &tail[..]].concat());
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        err.contains("--baseline") && err.contains("not a stream stress run"),
        "{err}"
    );
    assert!(!never.join("stress.json").exists());
    // No server: one line that says so, for either transport, and nothing written.
    let tour = dir.path().join("tour.json");
    ok(&["path", "--db", s(&db), "--kind", "tour", "-o", s(&tour)]);
    for stream in [false, true] {
        let mut args = vec![
            "loadtest",
            "--server",
            "http://127.0.0.1:1",
            "--path",
            s(&tour),
        ];
        args.extend(["--stress", "1", "--stress-seconds", "0.2", "-o", s(&never)]);
        if stream {
            args.push("--stream");
        }
        let out = common::portico(&args);
        assert!(
            !out.status.success(),
            "stream {stream}: succeeded without a server"
        );
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("no server answers at http://127.0.0.1:1/healthz"),
            "{err}"
        );
        assert!(!never.join("stress.json").exists());
    }

    let b = dir.path().join("bench");
    ok(&[
        "bench",
        "--db",
        s(&db),
        "--path-kind",
        "tour",
        "--max-frames",
        "12",
        "--size",
        "160x120",
        "--algorithms",
        "regular,optimize",
        "-o",
        s(&b),
    ]);
    let bench = json(&b.join("summary.json"));
    let runs = bench["runs"].as_array().expect("runs");
    assert_eq!(runs.len(), 2, "{bench}");
    assert!(b.join("report.md").is_file() && b.join("frames.csv").is_file());
}
