//! Programmed polishing passes (`scenarios/pass-*.toml`): the robot program commands the force process
//! over the process channels, the tool moves along a formed part. Every target of every pass is
//! checked on P1 and P2 with the shipped tuning; the ones the robust law does not meet yet are listed
//! in [`KNOWN_MISSES`] (and in the README) — any other miss fails, and a listed miss that starts to
//! pass fails too, so the list only ever shrinks.

use forcecell::runner::{RunSpec, run_inproc};
use forcecell::scenario::Scenario;

const PASSES: &[&str] = &[
    "pass-flat-20n",
    "pass-wavy-50",
    "pass-wavy-100",
    "pass-tilt-step",
    "pass-force-steps",
];

/// `(scenario, plant, metric)` the robust law misses today: on P2 its recovery from a 0.3 mm surface
/// step under a tilt overshoots and leaves the ±5 % band for longer than 2 % of the pass (97.5 %,
/// 14.6 %). The surface predictor takes the step (15 % of the set-point's penetration, below the
/// observer's `step_innovation` of 25 %) for motion, and the predicted feed-forward extrapolates it
/// over P2's lead: without that term the pass is met (98.2 %, 0.8 %); with `step_innovation` 0.1 or
/// 0.12 in the tuning too (98.5 %, 2.1 %), but at 0.1 and at 0.13 range cases fail (surface steps and
/// halvings at small set-points, touch-down under 0.85 N of noise).
const KNOWN_MISSES: &[(&str, &str, &str)] = &[
    ("pass-tilt-step", "p2", "pressing_in_band_pct"),
    ("pass-tilt-step", "p2", "press_overshoot_pct"),
];

#[test]
fn every_pass_meets_its_targets_on_p1_and_p2_but_the_listed_misses() {
    let mut wrong = Vec::new();
    for name in PASSES {
        let scenario = Scenario::load(name).unwrap();
        assert!(scenario.program.is_some(), "{name} runs a program");
        assert!(
            scenario.targets.len() >= 6,
            "{name} is judged by the pass targets"
        );
        for plant in ["p1", "p2"] {
            let spec = RunSpec::new(scenario.clone(), Some(plant), None).unwrap();
            let run = run_inproc(&spec, &mut |_| {}).unwrap();
            assert_eq!(
                run.ended_early, None,
                "{name} on {plant}: the program ran to its end"
            );
            for v in run.verdicts(&spec.scenario.targets) {
                let listed = KNOWN_MISSES.contains(&(*name, plant, v.target.metric.as_str()));
                println!(
                    "{name:18} {plant} {:22} {:10.4} {}",
                    v.target.metric,
                    v.value,
                    if v.pass { "pass" } else { "MISS" }
                );
                if v.pass == listed {
                    wrong.push(format!(
                        "{name} on {plant}: {} = {:.4} {}",
                        v.target.metric,
                        v.value,
                        if listed {
                            "now passes: take it off KNOWN_MISSES"
                        } else {
                            "misses its target"
                        }
                    ));
                }
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn a_pass_ends_with_the_correction_at_zero_and_off() {
    let scenario = Scenario::load("pass-flat-20n").unwrap();
    let spec = RunSpec::new(scenario, Some("p2"), None).unwrap();
    let run = run_inproc(&spec, &mut |_| {}).unwrap();
    let last = run.rows.last().unwrap();
    assert_eq!(last.phase, Some(0), "OFF");
    assert_eq!(last.x_cmd, 0.0);
    // Segments are recorded with every row, in the program's order.
    let mut segs: Vec<i64> = run.rows.iter().filter_map(|r| r.segment).collect();
    segs.dedup();
    assert_eq!(segs, [1, 2]);
    // The path advanced 100 mm at 50 mm/s.
    let s_max = run.rows.iter().map(|r| r.s).fold(0.0, f64::max);
    assert!((s_max - 0.1).abs() < 1e-9, "{s_max}");
}
