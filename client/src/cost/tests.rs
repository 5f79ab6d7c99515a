//! Tests of the cost model: the cost formula, the calibration fits (exact, noisy, collinear,
//! degenerate, per-draw overhead) and the online correction factor (Funkhouser 1993 §4.2.3).

use super::*;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

fn close(got: f64, want: f64, rel: f64) -> bool {
    (got - want).abs() <= rel * want.abs()
}

const TRUTH: CostModel = CostModel {
    c0: 1.0e-5,
    c1: 2.0e-7,
    c2: 5.0e-8,
    c3: 4.0e-9,
    c4: 3.0e-9,
};

fn geometry_samples(rng: &mut SmallRng, overhead: f64, noise: f64) -> Vec<(u64, u64, f64)> {
    (0..40)
        .map(|_| {
            let t = rng.random_range(1e3..1e6) as u64;
            let v = (t as f64 * rng.random_range(0.3..3.0)) as u64;
            let s = overhead + TRUTH.c1 * t as f64 + TRUTH.c2 * v as f64;
            let factor = if noise > 0.0 {
                rng.random_range(1.0 - noise..1.0 + noise)
            } else {
                1.0
            };
            (t, v, s * factor)
        })
        .collect()
}

#[test]
fn cost_is_max_of_geometry_and_fill() {
    let m = TRUTH;
    let geometry = m.c0 + m.c1 * 1000.0 + m.c2 * 500.0;
    assert_eq!(m.cost(1000, 500, 10.0), geometry);
    let fill = m.c3 * 1.0e7;
    assert!(fill > geometry);
    assert_eq!(m.cost(1000, 500, 1.0e7), fill);
}

#[test]
fn a_texture_adds_to_the_fill_stage_only() {
    let m = TRUTH;
    let geometry = m.c0 + m.c1 * 1000.0 + m.c2 * 500.0;
    // Geometry-bound: texturing changes nothing.
    assert_eq!(m.cost_of(1000, 500, 10.0, true), geometry);
    // Fill-bound: (c3 + c4) per pixel, and the untextured cost is `cost`.
    assert_eq!(m.cost_of(1000, 500, 1.0e7, true), (m.c3 + m.c4) * 1.0e7);
    assert_eq!(m.cost_of(1000, 500, 1.0e7, false), m.cost(1000, 500, 1.0e7));
    assert_eq!(m.cost_of(0, 0, 1.0e7, true), 0.0);
    assert_eq!(m.scaled(2.0).c4, 2.0 * m.c4);
}

#[test]
fn zero_triangles_cost_nothing_and_bad_pixels_are_ignored() {
    let m = CostModel::default();
    assert_eq!(m.cost(0, 0, 1.0e9), 0.0);
    assert_eq!(m.cost(10, 5, f64::NAN), m.cost(10, 5, 0.0));
    assert_eq!(m.cost(10, 5, -100.0), m.cost(10, 5, 0.0));
}

#[test]
fn default_is_about_eight_million_triangles_per_second() {
    let tps = CostModel::default().triangles_per_second();
    assert!((7.0e6..9.0e6).contains(&tps), "{tps}");
    let one_second = CostModel::default().cost(8_000_000, 4_000_000, 0.0);
    assert!((0.9..1.1).contains(&one_second), "{one_second}");
}

#[test]
fn fit_geometry_recovers_known_coefficients() {
    let samples = geometry_samples(&mut SmallRng::seed_from_u64(7), 2.0e-3, 0.0);
    let fit = CostModel::default().fit_geometry(&samples);
    assert!(fit.fitted);
    assert!(close(fit.model.c1, TRUTH.c1, 0.05), "{:?}", fit.model);
    assert!(close(fit.model.c2, TRUTH.c2, 0.05), "{:?}", fit.model);
    assert!(close(fit.overhead_s, 2.0e-3, 0.05), "{}", fit.overhead_s);
    assert_eq!(fit.model.c0, CostModel::default().c0);
    assert_eq!(fit.model.c3, CostModel::default().c3);
    assert!(fit.rms_error_s < 1e-9);
}

#[test]
fn fit_geometry_with_noise_stays_close() {
    let samples = geometry_samples(&mut SmallRng::seed_from_u64(11), 1.0e-3, 0.05);
    let fit = CostModel::default().fit_geometry(&samples);
    assert!(close(fit.model.c1, TRUTH.c1, 0.15), "{:?}", fit.model);
    assert!(close(fit.model.c2, TRUTH.c2, 0.25), "{:?}", fit.model);
    let predicted = fit.overhead_s + fit.model.cost(500_000, 250_000, 0.0) - fit.model.c0;
    let truth = 1.0e-3 + TRUTH.c1 * 500_000.0 + TRUTH.c2 * 250_000.0;
    assert!(close(predicted, truth, 0.05), "{predicted} vs {truth}");
}

#[test]
fn fit_draws_recovers_per_draw_overhead() {
    let mut rng = SmallRng::seed_from_u64(3);
    let samples: Vec<DrawSample> = (0..50)
        .map(|_| {
            let draws = rng.random_range(1.0..2000.0) as u64;
            let triangles = rng.random_range(1e3..1e6) as u64;
            let vertices = (triangles as f64 * rng.random_range(0.3..3.0)) as u64;
            let seconds = 5.0e-4
                + TRUTH.c0 * draws as f64
                + TRUTH.c1 * triangles as f64
                + TRUTH.c2 * vertices as f64;
            DrawSample {
                draws,
                triangles,
                vertices,
                seconds,
            }
        })
        .collect();
    let fit = CostModel::default().fit_draws(&samples);
    for (got, want) in [
        (fit.model.c0, TRUTH.c0),
        (fit.model.c1, TRUTH.c1),
        (fit.model.c2, TRUTH.c2),
        (fit.overhead_s, 5.0e-4),
    ] {
        assert!(close(got, want, 0.05), "{got} vs {want}");
    }
}

#[test]
fn fit_fill_recovers_per_pixel_coefficient() {
    let mut rng = SmallRng::seed_from_u64(5);
    let samples: Vec<(f64, f64)> = (0..20)
        .map(|_| {
            let px = rng.random_range(1e4..1e7);
            (px, 1.0e-3 + TRUTH.c3 * px)
        })
        .collect();
    let fit = CostModel::default().fit_fill(&samples);
    assert!(fit.fitted);
    assert!(close(fit.model.c3, TRUTH.c3, 0.05), "{:?}", fit.model);
    assert!(close(fit.overhead_s, 1.0e-3, 0.05));
    assert_eq!(fit.model.c1, CostModel::default().c1);
}

#[test]
fn collinear_vertices_give_a_finite_accurate_fit() {
    // Every sample is one mesh drawn n times: vertices = 3·triangles exactly.
    let samples: Vec<(u64, u64, f64)> = (1..=8)
        .map(|n| {
            let t = 10_000 * n;
            (
                t,
                3 * t,
                1.0e-3 + TRUTH.c1 * t as f64 + TRUTH.c2 * 3.0 * t as f64,
            )
        })
        .collect();
    let fit = CostModel::default().fit_geometry(&samples);
    let m = fit.model;
    assert!(fit.fitted && m.c1 >= 0.0 && m.c2 >= 0.0, "{m:?}");
    let per_tri = m.c1 + 3.0 * m.c2;
    assert!(close(per_tri, TRUTH.c1 + 3.0 * TRUTH.c2, 0.01), "{m:?}");
}

#[test]
fn negative_slopes_are_clamped_to_zero() {
    // Time falls with vertices: the unconstrained fit would make c2 negative.
    let samples: Vec<(u64, u64, f64)> = (0..10)
        .map(|i| {
            let t = 1000 + 1000 * i;
            let v = 20_000 - 1500 * i;
            (t, v, 1.0e-6 * t as f64)
        })
        .collect();
    let m = CostModel::default().fit_geometry(&samples).model;
    assert_eq!(m.c2, 0.0, "{m:?}");
    assert!(m.c1 > 0.0);
}

#[test]
fn degenerate_input_keeps_a_finite_prior() {
    let prior = CostModel::default();
    let cases: [&[(u64, u64, f64)]; 4] = [
        &[],
        &[(0, 0, 0.0), (0, 0, 0.0)],
        &[(100, 50, 0.0)],
        &[(5, 5, f64::NAN), (7, 7, f64::INFINITY), (9, 9, -1.0)],
    ];
    for samples in cases {
        let fit = prior.fit_geometry(samples);
        assert!(!fit.fitted);
        assert_eq!(fit.model, prior);
    }
    assert_eq!(prior.fit_fill(&[]).model, prior);
    assert_eq!(prior.fit_fill(&[(0.0, 0.0)]).model, prior);
    assert_eq!(prior.fit_draws(&[]).model, prior);
    let constant = prior.fit_geometry(&[(10, 5, 1.0e-3), (1000, 500, 1.0e-3)]);
    assert!(!constant.fitted, "no slope: keep the prior");
    assert_eq!(prior.fit_textured_fill(&[]).model, prior);
    assert_eq!(prior.fit_textured_fill(&[(1.0e5, f64::NAN)]).model, prior);
    let m = CostModel::calibrate(&[], &[], &[]);
    assert!([m.c0, m.c1, m.c2, m.c3, m.c4].iter().all(|c| c.is_finite()));
}

#[test]
fn calibrate_combines_geometry_and_fill() {
    let geometry = geometry_samples(&mut SmallRng::seed_from_u64(13), 0.0, 0.0);
    let fill = [(1.0e5, TRUTH.c3 * 1.0e5), (1.0e6, TRUTH.c3 * 1.0e6)];
    let per_pixel = TRUTH.c3 + TRUTH.c4;
    let textured = [
        (1.0e5, 2e-4 + per_pixel * 1.0e5),
        (1.0e6, 2e-4 + per_pixel * 1.0e6),
    ];
    let m = CostModel::calibrate(&geometry, &fill, &textured);
    assert!(
        close(m.c1, TRUTH.c1, 0.05) && close(m.c3, TRUTH.c3, 0.05) && close(m.c4, TRUTH.c4, 0.05),
        "{m:?}"
    );
    assert_eq!(m.c0, 0.0, "per-draw overhead is inside the fitted slopes");
    assert_eq!(CostModel::calibrate(&[], &[], &[]), CostModel::default());
    // Texturing faster than plain fill (noise) is not a negative cost.
    let cheap = [(1.0e5, TRUTH.c3 * 0.5e5), (1.0e6, TRUTH.c3 * 0.5e6)];
    assert_eq!(TRUTH.fit_textured_fill(&cheap).model.c4, 0.0);
}

#[test]
fn online_factor_converges_to_measured_over_predicted() {
    let base = 0.020;
    let measured = 0.050;
    let mut online = OnlineCost::default();
    for _ in 0..200 {
        let planned = online.correct(base);
        online.observe(planned, measured);
    }
    assert!(
        close(online.factor(), measured / base, 0.01),
        "{}",
        online.factor()
    );
    let corrected = online.apply(&TRUTH);
    assert!(close(corrected.c1, TRUTH.c1 * 2.5, 0.01));
}

#[test]
fn online_factor_is_clamped_and_ignores_garbage() {
    let mut online = OnlineCost::new(1.0);
    online.observe(0.01, 10.0);
    assert_eq!(online.factor(), MAX_FACTOR);
    online.observe(1.0, 0.0);
    online.observe(f64::NAN, 0.01);
    online.observe(0.01, f64::INFINITY);
    assert_eq!(online.factor(), MAX_FACTOR);
    for _ in 0..10 {
        online.observe(1.0, 1e-6);
    }
    assert_eq!(online.factor(), MIN_FACTOR);
}

#[test]
fn online_factor_smooths_a_single_spike() {
    let mut online = OnlineCost::default();
    online.observe(0.02, 0.2); // one 10× hiccup
    assert!(online.factor() < 1.2, "{}", online.factor());
}
