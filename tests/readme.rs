//! The README's commands run as written, and those of the documents it links in `docs/`: every
//! `portico …` command in their shell blocks, their prose and the Performance tables is given to
//! the real binary's argument parser (with `--help` at the end, so nothing runs but every flag
//! and value before it is checked), and must carry every option the usage line marks as
//! required. A renamed flag, a missing `-o` where one is required, or a value the command does
//! not accept fails here. The README stays a guide a newcomer reads in five minutes: at most
//! [`README_LINES`] lines, and every document it links exists.
//!
//! Placeholders are filled the way a reader would: `…` after `--server` is the default URL,
//! `a\|b` takes the first choice, `[...]` optional parts are left out.

use std::process::Command;

const README: &str = include_str!("../README.md");

/// The README and the documents in `docs/`, by name.
const DOCS: [(&str, &str); 9] = [
    ("README.md", README),
    ("docs/models.md", include_str!("../docs/models.md")),
    ("docs/browser.md", include_str!("../docs/browser.md")),
    ("docs/commands.md", include_str!("../docs/commands.md")),
    (
        "docs/how-it-works.md",
        include_str!("../docs/how-it-works.md"),
    ),
    ("docs/api.md", include_str!("../docs/api.md")),
    ("docs/deployment.md", include_str!("../docs/deployment.md")),
    (
        "docs/performance.md",
        include_str!("../docs/performance.md"),
    ),
    ("docs/status.md", include_str!("../docs/status.md")),
];

/// The most lines the README may have.
const README_LINES: usize = 200;

/// Every `portico …` command the documents ask a reader to type.
fn commands() -> Vec<Vec<String>> {
    DOCS.iter()
        .flat_map(|(name, text)| commands_in(text, *name == "docs/performance.md"))
        .collect()
}

/// Every `portico …` command `doc` asks a reader to type: lines of its fenced shell blocks, code
/// spans in its prose and in its Performance table (the whole document's tables when
/// `performance`), as argument vectors (without `portico`).
fn commands_in(doc: &str, performance: bool) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut in_block = false;
    let mut in_performance = performance;
    // Prose is taken a paragraph at a time: a code span may run over a line break.
    let mut paragraph = String::new();
    let spans = |text: &str, out: &mut Vec<Vec<String>>| {
        for span in text.split('`').skip(1).step_by(2) {
            out.extend(portico_args(span));
        }
    };
    for line in doc.lines() {
        let prose = !in_block
            && !line.starts_with("```")
            && !line.starts_with('|')
            && !line.starts_with('#')
            && !line.trim().is_empty();
        if prose {
            paragraph.push(' ');
            paragraph.push_str(line.trim());
            continue;
        }
        spans(&paragraph, &mut out);
        paragraph.clear();
        if line.starts_with("```") {
            in_block = !in_block;
        } else if in_block {
            let line = line.split(" #").next().unwrap_or_default();
            out.extend(portico_args(line));
        } else if line.starts_with("## ") && !performance {
            in_performance = line == "## Performance";
        } else if in_performance && line.starts_with('|') {
            // The Performance table's rows (the command table's synopses, with their
            // placeholders, are the one thing left out).
            spans(line, &mut out);
        }
    }
    spans(&paragraph, &mut out);
    out
}

/// The arguments after `portico` (or after `cargo run … --`), placeholders filled; `None` when
/// the text is not a portico command.
fn portico_args(text: &str) -> Option<Vec<String>> {
    let text = text.trim();
    let rest = if let Some(r) = text.strip_prefix("portico ") {
        r
    } else if text.starts_with("cargo run") {
        text.split_once(" -- ")?.1
    } else if text.starts_with("/usr/bin/time") {
        // `/usr/bin/time -f '…' portico build …`: the command after the timer.
        text.split_once(" portico ")?.1
    } else {
        return None;
    };
    let mut args = Vec::new();
    let mut words = rest.split_whitespace().peekable();
    while let Some(word) = words.next() {
        if word.starts_with('[') {
            // An optional part, possibly several words: leave it out.
            let mut w = word;
            while !w.ends_with(']') {
                w = words.next()?;
            }
            continue;
        }
        let word = word.split("\\|").next().unwrap_or(word);
        // Optional suffixes written inside a value: `look=any[,imp=1]`.
        let word = word.split('[').next().unwrap_or(word);
        if word == "…" {
            let flag = args.last().map(String::as_str).unwrap_or_default();
            assert_eq!(flag, "--server", "a `…` the test cannot fill in: {text}");
            args.push("http://127.0.0.1:7878".to_string());
            continue;
        }
        args.push(word.to_string());
    }
    Some(args)
}

#[test]
fn the_readmes_commands_parse_as_written() {
    let commands = commands();
    // The README names at least these: a test that found none would pass on any README.
    assert!(
        commands.len() >= 25,
        "only {} commands found",
        commands.len()
    );
    eprintln!("{} README commands checked", commands.len());
    for kind in [
        "demo", "build", "serve", "walk", "generate", "verify", "cull", "loadtest", "bench",
        "path", "inspect",
    ] {
        assert!(
            commands.iter().any(|c| c[0] == kind),
            "the README shows no `portico {kind}` command"
        );
    }
    for args in &commands {
        let out = Command::new(env!("CARGO_BIN_EXE_portico"))
            .args(args)
            .arg("--help")
            .output()
            .expect("run portico");
        assert!(
            out.status.success(),
            "`portico {}` as written in the README: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        );
        if args.len() == 1 {
            continue; // a command named in prose (`portico build` writes …), not one to type
        }
        let help = String::from_utf8(out.stdout).expect("utf-8 help");
        for (long, short) in required(&help) {
            assert!(
                args.iter()
                    .any(|a| *a == long || Some(a.as_str()) == short.as_deref()),
                "`portico {}` as written in the README lacks the required {long}",
                args.join(" ")
            );
        }
    }
}

/// The options a command's usage line requires (outside `[...]`), each with its short form
/// from the option list: `Usage: portico bench [OPTIONS] --db <DB> --out <DIR>` → `--db`,
/// `--out` / `-o`.
fn required(help: &str) -> Vec<(String, Option<String>)> {
    let usage = help
        .lines()
        .find_map(|l| l.strip_prefix("Usage: "))
        .expect("a usage line");
    let mut depth = 0;
    let mut top = String::new();
    for c in usage.chars() {
        match c {
            '[' => depth += 1,
            ']' => depth -= 1,
            _ if depth == 0 => top.push(c),
            _ => {}
        }
    }
    top.split_whitespace()
        .filter(|w| w.starts_with("--"))
        .map(|long| {
            let short = help.lines().find_map(|l| {
                let (s, rest) = l.trim().split_once(", ")?;
                (rest.split_whitespace().next() == Some(long) && s.len() == 2)
                    .then(|| s.to_string())
            });
            (long.to_string(), short)
        })
        .collect()
}

#[test]
fn the_readme_is_short_and_its_documents_exist() {
    let lines = README.lines().count();
    assert!(
        lines <= README_LINES,
        "the README has {lines} lines (at most {README_LINES}: the rest goes to docs/)"
    );
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut linked = 0;
    for (name, text) in DOCS {
        let dir = std::path::Path::new(name)
            .parent()
            .unwrap_or(std::path::Path::new(""));
        for target in text.split("](").skip(1).filter_map(|t| t.split(')').next()) {
            if target.starts_with("http") || target.starts_with('#') {
                continue;
            }
            let path = root
                .join(dir)
                .join(target.split('#').next().unwrap_or(target));
            assert!(path.exists(), "{name} links {target}, which does not exist");
            linked += 1;
        }
    }
    // Every document in `docs/` is one of DOCS, so its commands are checked too.
    for e in std::fs::read_dir(root.join("docs")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") {
            let name = format!("docs/{}", p.file_name().unwrap().to_string_lossy());
            assert!(
                DOCS.iter().any(|(n, _)| *n == name),
                "{name} is not checked here: add it to DOCS"
            );
        }
    }
    assert!(linked >= DOCS.len(), "only {linked} links followed");
}

#[test]
fn a_wrong_flag_is_caught() {
    // The check above would catch a README command with a flag that does not exist.
    let out = Command::new(env!("CARGO_BIN_EXE_portico"))
        .args(["walk", "--cache-megabytes", "8", "--help"])
        .output()
        .expect("run portico");
    assert!(!out.status.success());
    let help = "Usage: portico bench [OPTIONS] --db <DB> --out <DIR>\n  -o, --out <DIR>\n";
    assert_eq!(
        required(help),
        [
            ("--db".to_string(), None),
            ("--out".to_string(), Some("-o".to_string()))
        ]
    );
    let parsed = portico_args("portico walk --server … --elision optimize\\|impostors [--x y]");
    assert_eq!(
        parsed.expect("a command"),
        [
            "walk",
            "--server",
            "http://127.0.0.1:7878",
            "--elision",
            "optimize"
        ]
    );
}
