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
