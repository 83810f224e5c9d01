//! The estimators' unit tests.

use super::update::{MAX_FALL_RATE, MAX_RATE};
use super::*;

fn params() -> EstimatorParams {
    EstimatorParams {
        kc0: 50_000.0,
        kc_min: 10_000.0,
        kc_max: 500_000.0,
        memory: 0.5,
        excitation: 0.1,
        excitation_window: 0.05,
        initial_uncertainty: 1.0,
        max_surface_speed: 1e-3,
    }
}

/// A re-contact's recursion kept to the confidence its estimate earned moves less on a misleading
/// transient (a moving surface reads as a softer one) than one reopened to the initial
/// uncertainty (50 µm in 0.3 s, two 5 N penetrations at 200 kN/m, read at half the stiffness, slow
/// enough that the rate limit does not decide it); a limit above that uncertainty changes nothing.
#[test]
fn a_limited_uncertainty_keeps_the_estimate() {
    let k = 200_000.0;
    let run = |limit: Option<f64>| {
        let mut e = StiffnessEstimator::new(params(), 2.5e-5, 0.0);
        e.set_kc(k, 0.0);
        e.begin_contact(0.01, 0.0);
        if let Some(rel) = limit {
            e.limit_uncertainty(rel);
        }
        for i in 1..300 {
            let t = i as f64 * 1e-3;
            let x = 0.01 + 0.00005 * t / 0.3;
            let f = 0.5 * k * (x - 0.01);
            e.update(x, f, f, 0.0, 1e-3, false);
        }
        e.kc()
    };
    let (agile, kept, loose) = (run(None), run(Some(0.1)), run(Some(10.0)));
    assert!(
        agile < 0.8 * k,
        "the agile recursion learns the transient: {agile}"
    );
    assert!(k - kept < 0.5 * (k - agile), "kept {kept}, agile {agile}");
    assert_eq!(loose, agile);
}

/// One sample that asks for half the stiffness moves `k̂_c` down by [`MAX_FALL_RATE`]·dt at most;
/// one that asks for twice by up to [`MAX_RATE`]·dt.
#[test]
fn the_estimate_falls_slower_than_it_rises() {
    let step = |factor: f64| {
        let mut e = StiffnessEstimator::new(params(), 1e-4, 0.0);
        e.begin_contact(0.0100, 0.0);
        e.update(0.0100, 0.0, 0.0, 0.0, 1e-3, false);
        let x = 0.0101;
        let f = factor * 50_000.0 * (x - 0.0100);
        e.update(x, f, f, 0.0, 1e-3, false);
        e.kc() / 50_000.0 - 1.0
    };
    let (down, up) = (step(0.5), step(2.0));
    assert!(
        (-MAX_FALL_RATE * 1e-3 - 1e-9..0.0).contains(&down),
        "{down}"
    );
    assert!(up > 0.0 && up <= MAX_RATE * 1e-3 + 1e-9, "{up}");
    assert!(-down < 0.5 * up, "falls {down}, rises {up}");
}

#[test]
fn learns_stiffness_and_surface_from_a_transient() {
    let (k, xc) = (70_000.0, 0.010);
    let mut e = StiffnessEstimator::new(params(), 1e-4, 0.0);
    e.begin_contact(0.01001, k * 0.00001);
    for i in 0..300 {
        let t = i as f64 * 1e-3;
        let x = 0.01001 + 0.00006 * (1.0 - (-t / 0.02).exp()) + 1e-5 * (t * 30.0).sin();
        e.update(x, k * (x - xc), k * (x - xc), 0.0, 1e-3, false);
    }
    assert!((e.kc() - k).abs() / k < 0.01, "k̂ {}", e.kc());
    assert!((e.xc() - xc).abs() < 1e-6, "x̂ {}", e.xc());
}

#[test]
fn apparent_motion_from_a_wrong_stiffness_is_not_surface_motion() {
    let v = 0.002;
    // k̂ too low by 4: the observer moves against the robot.
    assert!(!surface_moving(-3.0 * v, v, 1e-3));
    // k̂ too high by 2: it moves with the robot, but slower.
    assert!(!surface_moving(0.5 * v, v, 1e-3));
    // A ramp the robot follows, and one it has not started to follow.
    assert!(surface_moving(v, v, 1e-3));
    assert!(surface_moving(v, 0.0, 1e-3));
    // Slow enough to ignore.
    assert!(!surface_moving(0.0005, 0.0, 1e-3));
}

#[test]
fn a_surface_moving_in_after_a_re_contact_is_no_stiffness() {
    // B5b's re-contact: the tool came in on a still surface, and now backs off at 1 mm/s while the
    // surface moves in at 6 mm/s, so the force rises as the position falls. Against the slow averages, which still
    // remember the tool coming in, both stand "the same way"; step by step they contradict a
    // still surface. The same positions with the force of a still, stiffer surface are learnt.
    let run = |moving_in: bool| {
        let mut e = StiffnessEstimator::new(
            EstimatorParams {
                kc0: 70_000.0,
                ..params()
            },
            1e-4,
            0.0,
        );
        let (k, mut x, mut xc) = (70_000.0, 0.01003, 0.01);
        e.begin_contact(x, k * (x - xc));
        for i in 0..40 {
            let v = if i < 10 { 4e-3 } else { -1e-3 };
            x += v * 1e-3;
            let f = if moving_in {
                if i >= 10 {
                    xc -= 6e-6;
                }
                k * (x - xc)
            } else {
                2.0 * k * (x - 0.010015)
            };
            e.update(x, f, f, 0.0, 1e-3, false);
        }
        e.kc()
    };
    assert!(
        (run(true) - 70_000.0).abs() < 0.02 * 70_000.0,
        "{}",
        run(true)
    );
    assert!(
        run(false) > 80_000.0,
        "a still stiffer surface is learnt: {}",
        run(false)
    );
}

#[test]
fn static_contact_does_not_adapt() {
    let mut e = StiffnessEstimator::new(params(), 1e-4, 0.0);
    e.begin_contact(0.0101, 5.0);
    for i in 0..1000 {
        // Drifting force at a still position: bias drift, no information about k_c.
        let f = 5.0 + i as f64 * 1e-3;
        let up = e.update(0.0101, f, f, 0.0, 1e-3, false);
        assert!(!up.adapted);
    }
    assert_eq!(e.kc(), 50_000.0);
}

#[test]
fn an_excursion_within_the_noise_is_no_excitation() {
    // Position and force move together by 0.2 N-equivalent steps over a second: excitation for
    // a clean sensor (`excitation` 0.1 N), none within four deviations of 0.5 N of noise.
    let run = |noise_sd: f64| {
        let mut e = StiffnessEstimator::new(params(), 1e-4, 0.0);
        e.begin_contact(0.0101, 5.0);
        let mut adapted = false;
        for i in 0..1000 {
            let x = 0.0101 + 2e-6 * (i as f64 * 0.05).sin();
            let f = 5.0 + 80_000.0 * (x - 0.0101);
            adapted |= e.update(x, f, f, noise_sd, 1e-3, false).adapted;
        }
        adapted
    };
    assert!(run(0.0));
    assert!(!run(0.5));
}

#[test]
fn projection_holds_the_bounds_and_says_so() {
    let mut e = StiffnessEstimator::new(params(), 1e-4, 0.0);
    e.begin_contact(0.0, 0.0);
    let mut projected = false;
    for i in 0..200 {
        let x = 1e-4 * (i as f64 * 0.1).sin();
        // A "stiffness" of 5 MN/m, far above kc_max.
        let up = e.update(x, 5.0e6 * x, 5.0e6 * x, 0.0, 1e-3, false);
        projected |= up.projected;
        assert!(e.kc() <= 500_000.0 + 1e-6);
    }
    assert!(projected);
}
#[test]
fn steady_contact_learns_from_noise_driven_motion_despite_drift() {
    // A micrometre of position wander (the loop's answer to earlier noise), 0.5 N of white sensor
    // noise and a bias drifting 0.5 N/min; the prior is 20 % low.
    let (k, xc, s, dt) = (70_000.0, 0.010, 1e-4, 1e-3);
    let mut e = SteadyEstimator::new(3600.0);
    let prior = 0.8 * k * s;
    e.start(0.010071, 5.0, prior, (0.2 * prior) * (0.2 * prior), s);
    let mut seed: u64 = 7;
    let mut uniform = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let mut wander = 0.0;
    for i in 0..200_000 {
        let t = i as f64 * dt;
        wander = 0.99 * wander + 5e-7 * uniform();
        let x = 0.010071 + wander;
        let noise = 0.5 * 12f64.sqrt() * uniform();
        let f = k * (x - xc) + noise + 0.5 / 60.0 * t;
        e.update(x, f, 0.25, dt);
    }
    let (kc, rel) = e.estimate().unwrap();
    assert!((kc - k).abs() / k < 0.03, "k̂ {kc} ± {rel}");
    assert!(rel < 0.03, "relative std {rel}");
}

#[test]
fn steady_contact_without_motion_keeps_its_prior() {
    let (s, dt) = (1e-4, 1e-3);
    let mut e = SteadyEstimator::new(3600.0);
    let prior = 50_000.0 * s;
    e.start(0.0101, 5.0, prior, prior * prior, s);
    for _ in 0..10_000 {
        e.update(0.0101, 5.0, 4e-4, dt);
    }
    let (kc, rel) = e.estimate().unwrap();
    assert!((kc - 50_000.0).abs() < 1.0, "k̂ {kc}");
    assert!(rel > 0.9, "relative std {rel}");
}
