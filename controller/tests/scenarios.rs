//! Scenarios B1–B9 of docs/controller.md in closed loop against the simulated cell, robust tuning,
//! on P1 and on P2. Deterministic: seeded sensor, simulated time only. (B10 gravity lives with
//! `controller::gravity`; B11 cost is `benches/step.rs` and `tests/no_alloc.rs`.)
//!
//! One source of truth: the scenarios and their targets are the files `scenarios/b*.toml` that
//! `forcecell sim` and `bench-scenarios` run, run by `forcecell-scenario` and measured by its metric
//! code. This file only adds what a target file cannot say: sweeps around a file, bounds on every step,
//! other initial guesses of the tuning.

use controller::{LawConfig, Tuning};
use scenario::run::{Run, run};
use scenario::scenario::{Scenario, load_tuning};
use sim::InnerLoopModel;

/// The plants the targets must hold on.
const PLANTS: [(&str, InnerLoopModel); 2] =
    [("P1", InnerLoopModel::P1), ("P2", InnerLoopModel::P2)];

fn robust() -> Tuning {
    load_tuning("robust").expect("the shipped robust tuning")
}

fn scenario(name: &str) -> Scenario {
    Scenario::load(name).expect("a built-in scenario")
}

/// Every target is asserted: a run prints every number first, then fails listing what it missed.
fn verdict(fails: Vec<String>) {
    assert!(fails.is_empty(), "targets missed:\n{}", fails.join("\n"));
}

/// The plants a scenario is judged on: P1 and P2, or its own when it names an explicit inner loop.
fn plants(s: &Scenario) -> Vec<(String, InnerLoopModel)> {
    match &s.plant {
        scenario::scenario::PlantSpec::Model(m) => vec![(s.plant.label(), *m)],
        _ => PLANTS.iter().map(|(n, p)| (n.to_string(), *p)).collect(),
    }
}

/// Run `s` on `plant` and check its targets, each miss labelled.
fn judge(
    t: &Tuning,
    s: &Scenario,
    name: &str,
    plant: &InnerLoopModel,
    fails: &mut Vec<String>,
) -> Run {
    let r = run(s, plant, t).expect("the simulated cell never fails");
    for c in r.check(&s.targets) {
        let bound = match (c.target.min, c.target.max) {
            (Some(lo), Some(hi)) => format!("in [{lo}, {hi}]"),
            (Some(lo), None) => format!(">= {lo}"),
            (None, Some(hi)) => format!("<= {hi}"),
            (None, None) => String::new(),
        };
        println!(
            "{:24} {name:5} {:22} {:>12.4}   target {bound}",
            s.name, c.target.metric, c.value
        );
        if !c.pass {
            fails.push(format!(
                "{} {name}: {} {} (target {bound})",
                s.name, c.target.metric, c.value
            ));
        }
    }
    r
}

/// Every target of the scenario files named `prefix*`, on their plants.
fn files(t: &Tuning, prefix: &str, fails: &mut Vec<String>) {
    let all = Scenario::builtins().expect("built-in scenarios parse");
    let chosen: Vec<&Scenario> = all.iter().filter(|s| s.name.starts_with(prefix)).collect();
    assert!(!chosen.is_empty(), "no scenario file {prefix}*");
    for s in chosen {
        for (name, plant) in plants(s) {
            judge(t, s, &name, &plant, fails);
        }
    }
}

// ---------------------------------------------------------------- B1–B5, B7
fn b1_targets(t: &Tuning, fails: &mut Vec<String>) {
    for (name, plant) in PLANTS {
        let r = judge(t, &scenario("b01-approach"), name, &plant, fails);
        let t0 = r.metrics(0.0, f64::INFINITY).first_contact;
        // 1 mm at 2 mm/s.
        assert!((0.4..0.6).contains(&t0), "{name}: contact at {t0} s");
    }
}

#[test]
fn b1_approach_contact_hold() {
    let mut fails = Vec::new();
    b1_targets(&robust(), &mut fails);
    verdict(fails);
}

#[test]
fn b2_stiffness_halves_doubles_soft_stiff() {
    let mut fails = Vec::new();
    files(&robust(), "b02", &mut fails);
    verdict(fails);
}

/// B2's "stable for any k_c in [10, 500] kN/m without retuning": the soft file's targets over the range.
fn b2_range_targets(t: &Tuning, fails: &mut Vec<String>) {
    for k in [10e3, 20e3, 40e3, 70e3, 150e3, 300e3, 500e3] {
        let mut s = scenario("b02c-soft");
        s.environment.k_c = k;
        s.name = format!("b02-range-{:.0}kN", k / 1e3);
        for (name, plant) in PLANTS {
            let r = judge(t, &s, name, &plant, fails);
            let settle = r.metrics(0.0, f64::INFINITY).settle_time;
            if !settle.is_finite() {
                fails.push(format!("{} {name}: never settled", s.name));
            }
        }
    }
}

#[test]
fn b2_stable_for_any_stiffness_in_10_to_500_kn_per_m() {
    let mut fails = Vec::new();
    b2_range_targets(&robust(), &mut fails);
    verdict(fails);
}

#[test]
fn b3_surface_steps() {
    let mut fails = Vec::new();
    files(&robust(), "b03", &mut fails);
    verdict(fails);
}

#[test]
fn b4_incline() {
    let mut fails = Vec::new();
    files(&robust(), "b04", &mut fails);
    verdict(fails);
}

#[test]
fn b5_curved_surface() {
    let mut fails = Vec::new();
    files(&robust(), "b05", &mut fails);
    verdict(fails);
}

/// B5's 1 mm / 1 Hz sine loses contact as it starts, and the search finds the surface again while it
/// moves in: the stiffness is not learnt from that motion (the estimator's excitation also asks the
/// last step not to contradict a still surface). It was: `k̂_c` ended 47 % (P1) and 27 % (P2) below
/// the surface's 70 kN/m, a loop gain of 1.5–1.9 against its bound of 2.
#[test]
fn b5_a_re_contact_on_the_moving_surface_learns_no_stiffness() {
    let s = scenario("b05b-curve-fast");
    for (name, plant) in plants(&s) {
        let r = run(&s, &plant, &robust()).expect("the simulated cell never fails");
        let m = r.metrics(3.0, f64::INFINITY);
        println!("{name}: k̂_c {:.0} N/m", m.kc_hat);
        assert!(
            m.kc_rel_error <= 0.1,
            "{name}: k̂_c off by {}",
            m.kc_rel_error
        );
    }
}

/// B5b's sine start on P2: the fast search re-contacts the receding surface and bounces off it; the
/// observer, restarted at that re-contact, had not seen the surface move (0.2 mm/s of its 6 mm/s), so
/// the search after the bounce went at approach speed and caught the surface 0.21 s later, as it
/// turned. The search now chases at the speed the surface was seen going away between the loss and
/// the re-contact, bounded by what stops within `2·f_r`: without contact for at most 0.15 s in all
/// (not a B5 target; 0.108 s in process, was 0.236 s), and every re-contact after that first bounce
/// within `2·f_r`
/// (the first, the fast search's, is bounded by the force limit only: see docs/known-limits.md).
#[test]
fn b5_the_sine_start_on_p2_is_caught_up_with_within_twice_the_set_point() {
    let s = scenario("b05b-curve-fast");
    let r = run(&s, &InnerLoopModel::P2, &robust()).expect("the simulated cell never fails");
    let rows: Vec<_> = r.rows.iter().filter(|r| r.t >= 2.0 && r.t < 2.5).collect();
    let without =
        rows.iter().filter(|r| r.f_true <= 0.0).count() as f64 * InnerLoopModel::P2.period;
    // The second loss of contact: the bounce off the fast search's re-contact.
    let lost: Vec<usize> = (1..rows.len())
        .filter(|&i| rows[i].f_true <= 0.0 && rows[i - 1].f_true > 0.0)
        .collect();
    assert!(lost.len() >= 2, "{} losses", lost.len());
    let after = rows[lost[1]..].iter().map(|r| r.f_true).fold(0.0, f64::max);
    println!("without contact {without:.3} s, peak after the bounce {after:.2} N");
    assert!(without <= 0.15, "without contact for {without} s");
    assert!(after <= 2.0 * 5.0, "a re-contact at {after} N");
}

/// B5 file `name` on a surface of stiffness `k_c` (not a spec'd case), on P1 and P2: the file's
/// targets hold and `k̂_c` ends within 10 %.
fn a_stiff_sine_holds_and_keeps_its_stiffness(name: &str, k_c: f64) {
    let mut s = scenario(name);
    s.environment.k_c = k_c;
    for (plant_name, plant) in plants(&s) {
        let r = run(&s, &plant, &robust()).expect("the simulated cell never fails");
        let m = r.metrics(3.0, f64::INFINITY);
        println!(
            "{plant_name}: {:.3} N RMS, k̂_c {:.0} N/m",
            m.rms_error, m.kc_hat
        );
        for c in r.check(&s.targets) {
            assert!(c.pass, "{plant_name}: {} {}", c.target.metric, c.value);
        }
        assert!(
            m.kc_rel_error <= 0.1,
            "{plant_name}: k̂_c off by {}",
            m.kc_rel_error
        );
    }
}

/// B5b's sine on a surface three times stiffer (200 kN/m; not a spec'd case). The sine start loses
/// contact, and every re-acquired contact on the moving surface started the recursion as agile as on an
/// unknown surface, its covariance reopened to the estimator's initial uncertainty: `k̂_c` ended at 160
/// kN/m on P2 and the loop, that much too eager, rang (1.12 N RMS; over the default wires 1.02 N, and
/// fault 2 at 61.5 N before the session's other changes). A re-acquired contact now keeps the confidence
/// `k̂_c` earned (its fit's or the steady estimator's deviation, at least `identify.steady_confidence`):
/// 0.33 N, 222 kN/m. Since a re-contact that found the surface moved waits (through the bounces that
/// follow it, `robust::identify::moved`): 0.163 / 0.418 N, `k̂_c` 200 kN/m on both. At 500 kN/m: the
/// next test.
#[test]
fn b5_a_stiff_sine_keeps_its_stiffness_through_re_contacts() {
    a_stiff_sine_holds_and_keeps_its_stiffness("b05b-curve-fast", 200e3);
}

/// B5b's sine on 500 kN/m (not a spec'd case). The sine start loses contact, and the search finds the
/// surface 1 mm further on, moving. On P1 the re-contact's transient, the tool backing off faster than
/// the surface came in, read as a softer surface: `k̂_c` went from 470 to 155 kN/m within 53 ms, and
/// the loop, three times too stiff, lost contact 122 times (9.7 N RMS over the default wires; fault 5
/// in process). A re-contact that found the surface moved now learns nothing for the observer's
/// `motion_hold` (`robust::identify::moved`): 0.28 N, `k̂_c` 500 kN/m.
#[test]
fn b5_a_sine_on_500_kn_per_m_keeps_its_stiffness_through_re_contacts() {
    a_stiff_sine_holds_and_keeps_its_stiffness("b05b-curve-fast", 500e3);
}

/// B5a's slow sine (0.5 mm at 0.5 Hz, at most 1.6 mm/s) on 500 kN/m (not a spec'd case). Where the
/// tool, catching up with the surface after a turn, backed off faster than it came in, the velocity
/// test took the surface for a still one seen through a `k̂_c` too high, and the recursion took the
/// falling force for a softer surface: on P1 `k̂_c` 499 → 376 kN/m (0.085 N RMS, passing), on P2
/// fault 2 at 62 N. The observed surface leaving its average by more than a still one can appear to
/// move now holds the recursion (`robust::observer::drift`): 0.101 / 0.186 N, `k̂_c` 500 / 499 kN/m.
#[test]
fn b5_a_slow_sine_on_500_kn_per_m_keeps_its_stiffness() {
    a_stiff_sine_holds_and_keeps_its_stiffness("b05a-curve-slow", 500e3);
}

/// B5a's slow sine on 200 kN/m (not a spec'd case). The sine's start lost contact on P2, the fast
/// search re-contacted 33 µm from the loss and its momentum pressed to 30 N; as the tool backed off
/// from that on the receding surface, the recursion read a stiffer one (177 → 238 kN/m in 16 ms over
/// the default wires, 223 kN/m in process). A re-contact the fast search made now waits like one
/// that found the surface moved (`robust::identify::moved`): `k̂_c` 200 kN/m.
#[test]
fn b5_a_slow_sine_on_200_kn_per_m_keeps_its_stiffness() {
    a_stiff_sine_holds_and_keeps_its_stiffness("b05a-curve-slow", 200e3);
}

/// B7's sweep: the 16 ms file's targets up to 16 ms of delay, the 32 ms file's up to 32 ms, contact
/// and finite commands at 48 ms.
fn b7_targets(t: &Tuning, fails: &mut Vec<String>) {
    let (fast, slow) = (scenario("b07-delay-16ms"), scenario("b07-delay-32ms"));
    for cycles in [0u32, 4, 8, 16, 24, 32, 48] {
        let plant = InnerLoopModel {
            delay_cycles: cycles,
            ..InnerLoopModel::P1
        };
        let label = format!("{cycles}ms");
        let base = if cycles <= 16 { &fast } else { &slow };
        let mut s = base.clone();
        if cycles > 32 {
            s.targets.clear();
        }
        let r = judge(t, &s, &label, &plant, fails);
        assert!(r.metrics(0.0, f64::INFINITY).first_contact.is_finite());
        assert!(r.rows.iter().all(|r| r.x_cmd.is_finite()), "{label}");
    }
}

#[test]
fn b7_delay_sweep() {
    let mut fails = Vec::new();
    b7_targets(&robust(), &mut fails);
    verdict(fails);
}

// ---------------------------------------------------------------- B8
fn b8_targets(t: &Tuning, fails: &mut Vec<String>) {
    let LawConfig::Robust(p) = &t.law else {
        panic!("robust tuning is robust")
    };
    let (lo, hi) = (p.estimator.kc_min, p.estimator.kc_max);
    for (name, plant) in PLANTS {
        let r = judge(t, &scenario("b08-identification"), name, &plant, fails);
        if let Some(row) = r.rows.iter().find(|r| !(lo..=hi).contains(&r.kc_hat)) {
            fails.push(format!(
                "B8 {name}: k̂ {} out of bounds at {} s",
                row.kc_hat, row.t
            ));
        }
    }
}

#[test]
fn b8_identification() {
    let mut fails = Vec::new();
    b8_targets(&robust(), &mut fails);
    verdict(fails);
}

// ---------------------------------------------------------------- B6 (long)
fn b6_targets(t: &Tuning, fails: &mut Vec<String>) {
    for (name, plant) in PLANTS {
        let r = judge(t, &scenario("b06-noise-drift"), name, &plant, fails);
        // x̂_c bounded.
        let dev = r
            .rows
            .iter()
            .filter(|r| r.t >= 5.0)
            .map(|r| (r.xc_hat - r.x_c).abs())
            .fold(0.0, f64::max);
        if dev > 2e-4 {
            fails.push(format!("B6 {name}: x̂_c off by {dev} m"));
        }
    }
}

#[test]
fn b6_noise_and_drift_ten_minutes() {
    let mut fails = Vec::new();
    b6_targets(&robust(), &mut fails);
    verdict(fails);
}

/// B6's targets are not one lucky noise sequence: eight sensor seeds, both plants.
#[test]
fn b6_over_sensor_seeds() {
    let mut fails = Vec::new();
    for seed in 1..=8 {
        let mut s = scenario("b06-noise-drift");
        s.sensor.seed = seed;
        s.name = format!("b06-seed-{seed}");
        for (name, plant) in PLANTS {
            judge(&robust(), &s, name, &plant, &mut fails);
        }
    }
    verdict(fails);
}

// ---------------------------------------------------------------- B9
fn b9_targets(t: &Tuning, fails: &mut Vec<String>) {
    let LawConfig::Robust(p) = &t.law else {
        panic!("robust tuning is robust")
    };
    for (name, plant) in PLANTS {
        let r = judge(t, &scenario("b09-faults"), name, &plant, fails);
        assert!(
            r.rows.iter().all(|r| r.x_cmd.is_finite()),
            "{name}: NaN reached the command"
        );
        let step = r
            .rows
            .windows(2)
            .map(|w| (w[1].x_cmd - w[0].x_cmd).abs())
            .fold(0.0, f64::max);
        let limit = p.limits.max_velocity * plant.period;
        println!(
            "b09-faults               {name:5} max command step m {step:>12.6}   target <= {limit}"
        );
        if step > limit * (1.0 + 1e-9) {
            fails.push(format!("B9 {name}: command step {step} m"));
        }
        assert!(r.stats.sensor_faults >= 1 && r.stats.nonfinite_inputs == 1);
    }
}

#[test]
fn b9_faults_nan_dropout() {
    let mut fails = Vec::new();
    b9_targets(&robust(), &mut fails);
    verdict(fails);
}

// ---------------------------------------------------------------- initial stiffness estimate
/// The shipped tuning with another initial stiffness estimate `k̂_c(0)`, N/m.
fn with_kc0(kc0: f64) -> Tuning {
    let mut t = robust();
    let LawConfig::Robust(p) = &mut t.law else {
        panic!("robust tuning is robust")
    };
    p.estimator.kc0 = kc0;
    t
}

/// Every B target of one tuning, each failure labelled with `label`.
fn every_target(t: &Tuning, label: &str) -> Vec<String> {
    let mut fails = Vec::new();
    b1_targets(t, &mut fails);
    for prefix in ["b02", "b03", "b04", "b05"] {
        files(t, prefix, &mut fails);
    }
    b2_range_targets(t, &mut fails);
    b6_targets(t, &mut fails);
    b7_targets(t, &mut fails);
    b8_targets(t, &mut fails);
    b9_targets(t, &mut fails);
    fails.into_iter().map(|f| format!("{label}: {f}")).collect()
}

/// The paper starts its estimate 29 % low (50 kN/m against 70): the targets must not depend on the
/// tuning's guess being the scenarios' true stiffness.
#[test]
fn every_target_with_the_initial_stiffness_29_pct_low() {
    verdict(every_target(&with_kc0(50_000.0), "k̂(0) 50 kN/m"));
}

/// … nor on a guess 43 % high, and the true value.
#[test]
fn every_target_with_the_initial_stiffness_43_pct_high_or_exact() {
    let mut fails = every_target(&with_kc0(100_000.0), "k̂(0) 100 kN/m");
    fails.extend(every_target(&with_kc0(70_000.0), "k̂(0) 70 kN/m"));
    verdict(fails);
}

/// … and far off: 57 % low, 186 % high.
#[test]
fn every_target_with_the_initial_stiffness_far_off() {
    let mut fails = every_target(&with_kc0(30_000.0), "k̂(0) 30 kN/m");
    fails.extend(every_target(&with_kc0(200_000.0), "k̂(0) 200 kN/m"));
    verdict(fails);
}
