//! The gentle re-acquire search (`[law.contact] reacquire_margin = inf`, the shipped `robust-gentle`
//! tuning) over the ranges of `ranges.rs`: after a lost contact every speed towards a surface not
//! found yet is one the cell stops within `2·f_r`, counting what the force reaches before the contact
//! is certainly seen. A surface that retreats anywhere from a few micrometres to 3 mm, on any cell,
//! at any set-point and stiffness, is found again without pressing past `2·f_r`, and the force settles
//! within 1 s of the time the gentle search can first reach it — or, where that is beyond what the
//! loop's contact-loss time allows, the loop ends on fault 5, backed off. Never a trip.
//!
//! What it costs against the shipped fast search is the time to find a surface that went away
//! (`reach_time`): docs/controller.md's "Choosing the re-acquire search" measures both over the default wires.

mod common;

use common::{CELLS, cell, census, config, reach_time, tuning_named};
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

/// Whether `peak` (N) is within `2·f_r`, with one count of the ATI's quantisation and 0.1 % of the
/// stopping model's interpolation to spare.
fn within_twice(peak: f64, f_r: f64) -> bool {
    peak <= 2.0 * f_r * 1.001 + 0.01
}

/// A retreat of `delta` (m, away from the tool) at 2 s in an `f_r` hold on `k_c`, quiet sensor: the
/// largest true force after the step stays within `2·f_r` ([`within_twice`]), and the force settles within 1 s of the time the
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
                within_twice(after.peak_force, f_r),
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

/// The bound is the gentle search's, not any search's: the shipped fast search presses a surface
/// found close by past `2·f_r` (a 0.5 mm retreat on 10 kN/m at f_r 2 N on P1, the figure in docs/controller.md).
#[test]
fn the_fast_search_presses_past_twice_the_set_point() {
    let s = cell(4.0, 10e3, 0.0, None, Some((2.0, 0.0005)), 0.0, 1);
    let r = run(&s, &CELLS[0], &tuning_named("robust", 2.0)).expect("no fault");
    let peak = r.metrics(2.0, f64::INFINITY).peak_force;
    println!("robust: {peak:.2} N after the retreat (2·f_r 4 N)");
    assert!(!within_twice(peak, 2.0), "{peak} N");
}

/// Retreats under sensor noise (ignored: the known limits' figures, asserted no more than measured):
/// 600 seeded cases drawn as [`gentle_retreats`] draws them, with σ 0–1 N, under `robust-gentle` and
/// the shipped `robust`; counted are trips (a fault other than a lost contact), lost contacts (fault
/// 5: the search did not find the surface within the loss time) and, for the gentle search, forces
/// after the retreat beyond `2·f_r` — where the law's strong threshold is itself beyond it (the
/// search then goes at the approach's speed, whose re-contact that threshold alone exceeds) and
/// elsewhere. A steady contact lost under noise far above the lift force is declared lost on samples
/// below a threshold raised with the noise ([`controller::robust::contact::LIFT_NOISE`]); below the
/// lift force alone (0.3 N under σ 0.9 N) it was declared late, and the law, still in contact, chased
/// the surface at the loop's speed (f_r 39 N, 1.47 mm, P1: 112 N; on the 12 ms cell a trip).
#[test]
#[ignore = "1200 closed-loop noisy retreats: the known limits' figures, not a criterion"]
fn noisy_retreats() {
    const KINDS: [&str; 4] = [
        "trip",
        "fault 5",
        "beyond 2·f_r, the strong threshold beyond it",
        "beyond 2·f_r",
    ];
    // Bounded per tuning and kind in tests/census-bounds.toml; the fast search's forces beyond
    // 2·f_r are no criterion (it presses up to its limit by design). Their history:
    // docs/robust-law-limits.md.
    for name in ["robust-gentle", "robust"] {
        println!("{name}:");
        census(
            600,
            (
                2.0f64..50.0,
                common::stiffness(10e3, 500e3),
                0.0f64..0.003,
                0usize..3,
                0.0f64..1.0,
                1u64..1000,
            ),
            &KINDS,
            &format!("noisy_retreats.{name}"),
            |(f_r, k_c, delta, cell_i, noise, seed)| {
                let plant = &CELLS[cell_i];
                let label = format!(
                    "f_r {f_r:.1} N, {k_c:.0} N/m, {delta:.5} m, {plant:?}, σ {noise:.2} N"
                );
                let s = cell(4.0, k_c, 0.0, None, Some((2.0, delta)), noise, seed);
                let e =
                    scenario::run::run_to_end(&s, plant, &tuning_named(name, f_r)).expect("a law");
                let mut misses = Vec::new();
                match e.fault_code {
                    Some(5) => misses.push("fault 5".to_string()),
                    Some(_) => misses.push(format!(
                        "trip: {}",
                        e.fault.map(|f| f.to_string()).unwrap_or_default()
                    )),
                    None => {}
                }
                let peak = e.run.metrics(2.0, f64::INFINITY).peak_force;
                if name == "robust-gentle" && !within_twice(peak, f_r) {
                    let machine = controller::robust::ContactMachine::new(
                        match &tuning_named(name, f_r).law {
                            LawConfig::Robust(p) => p.contact,
                            _ => unreachable!(),
                        },
                    );
                    let strong = machine.thresholds(f_r, noise, 0.0).strong;
                    let why = if strong >= 2.0 * f_r {
                        "beyond 2·f_r, the strong threshold beyond it"
                    } else {
                        "beyond 2·f_r"
                    };
                    misses.push(format!("{why}: {:.2}·f_r", peak / f_r));
                }
                (label, misses)
            },
        );
    }
}
