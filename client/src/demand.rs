//! What a frame lacked: demand fetch's need list, and the head of every other one.
//!
//! Funkhouser 1993 §5.2.4 reads a coarse LOD of everything visible before anything finer, so
//! that no visible object stays missing while finer detail loads. [`lacking`] is that order for
//! one frame's [`Decision`]: the eye cell's stab list, then the coarsest LOD of every wanted
//! object with nothing to draw, then every wanted LOD and texture level not resident, the
//! biggest on screen first within each group.
//!
//! Demand fetch asks for exactly this list. The oracle and the server's lookahead put it ahead
//! of their read-ahead ([`ahead_of`], [`crate::deadline::ReadPlan`]): the server's answer is a
//! round trip old and lists what its potentially visible sets hold, while this is what the
//! client's own view lacks now, so a cold start fetches what is in view as soon as demand fetch
//! would; and while the view has objects with nothing to draw, read-ahead waits.

use crate::frame::{Decision, Scene};
use std::collections::HashSet;

/// What `d` lacked, most urgent first (see the module docs); `has` says what is resident or
/// on its way.
pub fn lacking(d: &Decision, scene: &Scene<'_>, has: &dyn Fn(u32) -> bool) -> Vec<u32> {
    lacking_with(d, &|i| d.segments(scene, i), has)
}

/// [`lacking`] with each candidate's LOD segments (finest allowed first, as
/// [`Decision::segments`]) given by `segments`.
pub fn lacking_with(
    d: &Decision,
    segments: &dyn Fn(usize) -> Vec<u32>,
    has: &dyn Fn(u32) -> bool,
) -> Vec<u32> {
    let mut stand_ins = Vec::new();
    let mut wanted = Vec::new();
    for (i, (c, ch)) in d.candidates.iter().zip(&d.frame.choices).enumerate() {
        let Some(want) = ch.desired else { continue };
        let segs = segments(i);
        if ch.lod.is_none()
            && let Some(&coarsest) = segs.last()
            && !has(coarsest)
        {
            stand_ins.push((c.pixels, coarsest));
        }
        if let Some(&s) = segs.get(want)
            && !has(s)
        {
            wanted.push((c.pixels, s));
        }
    }
    // The texture level each drawn object's size asks for, when it lacks it.
    for o in &d.drawn {
        if let Some(t) = o.wants_texture.filter(|&t| !has(t)) {
            let pixels = d
                .candidates
                .iter()
                .find(|c| c.id == o.instance)
                .map_or(0.0, |c| c.pixels);
            wanted.push((pixels, t));
        }
    }
    stand_ins.sort_by(|a, b| b.0.total_cmp(&a.0));
    wanted.sort_by(|a, b| b.0.total_cmp(&a.0));
    let stab = d.eye_stab.filter(|&s| !has(s));
    ahead_of(
        &stab.into_iter().collect::<Vec<_>>(),
        stand_ins.into_iter().chain(wanted).map(|x| x.1),
    )
}

/// `first`, then what of `then` is not in it, each id once, in that order.
pub fn ahead_of(first: &[u32], then: impl IntoIterator<Item = u32>) -> Vec<u32> {
    let mut seen = HashSet::new();
    first
        .iter()
        .copied()
        .chain(then)
        .filter(|&s| seen.insert(s))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elision::{Candidate, Choice};
    use crate::frame::Drawn;

    /// Three candidates with LOD segments `[10, 11, 12]`, `[20, 21]`, `[30, 31]`: the first
    /// drawn at its coarsest wanting its finest, the second with nothing resident, the third
    /// not wanted at all; the first also wants texture level 40.
    fn decision() -> (Decision, Vec<Vec<u32>>) {
        let mut d = Decision {
            eye_stab: Some(7),
            ..Decision::default()
        };
        d.candidates = vec![
            Candidate::new(0, Vec::new(), 100.0),
            Candidate::new(1, Vec::new(), 400.0),
            Candidate::new(2, Vec::new(), 900.0),
        ];
        d.frame.choices = vec![
            Choice {
                lod: Some(2),
                desired: Some(0),
                lods_skipped: 2,
                object_skipped: false,
            },
            Choice {
                lod: None,
                desired: Some(0),
                lods_skipped: 0,
                object_skipped: true,
            },
            Choice::default(),
        ];
        d.drawn = vec![Drawn {
            instance: 0,
            lod: 2,
            segment: 12,
            texture: None,
            tint: [1.0; 4],
            wants_texture: Some(40),
        }];
        (d, vec![vec![10, 11, 12], vec![20, 21], vec![30, 31]])
    }

    #[test]
    fn the_stab_list_then_stand_ins_then_finer_detail_biggest_first() {
        let (d, segs) = decision();
        let resident = [12u32];
        let got = lacking_with(&d, &|i| segs[i].clone(), &|s| resident.contains(&s));
        // Stab list; object 1's coarsest (nothing drawn); then the finest wanted LODs and the
        // texture, the 400 px object before the 100 px one (its LOD before its texture: stable).
        assert_eq!(got, vec![7, 21, 20, 10, 40]);
    }

    #[test]
    fn nothing_resident_or_on_its_way_is_listed() {
        let (d, segs) = decision();
        let all = [7u32, 10, 20, 21, 40];
        assert!(lacking_with(&d, &|i| segs[i].clone(), &|s| all.contains(&s)).is_empty());
    }

    #[test]
    fn ahead_of_keeps_the_first_order_and_drops_repeats() {
        assert_eq!(ahead_of(&[3, 1], [1, 2, 3, 4, 2]), vec![3, 1, 2, 4]);
        assert_eq!(ahead_of(&[], [5, 5]), vec![5]);
    }
}
