//! A Robotiq FT 300 cell in simulation: the driver reads a simulated sensor over a real pseudo-terminal
//! (Modbus start-up through tokio-modbus, then the 100 Hz stream, one frame per 10 ms of simulated time)
//! while the robust law holds B1 on the RSI-like plant P2.

use forcecell::runner::RunSpec;
use forcecell::scenario::Scenario;

fn b1_on_p2(tuning: &str) -> forcecell::runner::RunResult {
    let spec = RunSpec::new(
        Scenario::load("b01-approach").unwrap(),
        Some("p2"),
        Some(tuning),
    )
    .unwrap();
    forcecell::robotiq::run_sim(&spec, &mut |_| {}).unwrap()
}

#[test]
fn a_robotiq_cell_holds_b1_on_p2_with_the_100_hz_tuning() {
    let spec = RunSpec::new(
        Scenario::load("b01-approach").unwrap(),
        Some("p2"),
        Some("robust-100hz"),
    )
    .unwrap();
    let run = b1_on_p2("robust-100hz");
    assert!(run.ended_early.is_none(), "{:?}", run.ended_early);
    assert_eq!(run.stats.sensor_faults, 0);
    let verdicts = run.verdicts(&spec.scenario.targets);
    assert!(!verdicts.is_empty());
    for v in &verdicts {
        assert!(
            v.pass,
            "{} = {} misses its target",
            v.target.metric, v.value
        );
    }
    // The force the loop saw came through the wire: 0.01 N quantisation, so the last value is a
    // multiple of it (the in-process model's is not).
    let f = run.rows.last().unwrap().f;
    assert!(((f * 100.0).round() - f * 100.0).abs() < 1e-6, "{f}");
}

/// Why the tuning changed: with the 1 kHz-sensor gain, every 10 ms frame is corrected by 2.5 commands,
/// and the approach overshoots more than with the slower gain.
#[test]
fn the_1_khz_gain_overshoots_more_with_a_100_hz_sensor() {
    let fast = b1_on_p2("robust");
    let slow = b1_on_p2("robust-100hz");
    assert!(
        fast.metrics.overshoot_pct > slow.metrics.overshoot_pct,
        "robust {} %, robust-100hz {} %",
        fast.metrics.overshoot_pct,
        slow.metrics.overshoot_pct
    );
}
