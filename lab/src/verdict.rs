//! Verdicts: each headline figure of a walk or a load test judged against its target, in
//! words, so a report says whether a number is good instead of leaving the reader to guess.
//!
//! The targets are the system's promises: frames within the budget and never waiting for data
//! (Funkhouser §5.2.4: the client draws what is resident), few LODs and objects skipped, a
//! cache that keeps to its budget; and for prefetch, that reading ahead pays for itself against
//! demand fetch (Funkhouser §5.3). A verdict that is not met says why when the reason is known.

use crate::loadtest::{LoadtestSummary, PolicyResult};
use portico_native::walk::WalkSummary;
use serde::Serialize;
use std::fmt;

/// One figure judged against its target.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verdict {
    /// What is judged, e.g. "frame time p99".
    pub figure: String,
    /// The target in words, e.g. "≤ the 50 ms budget".
    pub target: String,
    /// The measured value in words.
    pub value: String,
    /// Whether the target is met.
    pub met: bool,
    /// One sentence: what the figure means, and why when it is not met.
    pub why: String,
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mark = if self.met { "met" } else { "NOT met" };
        write!(
            f,
            "{mark}: {} {} (target {}). {}",
            self.figure, self.value, self.target, self.why
        )
    }
}

fn v(figure: &str, target: String, value: String, met: bool, why: String) -> Verdict {
    Verdict {
        figure: figure.into(),
        target,
        value,
        met,
        why,
    }
}

/// Largest mean LODs skipped per frame that counts as "nearly none".
pub const LODS_SKIPPED_TARGET: f64 = 0.05;
/// Largest mean objects skipped per frame (visible, nothing resident) for a walk.
pub const OBJECTS_SKIPPED_TARGET: f64 = 0.25;
/// Largest share of frames over the budget.
pub const OVER_BUDGET_SHARE: f64 = 0.01;
/// How many times fewer LODs prefetch should skip than demand fetch, where demand skips any.
pub const PREFETCH_GAIN_TARGET: f64 = 5.0;

/// A walk's verdicts: frame time, frames over budget, LODs and objects skipped, cache, IO.
pub fn walk(s: &WalkSummary) -> Vec<Verdict> {
    let ms = |x: f64| x * 1e3;
    let over = s.frames_over_budget as f64 / s.frames.max(1) as f64;
    vec![
        v(
            "frame time p99",
            format!("≤ the {:.0} ms budget", ms(s.budget_s)),
            format!("{:.1} ms", ms(s.frame_s.p99)),
            s.frame_s.p99 <= s.budget_s,
            "Detail elision keeps each frame's predicted cost within the budget.".into(),
        ),
        v(
            "frames over budget",
            format!("≤ {:.0} %", OVER_BUDGET_SHARE * 100.0),
            format!(
                "{} of {} ({:.1} %)",
                s.frames_over_budget,
                s.frames,
                over * 100.0
            ),
            over <= OVER_BUDGET_SHARE,
            "The client never waits for data: what has not arrived is not drawn.".into(),
        ),
        v(
            "LODs skipped per frame",
            format!("mean ≤ {LODS_SKIPPED_TARGET}"),
            format!(
                "{:.3} mean, {:.0} max",
                s.lods_skipped.mean, s.lods_skipped.max
            ),
            s.lods_skipped.mean <= LODS_SKIPPED_TARGET,
            "An object drawn coarser than chosen because the finer LOD had not arrived.".into(),
        ),
        v(
            "objects skipped per frame",
            format!("mean ≤ {OBJECTS_SKIPPED_TARGET}"),
            format!(
                "{:.3} mean, {:.0} max",
                s.objects_skipped.mean, s.objects_skipped.max
            ),
            s.objects_skipped.mean <= OBJECTS_SKIPPED_TARGET,
            if s.objects_skipped.max > 0.0 {
                "Visible objects with nothing resident yet, mostly in the first frames, before \
                 the first answers arrive."
                    .into()
            } else {
                "Every visible object had something resident.".into()
            },
        ),
        v(
            "cache peak",
            format!(
                "≤ the {:.0} MiB budget",
                s.cache_budget as f64 / 1_048_576.0
            ),
            format!("{:.1} MiB", s.cache_peak_bytes as f64 / 1_048_576.0),
            s.cache_peak_bytes <= s.cache_budget,
            "The cache makes room before anything goes in.".into(),
        ),
        v(
            "IO failures",
            "0".into(),
            s.io_failures.to_string(),
            s.io_failures == 0,
            "Segments refused (bad checksum) or requests that failed.".into(),
        ),
    ]
}

/// A load test's verdicts on its best prefetch policy against demand fetch and the oracle;
/// empty without the baselines.
pub fn loadtest(s: &LoadtestSummary) -> Vec<Verdict> {
    let (Some(p), Some(d)) = (s.best_prefetch(), s.get("demand")) else {
        return Vec::new();
    };
    let oracle = s.get("oracle");
    let mut out = vec![lods_gain(p, d)];
    out.push(v(
        "objects skipped per frame, prefetch",
        "≤ demand fetch's".into(),
        format!(
            "{:.2} vs {:.2}",
            p.objects_skipped_mean, d.objects_skipped_mean
        ),
        p.objects_skipped_mean <= d.objects_skipped_mean,
        if p.objects_skipped_mean <= d.objects_skipped_mean {
            "Reading ahead had the objects in view resident sooner.".into()
        } else {
            "Prefetch's early answers list many objects seen from the range cells before the \
             ones in view, so at the start the view waits behind read-ahead."
                .into()
        },
    ));
    if let (Some(pf), Some(df)) = (p.first_complete_frame_mean, d.first_complete_frame_mean) {
        out.push(v(
            "first complete frame, prefetch",
            "no later than demand fetch's".into(),
            format!("frame {pf:.1} vs {df:.1}"),
            pf <= df,
            if pf <= df {
                "The first view was whole as soon as demand fetch's.".into()
            } else {
                "Cold start: what the view lacked was read first, as demand fetch reads it, \
                 but it shared the link with read-ahead already on the wire."
                    .into()
            },
        ));
    }
    out.push(v(
        "request-to-resident latency p50, prefetch",
        "≤ demand fetch's".into(),
        format!(
            "{:.0} ms vs {:.0} ms",
            p.latency_p50_s * 1e3,
            d.latency_p50_s * 1e3
        ),
        p.latency_p50_s <= d.latency_p50_s,
        if p.latency_p50_s <= d.latency_p50_s {
            "Segments arrived as fast as demand fetch's.".into()
        } else {
            "Expected: prefetch asks frames ahead of need, so its requests queue behind one \
             another; what matters is whether they arrive before they are drawn (LODs skipped)."
                .into()
        },
    ));
    if let Some(o) = oracle {
        out.extend(against_oracle(p, o));
        let ratio = p.bytes_fetched as f64 / o.bytes_fetched.max(1) as f64;
        out.push(v(
            "bytes fetched, prefetch",
            "≤ 2× the oracle's".into(),
            format!(
                "{:.1} MB vs {:.1} MB per client ({ratio:.2}×)",
                p.bytes_fetched_per_client as f64 / 1e6,
                o.bytes_fetched_per_client as f64 / 1e6
            ),
            ratio <= 2.0,
            if ratio <= 2.0 {
                "Little is read that is never drawn.".into()
            } else {
                "Reading ahead from cell-to-object visibility fetches much that is never drawn \
                 (Funkhouser §5.3.1 found the same)."
                    .into()
            },
        ));
    }
    out
}

/// How many times the oracle's objects skipped per frame prefetch may skip, over the whole run.
pub const ORACLE_OBJECTS_FACTOR: f64 = 1.25;
/// How many more LODs skipped per frame than the oracle's prefetch may skip.
pub const ORACLE_LODS_SLACK: f64 = 0.02;

/// Prefetch against the oracle over the whole run, warm-up included: objects skipped ≤
/// [`ORACLE_OBJECTS_FACTOR`]× the oracle's, LODs skipped ≤ the oracle's +
/// [`ORACLE_LODS_SLACK`].
fn against_oracle(p: &PolicyResult, o: &PolicyResult) -> [Verdict; 2] {
    let objects_met = p.objects_skipped_mean <= o.objects_skipped_mean * ORACLE_OBJECTS_FACTOR;
    let lods_met = p.lods_skipped_mean <= o.lods_skipped_mean + ORACLE_LODS_SLACK;
    [
        v(
            "objects skipped per frame, prefetch vs oracle (warm-up included)",
            format!("≤ {ORACLE_OBJECTS_FACTOR}× the oracle's"),
            format!(
                "{:.2} vs {:.2}",
                p.objects_skipped_mean, o.objects_skipped_mean
            ),
            objects_met,
            if objects_met {
                "Prefetch had the objects in view nearly as soon as a client that knows the \
                 path."
                    .into()
            } else {
                "A client that knows the path has the objects in view sooner: the lookahead's \
                 order or its cold start costs frames."
                    .into()
            },
        ),
        v(
            "LODs skipped per frame, prefetch vs oracle (warm-up included)",
            format!("≤ the oracle's + {ORACLE_LODS_SLACK}"),
            format!("{:.3} vs {:.3}", p.lods_skipped_mean, o.lods_skipped_mean),
            lods_met,
            if lods_met {
                "The finer LODs arrived about as soon as a client that knows the path has them."
                    .into()
            } else {
                "The finer LODs arrive later than for a client that knows the path.".into()
            },
        ),
    ]
}

/// The cache sweep's verdict: prefetch skips no more objects per frame than demand fetch (within
/// [`NO_WORSE_SLACK`](crate::loadtest::cache_sweep::NO_WORSE_SLACK)) at every cache budget;
/// not met, naming the budgets, where it does (or where a budget has no baselines).
pub fn cache_sweep(rows: &[crate::loadtest::cache_sweep::Row]) -> Verdict {
    let worse: Vec<String> = rows
        .iter()
        .filter(|r| r.no_worse_than_demand() != Some(true))
        .map(|r| match (&r.prefetch, &r.demand) {
            (Some(p), Some(d)) => format!(
                "{} MiB: {:.2} vs {:.2}",
                r.cache_mb, p.objects_skipped_mean, d.objects_skipped_mean
            ),
            _ => format!("{} MiB: no prefetch or no demand run", r.cache_mb),
        })
        .collect();
    let met = worse.is_empty() && !rows.is_empty();
    let sizes: Vec<String> = rows.iter().map(|r| r.cache_mb.to_string()).collect();
    v(
        "objects skipped per frame, prefetch vs demand fetch, at every cache budget",
        format!(
            "≤ demand fetch's (+ {})",
            crate::loadtest::cache_sweep::NO_WORSE_SLACK
        ),
        if met {
            format!("no worse at {} MiB", sizes.join(", "))
        } else {
            format!("worse at {}", worse.join("; "))
        },
        met,
        if met {
            "The lookahead fits the cache beside the current view at every budget.".into()
        } else {
            "Where the cache is small, reading ahead evicts what the next frames draw \
             (thrash): the lookahead must stop at the budget left after the current view \
             (Funkhouser §5.3)."
                .into()
        },
    )
}

/// Prefetch against demand fetch on LODs skipped: ≥ 5× fewer, or both nearly none.
fn lods_gain(p: &PolicyResult, d: &PolicyResult) -> Verdict {
    let both_low = d.lods_skipped_mean <= LODS_SKIPPED_TARGET;
    let gain = d.lods_skipped_mean / p.lods_skipped_mean.max(1e-9);
    let met =
        both_low && p.lods_skipped_mean <= d.lods_skipped_mean || gain >= PREFETCH_GAIN_TARGET;
    let value = format!(
        "{:.3} vs {:.3} per frame{}",
        p.lods_skipped_mean,
        d.lods_skipped_mean,
        if p.lods_skipped_mean > 0.0 && gain >= 1.0 {
            format!(" ({gain:.1}× fewer)")
        } else if p.lods_skipped_mean > 0.0 {
            format!(" ({:.1}× more)", 1.0 / gain.max(1e-9))
        } else {
            String::new()
        }
    );
    let why = if both_low {
        "Demand fetch skips nearly nothing on this link either: there is little for reading \
         ahead to win."
    } else if met {
        "Reading ahead has the finer LODs resident before the frames that want them."
    } else {
        "Reading ahead does not arrive in time on this link for the LODs the frames want."
    };
    v(
        "LODs skipped per frame, prefetch vs demand fetch",
        format!("≥ {PREFETCH_GAIN_TARGET:.0}× fewer, or both ≤ {LODS_SKIPPED_TARGET}"),
        value,
        met,
        why.into(),
    )
}

/// Markdown table of verdicts.
pub fn table(verdicts: &[Verdict]) -> String {
    let mut s =
        String::from("| figure | value | target | verdict | why |\n|---|---|---|---|---|\n");
    for v in verdicts {
        s.push_str(&format!(
            "| {} | {} | {} | **{}** | {} |\n",
            v.figure,
            v.value,
            v.target,
            if v.met { "met" } else { "not met" },
            v.why
        ));
    }
    s
}
