//! Scenarios B1–B9 of `specs/controller.md` in closed loop against the simulated cell, robust tuning,
//! on P1 and on P2. Deterministic: seeded sensor, simulated time only. (B10 gravity lives with
//! `controller::gravity`; B11 cost is `benches/step.rs` and `tests/no_alloc.rs`.)

mod common;

use common::{Cell, PLANTS, Trace, robust, run_tuning};
use controller::Tuning;
use sim::{Event, InnerLoopModel, Schedule, SensorParams, Window};

/// Record a failed target instead of stopping, so a run prints every number before it fails.
macro_rules! check {
    ($fails:ident, $cond:expr, $($msg:tt)+) => {
        let ok: bool = $cond;
        if !ok {
            $fails.push(format!($($msg)+));
        }
    };
}

/// Every target is asserted: a run prints every number first, then fails listing what it missed.
fn verdict(fails: Vec<String>) {
    assert!(fails.is_empty(), "targets missed:\n{}", fails.join("\n"));
}

fn show(id: &str, plant: &str, what: &str, value: f64, target: &str) {
    println!("{id:4} {plant:3} {what:28} {value:>12.4}   target {target}");
}

// ---------------------------------------------------------------- B1
fn b1(t: &Tuning, plant: InnerLoopModel) -> Trace {
    run_tuning(t, &Cell::nominal(plant, 3.0))
}

#[test]
fn b1_approach_contact_hold() {
    let mut fails: Vec<String> = Vec::new();
    b1_targets(&robust(), &mut fails);
    verdict(fails);
}

fn b1_targets(t: &Tuning, fails: &mut Vec<String>) {
    for (name, plant) in PLANTS {
        let tr = b1(t, plant);
        let t0 = tr.first_contact();
        let peak = tr.peak(0.0, 10.0);
        let settle = tr.settle(0.0, 10.0);
        let overshoot = ((peak - 5.0) / 5.0 * 100.0).max(0.0);
        let ss = tr.max_error(2.5, 3.0);
        show("B1", name, "first contact s", t0, "≈0.5 (1 mm at 2 mm/s)");
        show("B1", name, "impact peak N", peak, "<= 10");
        show("B1", name, "settle after contact s", settle, "<= 0.5");
        show("B1", name, "overshoot %", overshoot, "<= 10");
        show("B1", name, "ss error N", ss, "<= 0.01");
        assert!((0.4..0.6).contains(&t0), "{name}: contact at {t0} s");
        check!(fails, peak <= 10.0, "{name}: peak {peak} N");
        check!(fails, settle <= 0.5, "{name}: settle {settle} s");
        check!(fails, overshoot <= 10.0, "{name}: overshoot {overshoot} %");
        check!(fails, ss <= 0.01, "{name}: steady-state error {ss} N");
    }
}

// ---------------------------------------------------------------- B2
fn stiffness_change(t: &Tuning, plant: InnerLoopModel, factor: f64) -> Trace {
    let mut cell = Cell::nominal(plant, 5.0);
    cell.k_c = Schedule::constant(70_000.0).with(Event::Scale { at: 3.0, factor });
    run_tuning(t, &cell)
}

#[test]
fn b2_stiffness_halves_and_doubles() {
    let mut fails: Vec<String> = Vec::new();
    b2_targets(&robust(), &mut fails);
    verdict(fails);
}

fn b2_targets(t: &Tuning, fails: &mut Vec<String>) {
    for (name, plant) in PLANTS {
        for factor in [0.5, 2.0] {
            let tr = stiffness_change(t, plant, factor);
            let settle = tr.settle(3.0, 10.0);
            let (losses, _) = tr.contact_losses(1.0, 10.0);
            show(
                "B2",
                name,
                &format!("k_c x{factor} settle s"),
                settle,
                "<= 0.3",
            );
            show(
                "B2",
                name,
                &format!("k_c x{factor} losses"),
                losses as f64,
                "0",
            );
            check!(fails, settle <= 0.3, "{name} x{factor}: settle {settle} s");
            check!(fails, losses == 0, "{name} x{factor}: contact lost");
        }
    }
}

#[test]
fn b2_stable_for_any_stiffness_in_10_to_500_kn_per_m() {
    let mut fails: Vec<String> = Vec::new();
    b2_range_targets(&robust(), &mut fails);
    verdict(fails);
}

fn b2_range_targets(t: &Tuning, fails: &mut Vec<String>) {
    for (name, plant) in PLANTS {
        for k in [10e3, 20e3, 40e3, 70e3, 150e3, 300e3, 500e3] {
            let mut cell = Cell::nominal(plant, 4.0);
            cell.k_c = Schedule::constant(k);
            let tr = run_tuning(t, &cell);
            let err = tr.max_error(3.0, 4.0);
            let settle = tr.settle(0.0, 10.0);
            show(
                "B2",
                name,
                &format!("k_c {:.0} kN/m settle s", k / 1e3),
                settle,
                "finite",
            );
            check!(
                fails,
                err <= 0.1 && settle.is_finite(),
                "{name} k_c {k}: error {err} N at the end, settle {settle} s"
            );
        }
    }
}

// ---------------------------------------------------------------- B3
fn surface_step(t: &Tuning, plant: InnerLoopModel, delta: f64) -> Trace {
    let mut cell = Cell::nominal(plant, 5.0);
    cell.x_c = Schedule::constant(0.010).with(Event::Step { at: 3.0, delta });
    run_tuning(t, &cell)
}

#[test]
fn b3_surface_steps() {
    let mut fails: Vec<String> = Vec::new();
    b3_targets(&robust(), &mut fails);
    verdict(fails);
}

fn b3_targets(t: &Tuning, fails: &mut Vec<String>) {
    for (name, plant) in PLANTS {
        let tr = surface_step(t, plant, 0.001);
        let settle = tr.settle(3.0, 10.0);
        let (_, lost) = tr.contact_losses(3.0, 10.0);
        show("B3", name, "retreat 1 mm settle s", settle, "<= 0.5");
        show("B3", name, "retreat 1 mm contact lost s", lost, "<= 0.05");
        show(
            "B3",
            name,
            "retreat 1 mm re-contact peak N",
            tr.peak(3.0, 10.0),
            "(reported)",
        );
        check!(fails, settle <= 0.5, "{name} retreat: settle {settle} s");
        check!(fails, lost <= 0.05, "{name} retreat: contact lost {lost} s");

        let tr = surface_step(t, plant, -0.0005);
        let settle = tr.settle(3.0, 10.0);
        show("B3", name, "advance 0.5 mm settle s", settle, "<= 0.5");
        show(
            "B3",
            name,
            "advance 0.5 mm peak N",
            tr.peak(3.0, 10.0),
            "(reported)",
        );
        check!(fails, settle <= 0.5, "{name} advance: settle {settle} s");
    }
}

// ---------------------------------------------------------------- B4
#[test]
fn b4_incline() {
    let mut fails: Vec<String> = Vec::new();
    b4_targets(&robust(), &mut fails);
    verdict(fails);
}

fn b4_targets(t: &Tuning, fails: &mut Vec<String>) {
    for (name, plant) in PLANTS {
        for rate in [0.002, -0.002] {
            let mut cell = Cell::nominal(plant, 6.0);
            cell.x_c = Schedule::constant(0.010).with(Event::Ramp {
                start: 2.0,
                end: None,
                rate,
            });
            let tr = run_tuning(t, &cell);
            let rms = tr.rms_error(2.5, 6.0);
            let max = tr.max_error(2.5, 6.0);
            let (losses, _) = tr.contact_losses(1.0, 6.0);
            show(
                "B4",
                name,
                &format!("ramp {rate} m/s rms N"),
                rms,
                "<= 0.25",
            );
            show(
                "B4",
                name,
                &format!("ramp {rate} m/s max N"),
                max,
                "<= 0.75",
            );
            check!(fails, rms <= 0.25, "{name} {rate}: rms {rms} N");
            check!(fails, max <= 0.75, "{name} {rate}: max {max} N");
            check!(fails, losses == 0, "{name} {rate}: contact lost");
        }
    }
}

// ---------------------------------------------------------------- B5
#[test]
fn b5_curved_surface() {
    let mut fails: Vec<String> = Vec::new();
    b5_targets(&robust(), &mut fails);
    verdict(fails);
}

fn b5_targets(t: &Tuning, fails: &mut Vec<String>) {
    for (name, plant) in PLANTS {
        for (amp, freq, target) in [(0.0005, 0.5, 0.25), (0.001, 1.0, 1.0)] {
            let mut cell = Cell::nominal(plant, 8.0);
            cell.x_c = Schedule::constant(0.010).with(Event::Sine {
                start: 2.0,
                amplitude: amp,
                frequency: freq,
            });
            let tr = run_tuning(t, &cell);
            let rms = tr.rms_error(3.0, 8.0);
            show(
                "B5",
                name,
                &format!("{amp} m at {freq} Hz rms N"),
                rms,
                &format!("<= {target}"),
            );
            check!(fails, rms <= target, "{name} {freq} Hz: rms {rms} N");
        }
    }
}

// ---------------------------------------------------------------- B7
fn with_delay(delay: f64) -> InnerLoopModel {
    InnerLoopModel {
        period: 0.001,
        tau: 0.010,
        delay_cycles: (delay / 0.001).round() as u32,
    }
}

#[test]
fn b7_delay_sweep() {
    let mut fails: Vec<String> = Vec::new();
    b7_targets(&robust(), &mut fails);
    verdict(fails);
}

fn b7_targets(t: &Tuning, fails: &mut Vec<String>) {
    for delay in [0.0, 0.004, 0.008, 0.016, 0.024, 0.032, 0.048] {
        let mut cell = Cell::nominal(with_delay(delay), 4.0);
        // A stiffness step as well, so the loop is exercised in contact and not only at the approach.
        cell.k_c = Schedule::constant(70_000.0).with(Event::Scale {
            at: 2.5,
            factor: 2.0,
        });
        let tr = run_tuning(t, &cell);
        let t0 = tr.first_contact();
        let overshoot = ((tr.peak(0.0, 2.4) - 5.0) / 5.0 * 100.0).max(0.0);
        let settle = tr.settle(0.0, 2.4);
        let end = tr.max_error(3.5, 4.0);
        let label = format!("delay {:.0} ms", delay * 1e3);
        show(
            "B7",
            "-",
            &format!("{label} overshoot %"),
            overshoot,
            "<= 20 up to 16 ms",
        );
        show(
            "B7",
            "-",
            &format!("{label} settle s"),
            settle,
            "finite up to 32 ms",
        );
        assert!(t0.is_finite());
        if delay <= 0.016 + 1e-9 {
            check!(fails, overshoot <= 20.0, "{label}: overshoot {overshoot} %");
        }
        if delay <= 0.032 + 1e-9 {
            // "Stable (slower)": settles after the approach and stays bounded after the stiffness step.
            check!(
                fails,
                settle.is_finite() && end <= 0.5,
                "{label}: settle {settle} s, end error {end} N"
            );
        }
    }
}

// ---------------------------------------------------------------- B8
#[test]
fn b8_identification() {
    let mut fails: Vec<String> = Vec::new();
    b8_targets(&robust(), &mut fails);
    verdict(fails);
}

fn b8_targets(t: &Tuning, fails: &mut Vec<String>) {
    let controller::LawConfig::Robust(p) = &t.law else {
        panic!("robust tuning is robust")
    };
    let bounds = (p.estimator.kc_min, p.estimator.kc_max);
    for (name, plant) in PLANTS {
        // The workpiece is 3.2 times stiffer than the tuning's initial guess (50 kN/m); two surface transients (0.05 mm
        // towards the tool and back, 8 N each) follow the approach, all within 2 s of first contact.
        let k = 160_000.0;
        let mut cell = Cell::nominal(plant, 4.0);
        cell.k_c = Schedule::constant(k);
        cell.x_c = Schedule::constant(0.010)
            .with(Event::Step {
                at: 1.2,
                delta: -0.00005,
            })
            .with(Event::Step {
                at: 1.8,
                delta: 0.00005,
            });
        let tr = run_tuning(t, &cell);
        let t0 = tr.first_contact();
        let kc = tr.at(t0 + 2.0).kc_hat;
        let rel = (kc - k).abs() / k;
        show("B8", name, "|k̂−k|/k 2 s after contact", rel, "<= 0.10");
        check!(fails, rel <= 0.10, "{name}: B8 k̂ {kc} N/m vs {k} N/m");
        for r in &tr.rows {
            check!(
                fails,
                r.kc_hat >= bounds.0 && r.kc_hat <= bounds.1,
                "{name}: k̂ {} out of bounds",
                r.kc_hat
            );
        }
    }
}

// ---------------------------------------------------------------- B6 (long)
#[test]
fn b6_noise_and_drift_ten_minutes() {
    let mut fails: Vec<String> = Vec::new();
    b6_targets(&robust(), &mut fails);
    verdict(fails);
}

fn b6_targets(t: &Tuning, fails: &mut Vec<String>) {
    for (name, plant) in PLANTS {
        let mut cell = Cell::nominal(plant, 600.0);
        cell.sensor = SensorParams {
            noise: 0.5,
            drift_per_min: 0.5,
            seed: 6,
            ..SensorParams::default()
        };
        let tr = run_tuning(t, &cell);
        let (std, slope) = tr.force_std_detrended(5.0, 600.0);
        let raw_std = tr.force_std(5.0, 600.0);
        let end = tr.at(599.0);
        let kc_rel = (end.kc_hat - 70_000.0).abs() / 70_000.0;
        let xc_dev = tr
            .rows
            .iter()
            .filter(|r| r.t >= 5.0)
            .map(|r| (r.xc_hat - r.x_c).abs())
            .fold(0.0, f64::max);
        show("B6", name, "true force std (detrended) N", std, "<= 0.1");
        show(
            "B6",
            name,
            "true force std (raw) N",
            raw_std,
            "(drift: unobservable)",
        );
        show(
            "B6",
            name,
            "true force trend N/min",
            slope * 60.0,
            "(= -sensor drift)",
        );
        show("B6", name, "|k̂−k|/k at 10 min", kc_rel, "<= 0.05");
        show("B6", name, "max |x̂_c − x_c| m", xc_dev, "bounded (<= 2e-4)");
        check!(fails, std <= 0.1, "{name}: std {std} N");
        check!(fails, kc_rel <= 0.05, "{name}: k̂ off by {kc_rel}");
        check!(fails, xc_dev <= 2e-4, "{name}: x̂_c off by {xc_dev} m");
    }
}

// ---------------------------------------------------------------- B9
#[test]
fn b9_faults_nan_dropout() {
    let mut fails: Vec<String> = Vec::new();
    b9_targets(&robust(), &mut fails);
    verdict(fails);
}

fn b9_targets(t: &Tuning, fails: &mut Vec<String>) {
    for (name, plant) in PLANTS {
        let mut cell = Cell::nominal(plant, 4.0);
        cell.sensor = SensorParams {
            nan_at: vec![2.0],
            dropouts: vec![Window {
                at: 2.5,
                duration: 0.020,
            }],
            ..SensorParams::default()
        };
        let tr = run_tuning(t, &cell);
        assert!(tr.commands_finite(), "{name}: NaN reached the command");
        let step = tr.max_command_step();
        let controller::LawConfig::Robust(p) = &t.law else {
            panic!()
        };
        let limit = p.limits.max_velocity * plant.period;
        let err = tr.max_error(2.0, 3.5);
        show(
            "B9",
            name,
            "max command step m",
            step,
            &format!("<= {limit}"),
        );
        show("B9", name, "max error after faults N", err, "<= 1.0 (20 %)");
        check!(fails, step <= limit * (1.0 + 1e-9), "{name}: step {step} m");
        check!(fails, err <= 1.0, "{name}: error {err} N");
        assert!(tr.stats.sensor_faults >= 1 && tr.stats.nonfinite_inputs == 1);
    }
}

// ---------------------------------------------------------------- initial stiffness estimate
/// The shipped tuning with another initial stiffness estimate `k̂_c(0)`, N/m.
fn with_kc0(kc0: f64) -> Tuning {
    let mut t = robust();
    let controller::LawConfig::Robust(p) = &mut t.law else {
        panic!("robust tuning is robust")
    };
    p.estimator.kc0 = kc0;
    t
}

/// Every B target of one tuning, each failure labelled with `label`.
fn every_target(t: &Tuning, label: &str) -> Vec<String> {
    let mut fails: Vec<String> = Vec::new();
    b1_targets(t, &mut fails);
    b2_targets(t, &mut fails);
    b2_range_targets(t, &mut fails);
    b3_targets(t, &mut fails);
    b4_targets(t, &mut fails);
    b5_targets(t, &mut fails);
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

/// B6's stiffness target is not one lucky noise sequence: eight sensor seeds, both plants, the shipped
/// tuning.
#[test]
fn b6_stiffness_over_sensor_seeds() {
    let mut fails: Vec<String> = Vec::new();
    for (name, plant) in PLANTS {
        for seed in 1..=8 {
            let mut cell = Cell::nominal(plant, 600.0);
            cell.sensor = SensorParams {
                noise: 0.5,
                drift_per_min: 0.5,
                seed,
                ..SensorParams::default()
            };
            let tr = run_tuning(&robust(), &cell);
            let (std, _) = tr.force_std_detrended(5.0, 600.0);
            let kc_rel = (tr.at(599.0).kc_hat - 70_000.0).abs() / 70_000.0;
            show(
                "B6",
                name,
                &format!("seed {seed} |k̂−k|/k"),
                kc_rel,
                "<= 0.05",
            );
            check!(fails, std <= 0.1, "{name} seed {seed}: std {std} N");
            check!(
                fails,
                kc_rel <= 0.05,
                "{name} seed {seed}: k̂ off by {kc_rel}"
            );
        }
    }
    verdict(fails);
}

/// … and far off: 57 % low, 186 % high.
#[test]
fn every_target_with_the_initial_stiffness_far_off() {
    let mut fails = every_target(&with_kc0(30_000.0), "k̂(0) 30 kN/m");
    fails.extend(every_target(&with_kc0(200_000.0), "k̂(0) 200 kN/m"));
    verdict(fails);
}
