//! The cues the frame is read from (see the module above): how pieces touch along an axis,
//! and the unit that puts storeys, thicknesses and width where buildings have them.

use super::{MIN_SLAB_SHARE, Piece, UNIT_MARGIN};
use crate::frame::{LengthUnit, UpAxis};
use rustc_hash::FxHashMap;

/// What a rarely used unit (decimetres) costs against the others, in e-folds.
const RARE: f64 = 0.3;

/// Storey heights (metres): what stands between a floor and what it carries.
const STOREY: (f64, f64) = (2.3, 4.0);
/// Wall and slab thicknesses (metres).
const THICKNESS: (f64, f64) = (0.05, 0.5);
/// A building's width (metres).
const WIDTH: (f64, f64) = (3.0, 2000.0);

/// Pieces asked about at most (evenly spread over a larger model).
const MAX_ASKED: usize = 20_000;

/// Supporters looked at per level at most (the largest first).
const MAX_LOOKED: usize = 64;

/// How the pieces touch along one axis.
#[derive(Debug, Clone, Default)]
pub(super) struct Contacts {
    /// Pieces asked (those not thin along the axis).
    pub(super) asked: usize,
    /// The share of the pieces asked whose lowest point lies
    /// on another piece's highest, their boxes overlapping across it: resting on it, if the
    /// axis is up.
    pub(super) resting: f64,
    /// The heights and areas of the pieces that rest on one piece and carry another (a wall
    /// between a floor and the slab above, a column under an arch): the storeys, if the axis
    /// is up.
    pub(super) between: Vec<(f64, f64)>,
}

/// How the pieces touch along `axis` (see [`Contacts`]).
pub(super) fn contacts(pieces: &[Piece], axis: usize) -> Contacts {
    if pieces.len() < 2 {
        return Contacts::default();
    }
    let lo = pieces
        .iter()
        .map(|p| p.bounds.min[axis])
        .fold(f64::INFINITY, f64::min);
    let hi = pieces
        .iter()
        .map(|p| p.bounds.max[axis])
        .fold(f64::NEG_INFINITY, f64::max);
    let tol = ((hi - lo) * 0.001).max(f64::MIN_POSITIVE);
    let key = |v: f64| ((v - lo) / tol).round() as i64;
    // Pieces by the level of their top and of their bottom, the largest footprint first.
    let across = |p: &Piece| {
        let s = p.bounds.max - p.bounds.min;
        (0..3).filter(|&a| a != axis).map(|a| s[a]).product::<f64>()
    };
    let mut tops: FxHashMap<i64, Vec<usize>> = FxHashMap::default();
    let mut bottoms: FxHashMap<i64, Vec<usize>> = FxHashMap::default();
    for (i, p) in pieces.iter().enumerate() {
        tops.entry(key(p.bounds.max[axis])).or_default().push(i);
        bottoms.entry(key(p.bounds.min[axis])).or_default().push(i);
    }
    for list in tops.values_mut().chain(bottoms.values_mut()) {
        list.sort_by(|&a, &b| across(&pieces[b]).total_cmp(&across(&pieces[a])));
        list.truncate(MAX_LOOKED);
    }
    let overlaps = |a: &Piece, b: &Piece| {
        (0..3).filter(|&x| x != axis).all(|x| {
            a.bounds.min[x] < b.bounds.max[x] - tol && b.bounds.min[x] < a.bounds.max[x] - tol
        })
    };
    // Whether a piece of `levels` other than `i` has its level (top or bottom) at `at` and
    // overlaps piece `i`.
    let touches = |levels: &FxHashMap<i64, Vec<usize>>, i: usize, at: f64, top: bool| {
        let k = key(at);
        (k - 1..=k + 1).any(|k| {
            levels.get(&k).is_some_and(|list| {
                list.iter().any(|&j| {
                    let b = &pieces[j].bounds;
                    let level = if top { b.max[axis] } else { b.min[axis] };
                    j != i && (level - at).abs() <= tol && overlaps(&pieces[i], &pieces[j])
                })
            })
        })
    };
    let stride = pieces.len().div_ceil(MAX_ASKED).max(1);
    let (mut asked, mut resting) = (0usize, 0usize);
    let mut between = Vec::new();
    for (i, p) in pieces.iter().enumerate().step_by(stride) {
        let s = p.bounds.max - p.bounds.min;
        let mut others: Vec<f64> = (0..3).filter(|&a| a != axis).map(|a| s[a]).collect();
        others.sort_by(f64::total_cmp);
        if s[axis] <= others[0] / 3.0 {
            continue; // thin along the axis: a slab on walls, a wall against a wall
        }
        asked += 1;
        if touches(&tops, i, p.bounds.min[axis], true) {
            resting += 1;
            if touches(&bottoms, i, p.bounds.max[axis], false) {
                between.push((s[axis], p.area));
            }
        }
    }
    Contacts {
        asked,
        resting: if asked == 0 {
            0.0
        } else {
            resting as f64 / asked as f64
        },
        between,
    }
}

/// The unit that puts the walls' heights, the thin pieces' thicknesses and the building's
/// width where buildings have them, if one does clearly; what was measured; and the share of
/// the area in slabs.
pub(super) fn unit_of(
    pieces: &[Piece],
    up: UpAxis,
    between: &[(f64, f64)],
) -> (Option<LengthUnit>, String, f64) {
    let up = up.index();
    let mut heights = Vec::new();
    let mut thicknesses = Vec::new();
    let total: f64 = pieces.iter().map(|p| p.area).sum();
    let mut slabs = 0.0;
    for p in pieces {
        let size = p.bounds.max - p.bounds.min;
        let mut axes = [0usize, 1, 2];
        axes.sort_by(|&a, &b| size[a].total_cmp(&size[b]));
        let (thin, mid) = (size[axes[0]], size[axes[1]]);
        if mid <= 0.0 || thin > mid / 3.0 {
            continue;
        }
        if thin > 0.0 {
            thicknesses.push((thin, p.area));
        }
        if axes[0] == up {
            slabs += p.area;
        }
        if axes[0] != up && size[up] > 2.0 * thin {
            heights.push((size[up], p.area));
        }
    }
    // The storey: what stands between a floor and what it carries where anything does (a
    // gable wall or an atrium's façade rises through several), else the walls' heights.
    let mut storeys = between.to_vec();
    let (height, measured) = match weighted_median(&mut storeys) {
        Some(h) => (Some(h), "storeys"),
        None => (weighted_median(&mut heights), "wall heights"),
    };
    let thickness = weighted_median(&mut thicknesses);
    let width = width_of(pieces, up);
    let score = |u: LengthUnit| {
        let m = u.metres();
        height.map_or(0.0, |h| fit(h * m, STOREY))
            + thickness.map_or(0.0, |t| fit(t * m, THICKNESS))
            + width.map_or(0.0, |w| fit(w * m, WIDTH))
            - if u == LengthUnit::Decimetre {
                RARE
            } else {
                0.0
            }
    };
    let mut ranked: Vec<(LengthUnit, f64)> =
        LengthUnit::ALL.iter().map(|&u| (u, score(u))).collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
    let slab_share = if total > 0.0 { slabs / total } else { 0.0 };
    let measures: Vec<String> = [
        (measured, height),
        ("thicknesses", thickness),
        ("width", width),
    ]
    .into_iter()
    .filter_map(|(what, v)| v.map(|v| format!("{what} {}", round3(v))))
    .collect();
    let why = format!(
        "{} in the file's units; {:.0} % of the area in floors and slabs{}",
        if measures.is_empty() {
            "nothing measured".to_string()
        } else {
            measures.join(", ")
        },
        100.0 * slab_share,
        if height.is_none() {
            "; no storeys or walls found"
        } else {
            ""
        }
    );
    let (best, best_score) = ranked[0];
    // Found only when the storey itself fits: the other cues cannot tell units 10× apart.
    let storey_fits = height.is_some_and(|h| fit(h * best.metres(), STOREY) > -0.5);
    let sure = storey_fits
        && slab_share >= MIN_SLAB_SHARE
        && best_score > -1.5
        && ranked[1].1 < best_score - UNIT_MARGIN;
    (sure.then_some(best), why, slab_share)
}

/// Three significant digits.
fn round3(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    let p = 10f64.powi(2 - v.abs().log10().floor() as i32);
    (v * p).round() / p
}

/// Log-plausibility of `v` for a range: 0 inside, minus the e-folds outside.
fn fit(v: f64, (lo, hi): (f64, f64)) -> f64 {
    if v <= 0.0 || !v.is_finite() {
        -10.0
    } else if v < lo {
        -(lo / v).ln()
    } else if v > hi {
        -(v / hi).ln()
    } else {
        0.0
    }
}

/// The area-weighted median of `(value, weight)` pairs.
fn weighted_median(v: &mut [(f64, f64)]) -> Option<f64> {
    let total: f64 = v.iter().map(|x| x.1).sum();
    if v.is_empty() || total <= 0.0 {
        return None;
    }
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut acc = 0.0;
    for &(value, w) in v.iter() {
        acc += w;
        if acc >= total * 0.5 {
            return Some(value);
        }
    }
    v.last().map(|x| x.0)
}

/// The building's width: the larger horizontal span from the 2nd percentile of the pieces'
/// lowest coordinates to the 98th of their highest (strays far away do not count).
fn width_of(pieces: &[Piece], up: usize) -> Option<f64> {
    if pieces.is_empty() {
        return None;
    }
    let at = |v: &mut Vec<f64>, q: f64| {
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q).round() as usize]
    };
    let best = (0..3)
        .filter(|&a| a != up)
        .map(|axis| {
            let mut lo: Vec<f64> = pieces.iter().map(|p| p.bounds.min[axis]).collect();
            let mut hi: Vec<f64> = pieces.iter().map(|p| p.bounds.max[axis]).collect();
            at(&mut hi, 0.98) - at(&mut lo, 0.02)
        })
        .fold(0.0, f64::max);
    (best > 0.0).then_some(best)
}
