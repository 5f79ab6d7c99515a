//! What a newcomer meets first: every command's help lists the values it accepts and spells the
//! output flag the same way; a model is served in one command, built once and again only when it
//! changes; the mistakes of a first hour (inspecting a model instead of a database, walking with
//! no server running) give one line that says what to do; the demo's report judges every figure
//! against its target.

use std::path::Path;
use std::process::{Command, Output};

fn portico(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_portico"))
        .args(args)
        .output()
        .expect("run portico")
}

fn help(command: &str) -> String {
    let out = portico(&[command, "--help"]);
    assert!(out.status.success(), "portico {command} --help failed");
    String::from_utf8(out.stdout).expect("utf-8")
}

/// Runs a command that must fail; returns its stderr (checked to be one `error:` line).
fn fails(args: &[&str]) -> String {
    let out = portico(args);
    assert!(!out.status.success(), "portico {args:?} should fail");
    let err = String::from_utf8_lossy(&out.stderr).trim().to_string();
    let last = err.lines().last().unwrap_or_default().to_string();
    assert!(last.starts_with("error: "), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(
        err.lines().filter(|l| l.starts_with("error")).count(),
        1,
        "not one error line: {err}"
    );
    last
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

#[test]
fn every_command_lists_the_values_it_accepts() {
    let presets = ["tiny", "small", "soda", "mega"];
    let paths = ["tour", "spin", "revisit", "orbit", "flythrough"];
    let elision = ["none", "static", "feedback", "optimize", "impostors"];
    let runs = [
        "regular",
        "none",
        "static",
        "feedback",
        "optimize",
        "impostors",
        "coarsest",
    ];
    let policy = [
        "depth=", "gran=", "object", "cell", "range=", "look=", "frustum", "imp=",
    ];
    let sweeps = ["reduced", "full", "depth", "gran", "cull"];
    let cases: [(&str, Vec<&str>); 7] = [
        ("generate", presets.to_vec()),
        ("demo", presets.to_vec()),
        ("path", paths.to_vec()),
        ("walk", [&paths[..], &elision[..], &policy[..]].concat()),
        ("bench", [&paths[..], &runs[..]].concat()),
        ("loadtest", [&paths[..], &policy[..], &sweeps[..]].concat()),
        ("inspect", vec!["--verify", "--json"]),
    ];
    for (command, values) in cases {
        let text = help(command);
        for v in values {
            assert!(
                text.contains(v),
                "`portico {command} --help` does not list `{v}`"
            );
        }
    }
}

#[test]
fn every_command_that_writes_spells_its_output_flag_the_same() {
    for command in [
        "generate", "build", "path", "walk", "loadtest", "bench", "demo",
    ] {
        let text = help(command);
        assert!(
            text.contains("-o, --out"),
            "`portico {command} --help` has no `-o, --out`"
        );
        assert!(
            text.contains("aliases: --output") || text.contains("alias: --output"),
            "`portico {command} --help` does not accept `--output`"
        );
    }
}

#[test]
fn defaults_agree_across_commands() {
    for command in ["walk", "bench", "demo"] {
        assert_eq!(
            default_of(&help(command), "--size").as_deref(),
            Some("640x480"),
            "`portico {command}` has another default image size"
        );
    }
    for command in ["path", "walk", "bench", "loadtest", "demo"] {
        assert_eq!(
            default_of(&help(command), "--legs").as_deref(),
            Some("4"),
            "`portico {command}` has another default leg count"
        );
    }
}

/// The `[default: …]` of one option in a command's `--help`: the first one between the option's
/// line and the next option's.
fn default_of(help: &str, flag: &str) -> Option<String> {
    let mut lines = help
        .lines()
        .skip_while(|l| !l.trim_start().split([',', ' ']).any(|w| w == flag));
    lines.next()?;
    lines
        .take_while(|l| !l.trim_start().starts_with('-'))
        .find_map(|l| {
            let d = l.trim().strip_prefix("[default: ")?;
            Some(d.trim_end_matches(']').to_string())
        })
}

#[test]
fn a_model_where_a_database_belongs_names_the_build_command() {
    let dir = tempfile::tempdir().expect("tempdir");
    let glb = dir.path().join("house.glb");
    let mut bytes = b"glTF".to_vec();
    bytes.extend_from_slice(&2u32.to_le_bytes());
    bytes.extend_from_slice(&[0; 64]);
    std::fs::write(&glb, bytes).expect("write");
    let err = fails(&["inspect", s(&glb)]);
    assert!(err.contains("house.glb"), "{err}");
    assert!(err.contains("GLB model"), "{err}");
    assert!(err.contains("portico build"), "{err}");
    // Served, a model is built first: a broken one is one error naming it, and no server.
    let err = fails(&["serve", s(&glb), "--listen", "127.0.0.1:0"]);
    assert!(err.contains("house.glb"), "{err}");
}

/// Runs `portico serve MODEL` until it says where to open the viewer (or that it has none);
/// returns what it said, then stops it.
fn serve_until_listening(model: &Path) -> String {
    use std::io::BufRead;
    let mut child = Command::new(env!("CARGO_BIN_EXE_portico"))
        .args(["serve", s(model), "--listen", "127.0.0.1:0"])
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("run portico serve");
    let mut said = String::new();
    let mut lines = std::io::BufReader::new(child.stderr.take().unwrap()).lines();
    for line in lines.by_ref() {
        let line = line.expect("stderr");
        said.push_str(&line);
        said.push('\n');
        if line.contains("browser viewer") {
            break;
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    said
}

#[test]
fn serving_a_model_builds_it_once_and_again_when_it_changes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let glb = dir.path().join("house.glb");
    let tiny = |seed| {
        let params = portico_generator::Params {
            preset: portico_generator::Preset::Tiny,
            seed,
            floors: None,
        };
        portico_generator::generate(&params, &mut |_| {})
            .unwrap()
            .glb
    };
    std::fs::write(&glb, tiny(1)).unwrap();
    let cached = dir.path().join(".portico/house.glb.portico");
    let first = serve_until_listening(&glb);
    assert!(
        first.contains("no cached build; building it into"),
        "{first}"
    );
    assert!(first.contains("serving"), "{first}");
    assert!(first.contains("http://127.0.0.1:"), "{first}");
    assert!(cached.is_file(), "{first}");
    let db = portico_data::Database::open(&cached).unwrap();
    assert!(
        db.segments()
            .iter()
            .any(|e| portico_data::codec::is_compressed(&db.segment(e.id).unwrap())),
        "built compressed, as `portico build` does by default"
    );
    let built = std::fs::metadata(&cached).unwrap().modified().unwrap();
    // Unchanged: served from the cache, not built again.
    let second = serve_until_listening(&glb);
    assert!(second.contains("unchanged, serving its build"), "{second}");
    assert!(!second.contains("building"), "{second}");
    assert_eq!(
        std::fs::metadata(&cached).unwrap().modified().unwrap(),
        built
    );
    // Another building in the same file: built again.
    std::fs::write(&glb, tiny(2)).unwrap();
    let third = serve_until_listening(&glb);
    assert!(
        third.contains("the model or a file beside it changed since the cached build; building it"),
        "{third}"
    );
}

#[test]
fn walking_with_no_server_says_so_in_one_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Port 9 (discard) is closed on test machines: the connection is refused at once.
    let err = fails(&[
        "walk",
        "--server",
        "http://127.0.0.1:9",
        "--max-frames",
        "1",
        "-o",
        s(&dir.path().join("w")),
    ]);
    assert!(err.contains("cannot connect"), "{err}");
    assert!(err.contains("portico serve"), "{err}");
    assert!(err.len() < 300, "{err}");
}

#[test]
fn the_demo_judges_every_figure_against_its_target() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("demo");
    let run = portico(&[
        "demo",
        "--preset",
        "tiny",
        "--max-frames",
        "40",
        "--clients",
        "2",
        "--loadtest-frames",
        "40",
        "-o",
        s(&out),
    ]);
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(run.status.success(), "demo failed: {said}");
    let report = std::fs::read_to_string(out.join("report.md")).expect("report.md");
    let targets = [
        "frame time p99",
        "frames over budget",
        "LODs skipped per frame",
        "objects skipped per frame",
        "cache peak",
        "IO failures",
        "LODs skipped per frame, prefetch vs demand fetch",
        "objects skipped per frame, prefetch",
        "first complete frame, prefetch",
        "request-to-resident latency p50, prefetch",
        "objects skipped per frame, prefetch vs oracle (warm-up included)",
        "LODs skipped per frame, prefetch vs oracle (warm-up included)",
        "bytes fetched, prefetch",
    ];
    let rows: Vec<&str> = report
        .lines()
        .filter(|l| l.contains("| **met** |") || l.contains("| **not met** |"))
        .collect();
    assert_eq!(rows.len(), targets.len(), "verdict rows: {rows:#?}");
    for t in targets {
        assert!(
            rows.iter().any(|r| r.starts_with(&format!("| {t} |"))),
            "no verdict for `{t}` in report.md"
        );
    }
    let met = rows.iter().filter(|r| r.contains("| **met** |")).count();
    assert!(
        report.contains(&format!(
            "## Verdicts: {met} of {} targets met",
            targets.len()
        )),
        "the heading does not count the verdicts"
    );
    // Every step is announced and the closing summary repeats the verdicts.
    for step in ["[1/6] generate", "[6/6] loadtest", "demo done in"] {
        assert!(said.contains(step), "the demo does not say `{step}`");
    }
    for picture in ["contact_sheet.png", "birdseye.png"] {
        assert!(out.join(picture).is_file(), "{picture} missing");
    }
}
