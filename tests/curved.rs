//! Passes on curved parts (`scenarios/curved-*.toml`, docs/curved-parts.md): each target of each
//! pass is met on P1 and P2 with the shipped tuning (orientation following on), and the same passes
//! with orientation following off miss the tilt targets. Prints the side-by-side table of
//! docs/curved-parts.md: `cargo test --release --test curved -- --nocapture`.

use forcecell::runner::{RunResult, RunSpec, run_inproc};
use forcecell::scenario::Scenario;
use scenario::metrics::Metrics;

const PASSES: &[&str] = &[
    "curved-cylinder",
    "curved-saddle",
    "curved-flat-friction",
    "curved-disc-tilt",
];

/// 2° in rad: the tilt bound while pressing.
const TWO_DEG: f64 = 0.0349;

fn run(name: &str, plant: &str, following: bool) -> (RunSpec, RunResult) {
    let scenario = Scenario::load(name).unwrap();
    let mut spec = RunSpec::new(scenario, Some(plant), None).unwrap();
    assert!(
        spec.tuning.orientation.is_some(),
        "{name} ships a tuning that follows the surface"
    );
    if !following {
        spec.tuning.orientation = None;
    }
    let run = run_inproc(&spec, &mut |_| {}).unwrap();
    (spec, run)
}

/// Normal-force error (the largest |f − F|/F while PRESSING, %) and in-band share of a run.
fn force_error(run: &RunResult) -> f64 {
    run.rows
        .iter()
        .filter(|r| r.phase == Some(3))
        .map(|r| (r.f_true - r.f_cmd).abs() / r.f_cmd * 100.0)
        .fold(0.0, f64::max)
}

#[test]
fn every_curved_pass_meets_its_targets_on_p1_and_p2_and_misses_them_without_following() {
    let mut wrong = Vec::new();
    let mut table = vec![
        "| pass | plant | following | in band (%) | max normal-force error (%) | max tilt error while pressing (°) | after 0.3 s (°) | max rotation (°) | ended |".to_string(),
        "|---|---|---|---|---|---|---|---|---|".to_string(),
    ];
    for name in PASSES {
        for plant in ["p1", "p2"] {
            for following in [true, false] {
                let (spec, run) = run(name, plant, following);
                let m = Metrics::compute(&run.rows[..run.control], 0.0, f64::INFINITY);
                table.push(format!(
                    "| {name} | {plant} | {} | {:.1} | {:.1} | {:.2} | {:.2} | {:.2} | {} |",
                    if following { "on" } else { "off" },
                    m.pressing_in_band_pct,
                    force_error(&run),
                    m.tilt_error_max.to_degrees(),
                    m.tilt_error_settled.to_degrees(),
                    m.max_rotation.to_degrees(),
                    run.ended_early.as_deref().unwrap_or("at its end"),
                ));
                if following {
                    if let Some(why) = &run.ended_early {
                        wrong.push(format!("{name} on {plant}: ended early: {why}"));
                    }
                    for v in run.verdicts(&spec.scenario.targets) {
                        if !v.pass {
                            wrong.push(format!(
                                "{name} on {plant}: {} = {:.5} misses its target",
                                v.target.metric, v.value
                            ));
                        }
                    }
                    assert!(
                        m.max_rotation > 0.01,
                        "{name} on {plant}: the tool turned ({})",
                        m.max_rotation
                    );
                } else {
                    // Along the normal only: the tool never turns, and the tilt stays the part's.
                    assert_eq!(m.max_rotation, 0.0, "{name} on {plant}");
                    assert!(
                        m.tilt_error_max > TWO_DEG,
                        "{name} on {plant} without following: tilt error {} rad is expected beyond 2°",
                        m.tilt_error_max
                    );
                }
            }
        }
    }
    println!("{}", table.join("\n"));
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// The cylinder pass with the tuning changed by `edit` and the scenario by `edit_scenario`.
fn cylinder_with(
    edit: impl FnOnce(&mut controller::OrientationParams),
    edit_scenario: impl FnOnce(&mut Scenario),
) -> RunResult {
    let mut scenario = Scenario::load("curved-cylinder").unwrap();
    edit_scenario(&mut scenario);
    let mut spec = RunSpec::new(scenario, Some("p2"), None).unwrap();
    edit(spec.tuning.orientation.as_mut().unwrap());
    run_inproc(&spec, &mut |_| {}).unwrap()
}

#[test]
fn a_rotation_at_its_envelope_faults_and_backs_off_with_the_tool_turned_back() {
    let run = cylinder_with(|o| o.max_angle = 0.05, |_| {});
    let why = run.ended_early.as_deref().unwrap_or_default();
    assert!(why.contains("FAULT 3"), "{why}");
    assert!(run.law_events.orientation_envelopes >= 1);
    let control = &run.rows[..run.control];
    // Never beyond the envelope, and once the fault latched the command backs off and turns back.
    assert!(control.iter().all(|r| r.rotation < 0.05));
    let faulted = control.iter().position(|r| r.fault == Some(3)).unwrap();
    // (The program aborts on the FAULT; the back-off goes on in the return's rows.)
    let after = &run.rows[faulted..];
    let last = after.last().unwrap();
    assert!(last.x_cmd < after[0].x_cmd, "backed off");
    assert!(last.rotation < after[0].rotation, "turned back");
}

#[test]
fn a_saturated_moment_holds_the_rotation_and_counts_it() {
    // Every moment of the pass is beyond the believed range: the tool never turns.
    let run = cylinder_with(|o| o.max_moment = 1e-4, |_| {});
    assert!(
        run.law_events.orientation_holds > 100,
        "{:?}",
        run.law_events
    );
    assert!(run.rows.iter().all(|r| r.rotation == 0.0));
}

#[test]
fn a_stale_or_nan_sample_holds_the_rotation_and_never_reaches_the_command() {
    // A 40 ms dropout and a NaN sample while pressing.
    let run = cylinder_with(
        |_| {},
        |s| {
            s.sensor.dropouts = vec![sim::Window {
                at: 1.5,
                duration: 0.04,
            }];
            s.sensor.nan_at = vec![2.0];
        },
    );
    assert_eq!(run.ended_early, None);
    assert!(run.stats.sensor_faults >= 9, "{:?}", run.stats);
    assert!(run.stats.nonfinite_inputs >= 1, "{:?}", run.stats);
    assert!(run.rows.iter().all(|r| r.rotation.is_finite()));
    // Through the dropout the rotation sent stands still.
    let held: Vec<f64> = run
        .rows
        .iter()
        .filter(|r| r.t > 1.505 && r.t < 1.535)
        .map(|r| r.rotation)
        .collect();
    assert!(
        held.len() >= 5 && held.windows(2).all(|w| w[0] == w[1]),
        "{held:?}"
    );
}
