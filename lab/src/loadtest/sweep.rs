//! The policy grids of Funkhouser §5.3 (Tables 5.1–5.10): lookahead depth 1, 4, 8, 16, 32, 64
//! frames × granularity object | cell × range cull any | plane | frustum | direction ×
//! lookahead cull any | plane | frustum. The whole grid is 144 runs; named subsets reproduce one
//! table each, and `reduced` (the default of `--sweep`) touches every axis in 13 runs.

use portico_client::policy::policy_spec;
use portico_protocol::{Granularity, LookaheadCull, Policy, RangeCull};

/// Funkhouser's lookahead depths (frames).
pub const DEPTHS: [u32; 6] = [1, 4, 8, 16, 32, 64];
/// Granularities, in table order.
pub const GRANULARITIES: [Granularity; 2] = [Granularity::Object, Granularity::Cell];
/// Range culls, in table order.
pub const RANGE_CULLS: [RangeCull; 4] = [
    RangeCull::Any,
    RangeCull::Plane,
    RangeCull::Frustum,
    RangeCull::Direction,
];
/// Lookahead culls, in table order.
pub const LOOK_CULLS: [LookaheadCull; 3] = [
    LookaheadCull::Any,
    LookaheadCull::Plane,
    LookaheadCull::Frustum,
];
/// The names [`grid`] knows.
pub const GRIDS: [&str; 5] = ["reduced", "full", "depth", "gran", "cull"];

/// An unknown sweep name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown sweep {0:?} (expected reduced, full, depth, gran or cull)")]
pub struct UnknownSweep(pub String);

/// The named grid of policies on top of `base` (its budgets and size threshold are kept), each
/// named by its spec, in Funkhouser's table order (granularity, range cull, depth, look cull):
///
/// - `reduced` (13): Table 5.3 at depths 1, 4, 16, 64, plus each other range cull and each
///   other lookahead cull at depth 16 with object granularity;
/// - `full` (144): every combination;
/// - `depth` (6): Table 5.1, object granularity, no culls;
/// - `gran` (12): Table 5.3, both granularities, no culls;
/// - `cull` (72): Tables 5.5–5.10, object granularity, every range × lookahead cull.
pub fn grid(name: &str, base: Policy) -> Result<Vec<(String, Policy)>, UnknownSweep> {
    let mut all = Vec::new();
    for g in GRANULARITIES {
        for r in RANGE_CULLS {
            for d in DEPTHS {
                for l in LOOK_CULLS {
                    all.push((g, r, d, l));
                }
            }
        }
    }
    use {Granularity as G, LookaheadCull as L, RangeCull as R};
    let keep = |&(g, r, d, l): &(G, R, u32, L)| -> Result<bool, UnknownSweep> {
        let plain = r == R::Any && l == L::Any;
        Ok(match name.trim() {
            "" | "reduced" => {
                (plain && [1, 4, 16, 64].contains(&d))
                    || (g == G::Object && d == 16 && (r == R::Any || l == L::Any))
            }
            "full" => true,
            "depth" => plain && g == G::Object,
            "gran" => plain,
            "cull" => g == G::Object,
            other => return Err(UnknownSweep(other.to_string())),
        })
    };
    let mut out = Vec::new();
    for c in all {
        if keep(&c)? {
            let (granularity, range_cull, depth_frames, lookahead_cull) = c;
            let p = Policy {
                depth_frames,
                granularity,
                range_cull,
                lookahead_cull,
                ..base
            };
            out.push((policy_spec(&p), p));
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grids_have_funkhousers_sizes() {
        let n = |s| grid(s, Policy::default()).unwrap().len();
        assert_eq!(n("full"), 144);
        assert_eq!(n("reduced"), 13);
        assert_eq!(n(""), 13);
        assert_eq!(n("depth"), 6);
        assert_eq!(n("gran"), 12);
        assert_eq!(n("cull"), 72);
        assert_eq!(
            grid("huge", Policy::default()),
            Err(UnknownSweep("huge".into()))
        );
        let full = grid("full", Policy::default()).unwrap();
        let names: std::collections::HashSet<_> = full.iter().map(|(n, _)| n.clone()).collect();
        assert_eq!(names.len(), 144, "every run has its own name");
        assert_eq!(full[0].0, "depth=1,gran=object,range=any,look=any");
    }
}
