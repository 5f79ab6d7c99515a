//! `portico loadtest` end to end on the tiny building: a real server on 127.0.0.1:0 (in this
//! process), simulated clients through emulated links, one prefetch policy and both baselines.

use portico_client::policy::{parse_policy, policy_spec};
use portico_data::path::{CameraPath, PathKind, generate};
use portico_lab::drawn::DrawnLog;
use portico_lab::loadtest::{Link, LinkError, LoadtestConfig, LoadtestSummary, Transport, run};
use portico_protocol::Policy;
use std::path::{Path, PathBuf};

mod common;

/// The tiny building served in this process: base URL and database file.
/// The load tests run in real time, their simulated clients against their frame clocks: run
/// side by side on two cores they starve each other (a slow-link run's LODs skipped tripled
/// under CI's load), so each holds this while it runs.
fn alone() -> std::sync::MutexGuard<'static, ()> {
    static ONE: std::sync::Mutex<()> = std::sync::Mutex::new(());
    ONE.lock().unwrap_or_else(|e| e.into_inner())
}

/// The tiny building with plain geometry, served: the load tests compare policies where the
/// link binds, and were calibrated there. Compressed (the build's default), its tour is 0.06 MB
/// per client, which a 10 Mbit/s link carries with nothing to choose between the policies (the
/// range lookahead and the default then skip the same LODs).
fn serve_tiny(dir: &Path) -> (String, PathBuf) {
    let plain = portico_data::build::BuildOptions {
        compress: false,
        ..Default::default()
    };
    let db = common::build_tiny_with(dir, &plain);
    let (url, _) = common::serve_db(&db);
    (url, db)
}

/// A brisk tour (so 40 frames of 20 ms cross into new rooms).
fn tour(db: &Path) -> CameraPath {
    let db = portico_data::Database::open(db).unwrap();
    let graph = db.cell_graph().unwrap().unwrap();
    generate(&graph, PathKind::Tour, 3, 1, 6.0, 6.0).unwrap()
}

fn config(server: String, path: CameraPath, out: PathBuf) -> LoadtestConfig {
    let policy =
        parse_policy("depth=16,gran=object,range=any,look=any", Policy::default()).unwrap();
    LoadtestConfig {
        server,
        token: None,
        clients: 3,
        path,
        policies: vec![(policy_spec(&policy), policy)],
        transports: vec![Transport::Pull],
        baselines: true,
        // A slow link, so that what is fetched late shows.
        link: Link::parse("rtt=40ms,rate=20mbit").unwrap(),
        cache_bytes: 16 << 20,
        budget_s: 0.02,
        max_frames: Some(40),
        out,
    }
}

fn names(s: &LoadtestSummary) -> Vec<&str> {
    s.policies.iter().map(|p| p.name.as_str()).collect()
}

#[test]
fn a_loadtest_measures_the_policy_and_both_baselines_and_writes_its_report() {
    let _alone = alone();
    let dir = tempfile::tempdir().unwrap();
    let (server, db) = serve_tiny(dir.path());
    let out = dir.path().join("lt");
    let cfg = config(server, tour(&db), out.clone());
    let mut last = (0, 0);
    let s = run(&cfg, &mut |d, t| last = (d, t)).unwrap();

    assert_eq!(
        names(&s),
        [
            "depth=16,gran=object,range=any,look=any",
            "demand",
            "oracle"
        ]
    );
    assert_eq!(last, (3 * 3 * 40, 3 * 3 * 40), "progress reaches its total");
    for p in &s.policies {
        assert_eq!(p.frames, 3 * 40, "{}", p.name);
        assert!(p.bytes_fetched > 0, "{} fetched nothing", p.name);
        assert!(
            p.cache_peak_bytes <= p.cache_budget_bytes,
            "{}: cache peak {} over its budget {}",
            p.name,
            p.cache_peak_bytes,
            p.cache_budget_bytes
        );
        assert!(p.bytes_wasted <= p.bytes_fetched, "{}", p.name);
        // Summed over the clients in `bytes_fetched`, averaged in the per-client figure the
        // reports show.
        assert_eq!(
            p.bytes_fetched_per_client,
            p.bytes_fetched / 3,
            "{}",
            p.name
        );
        assert_eq!(p.bytes_wasted_per_client, p.bytes_wasted / 3, "{}", p.name);
        assert!((0.0..=1.0).contains(&p.cache_hit_rate), "{}", p.name);
        assert!(p.latency_p50_s <= p.latency_p95_s && p.latency_p95_s <= p.latency_p99_s);
        // Every arrival paid at least the round trip of the emulated link.
        assert!(
            p.latency_p50_s >= 0.04,
            "{}: p50 {}",
            p.name,
            p.latency_p50_s
        );
        assert_eq!(p.io_failures, 0, "{}", p.name);
    }
    let prefetch = &s.policies[0];
    assert!(prefetch.prefetch_requests > 0 && prefetch.prefetch_rps > 0.0);
    assert!(prefetch.lookahead_mb_max > 0.0 && prefetch.range_cells_max >= 1.0);
    assert_eq!(s.get("demand").unwrap().prefetch_requests, 0);
    assert!(
        s.policies[0].server_cpu_s.is_some(),
        "the in-process server's CPU is measured"
    );
    assert!(s.server_cpu_source.starts_with("in-process"));

    // The oracle fetches, ahead of time and nearest first, exactly what a client with
    // everything would draw, so it can only be short of what demand fetch (which asks once it
    // is already short) is short of. Timing on a shared machine could in principle reorder
    // two nearly equal runs, so the comparison is on the whole deficit in LOD levels (skipped
    // LODs plus skipped objects' levels), where the oracle's lead is about 2x. (LODs skipped
    // alone, a few tenths per frame, flipped once on a loaded machine: too close to assert.)
    let (demand, oracle) = (s.get("demand").unwrap(), s.get("oracle").unwrap());
    assert!(
        oracle.lod_deficit_mean <= demand.lod_deficit_mean,
        "oracle deficit {} vs demand {}",
        oracle.lod_deficit_mean,
        demand.lod_deficit_mean
    );

    // The outputs.
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(json["policies"].as_array().unwrap().len(), 3);
    assert_eq!(json["clients"], 3);
    assert!(json["database_id"].as_str().is_some_and(|d| !d.is_empty()));
    assert!(json["machine"]["cores"].as_u64().unwrap() >= 1);
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(report.contains("Look Depth") && report.contains("LODs Skipped"));
    assert!(report.contains("demand") && report.contains("oracle"));
    assert!(report.contains("MB fetched per client"), "{report}");
    for png in ["lods_skipped.png", "lookahead_mb.png"] {
        let img = image::open(out.join(png)).unwrap_or_else(|e| panic!("{png}: {e}"));
        assert!(img.width() > 100 && img.height() > 100);
    }
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 3 * 40);

    // Client 0's drawn frames, one log per run, for `portico bench --replay`.
    for (file, run) in [
        ("depth_16_gran_object_range_any_look_any.json", names(&s)[0]),
        ("demand.json", "demand"),
        ("oracle.json", "oracle"),
    ] {
        assert_eq!(portico_lab::loadtest::drawn_file(run), file);
        let log = DrawnLog::read(&out.join("drawn").join(file)).unwrap();
        assert_eq!(log.run, run);
        assert_eq!(log.database_id, s.database_id);
        assert_eq!((log.dt_s, log.size, log.fovy_deg), (0.02, (640, 480), 60.0));
        let frames: Vec<usize> = log.frames.iter().map(|f| f.path_frame).collect();
        assert_eq!(frames, (0..40).collect::<Vec<_>>(), "{run}");
        assert!(log.frames.iter().any(|f| !f.objects.is_empty()), "{run}");
    }
}

#[test]
fn bad_link_specs_are_clear_errors() {
    let _alone = alone();
    let e = Link::parse("rtt=20ms,rate=lots").unwrap_err();
    assert_eq!(e, LinkError::BadRate("lots".into()));
    assert!(e.to_string().contains("rate=\"lots\""), "{e}");
    let e = Link::parse("rtt=20ms;rate=1mbit").unwrap_err();
    assert!(matches!(e, LinkError::BadRtt(_)), "{e:?}");
    assert!(
        Link::parse("delay=3ms")
            .unwrap_err()
            .to_string()
            .contains("delay")
    );
    assert!(Link::parse("").is_err());
}

#[test]
fn a_bad_config_is_refused_before_anything_runs() {
    let _alone = alone();
    let dir = tempfile::tempdir().unwrap();
    let path = CameraPath {
        kind: "x".into(),
        keyframes: vec![],
    };
    let mut cfg = config("http://127.0.0.1:1".into(), path, dir.path().join("o"));
    let e = run(&cfg, &mut |_, _| {}).unwrap_err();
    assert!(format!("{e:#}").contains("path"), "{e:#}");
    cfg.path = CameraPath {
        kind: "x".into(),
        keyframes: vec![portico_data::path::Keyframe {
            t: 0.0,
            eye: [0.0; 3],
            dir: [1.0, 0.0, 0.0],
        }],
    };
    cfg.clients = 0;
    assert!(format!("{:#}", run(&cfg, &mut |_, _| {}).unwrap_err()).contains("clients"));
    cfg.clients = 1;
    // Nothing listens there: the error names the server.
    let e = format!("{:#}", run(&cfg, &mut |_, _| {}).unwrap_err());
    assert!(e.contains("127.0.0.1:1"), "{e}");
}

#[test]
fn impostor_clients_always_have_something_for_every_visible_object() {
    let _alone = alone();
    let dir = tempfile::tempdir().unwrap();
    let (server, db) = serve_tiny(dir.path());
    let mut cfg = config(server, tour(&db), dir.path().join("lt"));
    let plain = parse_policy("depth=16,gran=object,range=any,look=any", Policy::default()).unwrap();
    let imp = Policy {
        impostors: true,
        ..plain
    };
    cfg.policies = vec![(policy_spec(&plain), plain), (policy_spec(&imp), imp)];
    cfg.baselines = false;
    let s = run(&cfg, &mut |_, _| {}).unwrap();
    assert_eq!(
        names(&s),
        [
            "depth=16,gran=object,range=any,look=any",
            "depth=16,gran=object,range=any,look=any,imp=1"
        ]
    );
    let (plain, imp) = (&s.policies[0], &s.policies[1]);
    // With average-colour boxes in the header, a visible object lacks a representation only
    // while its cluster contains the eye; a plain client lacks every object not yet arrived.
    assert!(
        imp.objects_skipped_mean <= plain.objects_skipped_mean,
        "impostors {} vs plain {}",
        imp.objects_skipped_mean,
        plain.objects_skipped_mean
    );
    for p in [plain, imp] {
        assert!(
            p.complete_clients >= 1,
            "{}: never a complete frame",
            p.name
        );
        assert!(p.first_complete_bytes_mean.is_some_and(|b| b > 0.0));
    }
}

/// Funkhouser's claim (§5.3, Table 5.11), and Portico's: reading ahead leaves fewer LODs short
/// of what the frame wants, and no more objects missing, than fetching on demand — over the
/// whole run, cold start included, on a slow link where what arrives late shows.
#[test]
fn prefetch_beats_demand_fetch_over_the_whole_run_on_a_slow_link() {
    let _alone = alone();
    let dir = tempfile::tempdir().unwrap();
    let (server, db) = serve_tiny(dir.path());
    let mut cfg = config(server, tour(&db), dir.path().join("lt"));
    cfg.link = Link::parse("rtt=60ms,rate=8mbit").unwrap();
    cfg.budget_s = 0.05;
    cfg.max_frames = Some(120);
    let s = run(&cfg, &mut |_, _| {}).unwrap();
    let (prefetch, demand) = (&s.policies[0], s.get("demand").unwrap());
    eprintln!(
        "LOD deficit {:.3} vs {:.3}; LODs skipped {:.3} vs {:.3}; objects skipped {:.3} vs {:.3}; \
         first complete frame {:?} vs {:?}",
        prefetch.lod_deficit_mean,
        demand.lod_deficit_mean,
        prefetch.lods_skipped_mean,
        demand.lods_skipped_mean,
        prefetch.objects_skipped_mean,
        demand.objects_skipped_mean,
        prefetch.first_complete_frame_mean,
        demand.first_complete_frame_mean,
    );
    assert!(
        prefetch.lod_deficit_mean < demand.lod_deficit_mean,
        "LOD deficit per frame: prefetch {} vs demand {}",
        prefetch.lod_deficit_mean,
        demand.lod_deficit_mean
    );
    assert!(
        prefetch.objects_skipped_mean <= demand.objects_skipped_mean,
        "objects skipped per frame: prefetch {} vs demand {}",
        prefetch.objects_skipped_mean,
        demand.objects_skipped_mean
    );
}

/// A standing observer at the tour's start, for the cold start: with nothing coming into view
/// later, the first complete frame is when the first view's stab list and coarse LODs are in,
/// and a read that misses its frame by a hair costs one frame, not the several until the next
/// lull in a walk (a walking client's first complete frame jumps between 2 and 11 on such a
/// race, whatever the policy).
fn standing(path: &CameraPath) -> CameraPath {
    let k = path.keyframes[0];
    let mut later = k;
    later.t = 60.0;
    CameraPath {
        kind: "stand".into(),
        keyframes: vec![k, later],
    }
}

/// The default policy against Funkhouser's range lookahead (with both baselines) in one run:
/// the tiny building served in `dir`, its tour made into a path by `path`, over `link`, 50 ms
/// frames, `frames` of them.
fn default_against_range(
    dir: &Path,
    path: fn(&CameraPath) -> CameraPath,
    link: &str,
    frames: u64,
) -> LoadtestSummary {
    let (server, db) = serve_tiny(dir);
    let mut cfg = config(server, path(&tour(&db)), dir.join("lt"));
    cfg.link = Link::parse(link).unwrap();
    cfg.budget_s = 0.05;
    cfg.max_frames = Some(frames);
    let range = parse_policy("look=any", Policy::default()).unwrap();
    cfg.policies = vec![
        ("default".into(), Policy::default()),
        ("range".into(), range),
    ];
    run(&cfg, &mut |_, _| {}).unwrap()
}

/// Cold start (Funkhouser §5.2.4, and the claim of `portico_client::deadline`): what the frame
/// lacks is read ahead of the server's answer, which is a round trip old and at the start not
/// there yet, so the first complete frame comes with demand fetch's, in frames and in bytes,
/// under the default policy and Funkhouser's range lookahead alike (before the IO stage read
/// what the frame lacked, the range lookahead's came up to 3.3 frames later on a walk here).
#[test]
fn the_cold_start_is_no_slower_than_demand_fetch() {
    let _alone = alone();
    let dir = tempfile::tempdir().unwrap();
    let s = default_against_range(dir.path(), standing, "rtt=60ms,rate=8mbit", 24);
    let firsts = |name: &str| -> Vec<(u64, u64)> {
        s.get(name)
            .unwrap()
            .per_client
            .iter()
            .map(|c| {
                c.first_complete
                    .unwrap_or_else(|| panic!("{name}: never complete"))
            })
            .collect()
    };
    let demand = firsts("demand");
    for name in ["default", "range"] {
        let p = firsts(name);
        eprintln!("{name}: (frame, bytes) {p:?}; demand {demand:?}");
        for (c, (&(pf, pb), &(df, db))) in p.iter().zip(&demand).enumerate() {
            // A frame of slack: a read finishing just after a frame's start is drawn one later.
            assert!(
                pf <= df + 1,
                "{name}, client {c}: first complete frame {pf} vs demand {df}"
            );
            assert!(
                pb as f64 <= 1.25 * db as f64,
                "{name}, client {c}: {pb} bytes before the first complete frame vs demand {db}"
            );
        }
    }
}

/// The regression guard of the prefetch's bytes: the predicted lookahead with deadline-ordered
/// reads (the default policy) against Funkhouser's range lookahead and the oracle, in one run on
/// a slow link. It fails if the lookahead goes back to reading what the range cells' stab lists
/// hold, or its reads stop waiting for their deadlines.
#[test]
fn the_default_prefetch_reads_little_more_than_the_oracle_and_skips_no_more() {
    let _alone = alone();
    let dir = tempfile::tempdir().unwrap();
    let s = default_against_range(dir.path(), |t| t.clone(), "rtt=50ms,rate=10mbit", 120);
    let (p, r, o) = (
        s.get("default").unwrap(),
        s.get("range").unwrap(),
        s.get("oracle").unwrap(),
    );
    let mb = |x: &portico_lab::loadtest::PolicyResult| x.bytes_fetched_per_client as f64 / 1e6;
    eprintln!(
        "MB per client: default {:.3}, range {:.3}, oracle {:.3}; objects skipped {:.3} / {:.3} / \
         {:.3}; LODs skipped {:.3} / {:.3} / {:.3}",
        mb(p),
        mb(r),
        mb(o),
        p.objects_skipped_mean,
        r.objects_skipped_mean,
        o.objects_skipped_mean,
        p.lods_skipped_mean,
        r.lods_skipped_mean,
        o.lods_skipped_mean
    );
    // Measured (tiny, 3 clients × 120 frames): 0.46 MB per client against the oracle's 0.31
    // and the range lookahead's 0.74, every run alike; objects skipped within ±0.1 of the
    // oracle's from run to run.
    assert!(
        mb(p) <= 1.75 * mb(o),
        "default prefetch {:.3} MB vs the oracle's {:.3}",
        mb(p),
        mb(o)
    );
    assert!(
        mb(p) <= 0.75 * mb(r),
        "default prefetch {:.3} MB vs the range lookahead's {:.3}",
        mb(p),
        mb(r)
    );
    assert!(
        p.objects_skipped_mean <= 1.25 * o.objects_skipped_mean + 0.15,
        "objects skipped {} vs the oracle's {}",
        p.objects_skipped_mean,
        o.objects_skipped_mean
    );
    // LODs skipped move with the machine's load (the clients run in real time): over five
    // full runs on 2 cores (2026-12-06) the default skipped 0.09-0.12, the oracle 0.02-0.16 and
    // the range lookahead 0.17-0.24, and +0.05 on the oracle failed two of them. The default
    // must stay near the oracle and clearly under the range lookahead it replaced.
    assert!(
        p.lods_skipped_mean <= o.lods_skipped_mean + 0.1
            && p.lods_skipped_mean < r.lods_skipped_mean,
        "LODs skipped {} vs the oracle's {} and the range lookahead's {}",
        p.lods_skipped_mean,
        o.lods_skipped_mean,
        r.lods_skipped_mean
    );
}

#[test]
fn a_cache_sweep_runs_every_budget_with_both_baselines_and_judges_them() {
    let _alone = alone();
    let dir = tempfile::tempdir().unwrap();
    let (server, db) = serve_tiny(dir.path());
    let out = dir.path().join("sweep");
    let mut cfg = config(server, tour(&db), out.clone());
    cfg.max_frames = Some(30);
    let mut runs = std::collections::BTreeSet::new();
    let (rows, summaries) =
        portico_lab::loadtest::cache_sweep::sweep(&cfg, &[1, 16], &mut |run, _, _| {
            runs.insert(run);
        })
        .unwrap();
    assert_eq!(runs.into_iter().collect::<Vec<_>>(), [0, 1]);
    assert_eq!(rows.iter().map(|r| r.cache_mb).collect::<Vec<_>>(), [1, 16]);
    for (r, s) in rows.iter().zip(&summaries) {
        assert_eq!(s.cache_bytes, r.cache_mb << 20);
        assert_eq!(names(s).len(), 3, "{:?}", names(s));
        assert!(r.prefetch.is_some() && r.demand.is_some() && r.oracle.is_some());
        // Each budget's own run, with its own report.
        let sub = out.join(format!("cache-{}mb", r.cache_mb));
        assert!(sub.join("summary.json").is_file() && sub.join("report.md").is_file());
        // Every run at every budget keeps to its budget.
        for p in &s.policies {
            assert!(p.cache_budget_bytes <= s.cache_bytes, "{}", p.name);
            assert!(p.cache_peak_bytes <= p.cache_budget_bytes, "{}", p.name);
        }
    }
    let md = std::fs::read_to_string(out.join("cache_sweep.md")).unwrap();
    assert!(md.contains("| 1 | ") && md.contains("| 16 | "), "{md}");
    assert!(md.contains("at every cache budget"), "{md}");
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("cache_sweep.json")).unwrap()).unwrap();
    assert_eq!(json.as_array().unwrap().len(), 2);
    assert!(image::open(out.join("cache_sweep.png")).is_ok());
    // One budget is not a sweep.
    let err =
        portico_lab::loadtest::cache_sweep::sweep(&cfg, &[16], &mut |_, _, _| {}).unwrap_err();
    assert!(err.to_string().contains("at least two budgets"), "{err}");
    let err = portico_lab::loadtest::cache_sweep::sweep(&cfg, &[4, 16, 4], &mut |_, _, _| {})
        .unwrap_err();
    assert!(err.to_string().contains("4 MiB is given twice"), "{err}");
}

/// Both transports in one session (issue #17: server push as the default, pull as the
/// fallback): the same policy pushed over `/v1/stream` and pulled, against the same baselines
/// on the same slow link. Push needs no round trip per answer, so it skips no more than pull
/// and reads about as little.
#[test]
fn push_and_pull_run_in_one_session_and_push_skips_no_more() {
    let _alone = alone();
    let dir = tempfile::tempdir().unwrap();
    let (server, db) = serve_tiny(dir.path());
    let mut cfg = config(server, tour(&db), dir.path().join("lt"));
    cfg.link = Link::parse("rtt=50ms,rate=10mbit").unwrap();
    cfg.budget_s = 0.05;
    cfg.max_frames = Some(120);
    cfg.policies = vec![("default".into(), Policy::default())];
    cfg.transports = vec![Transport::Pull, Transport::Push];
    let s = run(&cfg, &mut |_, _| {}).unwrap();
    assert_eq!(names(&s), ["default", "default+push", "demand", "oracle"]);
    let (pull, push, o) = (
        s.get("default").unwrap(),
        s.get("default+push").unwrap(),
        s.get("oracle").unwrap(),
    );
    assert_eq!(
        (pull.transport.as_str(), push.transport.as_str()),
        ("pull", "push")
    );
    let mb = |x: &portico_lab::loadtest::PolicyResult| x.bytes_fetched_per_client as f64 / 1e6;
    eprintln!(
        "pull / push / oracle: MB per client {:.3} / {:.3} / {:.3}; objects skipped {:.3} / \
         {:.3} / {:.3}; LODs skipped {:.3} / {:.3} / {:.3}; first complete {:?} / {:?}; \
         failures {} / {}",
        mb(pull),
        mb(push),
        mb(o),
        pull.objects_skipped_mean,
        push.objects_skipped_mean,
        o.objects_skipped_mean,
        pull.lods_skipped_mean,
        push.lods_skipped_mean,
        o.lods_skipped_mean,
        pull.first_complete_frame_mean,
        push.first_complete_frame_mean,
        pull.io_failures,
        push.io_failures,
    );
    assert_eq!(push.io_failures, 0, "the push sessions fell back or failed");
    assert!(push.complete_clients == cfg.clients as u64);
    assert!(
        push.objects_skipped_mean <= pull.objects_skipped_mean * 1.25 + 0.05,
        "objects skipped per frame: push {} vs pull {}",
        push.objects_skipped_mean,
        pull.objects_skipped_mean
    );
    assert!(
        mb(push) <= 2.0 * mb(o),
        "push read {:.3} MB per client, the oracle {:.3}",
        mb(push),
        mb(o)
    );
}

/// The textured building with its texture segments cut into 4 KiB parts: every client of every
/// run (prefetch pulled and pushed, demand fetch, the oracle) asks for the parts with their
/// heads, joins them and draws the textures.
#[test]
fn every_client_joins_texture_parts_and_draws_the_textures() {
    let _alone = alone();
    let dir = tempfile::tempdir().unwrap();
    let db = common::build_tiny_textured(dir.path());
    let cut = {
        let d = portico_data::Database::open(&db).unwrap();
        d.header()
            .textures
            .iter()
            .flat_map(|t| &t.segments)
            .filter(|s| s.parts > 0)
            .map(|s| s.segment)
            .collect::<std::collections::HashSet<u32>>()
    };
    assert!(cut.len() >= 4, "{} texture segments in parts", cut.len());
    let (server, _) = common::serve_db(&db);
    let out = dir.path().join("lt");
    let mut cfg = config(server, tour(&db), out.clone());
    cfg.clients = 1;
    cfg.transports = vec![Transport::Pull, Transport::Push];
    let s = run(&cfg, &mut |_, _| {}).unwrap();
    for p in &s.policies {
        let file = portico_lab::loadtest::drawn_file(&p.name);
        let log = DrawnLog::read(&out.join("drawn").join(&file)).unwrap();
        let joined = log
            .frames
            .iter()
            .flat_map(|f| &f.objects)
            .filter(|o| o.texture.is_some_and(|t| cut.contains(&t)))
            .count();
        assert!(
            joined > 0,
            "{}: no texture joined from its parts was drawn",
            p.name
        );
    }
}
