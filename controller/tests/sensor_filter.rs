//! A force sensor with its own low-pass filter (`[sensor] bandwidth` in a scenario: a second-order
//! Butterworth, as F/T boards offer): its force is older than the position it arrives with. The law
//! pairs each force with the position of its time and counts the sensor's delay in its loop's
//! (`[law.cell] sensor_delay`, which the simulator sets from the sensor's filter as it sets the robot's
//! lag and delay from the plant). Closed loop, simulated time only.

mod common;

use common::{CELLS, cell, floor, floor_after, sine, tuning};
use scenario::run::{run, run_to_end};
use scenario::scenario::Scenario;

/// Scenario `s` read through a sensor filtered at `bandwidth` (Hz; 0: none).
fn through(mut s: Scenario, bandwidth: f64) -> Scenario {
    s.sensor.bandwidth = bandwidth;
    s
}

/// 0.5 mm at 0.5 Hz on 500 kN/m at f_r 20 N on P1, read through a 100 Hz filter (2.25 ms): paired with
/// the position it arrived with, the force's lag behind the tool's own motion read as the surface
/// moving with the tool, and the law chased it — 9.7 and 8.3 N RMS after 3 s, the sine towards and
/// away from the tool (0.10 N with a clean sensor). Paired with the position of its time and fed
/// forward over the loop's whole delay: 0.11 N (paired alone 1.4 N, the other half alone 12.2 N).
#[test]
fn a_filtered_force_is_paired_with_the_position_of_its_time() {
    for amplitude in [-0.5e-3, 0.5e-3] {
        let s = through(sine(500e3, amplitude, 0.5), 100.0);
        let r = run(&s, &CELLS[0], &tuning(20.0)).expect("no fault");
        let m = r.metrics(3.0, f64::INFINITY);
        assert!(m.rms_error <= 0.5, "RMS error {} N", m.rms_error);
        assert!(m.kc_rel_error <= 0.1, "k̂_c off by {}", m.kc_rel_error);
    }
}

/// B5b's sine (1 mm at 1 Hz on 70 kN/m, f_r 5 N) on P1 through a 100 Hz filter: the surface the law
/// sees is 2.25 ms old, so its feed-forward must reach that much further ahead. Paired but fed forward
/// over the robot's delay alone, 0.93 N RMS after 3 s (B5b's target is 1 N; 0.061 N unpaired, 0.046 N
/// with a clean sensor); over the loop's whole delay 0.061 N.
#[test]
fn a_filtered_force_is_fed_forward_over_the_sensor_s_delay_too() {
    let s = through(sine(70e3, 1e-3, 1.0), 100.0);
    let r = run(&s, &CELLS[0], &tuning(5.0)).expect("no fault");
    let m = r.metrics(3.0, f64::INFINITY);
    assert!(m.rms_error <= 0.25, "RMS error {} N", m.rms_error);
}

/// A hold at f_r 2 N on 500 kN/m on the 12 ms cell through a 100, 200 or 400 Hz filter, a 20 µm step
/// at 2 s (`filtered_sensors` cases). The touch-down bounced, and the contact ended between two
/// samples: the filter still showed 1.47 N 51 µm behind the surface, which the onset fit took for a
/// sample on the spring's line (`k̂_c` 397 → 116 kN/m at 100 Hz; at 400 Hz 119 kN/m and a trip at
/// 77 N). It is off the line now, beyond the fit's doubt. Then the surface observer's velocity,
/// learnt on the bounce, carried it a jump threshold a cycle off the still surface, was taken for a
/// jump every other cycle and never decayed: the hold stood at 5.3 N, its feed-forward cancelling the
/// correction. Now: no fault, back within ±2 % within 0.6 s of the step.
#[test]
fn a_filtered_bounce_at_a_small_set_point_on_a_slow_cell_settles() {
    for bandwidth in [100.0, 200.0, 400.0] {
        let s = through(
            cell(4.0, 500e3, 0.0, None, Some((2.0, 0.02e-3)), 0.0, 1),
            bandwidth,
        );
        let r = run(&s, &CELLS[2], &tuning(2.0)).expect("no fault");
        let m = r.metrics(2.0, f64::INFINITY);
        println!(
            "{bandwidth} Hz: settle {} s, k̂_c off {}",
            m.settle_time, m.kc_rel_error
        );
        assert!(
            m.settle_time <= 0.6,
            "{bandwidth} Hz: settled after {} s",
            m.settle_time
        );
    }
}

/// The cost of a filtered sensor, measured, not a criterion: per filter cut-off, over the three cells,
/// of 216 surface steps (−3 mm to +2.62 mm on 10, 70 and 500 kN/m at f_r 2, 20 and 50 N) those that
/// end on a fault although the step's own jump is under the force limit, those not back within ±2 %
/// 1.5 s after the step, of 48 touch-downs (10–500 kN/m, f_r 2–50 N) those over `2·f_r` above the
/// floor (the cell's and the sensor's delay: the filter shows the contact that much later) or ending
/// on a fault, and of 648 sines (0.2–1 mm at 0.25–1 Hz on 100–500 kN/m, both ways,
/// f_r 2–50 N) those ending on a fault; no more than measured.
#[test]
#[ignore = "2736 closed-loop runs: the known limits' figures, not a criterion"]
fn filtered_sensors() {
    // Per bandwidth (0: no filter): step faults, unsettled steps, touch-down misses, sine faults;
    // bounds in tests/census-bounds.toml, their history in docs/robust-law-limits.md.
    let rows = [0.0, 50.0, 100.0, 200.0, 400.0].map(|bandwidth: f64| {
        let b = |what: &str| common::bound("filtered_sensors", &format!("{bandwidth} Hz {what}"));
        (
            bandwidth,
            b("step faults"),
            b("unsettled"),
            b("touch-downs"),
            b("sine faults"),
        )
    });
    for (bandwidth, steps_measured, unsettled_measured, touch_measured, sines_measured) in rows {
        let (mut faults, mut unsettled) = (0, 0);
        for plant in &CELLS {
            for k_c in [10e3, 70e3, 500e3] {
                for f_r in [2.0f64, 20.0, 50.0] {
                    for delta in [
                        -3e-3f64, -0.5e-3, -0.1e-3, -0.02e-3, 0.02e-3, 0.1e-3, 1e-3, 2.62e-3,
                    ] {
                        let t = tuning(f_r);
                        let limit = t.loop_cfg.process.max_force;
                        let jump = f_r + k_c * (-delta).max(0.0);
                        let step = Some((2.0, delta));
                        let s = through(cell(4.0, k_c, 0.0, None, step, 0.0, 1), bandwidth);
                        let e = run_to_end(&s, plant, &t).expect("a valid tuning");
                        if e.fault.is_some() {
                            faults += usize::from(jump <= limit);
                        } else if e.run.metrics(2.0, f64::INFINITY).settle_time > 1.5 {
                            unsettled += 1;
                        }
                    }
                }
            }
        }
        // Over the bound with the cell's floor alone, the sensor's delay not counted.
        let (mut touch, mut over_cell) = (0, 0);
        for plant in &CELLS {
            for k_c in [10e3, 70e3, 200e3, 500e3] {
                for f_r in [2.0, 5.0, 20.0, 50.0] {
                    let s = through(cell(3.0, k_c, 0.0, None, None, 0.0, 1), bandwidth);
                    let e = run_to_end(&s, plant, &tuning(f_r)).expect("a valid tuning");
                    let peak = e.run.metrics(0.0, f64::INFINITY).peak_force;
                    // The filter shows the contact its delay later: the tool goes on for that too.
                    let seen = floor_after(k_c, 0.002, plant, s.sensor.delay());
                    touch += usize::from(e.fault.is_some() || peak > 2.0 * f_r + seen);
                    over_cell += usize::from(
                        e.fault.is_none() && peak > 2.0 * f_r + floor(k_c, 0.002, plant),
                    );
                }
            }
        }
        let mut sines = 0;
        for k_c in [100e3, 300e3, 500e3] {
            for f_r in [2.0, 5.0, 20.0, 50.0] {
                for plant in &CELLS {
                    for amplitude in [-1e-3, -0.5e-3, -0.2e-3, 0.2e-3, 0.5e-3, 1e-3] {
                        for frequency in [0.25, 0.5, 1.0] {
                            let s = through(sine(k_c, amplitude, frequency), bandwidth);
                            let e = run_to_end(&s, plant, &tuning(f_r)).expect("a valid tuning");
                            sines += usize::from(e.fault.is_some());
                        }
                    }
                }
            }
        }
        println!(
            "{bandwidth} Hz: {faults} of 216 steps on a fault, {unsettled} unsettled; {touch} of 48 \
             touch-downs over their bound ({over_cell} over the cell's floor alone); {sines} of 648 \
             sines on a fault"
        );
        assert!(
            faults as f64 <= steps_measured,
            "{faults} > {steps_measured}"
        );
        assert!(
            unsettled as f64 <= unsettled_measured,
            "{unsettled} > {unsettled_measured}"
        );
        assert!(touch as f64 <= touch_measured, "{touch} > {touch_measured}");
        assert!(sines as f64 <= sines_measured, "{sines} > {sines_measured}");
    }
}

/// Stiffness changes through a filtered sensor, measured, not a criterion: per filter cut-off, of 108
/// changes (×0.5 and ×2 at 3 s on 20, 70 and 200 kN/m at f_r 5, 20 and 50 N, clean and under σ 0.3 N,
/// the three cells) those that end on a fault or with `k̂_c` more than 10 % off 2 s after the change;
/// no more than measured.
#[test]
#[ignore = "540 closed-loop runs: the known limits' figures, not a criterion"]
fn filtered_stiffness_changes() {
    // Per bandwidth, the misses' bound in tests/census-bounds.toml.
    for bandwidth in [0.0f64, 50.0, 100.0, 200.0, 400.0] {
        let measured = common::bound("filtered_stiffness_changes", &format!("{bandwidth} Hz"));
        let mut misses = 0;
        for plant in &CELLS {
            for k_c in [20e3, 70e3, 200e3] {
                for f_r in [5.0, 20.0, 50.0] {
                    for factor in [0.5, 2.0] {
                        for noise in [0.0, 0.3] {
                            let s = cell(5.0, k_c, 0.0, Some((3.0, factor)), None, noise, 7);
                            let e = run_to_end(&through(s, bandwidth), plant, &tuning(f_r))
                                .expect("a valid tuning");
                            let off = e.run.metrics(3.0, f64::INFINITY).kc_rel_error;
                            misses += usize::from(e.fault.is_some() || off.is_nan() || off > 0.1);
                        }
                    }
                }
            }
        }
        println!("{bandwidth} Hz: {misses} of 108 stiffness changes on a fault or k̂_c > 10 % off");
        assert!(misses as f64 <= measured, "{misses} > {measured}");
    }
}
