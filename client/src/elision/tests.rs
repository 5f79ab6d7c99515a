//! Tests of detail elision: the algorithm names, the accuracy and weight formulas, the static,
//! feedback and residency rules, and the optimiser's budget, residency, warm start, hysteresis
//! and closeness to a brute-force optimum (Funkhouser 1993 §4.2).

use super::*;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

fn lod(triangles: u32, resident: bool) -> LodOption {
    LodOption::new(triangles, triangles / 2 + 3, 0.0, resident)
}

/// LODs of `finest`, `finest/4`, … triangles (finest first), all resident.
fn chain(finest: u32, levels: usize) -> Vec<LodOption> {
    (0..levels)
        .map(|k| lod((finest >> (2 * k)).max(1), true))
        .collect()
}

fn random_candidates(
    rng: &mut SmallRng,
    n: usize,
    levels: usize,
    resident_p: f64,
) -> Vec<Candidate> {
    (0..n)
        .map(|i| {
            let finest = rng.random_range(50.0..20_000.0) as u32;
            let mut lods = chain(finest, levels);
            for l in &mut lods {
                l.resident = rng.random_bool(resident_p);
            }
            let mut c = Candidate::new(i as u32, lods, rng.random_range(10.0..200_000.0) as f32);
            c.focus = rng.random_range(0.0..1.0) as f32;
            c.motion = rng.random_range(0.0..1.0) as f32;
            c.importance = rng.random_range(0.5..2.0) as f32;
            c
        })
        .collect()
}

fn frame_cost(cands: &[Candidate], frame: &Frame, model: &CostModel) -> f64 {
    cands
        .iter()
        .zip(&frame.choices)
        .filter_map(|(c, ch)| ch.lod.map(|l| lod_cost(model, &c.lods[l], c.pixels)))
        .sum()
}

fn lods_of(frame: &Frame) -> Vec<Option<usize>> {
    frame.choices.iter().map(|c| c.lod).collect()
}

#[test]
fn algorithm_names_round_trip() {
    for a in Algorithm::ALL {
        assert_eq!(a.to_string().parse::<Algorithm>(), Ok(a));
    }
    assert_eq!(" Optimise ".parse::<Algorithm>(), Ok(Algorithm::Optimize));
    let err = "fast".parse::<Algorithm>().unwrap_err();
    assert!(err.to_string().contains("`fast`"), "{err}");
    assert_eq!(Algorithm::default(), Algorithm::Optimize);
}

#[test]
fn accuracy_follows_funkhouser() {
    let p = Params::default();
    assert_eq!(accuracy(&p, 1, 1000.0), 0.5);
    assert_eq!(accuracy(&p, 100, 1000.0), 0.995);
    // Samples never exceed the pixels covered.
    assert_eq!(accuracy(&p, 10_000, 100.0), accuracy(&p, 100, 100.0));
    assert_eq!(accuracy(&p, 0, 100.0), 0.0);
    assert_eq!(accuracy(&p, 50, f32::NAN), 0.5);
}

#[test]
fn texture_accuracy_counts_texels_up_to_the_pixels() {
    let p = Params::default();
    assert_eq!(texture_accuracy(&p, None, 1000.0), 1.0, "untextured");
    assert_eq!(
        texture_accuracy(&p, Some(0.0), 1000.0),
        0.5,
        "average colour"
    );
    assert_eq!(texture_accuracy(&p, Some(64.0), 1000.0), 1.0 - 0.5 / 64.0);
    // Texels finer than the pixels they land on add nothing.
    assert_eq!(
        texture_accuracy(&p, Some(1.0e6), 100.0),
        texture_accuracy(&p, Some(100.0), 100.0)
    );
    assert_eq!(texture_accuracy(&p, Some(f32::NAN), 100.0), 0.5);
    let textured = LodOption {
        texels: Some(0.0),
        ..lod(100, true)
    };
    assert_eq!(lod_accuracy(&p, &textured, 1000.0), 0.995 * 0.5);
    assert!(!textured.textured() && !lod(100, true).textured());
}

#[test]
fn optimize_spends_detail_where_the_texture_shows() {
    // Two objects alike but for their textures: A's is resident, B's is not (it would draw in
    // the average colour). Geometry-bound costs, a budget for one finest LOD and one coarse.
    let model = CostModel {
        c3: 0.0,
        c4: 0.0,
        ..CostModel::default()
    };
    let with = |texels: f32| {
        chain(1000, 2)
            .into_iter()
            .map(|l| LodOption {
                texels: Some(texels),
                ..l
            })
            .collect::<Vec<_>>()
    };
    let cands = vec![
        Candidate::new(0, with(0.0), 50_000.0),
        Candidate::new(1, with(4096.0), 50_000.0),
    ];
    let budget = model.cost(1000, 503, 0.0) + model.cost(250, 128, 0.0) + 1e-9;
    let frame = Elider::new(Algorithm::Optimize, budget).choose(&cands, &model, None);
    assert_eq!(lods_of(&frame), vec![Some(1), Some(0)]);
}

#[test]
fn a_texture_makes_fill_bound_objects_cost_more() {
    let model = CostModel::default();
    let plain = vec![Candidate::new(0, chain(100, 1), 200_000.0)];
    let textured = vec![Candidate::new(
        0,
        vec![LodOption {
            texels: Some(4096.0),
            ..chain(100, 1)[0]
        }],
        200_000.0,
    )];
    let predicted = |c: &[Candidate]| {
        Elider::new(Algorithm::None, 1.0)
            .choose(c, &model, None)
            .predicted_s
    };
    assert_eq!(predicted(&plain), model.c3 * 200_000.0);
    assert_eq!(predicted(&textured), (model.c3 + model.c4) * 200_000.0);
}

#[test]
fn object_weight_multiplies_size_importance_focus_motion() {
    let p = Params::default();
    let mut c = Candidate::new(1, chain(100, 2), 1000.0);
    assert_eq!(object_weight(&p, &c), 1000.0);
    c.focus = 0.0;
    c.motion = 0.0;
    c.importance = 2.0;
    assert_eq!(object_weight(&p, &c), 1000.0 * 2.0 * 0.5 * 0.5);
    c.pixels = f32::INFINITY;
    assert_eq!(object_weight(&p, &c), 0.0);
}

#[test]
fn none_draws_the_finest_lod() {
    let cands = vec![
        Candidate::new(1, chain(4096, 3), 10.0),
        Candidate::new(2, vec![], 10.0),
    ];
    let f = Elider::new(Algorithm::None, 0.0).choose(&cands, &CostModel::default(), None);
    assert_eq!(lods_of(&f), vec![Some(0), None]);
    assert_eq!(f.objects_skipped, 0);
    assert!(f.predicted_s > 0.0);
}

#[test]
fn static_picks_the_finest_lod_with_1024_pixels_per_polygon() {
    let lods = chain(4096, 4); // 4096, 1024, 256, 64 triangles
    let t = 1024.0;
    assert_eq!(static_lod(&lods, 4096.0 * 1024.0, t), Some(0));
    assert_eq!(static_lod(&lods, 4096.0 * 1024.0 - 1.0, t), Some(1));
    assert_eq!(static_lod(&lods, 256.0 * 1024.0, t), Some(2));
    assert_eq!(static_lod(&lods, 64.0 * 1024.0, t), Some(3));
    assert_eq!(static_lod(&lods, 10.0, t), Some(3), "else the coarsest");
    assert_eq!(static_lod(&[], 10.0, t), None);
    let cands = vec![Candidate::new(7, lods, 300_000.0)];
    let f = Elider::new(Algorithm::Static, 0.1).choose(&cands, &CostModel::default(), None);
    assert_eq!(f.choices[0].lod, Some(2));
}

#[test]
fn residency_fallback_counts_skips() {
    let lods = vec![
        lod(1000, false),
        lod(250, false),
        lod(60, true),
        lod(15, true),
    ];
    let c = resident_fallback(&lods, Some(0));
    assert_eq!(
        (c.lod, c.desired, c.lods_skipped, c.object_skipped),
        (Some(2), Some(0), 2, false)
    );
    assert_eq!(resident_fallback(&lods, Some(3)).lods_skipped, 0);
    let none = vec![lod(1000, false), lod(250, false)];
    let c = resident_fallback(&none, Some(0));
    assert_eq!((c.lod, c.lods_skipped, c.object_skipped), (None, 0, true));
    // Never draws a finer LOD than desired, even if only that one is resident.
    let fine_only = vec![lod(1000, true), lod(250, false)];
    assert!(resident_fallback(&fine_only, Some(1)).object_skipped);
    assert_eq!(resident_fallback(&lods, None), Choice::default());
}

#[test]
fn static_frame_totals_skips() {
    let cands = vec![
        Candidate::new(1, vec![lod(1000, false), lod(250, true)], 1.0e7),
        Candidate::new(2, vec![lod(1000, false), lod(250, false)], 1.0e7),
    ];
    let f = Elider::new(Algorithm::Static, 0.1).choose(&cands, &CostModel::default(), None);
    assert_eq!(lods_of(&f), vec![Some(1), None]);
    assert_eq!((f.lods_skipped, f.objects_skipped), (1, 1));
}

#[test]
fn feedback_threshold_follows_frame_time() {
    let mut e = Elider::new(Algorithm::Feedback, 0.1);
    let model = CostModel::default();
    let cands = vec![Candidate::new(1, chain(4096, 4), 256.0 * 1024.0)];
    assert_eq!(e.choose(&cands, &model, None).choices[0].lod, Some(2));
    // Too slow: the threshold doubles (clamped step), so coarser LODs are chosen.
    let f = e.choose(&cands, &model, Some(0.5));
    assert_eq!(e.threshold_px(), 2048.0);
    assert_eq!(f.choices[0].lod, Some(3));
    // Too fast: it falls again.
    e.choose(&cands, &model, Some(0.025));
    e.choose(&cands, &model, Some(0.025));
    assert_eq!(e.threshold_px(), 512.0);
    for _ in 0..100 {
        e.choose(&cands, &model, Some(0.0));
    }
    assert_eq!(e.threshold_px(), e.params().feedback_min_px_per_tri);
    e.choose(&cands, &model, Some(f64::NAN));
    assert_eq!(e.threshold_px(), e.params().feedback_min_px_per_tri);
}

#[test]
fn optimize_never_exceeds_the_budget() {
    let mut rng = SmallRng::seed_from_u64(0x5eed);
    let model = CostModel::default();
    for round in 0..200 {
        let n = 1 + rng.random_range(0..60usize);
        let levels = 1 + rng.random_range(0..5usize);
        let cands = random_candidates(&mut rng, n, levels, 0.8);
        let budget = rng.random_range(0.0..0.05);
        let mut e = Elider::new(Algorithm::Optimize, budget);
        for _ in 0..3 {
            let f = e.choose(&cands, &model, None);
            let cost = frame_cost(&cands, &f, &model);
            assert!(
                cost <= budget * (1.0 + 1e-12),
                "round {round}: {cost} > {budget}"
            );
            assert!((cost - f.predicted_s).abs() <= 1e-12 * budget.max(1e-9));
        }
    }
}

#[test]
fn optimize_never_picks_a_non_resident_lod() {
    let mut rng = SmallRng::seed_from_u64(42);
    let model = CostModel::default();
    for _ in 0..100 {
        let cands = random_candidates(&mut rng, 40, 5, 0.5);
        let mut e = Elider::new(Algorithm::Optimize, rng.random_range(0.0..0.1));
        for _ in 0..2 {
            let f = e.choose(&cands, &model, None);
            for (c, ch) in cands.iter().zip(&f.choices) {
                if let Some(l) = ch.lod {
                    assert!(c.lods[l].resident);
                }
                if c.lods.iter().all(|l| !l.resident) {
                    assert_eq!(ch.lod, None);
                }
            }
        }
    }
}

#[test]
fn huge_budget_draws_the_finest_resident_lod() {
    let mut rng = SmallRng::seed_from_u64(9);
    let mut cands = random_candidates(&mut rng, 50, 4, 0.6);
    for c in &mut cands {
        c.pixels = 1.0e6; // more pixels than triangles: finer LODs always add accuracy
    }
    let f = Elider::new(Algorithm::Optimize, 1.0e9).choose(&cands, &CostModel::default(), None);
    for (c, ch) in cands.iter().zip(&f.choices) {
        assert_eq!(ch.lod, c.lods.iter().position(|l| l.resident));
        assert_eq!(ch.object_skipped, ch.lod.is_none());
        assert_eq!(ch.desired, Some(0), "everything is wanted at full detail");
    }
}

#[test]
fn zero_budget_draws_nothing() {
    let mut rng = SmallRng::seed_from_u64(10);
    let cands = random_candidates(&mut rng, 30, 3, 1.0);
    let mut e = Elider::new(Algorithm::Optimize, 0.0);
    for _ in 0..2 {
        let f = e.choose(&cands, &CostModel::default(), None);
        assert!(f.choices.iter().all(|c| c.lod.is_none()));
        assert_eq!(f.predicted_s, 0.0);
        assert_eq!(
            f.objects_skipped, 0,
            "not drawn for lack of time, not of data"
        );
    }
    e.set_budget(-1.0);
    assert_eq!(e.budget_s(), 0.0);
}

#[test]
fn optimize_prefers_larger_objects() {
    let cands = vec![
        Candidate::new(1, chain(1000, 1), 100.0),
        Candidate::new(2, chain(1000, 1), 100_000.0),
    ];
    let model = CostModel::default();
    let one = model.cost(1000, 503, 100_000.0);
    let f = Elider::new(Algorithm::Optimize, one * 1.5).choose(&cands, &model, None);
    assert_eq!(lods_of(&f), vec![None, Some(0)]);
}

#[test]
fn optimize_reports_lods_skipped_for_missing_detail() {
    // With everything resident the object gets LOD 0 under a generous budget; with LOD 0
    // missing it gets LOD 1 and one LOD is reported skipped.
    let mut lods = chain(1000, 3);
    let model = CostModel::default();
    let mut e = Elider::new(Algorithm::Optimize, 1.0);
    let full = e.choose(&[Candidate::new(1, lods.clone(), 1.0e6)], &model, None);
    assert_eq!((full.choices[0].lod, full.lods_skipped), (Some(0), 0));
    lods[0].resident = false;
    let mut e = Elider::new(Algorithm::Optimize, 1.0);
    let f = e.choose(&[Candidate::new(1, lods.clone(), 1.0e6)], &model, None);
    assert_eq!(f.choices[0].lod, Some(1));
    assert_eq!(f.choices[0].desired, Some(0));
    assert_eq!((f.lods_skipped, f.objects_skipped), (1, 0));
    for l in &mut lods {
        l.resident = false;
    }
    let f = e.choose(&[Candidate::new(1, lods, 1.0e6)], &model, None);
    assert_eq!(f.choices[0].lod, None);
    assert_eq!(f.objects_skipped, 1);
}

#[test]
fn warm_start_is_stable_and_never_worse() {
    let mut rng = SmallRng::seed_from_u64(77);
    let model = CostModel::default();
    let (mut same, rounds) = (0, 100);
    for _ in 0..rounds {
        let cands = random_candidates(&mut rng, 50, 5, 0.9);
        let mut e = Elider::new(Algorithm::Optimize, rng.random_range(0.001..0.03));
        let first = e.choose(&cands, &model, None);
        let second = e.choose(&cands, &model, None);
        assert!(second.benefit >= first.benefit - 1e-9 * first.benefit.abs());
        same += usize::from(lods_of(&first) == lods_of(&second));
        let third = e.choose(&cands, &model, None);
        assert_eq!(
            lods_of(&second),
            lods_of(&third),
            "a repeated frame is a fixed point"
        );
    }
    assert!(
        same * 10 >= rounds * 9,
        "only {same} of {rounds} repeated frames unchanged"
    );
}

#[test]
fn warm_start_same_input_same_result() {
    let cands = random_candidates(&mut SmallRng::seed_from_u64(5), 200, 5, 1.0);
    let model = CostModel::default();
    let mut e = Elider::new(Algorithm::Optimize, 0.01);
    let first = e.choose(&cands, &model, None);
    let second = e.choose(&cands, &model, None);
    assert_eq!(lods_of(&first), lods_of(&second));
    assert!(second.benefit >= first.benefit);
}

/// Best `Σ Benefit` over all assignments (each object: not drawn or one resident LOD).
fn brute_force(cands: &[Candidate], model: &CostModel, budget: f64) -> f64 {
    let params = Params::default();
    let options: Vec<Vec<(f64, f64)>> = cands
        .iter()
        .map(|c| {
            let w = object_weight(&params, c);
            let mut o = vec![(0.0, 0.0)];
            for l in c.lods.iter().filter(|l| l.resident) {
                o.push((
                    lod_cost(model, l, c.pixels),
                    w * lod_accuracy(&params, l, c.pixels),
                ));
            }
            o
        })
        .collect();
    let mut best = 0.0f64;
    let mut pick = vec![0usize; cands.len()];
    loop {
        let (c, b) = pick.iter().enumerate().fold((0.0, 0.0), |(c, b), (i, &k)| {
            (c + options[i][k].0, b + options[i][k].1)
        });
        if c <= budget {
            best = best.max(b);
        }
        let Some(i) = (0..pick.len()).find(|&i| pick[i] + 1 < options[i].len()) else {
            return best;
        };
        pick[i] += 1;
        pick[..i].iter_mut().for_each(|k| *k = 0);
    }
}

#[test]
fn greedy_is_close_to_brute_force() {
    let mut rng = SmallRng::seed_from_u64(2024);
    let model = CostModel::default();
    let (mut sum_ratio, rounds) = (0.0, 300);
    for _ in 0..rounds {
        let cands = random_candidates(&mut rng, 3, 3, 0.9);
        let budget = rng.random_range(0.0..0.003);
        let optimum = brute_force(&cands, &model, budget);
        let f = Elider::new(Algorithm::Optimize, budget).choose(&cands, &model, None);
        assert!(f.benefit <= optimum * (1.0 + 1e-9) + 1e-9);
        let ratio = if optimum > 0.0 {
            f.benefit / optimum
        } else {
            1.0
        };
        assert!(ratio >= 0.5, "greedy {} vs optimum {optimum}", f.benefit);
        sum_ratio += ratio;
    }
    let mean = sum_ratio / rounds as f64;
    assert!(mean >= 0.95, "mean ratio to the optimum {mean}");
}

/// Two objects competing for a budget that fits one of them at LOD 0 and one at LOD 1.
fn rivals(pixels_b: f32) -> Vec<Candidate> {
    let lods = || vec![lod(400, true), lod(100, true)];
    vec![
        Candidate::new(1, lods(), 100_000.0),
        Candidate::new(2, lods(), pixels_b),
    ]
}

#[test]
fn hysteresis_keeps_choices_through_small_changes() {
    // Geometry-bound costs, so that LOD 0 costs more than LOD 1.
    let model = CostModel {
        c3: 0.0,
        c4: 0.0,
        ..CostModel::default()
    };
    let budget = model.cost(400, 203, 0.0) + model.cost(100, 53, 0.0) + 1e-7;
    let run = |h: f64| {
        let params = Params {
            hysteresis: h,
            ..Params::default()
        };
        let mut e = Elider::new(Algorithm::Optimize, budget).with_params(params);
        let before = lods_of(&e.choose(&rivals(98_000.0), &model, None));
        let after = lods_of(&e.choose(&rivals(102_000.0), &model, None));
        (before, after)
    };
    let (before, after) = run(0.0);
    assert_eq!(before, vec![Some(0), Some(1)]);
    assert_eq!(
        after,
        vec![Some(1), Some(0)],
        "without hysteresis a 4 % change flips"
    );
    let (before, after) = run(0.1);
    assert_eq!(before, after, "with hysteresis it does not");
    let far = {
        let mut e = Elider::new(Algorithm::Optimize, budget);
        e.choose(&rivals(98_000.0), &model, None);
        lods_of(&e.choose(&rivals(150_000.0), &model, None))
    };
    assert_eq!(far, vec![Some(1), Some(0)], "a large change still switches");
}

#[test]
fn objects_that_leave_the_view_are_dropped_from_the_warm_start() {
    let model = CostModel::default();
    let mut e = Elider::new(Algorithm::Optimize, 0.01);
    let a = random_candidates(&mut SmallRng::seed_from_u64(1), 20, 3, 1.0);
    e.choose(&a, &model, None);
    let mut b: Vec<Candidate> = a[10..].to_vec();
    b[0].lods.truncate(1); // an index from last frame may now be out of range
    let f = e.choose(&b, &model, None);
    assert_eq!(f.choices.len(), b.len());
    assert!(frame_cost(&b, &f, &model) <= 0.01);
}

#[test]
fn optimize_on_10k_candidates_fits_and_reset_starts_over() {
    let cands = random_candidates(&mut SmallRng::seed_from_u64(123), 10_000, 5, 0.9);
    let model = CostModel::default();
    let mut e = Elider::new(Algorithm::Optimize, 0.05);
    let t = std::time::Instant::now();
    let cold = e.choose(&cands, &model, None);
    let cold_s = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let warm = e.choose(&cands, &model, None);
    let warm_s = t.elapsed().as_secs_f64();
    e.reset();
    let t = std::time::Instant::now();
    let again = e.choose(&cands, &model, None);
    let reset_s = t.elapsed().as_secs_f64();
    println!(
        "optimize 10k×5: first {:.2} ms, warm {:.2} ms, after reset {:.2} ms; \
         {} drawn, predicted {:.4} s",
        cold_s * 1e3,
        warm_s * 1e3,
        reset_s * 1e3,
        warm.choices.iter().filter(|c| c.lod.is_some()).count(),
        warm.predicted_s
    );
    // (The times are printed for a person; speed is the bench's business, not a test's.)
    assert!(cold.predicted_s <= 0.05 && warm.predicted_s <= 0.05);
    // After a reset the incremental search starts from nothing again: the first frame's choice.
    assert_eq!(again, cold);
    assert!(
        cold.choices.iter().any(|c| c.lod.is_some()),
        "nothing drawn"
    );
}
