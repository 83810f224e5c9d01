//! Programmed polishing passes (`scenarios/pass-*.toml`): the robot program commands the force process
//! over the process channels, the tool moves along a formed part. Every target of every pass is
//! checked on P1 and P2 with the shipped tuning, and every one is met.

use forcecell::runner::{RunSpec, run_inproc};
use forcecell::scenario::Scenario;

const PASSES: &[&str] = &[
    "pass-flat-20n",
    "pass-wavy-50",
    "pass-wavy-100",
    "pass-tilt-step",
    "pass-force-steps",
];

#[test]
fn every_pass_meets_its_targets_on_p1_and_p2() {
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
                println!(
                    "{name:18} {plant} {:22} {:10.4} {}",
                    v.target.metric,
                    v.value,
                    if v.pass { "pass" } else { "MISS" }
                );
                if !v.pass {
                    wrong.push(format!(
                        "{name} on {plant}: {} = {:.4} misses its target",
                        v.target.metric, v.value
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
