//! The gentle re-acquire search (`[law.contact] reacquire_margin = inf`, the shipped `robust-gentle`
//! tuning) over the ranges of `ranges.rs`: after a lost contact every speed towards a surface not
//! found yet is one the cell stops within `2·f_r`, counting what the force reaches before the contact
//! is certainly seen. A surface that retreats anywhere from a few micrometres to 3 mm, on any cell,
//! at any set-point and stiffness, is found again without pressing past `2·f_r`, and the force settles
//! within 1 s of the time the gentle search can first reach it — or, where that is beyond what the
//! loop's contact-loss time allows, the loop ends on fault 5, backed off. Never a trip.
//!
//! What it costs against the shipped fast search is the time to find a surface that went away
//! (`reach_time`): the README's "Choosing the re-acquire search" measures both over the default wires.

mod common;

use common::{CELLS, cell, config, reach_time, tuning_named};
use controller::{LawConfig, Tuning};
use proptest::prelude::*;
use scenario::run::run;
use sim::InnerLoopModel;

/// The shipped gentle tuning at set-point `f_r`.
fn gentle(f_r: f64) -> Tuning {
    let t = tuning_named("robust-gentle", f_r);
    let LawConfig::Robust(p) = &t.law else {
        panic!("robust")
    };
    assert!(
        p.contact.reacquire_margin.is_infinite(),
        "the gentle tuning"
    );
    t
}

/// A retreat of `delta` (m, away from the tool) at 2 s in an `f_r` hold on `k_c`, quiet sensor: the
/// largest true force after the step stays within `2·f_r` (one count of the ATI's quantisation and
/// 0.1 % of the model's interpolation to spare), and the force settles within 1 s of the time the
/// search can first reach the surface; or the surface is farther than the search reaches in 80 % of
/// the loop's contact-loss time, and the loop ends on fault 5.
fn retreat(f_r: f64, k_c: f64, delta: f64, plant: &InnerLoopModel) -> Result<f64, TestCaseError> {
    let s = cell(4.0, k_c, 0.0, None, Some((2.0, delta)), 0.0, 1);
    let t = gentle(f_r);
    let reach = reach_time(&t, k_c, delta - f_r / k_c, plant);
    let loss_time = t.loop_cfg.process.contact_loss_time;
    match run(&s, plant, &t) {
        Ok(r) => {
            let after = r.metrics(2.0, f64::INFINITY);
            prop_assert!(
                after.peak_force <= 2.0 * f_r * 1.001 + 0.01,
                "pressed {} N after the step (2·f_r {} N)",
                after.peak_force,
                2.0 * f_r
            );
            prop_assert!(
                after.settle_time <= 1.0 + reach,
                "back in ±2 % after {} s (the surface {reach} s away)",
                after.settle_time
            );
            Ok(after.peak_force / f_r)
        }
        Err(e) => {
            let e = e.to_string();
            prop_assert!(
                reach > 0.8 * loss_time && e.contains("fault 5 (contact lost)"),
                "the surface {reach} s away: {e}"
            );
            Ok(f64::NAN)
        }
    }
}

proptest! {
    #![proptest_config(config(200))]

    /// B3's retreat carried over, searched gently: see [`retreat`].
    #[test]
    fn gentle_retreats(
        f_r in 2.0f64..50.0,
        k_c in common::stiffness(10e3, 500e3),
        delta in 0.0f64..0.003,
        cell_i in 0usize..3,
    ) {
        retreat(f_r, k_c, delta, &CELLS[cell_i])?;
    }
}

/// The corners: every cell, soft to stiff, small to large set-points, retreats from within the
/// set-point's penetration to 3 mm. B3a's own retreat (1 mm on 70 kN/m at 5 N) is among them.
#[test]
fn gentle_retreat_corners() {
    let mut worst = (0.0f64, String::new());
    for plant in &CELLS {
        for k_c in [10e3, 70e3, 500e3] {
            for f_r in [2.0, 5.0, 20.0, 50.0] {
                for delta in [0.00002, 0.0005, 0.001, 0.00262, 0.003] {
                    match retreat(f_r, k_c, delta, plant) {
                        Ok(ratio) if ratio > worst.0 => {
                            worst = (ratio, format!("{plant:?} {k_c} N/m f_r {f_r} N {delta} m"))
                        }
                        Ok(_) => {}
                        Err(e) => {
                            panic!("{plant:?}, {k_c} N/m, f_r {f_r} N, retreat {delta} m: {e}")
                        }
                    }
                }
            }
        }
    }
    println!(
        "largest force after a retreat: {:.3}·f_r ({})",
        worst.0, worst.1
    );
}

/// Retreats under sensor noise (ignored: the known limits' figures, asserted no more than measured):
/// 600 seeded retreats as [`gentle_retreats`] draws them, with σ 0–1 N, under `robust-gentle` and the
/// shipped `robust`. Under noise the gentle bound is not kept everywhere: where the strong threshold
/// (`3·max(min(1 N, f_r/2), 4σ)`) is beyond `2·f_r` the search goes at the approach's speed, whose
/// re-contact that threshold alone exceeds. A steady contact lost under noise far above the lift
/// force is declared lost on samples below a threshold raised with the noise
/// ([`controller::robust::contact::LIFT_NOISE`]); below the lift force alone (0.3 N under σ 0.9 N),
/// it was declared late, and the law, still in contact, chased the surface at the loop's speed (f_r
/// 39 N, 1.47 mm, P1: 112 N; on the 12 ms cell a trip).
#[test]
#[ignore = "1200 closed-loop noisy retreats: the known limits' figures, not a criterion"]
fn noisy_retreats() {
    // (tuning, trips, and for the gentle search its overshoots of 2·f_r where the strong threshold is
    // beyond it and elsewhere) measured; the fast search presses up to its limit by design. Before
    // the lift-off threshold rose with the noise: gentle 1 trip (61.2 N, f_r 17.3 N on the 12 ms
    // cell, σ 0.99 N), over 2·f_r 2 and 3 (worst 3.51·f_r), 59 fault 5; robust 2 trips, 8 fault 5.
    for (name, trips_measured, over_measured) in
        [("robust-gentle", 0, Some((1, 0))), ("robust", 1, None)]
    {
        let mut state: u64 = 0x0011_2026;
        let mut uniform = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut fault5, mut trips, mut fallback, mut late) = (0, 0, 0, 0);
        let mut worst = (0.0f64, String::new());
        for _ in 0..600 {
            let f_r = 2.0 + 48.0 * uniform();
            let k_c = (10e3f64.ln() + (500e3f64 / 10e3).ln() * uniform()).exp();
            let delta = 0.003 * uniform();
            let plant = &CELLS[((uniform() * 3.0) as usize).min(2)];
            let noise = uniform();
            let seed = 1 + (uniform() * 998.0) as u64;
            let case =
                format!("f_r {f_r:.1} N, {k_c:.0} N/m, {delta:.5} m, {plant:?}, σ {noise:.2} N");
            let s = cell(4.0, k_c, 0.0, None, Some((2.0, delta)), noise, seed);
            let e = scenario::run::run_to_end(&s, plant, &tuning_named(name, f_r)).expect("a law");
            match e.fault_code {
                Some(5) => fault5 += 1,
                Some(_) => {
                    trips += 1;
                    println!(
                        "{name}: {case}: {}",
                        e.fault.map(|f| f.to_string()).unwrap_or_default()
                    );
                }
                None => {}
            }
            let peak = e.run.metrics(2.0, f64::INFINITY).peak_force;
            if peak > 2.0 * f_r * 1.001 + 0.01 {
                if 3.0 * (0.5 * f_r).min(1.0).max(4.0 * noise) >= 2.0 * f_r {
                    fallback += 1;
                } else {
                    late += 1;
                }
                if peak / f_r > worst.0 {
                    worst = (peak / f_r, case);
                }
            }
        }
        println!(
            "{name}: 600 noisy retreats, {fault5} fault 5, {trips} other faults; over 2·f_r {fallback} \
             where the strong threshold is beyond it, {late} elsewhere; worst {:.2}·f_r ({})",
            worst.0, worst.1
        );
        assert!(trips <= trips_measured, "{name}: {trips} trips");
        if let Some((fallback_measured, late_measured)) = over_measured {
            assert!(
                fallback <= fallback_measured && late <= late_measured,
                "{name}: over 2·f_r {fallback} and {late}"
            );
        }
    }
}
