//! Property tests of the robust law: whatever it is fed, the command is finite, stays within the
//! deviation limit and moves within the velocity and acceleration limits.

use controller::{ForceLaw, LawConfig, RobustLaw, RobustParams, Tuning};
use proptest::prelude::*;

fn params() -> RobustParams {
    let t: Tuning = toml::from_str(include_str!("../../tunings/robust.toml")).unwrap();
    match t.law {
        LawConfig::Robust(p) => *p,
        other => panic!("robust tuning expected, got {other:?}"),
    }
}

/// A sample: position, force, and whether to corrupt it.
fn sample() -> impl Strategy<Value = (f64, f64, u8)> {
    (-0.1f64..0.1, -2_000.0f64..2_000.0, 0u8..20)
}

fn corrupt(v: f64, how: u8) -> f64 {
    match how {
        0 => f64::NAN,
        1 => f64::INFINITY,
        2 => f64::NEG_INFINITY,
        _ => v,
    }
}

proptest! {
    // Seeded: the same cases on every run (the regressions file adds the ones found so far).
    #![proptest_config(ProptestConfig {
        cases: 200,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed_f0ce),
        ..ProptestConfig::default()
    })]

    #[test]
    fn command_is_finite_bounded_and_rate_limited(
        x0 in -0.05f64..0.05,
        period in prop_oneof![Just(0.001), Just(0.004), Just(0.012)],
        samples in proptest::collection::vec(sample(), 1..400),
    ) {
        let p = params();
        let mut law = RobustLaw::new(p).unwrap();
        law.start(x0);
        let mut last = x0;
        let mut last_v = 0.0;
        for (x, f, how) in samples {
            let (x, f) = if how % 2 == 0 { (corrupt(x, how), f) } else { (x, corrupt(f, how)) };
            let out = law.step(x, f, period);
            prop_assert!(out.x_cmd.is_finite(), "non-finite command from x {x}, f {f}");
            prop_assert!(out.x_cmd.abs() <= p.limits.max_deviation.max(x0.abs()) + 1e-12);
            let v = (out.x_cmd - last) / period;
            prop_assert!(v.abs() <= p.limits.max_velocity * (1.0 + 1e-9), "velocity {v} m/s");
            if x.is_finite() && f.is_finite() {
                // The deviation limit is a position limit: where the command meets it, it stops there
                // even if that takes more than the acceleration limit — and says so.
                prop_assert!(
                    (v - last_v).abs() <= p.limits.max_acceleration * period * (1.0 + 1e-6) + 1e-12
                        || out.events.deviation_limit,
                    "acceleration {} m/s² without a deviation-limit event", (v - last_v) / period
                );
            } else {
                // A held step stops the command (the loop does the same on a fault); it then moves
                // off from rest within the acceleration limit.
                prop_assert!(out.events.bad_input);
                prop_assert_eq!(out.x_cmd, last, "bad input must hold the command");
            }
            last = out.x_cmd;
            last_v = v;
        }
    }

    #[test]
    fn a_steady_spring_is_held_without_limit_events(
        k in 20_000.0f64..400_000.0,
        xc in 0.002f64..0.02,
    ) {
        // A tool at rest 0.5 mm short of a spring, ideal inner loop: approach, contact, hold.
        let p = params();
        let mut law = RobustLaw::new(p).unwrap();
        let mut x = xc - 0.0005;
        law.start(x);
        let mut last = None;
        for _ in 0..3000 {
            let f = (k * (x - xc)).max(0.0);
            let out = law.step(x, f, 1e-3);
            x = out.x_cmd;
            last = Some(out);
        }
        let out = last.unwrap();
        let f = (k * (x - xc)).max(0.0);
        prop_assert!((f - p.f_r).abs() < 0.05, "force {f} N at k {k}");
        prop_assert!(!out.events.any_limit());
        prop_assert!(
            (p.estimator.kc_min..=p.estimator.kc_max).contains(&out.kc_hat),
            "k̂ {} outside its bounds", out.kc_hat
        );
    }
}
