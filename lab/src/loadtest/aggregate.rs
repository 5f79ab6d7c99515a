//! One policy's figures from its clients' results: LODs and objects skipped and the LOD deficit
//! (Funkhouser 1993 §5.2.4), before and after the warm-up, cache hits, fetch latencies, the
//! server's answers and CPU, and every run's ratio to demand fetch.

use super::sim::{self, ClientResult, FrameStat, Mode};
use super::{ClientFigures, LoadtestConfig, PolicyResult, Transport, WARMUP_S, cpu};
use portico_client::stats::Series;

/// One policy's figures from its clients' results.
pub(super) fn aggregate(
    name: String,
    mode: Mode,
    cfg: &LoadtestConfig,
    clients: Vec<ClientResult>,
    wall_s: f64,
    usage: cpu::Usage,
) -> PolicyResult {
    let rows: Vec<&FrameStat> = clients.iter().flat_map(|c| &c.rows).collect();
    let col =
        |f: &dyn Fn(&FrameStat) -> f64| Series::of(&rows.iter().map(|r| f(r)).collect::<Vec<_>>());
    let answers: Vec<_> = clients.iter().flat_map(|c| &c.answers).collect();
    let acol = |f: &dyn Fn(&sim::AnswerStat) -> f64| {
        Series::of(&answers.iter().map(|a| f(a)).collect::<Vec<_>>())
    };
    let latencies: Vec<f64> = clients
        .iter()
        .flat_map(|c| c.latencies.iter().copied())
        .collect();
    let lat = Series::of(&latencies);
    let sum = |f: &dyn Fn(&ClientResult) -> u64| clients.iter().map(f).sum::<u64>();
    let n_clients = clients.len().max(1) as u64;
    let wanted: u64 = rows.iter().map(|r| r.wanted as u64).sum();
    let hits: u64 = rows.iter().map(|r| r.hits as u64).sum();
    let (lods, objects, deficit) = (
        col(&|r| r.lods_skipped as f64),
        col(&|r| r.objects_skipped as f64),
        col(&|r| r.lod_deficit as f64),
    );
    let lookahead = col(&|r| r.lookahead_bytes as f64 / 1e6);
    let (range, look, answer_ms) = (
        acol(&|a| a.range_cells as f64),
        acol(&|a| a.lookahead_objects as f64),
        acol(&|a| a.micros as f64 / 1e3),
    );
    let wall = wall_s.max(1e-9);
    let warmup = (WARMUP_S / cfg.budget_s).ceil() as usize;
    let warm: Vec<&FrameStat> = clients
        .iter()
        .flat_map(|c| c.rows.iter().skip(warmup))
        .collect();
    let warm_mean = |f: &dyn Fn(&FrameStat) -> u32| {
        (!warm.is_empty())
            .then(|| warm.iter().map(|r| f(r) as f64).sum::<f64>() / warm.len() as f64)
    };
    let complete: Vec<(u64, u64)> = clients.iter().filter_map(|c| c.first_complete).collect();
    let mean_of = |f: &dyn Fn(&(u64, u64)) -> u64| {
        (!complete.is_empty())
            .then(|| complete.iter().map(|c| f(c) as f64).sum::<f64>() / complete.len() as f64)
    };
    PolicyResult {
        complete_clients: complete.len() as u64,
        first_complete_frame_mean: mean_of(&|c| c.0),
        first_complete_bytes_mean: mean_of(&|c| c.1),
        kind: match mode {
            Mode::Prefetch(..) => "prefetch",
            Mode::Demand => "demand",
            Mode::Oracle { .. } => "oracle",
        }
        .into(),
        policy: match mode {
            Mode::Prefetch(p, _) => Some(p),
            _ => None,
        },
        transport: match mode {
            Mode::Prefetch(_, t) => t,
            _ => Transport::Pull,
        }
        .to_string(),
        name,
        frames: rows.len() as u64,
        lods_skipped_mean: lods.mean,
        lods_skipped_max: lods.max,
        objects_skipped_mean: objects.mean,
        objects_skipped_max: objects.max,
        lod_deficit_mean: deficit.mean,
        lod_deficit_max: deficit.max,
        lods_skipped_warm_mean: warm_mean(&|r| r.lods_skipped),
        objects_skipped_warm_mean: warm_mean(&|r| r.objects_skipped),
        lod_deficit_warm_mean: warm_mean(&|r| r.lod_deficit),
        visible_objects_mean: col(&|r| r.visible_objects as f64).mean,
        fallback_frames: rows.iter().filter(|r| r.fallback).count() as u64,
        outside_frames: rows.iter().filter(|r| r.outside).count() as u64,
        bytes_fetched: sum(&|c| c.bytes_fetched),
        bytes_fetched_per_client: sum(&|c| c.bytes_fetched) / n_clients,
        segments_fetched: sum(&|c| c.segments_fetched),
        bytes_wasted: sum(&|c| c.bytes_wasted),
        bytes_wasted_per_client: sum(&|c| c.bytes_wasted) / n_clients,
        waste_per_client: {
            let mut w = super::waste::Waste::default();
            clients.iter().for_each(|c| w.add(&c.waste));
            w.per(n_clients)
        },
        cache_hit_rate: if wanted == 0 {
            1.0
        } else {
            hits as f64 / wanted as f64
        },
        latency_p50_s: lat.p50,
        latency_p95_s: lat.p95,
        latency_p99_s: lat.p99,
        latency_mean_s: lat.mean,
        prefetch_requests: answers.len() as u64,
        prefetch_rps: answers.len() as f64 / wall,
        segment_rps: sum(&|c| c.segments_fetched) as f64 / wall,
        lookahead_mb_mean: lookahead.mean,
        lookahead_mb_max: lookahead.max,
        range_cells_mean: range.mean,
        range_cells_max: range.max,
        lookahead_objects_mean: look.mean,
        lookahead_objects_max: look.max,
        answer_ms_mean: answer_ms.mean,
        answer_ms_max: answer_ms.max,
        server_cpu_s: usage.server_s,
        server_cpu_cores: usage.server_s.map(|s| s / wall),
        server_handler_s: usage.handler_s,
        cache_budget_bytes: cfg.cache_bytes,
        cache_peak_bytes: clients.iter().map(|c| c.cache_peak).max().unwrap_or(0),
        evictions: sum(&|c| c.evictions),
        io_failures: sum(&|c| c.failures),
        wall_s,
        frame_period_s: wall_s / cfg.frames().max(1) as f64,
        lods_skipped_vs_demand: None,
        lod_deficit_vs_demand: None,
        lods_skipped_warm_vs_demand: None,
        per_client: clients.iter().map(client_figures).collect(),
        client0: clients.first().map(|c| c.rows.clone()).unwrap_or_default(),
    }
}

fn client_figures(c: &ClientResult) -> ClientFigures {
    let mean = |f: &dyn Fn(&FrameStat) -> u32| {
        c.rows.iter().map(|r| f(r) as f64).sum::<f64>() / c.rows.len().max(1) as f64
    };
    ClientFigures {
        start_frame: c.rows.first().map_or(0, |r| r.path_frame),
        lods_skipped_mean: mean(&|r| r.lods_skipped),
        objects_skipped_mean: mean(&|r| r.objects_skipped),
        lod_deficit_mean: mean(&|r| r.lod_deficit),
        fallback_frames: c.rows.iter().filter(|r| r.fallback).count() as u64,
        bytes_fetched: c.bytes_fetched,
        io_failures: c.failures,
        first_complete: c.first_complete,
    }
}

/// Fills in every run's ratio to demand fetch (how many times fewer LODs it skipped).
pub(super) fn compare_with_demand(results: &mut [PolicyResult]) {
    let Some(d) = results.iter().find(|r| r.kind == "demand") else {
        return;
    };
    let (lods, deficit, warm) = (
        d.lods_skipped_mean,
        d.lod_deficit_mean,
        d.lods_skipped_warm_mean,
    );
    let ratio = |base: f64, x: f64| (x > 0.0).then(|| base / x);
    for r in results.iter_mut() {
        r.lods_skipped_vs_demand = ratio(lods, r.lods_skipped_mean);
        r.lod_deficit_vs_demand = ratio(deficit, r.lod_deficit_mean);
        r.lods_skipped_warm_vs_demand = warm
            .zip(r.lods_skipped_warm_mean)
            .and_then(|(base, x)| ratio(base, x));
    }
}
