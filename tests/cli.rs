//! End-to-end tests of the `portico` command line on the `tiny` preset: generate → build →
//! inspect → verify → cull, and bad input giving one-line errors and no output file.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{ok, portico, s};

/// Runs a command that must fail; returns its stderr (checked to be one `error:` line).
fn fails(args: &[&str]) -> String {
    let out = portico(args);
    assert!(!out.status.success(), "portico {args:?} should fail");
    let err = String::from_utf8_lossy(&out.stderr).trim().to_string();
    assert!(err.starts_with("error: "), "{err}");
    assert_eq!(err.lines().count(), 1, "not one line: {err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

fn generated(dir: &Path) -> PathBuf {
    let glb = dir.join("tiny.glb");
    let _ = ok(&["generate", "--preset", "tiny", "--seed", "5", "-o", s(&glb)]);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&glb).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o644, "other tools and users can read the model");
    }
    glb
}

#[test]
fn generate_build_inspect_verify_cull() {
    let dir = tempfile::tempdir().unwrap();
    let glb = generated(dir.path());
    let db = dir.path().join("tiny.portico");
    let _ = ok(&["build", s(&glb), "-o", s(&db)]);
    // Geometry is compressed by default, and stored plain with --no-compress.
    let compressed = |db: &std::path::Path| {
        let db = portico_data::Database::open(db).unwrap();
        db.segments()
            .iter()
            .filter(|e| portico_data::codec::is_compressed(&db.segment(e.id).unwrap()))
            .count()
    };
    assert!(compressed(&db) > 0, "build compresses by default");
    let plain = dir.path().join("plain.portico");
    let _ = ok(&["build", s(&glb), "-o", s(&plain), "--no-compress"]);
    assert_eq!(compressed(&plain), 0, "--no-compress stores geometry plain");
    let stats: serde_json::Value =
        serde_json::from_str(&ok(&["inspect", s(&db), "--json", "--verify"])).unwrap();
    for key in [
        "objects",
        "instances",
        "triangles_highest",
        "triangles_all_lods",
        "segments",
        "file_bytes",
        "cells",
        "portals",
    ] {
        assert!(
            stats[key].as_u64().unwrap_or(0) > 0,
            "{key} missing or zero: {stats}"
        );
    }
    assert!(stats["triangles_all_lods"].as_u64() > stats["triangles_highest"].as_u64());
    assert_eq!(
        stats["file_bytes"].as_u64(),
        Some(std::fs::metadata(&db).unwrap().len())
    );
    let table = stats["lod_table"].as_array().unwrap();
    assert_eq!(table.last().unwrap()["level"], "all");
    let verify: serde_json::Value =
        serde_json::from_str(&ok(&["verify", s(&db), "--rays", "5000", "--json"])).unwrap();
    assert_eq!(verify["false_negatives"], 0, "{verify}");
    let cull: serde_json::Value =
        serde_json::from_str(&ok(&["cull", s(&db), "--views", "50", "--json"])).unwrap();
    let rows = cull.as_array().unwrap();
    let objects = |i: usize| rows[i]["objects"][0].as_f64().unwrap();
    assert!(
        objects(4) <= objects(2) && objects(2) <= objects(0),
        "{cull}"
    );

    // Flattened: same instances, more bytes, every instance has its own geometry.
    let flat = dir.path().join("flat.portico");
    let _ = ok(&[
        "build",
        s(&glb),
        "-o",
        s(&flat),
        "--flatten",
        "--threads",
        "1",
    ]);
    let fstats: serde_json::Value =
        serde_json::from_str(&ok(&["inspect", s(&flat), "--json"])).unwrap();
    assert_eq!(fstats["instances"], stats["instances"]);
    assert_eq!(fstats["flattened"], true);
    assert!(fstats["file_bytes"].as_u64() > stats["file_bytes"].as_u64());
    assert_eq!(fstats["triangles_highest"], stats["triangles_highest"]);
}

#[test]
fn generate_is_deterministic() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    assert_eq!(
        std::fs::read(generated(a.path())).unwrap(),
        std::fs::read(generated(b.path())).unwrap()
    );
}

/// A build is a function of its input: twice, with one thread and with four, the same bytes
/// (LODs, cells, stab lists, impostor atlases, the database id derived from them).
#[test]
fn build_is_deterministic_whatever_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let glb = generated(dir.path());
    let mut files = Vec::new();
    for (name, threads) in [("a", "1"), ("b", "4"), ("c", "1")] {
        let out = dir.path().join(format!("{name}.portico"));
        ok(&["build", s(&glb), "-o", s(&out), "--threads", threads]);
        files.push(std::fs::read(&out).unwrap());
    }
    assert!(files[0] == files[2], "two builds with one thread differ");
    assert!(files[0] == files[1], "one thread and four differ");
}

#[test]
fn bad_input_is_one_clear_line_and_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let glb = generated(dir.path());
    let good = dir.path().join("good.portico");
    let _ = ok(&["build", s(&glb), "-o", s(&good), "--no-cells"]);
    let bytes = std::fs::read(&good).unwrap();

    let missing = dir.path().join("missing.portico");
    assert!(fails(&["inspect", s(&missing)]).contains("missing.portico"));

    let truncated = dir.path().join("truncated.portico");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    assert!(fails(&["inspect", s(&truncated)]).contains("truncated"));

    let corrupt = dir.path().join("corrupt.portico");
    let mut c = bytes.clone();
    let at = c.len() - 20; // inside the segment index
    c[at] ^= 0xff;
    std::fs::write(&corrupt, &c).unwrap();
    assert!(fails(&["inspect", s(&corrupt)]).contains("corrupt"));

    assert!(fails(&["inspect", s(&glb)]).contains("not a Portico display database"));
    assert!(fails(&["verify", s(&good)]).contains("without cells"));

    // Broken models: the build fails and writes no output.
    let broken_obj = dir.path().join("broken.obj");
    std::fs::write(&broken_obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n").unwrap();
    let broken_gltf = dir.path().join("missing_buffer.gltf");
    std::fs::write(
        &broken_gltf,
        r#"{"asset":{"version":"2.0"},"buffers":[{"uri":"nowhere.bin","byteLength":36}],
            "bufferViews":[{"buffer":0,"byteLength":36}],
            "accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}],
            "meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
            "nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}],"scene":0}"#,
    )
    .unwrap();
    for model in [&broken_obj, &broken_gltf] {
        let out = dir.path().join("out.portico");
        let err = fails(&["build", s(model), "-o", s(&out)]);
        assert!(
            err.contains(model.file_name().unwrap().to_str().unwrap()),
            "{err}"
        );
        assert!(!out.exists(), "{} left an output file", model.display());
    }
    // A build that fails at the very end, after the whole database was written: the output
    // path is a directory, so the rename into place fails. The directory and what is in it
    // stay, and the temporary file written beside it is gone.
    let taken = dir.path().join("taken.portico");
    std::fs::create_dir(&taken).unwrap();
    std::fs::write(taken.join("keep"), "mine").unwrap();
    let out = portico(&[
        "build",
        s(&glb),
        "-o",
        s(&taken),
        "--no-cells",
        "--no-hierarchy",
    ]);
    assert!(!out.status.success());
    // (The build's progress lines come first: the failure is at the end.)
    let err = String::from_utf8_lossy(&out.stderr);
    let last = err.trim().lines().last().unwrap_or_default();
    assert!(
        last.starts_with("error: ") && last.contains("taken.portico"),
        "{err}"
    );
    assert_eq!(err.lines().filter(|l| l.starts_with("error")).count(), 1);
    assert_eq!(std::fs::read_to_string(taken.join("keep")).unwrap(), "mine");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

/// `GET /healthz`-style plain HTTP/1.1 request; the body of a 200 answer.
fn http_get(addr: &str, path: &str) -> Option<String> {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).ok()?;
    let req = format!(
        "GET {path} HTTP/1.1\r\nHost: x\r\nAccept: application/json\r\nConnection: close\r\n\r\n"
    );
    s.write_all(req.as_bytes()).ok()?;
    let mut out = String::new();
    s.read_to_string(&mut out).ok()?;
    out.starts_with("HTTP/1.1 200")
        .then(|| out.split("\r\n\r\n").nth(1).unwrap_or("").to_string())
}

fn database_id(addr: &str) -> Option<String> {
    let body = http_get(addr, "/v1/manifest")?;
    let v: serde_json::Value = serde_json::from_str(&body).ok()?;
    v["database_id"].as_str().map(str::to_string)
}

/// A server's stderr, line by line, read on a thread so that a silent server fails the test
/// (see [`next_line`]) instead of hanging it.
fn stderr_lines(child: &mut std::process::Child) -> std::sync::mpsc::Receiver<String> {
    use std::io::BufRead;
    let stderr = child.stderr.take().expect("piped stderr");
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stderr)
            .lines()
            .map_while(Result::ok)
        {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

/// The server's next log line, within 30 s.
fn next_line(lines: &std::sync::mpsc::Receiver<String>) -> String {
    lines
        .recv_timeout(std::time::Duration::from_secs(30))
        .expect("the server said nothing for 30 s (or exited)")
}

#[test]
fn serve_picks_up_a_rebuilt_file_on_sighup_and_stops_on_sigterm() {
    let dir = tempfile::tempdir().unwrap();
    let glb = generated(dir.path());
    let db = dir.path().join("served.portico");
    ok(&["build", s(&glb), "-o", s(&db)]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_portico"))
        .args(["serve", s(&db), "--listen", "127.0.0.1:0"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let lines = stderr_lines(&mut child);
    let first = next_line(&lines);
    // Then where the browser viewer is (or how to build it).
    let viewer = next_line(&lines);
    assert!(viewer.contains("browser viewer"), "{viewer}");
    let addr = first.rsplit("http://").next().unwrap().trim().to_string();
    let before = database_id(&addr).expect("manifest");
    // A damaged file renamed over the served one: the reload fails, says so in one line, and
    // the server goes on serving the file it has.
    let bad = dir.path().join("bad.tmp");
    let mut garbage = std::fs::read(&db).unwrap();
    garbage.truncate(garbage.len() / 2);
    std::fs::write(&bad, garbage).unwrap();
    std::fs::rename(&bad, &db).unwrap();
    let hup = Command::new("kill")
        .args(["-HUP", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(hup.success());
    let failed = next_line(&lines);
    assert!(
        failed.starts_with("reload failed, still serving the previous file: ")
            && failed.contains("served.portico"),
        "{failed}"
    );
    assert_eq!(
        database_id(&addr).as_deref(),
        Some(before.as_str()),
        "a failed reload keeps the old map"
    );
    // A different model renamed over the served file, as a rebuild does.
    let other = dir.path().join("other.glb");
    ok(&[
        "generate",
        "--preset",
        "tiny",
        "--seed",
        "9",
        "-o",
        s(&other),
    ]);
    ok(&["build", s(&other), "-o", s(&db)]);
    assert_eq!(
        database_id(&addr).as_deref(),
        Some(before.as_str()),
        "still the old map"
    );
    let hup = Command::new("kill")
        .args(["-HUP", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(hup.success());
    // The server says when it serves the new file.
    let reloaded = next_line(&lines);
    assert!(reloaded.starts_with("serving "), "{reloaded}");
    let after = database_id(&addr).expect("manifest after reload");
    assert_ne!(before, after, "the rebuilt file is served");
    // SIGTERM drains and exits cleanly (bounded wait: 10 s).
    let term = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(term.success());
    let mut status = None;
    for _ in 0..200 {
        status = child.try_wait().unwrap();
        if status.is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let Some(status) = status else {
        let _ = child.kill();
        panic!("the server did not stop on SIGTERM");
    };
    assert!(status.success(), "{status}");
    // The process has exited: the reader thread sees the end of stderr and hangs up.
    let rest: Vec<String> = lines.iter().collect();
    assert_eq!(rest.last().map(String::as_str), Some("stopped"), "{rest:?}");
}

/// Fault 7 of the server hardening: a SIGHUP while a client reads slowly used to stall every new
/// connection for the whole drain (10 s), and the log claimed connections were closed that were
/// not. Now new connections get the rebuilt file at once, the slow one is closed after the drain
/// (`--drain-secs`), and the log says exactly that. SIGTERM then stops within the drain too.
#[test]
fn sighup_with_a_slow_reader_stalls_nobody_and_says_what_it_did() {
    use std::io::{Read, Write};
    let dir = tempfile::tempdir().unwrap();
    let glb = generated(dir.path());
    let db = dir.path().join("served.portico");
    ok(&["build", s(&glb), "-o", s(&db), "--no-hierarchy"]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_portico"))
        .args([
            "serve",
            s(&db),
            "--listen",
            "127.0.0.1:0",
            "--drain-secs",
            "2",
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let lines = stderr_lines(&mut child);
    let first = next_line(&lines);
    // Then where the browser viewer is (or how to build it).
    let viewer = next_line(&lines);
    assert!(viewer.contains("browser viewer"), "{viewer}");
    let addr = first.rsplit("http://").next().unwrap().trim().to_string();
    let before = database_id(&addr).expect("manifest");
    // A slow reader: a batch of the biggest segment a thousand times over, never read.
    let biggest = portico_data::Database::open(&db)
        .unwrap()
        .segments()
        .iter()
        .max_by_key(|e| e.length)
        .unwrap()
        .id;
    let ids = vec![biggest.to_string(); 1000].join(",");
    let sock = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None).unwrap();
    sock.set_recv_buffer_size(4096).unwrap();
    sock.connect(&addr.parse::<std::net::SocketAddr>().unwrap().into())
        .unwrap();
    let mut slow: std::net::TcpStream = sock.into();
    write!(slow, "GET /v1/batch?ids={ids} HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
    std::thread::sleep(std::time::Duration::from_millis(300));
    // Rebuild and reload: a new connection is answered at once, by the new file.
    let other = dir.path().join("other.glb");
    ok(&[
        "generate",
        "--preset",
        "tiny",
        "--seed",
        "9",
        "-o",
        s(&other),
    ]);
    ok(&["build", s(&other), "-o", s(&db), "--no-hierarchy"]);
    assert!(
        Command::new("kill")
            .args(["-HUP", &child.id().to_string()])
            .status()
            .unwrap()
            .success()
    );
    let reloaded = next_line(&lines);
    assert!(reloaded.starts_with("serving "), "{reloaded}");
    let t0 = std::time::Instant::now();
    let after = database_id(&addr).expect("manifest after the reload");
    let waited = t0.elapsed();
    assert_ne!(before, after);
    assert!(
        waited < std::time::Duration::from_millis(100),
        "a new connection waited {waited:?}"
    );
    // After the drain the log tells the truth: the slow reader was closed, and it was.
    let drained = next_line(&lines);
    assert!(
        drained.contains("1 still busy after 2 s were closed"),
        "{drained}"
    );
    slow.set_read_timeout(Some(std::time::Duration::from_secs(5)))
        .unwrap();
    let mut sink = vec![0u8; 1 << 20];
    let closed = loop {
        match slow.read(&mut sink) {
            Ok(0) => break true,
            Ok(_) => continue,
            Err(e) => break e.kind() == std::io::ErrorKind::ConnectionReset,
        }
    };
    assert!(closed, "the slow reader's connection was not closed");
    // SIGTERM: stops within the drain.
    let t0 = std::time::Instant::now();
    assert!(
        Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status()
            .unwrap()
            .success()
    );
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        assert!(
            t0.elapsed() < std::time::Duration::from_secs(10),
            "no stop within 10 s"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    assert!(status.success());
}
