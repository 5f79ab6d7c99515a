//! `report.md` with tables in Funkhouser's layout (§5.3: Table 5.1/5.3 "Look Gran, Look Depth,
//! Range Cells, Look Objects, LODs Skipped" with mean and max; Tables 5.5–5.7 pivoted by range
//! cull × depth against lookahead cull), the network and cache figures, the baselines, and
//! `frames.csv` with client 0's frames for every run.

use super::{LoadtestSummary, PolicyResult};
use portico_protocol::{Granularity, LookaheadCull, Policy, RangeCull};
use std::fmt::Write;

/// Funkhouser's short names.
fn gran(g: Granularity) -> &'static str {
    match g {
        Granularity::Object => "Obj",
        Granularity::Cell => "Cell",
    }
}

fn range(r: RangeCull) -> &'static str {
    match r {
        RangeCull::Any => "Any",
        RangeCull::Plane => "Plane",
        RangeCull::Frustum => "Frust",
        RangeCull::Direction => "Dir",
    }
}

fn look(l: LookaheadCull) -> &'static str {
    match l {
        LookaheadCull::Any => "Any",
        LookaheadCull::Plane => "Plane",
        LookaheadCull::Frustum => "Frust",
        LookaheadCull::Predicted => "Pred",
    }
}

fn mb(b: u64) -> f64 {
    b as f64 / 1e6
}

/// Cache sizes are binary: `--cache-mb 64` is 64 MiB.
fn mib(b: u64) -> f64 {
    b as f64 / 1_048_576.0
}

fn ratio(x: Option<f64>) -> String {
    x.map_or("∞ (none skipped)".into(), |r| format!("{r:.1}×"))
}

/// The whole report.
pub fn markdown(s: &LoadtestSummary) -> String {
    let mut r = String::new();
    header(&mut r, s);
    headline(&mut r, s);
    set_table(&mut r, s);
    pivots(&mut r, s);
    network_table(&mut r, s);
    waste(&mut r, s);
    first_complete(&mut r, s);
    per_client(&mut r, s);
    plots(&mut r, s);
    method(&mut r, s);
    r
}

fn header(r: &mut String, s: &LoadtestSummary) {
    let _ = writeln!(
        r,
        "# Load test: `{}`, {} clients, {}\n",
        s.model, s.clients, s.link_spec
    );
    let rows = [
        (
            "machine",
            format!("{} ({} cores)", s.machine.hostname, s.machine.cores),
        ),
        ("server", s.server.clone()),
        ("database id", format!("`{}`", s.database_id)),
        (
            "path",
            format!(
                "{} (hash `{}`), {} frames per pass",
                s.path, s.path_hash, s.path_frames
            ),
        ),
        (
            "frames",
            format!(
                "{} per client at {:.0} ms (real time)",
                s.frames_per_client,
                s.budget_s * 1e3
            ),
        ),
        (
            "cache",
            format!("{:.1} MiB per client", s.cache_bytes as f64 / 1048576.0),
        ),
        ("link", format!("{} per client", s.link_spec)),
        ("server CPU", s.server_cpu_source.clone()),
        ("wall time", format!("{:.1} s", s.wall_s)),
    ];
    let _ = writeln!(r, "| | |\n|---|---|");
    for (k, v) in rows {
        let _ = writeln!(r, "| {k} | {v} |");
    }
    r.push('\n');
}

fn opt(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{v:.2}"))
}

fn headline(r: &mut String, s: &LoadtestSummary) {
    let (Some(best), Some(demand)) = (s.best_prefetch(), s.get("demand")) else {
        return;
    };
    let _ = writeln!(r, "## Prefetch against the baselines\n");
    let _ = writeln!(
        r,
        "| run | LODs skipped mean | max | objects skipped mean | LOD deficit mean | after {:.0} s warm-up: LODs / objects / deficit | hit rate | MB fetched per client | MB never drawn per client |\n|---|---|---|---|---|---|---|---|---|",
        super::WARMUP_S
    );
    let oracle = s.get("oracle");
    for p in [Some(best), Some(demand), oracle].into_iter().flatten() {
        let _ = writeln!(
            r,
            "| {} | {:.2} | {:.0} | {:.2} | {:.2} | {} / {} / {} | {:.3} | {:.1} | {:.1} |",
            p.name,
            p.lods_skipped_mean,
            p.lods_skipped_max,
            p.objects_skipped_mean,
            p.lod_deficit_mean,
            opt(p.lods_skipped_warm_mean),
            opt(p.objects_skipped_warm_mean),
            opt(p.lod_deficit_warm_mean),
            p.cache_hit_rate,
            mb(p.bytes_fetched_per_client),
            mb(p.bytes_wasted_per_client)
        );
    }
    let _ = writeln!(
        r,
        "\nBest prefetch policy `{}` against demand fetch: **{}** fewer LODs skipped per frame \
         ({} after the warm-up) and {} smaller LOD deficit.\n",
        best.name,
        ratio(best.lods_skipped_vs_demand),
        ratio(best.lods_skipped_warm_vs_demand),
        ratio(best.lod_deficit_vs_demand)
    );
    let _ = writeln!(
        r,
        "### Verdicts\n\n{}",
        crate::verdict::table(&crate::verdict::loadtest(s))
    );
}

/// How soon a cold client draws every visible object (its own LOD, or with impostors a box
/// above it), and how many bytes that took.
fn first_complete(r: &mut String, s: &LoadtestSummary) {
    let _ = writeln!(
        r,
        "## First complete frame

| run | clients that got one | first complete frame, mean | bytes arrived by then, mean |
|---|---|---|---|"
    );
    for p in &s.policies {
        let frame = p
            .first_complete_frame_mean
            .map_or("–".into(), |f| format!("{f:.1}"));
        let bytes = p
            .first_complete_bytes_mean
            .map_or("–".into(), |b| format!("{:.0} KB", b / 1e3));
        let _ = writeln!(
            r,
            "| {} | {} of {} | {frame} | {bytes} |",
            p.name, p.complete_clients, s.clients
        );
    }
    r.push('\n');
}

/// Where the bytes never drawn went ([`super::waste`]), per client.
fn waste(r: &mut String, s: &LoadtestSummary) {
    let _ = writeln!(
        r,
        "## Bytes never drawn, by reason (MB per client)

| run | fetched | never drawn | objects no frame drew | finer than any LOD drawn | coarser than the finest drawn | textures | stab lists | arrived twice |
|---|---|---|---|---|---|---|---|---|"
    );
    for p in &s.policies {
        let w = &p.waste_per_client;
        let _ = writeln!(
            r,
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
            p.name,
            mb(p.bytes_fetched_per_client),
            mb(p.bytes_wasted_per_client),
            mb(w.object_never_drawn),
            mb(w.finer_than_drawn),
            mb(w.coarser_than_drawn),
            mb(w.textures),
            mb(w.stab_lists),
            mb(w.twice)
        );
    }
    r.push('\n');
}

/// How evenly the clients fared: LOD deficit per client.
fn per_client(r: &mut String, s: &LoadtestSummary) {
    let _ = writeln!(
        r,
        "## Per client\n\n| run | LOD deficit mean: best client | median | worst | worst client's start frame | fallback frames (all clients) | of which eye in no live cell |\n|---|---|---|---|---|---|---|"
    );
    for p in &s.policies {
        let mut d: Vec<(f64, usize)> = p
            .per_client
            .iter()
            .map(|c| (c.lod_deficit_mean, c.start_frame))
            .collect();
        if d.is_empty() {
            continue;
        }
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        let _ = writeln!(
            r,
            "| {} | {:.2} | {:.2} | {:.2} | {} | {} | {} |",
            p.name,
            d[0].0,
            d[d.len() / 2].0,
            d[d.len() - 1].0,
            d[d.len() - 1].1,
            p.fallback_frames,
            p.outside_frames
        );
    }
    r.push('\n');
}

/// Tables 5.1 / 5.3: one row per run.
fn set_table(r: &mut String, s: &LoadtestSummary) {
    let _ = writeln!(
        r,
        "## Set statistics (Funkhouser Tables 5.1, 5.3)\n\n\
         | Look Gran | Range Cull | Look Cull | Look Depth | Range Cells Mean | Max | Look Objects Mean | Max | LODs Skipped Mean | Max |\n\
         |---|---|---|---|---|---|---|---|---|---|"
    );
    for p in &s.policies {
        match p.policy {
            Some(pol) => {
                let _ = writeln!(
                    r,
                    "| {} | {} | {} | {} | {:.2} | {:.0} | {:.0} | {:.0} | {:.2} | {:.0} |",
                    gran(pol.granularity),
                    range(pol.range_cull),
                    look(pol.lookahead_cull),
                    pol.depth_frames,
                    p.range_cells_mean,
                    p.range_cells_max,
                    p.lookahead_objects_mean,
                    p.lookahead_objects_max,
                    p.lods_skipped_mean,
                    p.lods_skipped_max
                );
            }
            None => {
                let _ = writeln!(
                    r,
                    "| *{}* | – | – | – | – | – | – | – | {:.2} | {:.0} |",
                    p.name, p.lods_skipped_mean, p.lods_skipped_max
                );
            }
        }
    }
    r.push('\n');
}

/// Tables 5.5–5.7: for each granularity with more than one lookahead cull measured, rows of
/// range cull × depth and columns of lookahead cull.
fn pivots(r: &mut String, s: &LoadtestSummary) {
    let find = |g: Granularity, rc: RangeCull, d: u32, l: LookaheadCull| {
        s.policies.iter().find(|p| {
            p.policy.is_some_and(|q| {
                q.granularity == g
                    && q.range_cull == rc
                    && q.depth_frames == d
                    && q.lookahead_cull == l
            })
        })
    };
    type Metric = (&'static str, fn(&PolicyResult) -> (f64, f64), usize);
    let metrics: [Metric; 3] = [
        (
            "Range cells (Table 5.5)",
            |p| (p.range_cells_mean, p.range_cells_max),
            2,
        ),
        (
            "Lookahead objects (Table 5.6)",
            |p| (p.lookahead_objects_mean, p.lookahead_objects_max),
            0,
        ),
        (
            "LODs skipped (Table 5.7)",
            |p| (p.lods_skipped_mean, p.lods_skipped_max),
            2,
        ),
    ];
    for g in super::sweep::GRANULARITIES {
        let rows = pivot_rows(s, g);
        let looks: Vec<LookaheadCull> = super::sweep::LOOK_CULLS
            .into_iter()
            .filter(|&l| rows.iter().any(|&(rc, d)| find(g, rc, d, l).is_some()))
            .collect();
        if looks.len() < 2 {
            continue;
        }
        for (title, value, digits) in metrics {
            let _ = write!(
                r,
                "### {title}, {} granularity\n\n| Range Cull | Look Depth |",
                gran(g)
            );
            for &l in &looks {
                let _ = write!(r, " {} Mean | Max |", look(l));
            }
            let _ = writeln!(r, "\n|---|---|{}", "---|---|".repeat(looks.len()));
            for &(rc, d) in &rows {
                let _ = write!(r, "| {} | {d} |", range(rc));
                for &l in &looks {
                    match find(g, rc, d, l) {
                        Some(p) => {
                            let (mean, max) = value(p);
                            let _ = write!(r, " {mean:.digits$} | {max:.0} |");
                        }
                        None => r.push_str(" – | – |"),
                    }
                }
                r.push('\n');
            }
            r.push('\n');
        }
    }
}

/// (range cull, depth) pairs measured with granularity `g`, in table order.
fn pivot_rows(s: &LoadtestSummary, g: Granularity) -> Vec<(RangeCull, u32)> {
    let mut rows: Vec<(RangeCull, u32)> = Vec::new();
    let measured: Vec<Policy> = s.policies.iter().filter_map(|p| p.policy).collect();
    for rc in super::sweep::RANGE_CULLS {
        let mut depths: Vec<u32> = measured
            .iter()
            .filter(|p| p.granularity == g && p.range_cull == rc)
            .map(|p| p.depth_frames)
            .collect();
        depths.sort_unstable();
        depths.dedup();
        rows.extend(depths.into_iter().map(|d| (rc, d)));
    }
    rows
}

fn network_table(r: &mut String, s: &LoadtestSummary) {
    let _ = writeln!(
        r,
        "## Network, cache and server\n\n\
         | run | objects skipped mean | LOD deficit mean / max | hit rate | MB fetched per client | MB never drawn per client | latency p50 / p95 / p99 ms | prefetch req/s | segments/s | lookahead MB mean / max | compute ms mean / max | server CPU s (cores) | cache peak / budget MiB | LODs skipped vs demand |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for p in &s.policies {
        let cpu = p.server_cpu_s.map_or("–".into(), |c| {
            format!("{c:.2} ({:.2})", p.server_cpu_cores.unwrap_or(0.0))
        });
        let _ = writeln!(
            r,
            "| {} | {:.2} | {:.2} / {:.0} | {:.3} | {:.1} | {:.1} | {:.0} / {:.0} / {:.0} | {:.1} | {:.0} | {:.2} / {:.2} | {:.2} / {:.2} | {} | {:.1} / {:.1} | {} |",
            p.name,
            p.objects_skipped_mean,
            p.lod_deficit_mean,
            p.lod_deficit_max,
            p.cache_hit_rate,
            mb(p.bytes_fetched_per_client),
            mb(p.bytes_wasted_per_client),
            p.latency_p50_s * 1e3,
            p.latency_p95_s * 1e3,
            p.latency_p99_s * 1e3,
            p.prefetch_rps,
            p.segment_rps,
            p.lookahead_mb_mean,
            p.lookahead_mb_max,
            p.answer_ms_mean,
            p.answer_ms_max,
            cpu,
            mib(p.cache_peak_bytes),
            mib(p.cache_budget_bytes),
            ratio(p.lods_skipped_vs_demand)
        );
    }
    let late: Vec<String> = s
        .policies
        .iter()
        .filter(|p| p.frame_period_s > s.budget_s * 1.1)
        .map(|p| format!("`{}` ({:.1} ms)", p.name, p.frame_period_s * 1e3))
        .collect();
    if !late.is_empty() {
        let _ = writeln!(
            r,
            "\nThe simulator fell behind real time (mean frame period over the budget) in: {}.",
            late.join(", ")
        );
    }
    r.push('\n');
}

fn plots(r: &mut String, s: &LoadtestSummary) {
    if s.plots.is_empty() {
        return;
    }
    let _ = writeln!(
        r,
        "## Plots (client 0; Funkhouser Fig. 5.11–5.13)\n\n![LODs skipped per frame](lods_skipped.png)\n\n![Lookahead MB per frame](lookahead_mb.png)\n"
    );
    let _ = writeln!(
        r,
        "Client 0's frames as drawn, one log per run, are in `drawn/` ({}): `portico bench --db <the same database> --path <the same path> --frame-step-ms {} --replay drawn/<file> -o DIR` draws them beside the full-detail frames and scores them (PSNR, Es, Et).\n",
        s.policies
            .iter()
            .map(|p| format!("`{}`", super::drawn_file(&p.name)))
            .collect::<Vec<_>>()
            .join(", "),
        s.budget_s * 1e3
    );
}

fn method(r: &mut String, s: &LoadtestSummary) {
    let _ = writeln!(
        r,
        "## Method\n\n\
- {n} simulated clients per run, client *i* starting *i*/{n} of the way along the path (wrapping), frames every {ms:.0} ms of real time, frame-indexed; every run starts with empty caches.\n\
- Each client runs the real client's visibility (eye-to-cell/eye-to-object with the eye cell's stab list when it is resident, frustum culling otherwise), candidates and the `optimize` elider with the default cost model over RESIDENT LODs; it never waits (Funkhouser §5.2.4). As in Funkhouser's §5.3 tests, the elider is combined with a static size threshold ({px} pixels per triangle, the policy's, which the server also uses to cap each lookahead object's LOD): no client wants a LOD finer than that.\n\
- **LODs skipped**: levels given up for a coarser resident LOD. **Objects skipped**: wanted objects with no resident LOD. **LOD deficit**: LODs skipped plus, per skipped object, the levels from the wanted one down to the coarsest. **Hit rate**: of the LODs the elider wanted, the fraction resident. **Wasted**: fetched bytes never drawn before their release or the end of the run (or fetched twice).\n\
- **Latency**: from the prefetch request whose answer listed a segment (demand/oracle: the frame whose list first named it; `+push` runs: the latest observer sent before it came, a lower bound) until it was resident in the cache.\n\
- Runs named `+push` take the same policy over server push (`/v1/stream`): the observer sent every frame through the client's half of the round trip, segments pushed at the link's rate (the session is paced to it) and brought through the same token bucket and the other half; the others pull (`/v1/prefetch` and `/v1/batch`).\n\
- Range cells, lookahead objects and compute time are per prefetch answer (`/v1/prefetch`, computed on the server); lookahead MB is the latest answer's `lookahead_bytes` at each frame.\n\
- **demand**: each frame asks for exactly the missing LODs its elider wanted (and the eye cell's stab list), biggest on screen first. **oracle**: knows the path; each frame asks for what a client with everything resident would draw in the next {k} frames, nearest first, up to the cache budget.\n\
- Each client has its own link ({link}): half the round trip before each request and half after its answer, response bodies paced by a token bucket at the link rate; up to 8 segment fetches in flight.\n\
- The server's decoded stab lists stay warm from one run to the next (everything else it keeps is per request); before the first run an unmeasured pass of it over the clients' first 20 frames warms the server, so that no run pays for the server's own cold start.\n\
- **Bytes never drawn, by reason**: of the fetched segments no frame drew, the geometry of objects no frame drew at any LOD, LODs finer than every LOD of their object drawn, coarser ones never drawn, textures, stab lists, and segments that arrived twice.",
        n = s.clients,
        ms = s.budget_s * 1e3,
        k = s.oracle_lookahead_frames,
        px = s.size_threshold_px,
        link = s.link_spec,
    );
}

/// `frames.csv`: client 0's frames for every run.
pub fn frames_csv(s: &LoadtestSummary) -> String {
    let mut out = String::from(
        "policy,frame,path_frame,lods_skipped,objects_skipped,lod_deficit,visible_objects,wanted,hits,lookahead_bytes,fallback,outside\n",
    );
    for p in &s.policies {
        for (f, row) in p.client0.iter().enumerate() {
            let _ = writeln!(
                out,
                "\"{}\",{f},{},{},{},{},{},{},{},{},{},{}",
                p.name.replace('"', "\"\""),
                row.path_frame,
                row.lods_skipped,
                row.objects_skipped,
                row.lod_deficit,
                row.visible_objects,
                row.wanted,
                row.hits,
                row.lookahead_bytes,
                u8::from(row.fallback),
                u8::from(row.outside)
            );
        }
    }
    out
}
