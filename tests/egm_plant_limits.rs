//! Known failures on the pessimistic EGM plant (docs/egm.md, "The plants"): a 4 ms cycle, a 10 ms lag and
//! 20 ms of **pure** delay on top — the top of EGM's documented 10–20 ms control lag read as delay. Two B
//! targets are missed there (none on P1 and P2, where the targets apply): B1's entry overshoot and
//! B3a's contact loss on the 1 mm retreat. These tests hold them where they were measured (limits only
//! shrink: a change that worsens either fails here; one that improves it lowers the bound in the same
//! change) and check that every other target of those scenarios is still met. The figures are the law's and
//! the plant's, not a wire's: `scripts/egm-tables.sh` gives the same digits over EGM and over RSI.

use forcecell::runner::{RunSpec, run_inproc};
use forcecell::scenario::{PlantSpec, Scenario};
use sim::inner::InnerLoopModel;

/// The EGM plant of docs/egm.md and `scripts/egm-tables.sh`.
const EGM_PLANT: InnerLoopModel = InnerLoopModel {
    period: 0.004,
    tau: 0.010,
    delay_cycles: 5,
};

/// Run `name` on the EGM plant; returns (metric, value, pass) for each of its targets.
fn targets_on_egm_plant(name: &str) -> Vec<(String, f64, bool)> {
    let mut scenario = Scenario::load(name).unwrap();
    scenario.plant = PlantSpec::Model(EGM_PLANT);
    let spec = RunSpec::new(scenario, None, None).unwrap();
    let run = run_inproc(&spec, &mut |_| {}).unwrap();
    run.verdicts(&spec.scenario.targets)
        .into_iter()
        .map(|v| {
            println!(
                "{name} EGM {:20} {:10.4} {}",
                v.target.metric,
                v.value,
                if v.pass { "pass" } else { "MISS" }
            );
            (v.target.metric.clone(), v.value, v.pass)
        })
        .collect()
}

/// Every target but `known` is met, and `known`'s value is at most `bound`.
fn only_known_miss(name: &str, known: &str, bound: f64) {
    let got = targets_on_egm_plant(name);
    assert!(
        got.iter().any(|(m, _, _)| m == known),
        "{name} has a {known} target"
    );
    for (metric, value, pass) in &got {
        if metric == known {
            assert!(
                *value <= bound,
                "{name} on the EGM plant: {metric} = {value:.4}, worse than the measured {bound} \
                 (limits only shrink)"
            );
        } else {
            assert!(
                *pass,
                "{name} on the EGM plant: {metric} = {value:.4} misses"
            );
        }
    }
}

/// B1: the first touch-down overshoots 11.6 % (target ≤ 10 %): the set-point ramp is answered after
/// 20 ms of delay and 10 ms of lag. With 16 ms of delay it holds (0.57 %).
#[test]
fn known_failure_b01_overshoot_on_the_egm_plant() {
    only_known_miss("b01-approach", "overshoot_pct", 11.63);
}

/// B3a: the surface retreats 1 mm; the tool loses contact for 64 ms (target ≤ 50 ms): the retreat is
/// only seen after the delay and followed after the lag.
#[test]
fn known_failure_b03a_contact_loss_on_the_egm_plant() {
    // 16 cycles of 4 ms; the time is a sum of periods, so compare whole cycles.
    let cycles = 16.0;
    only_known_miss(
        "b03a-surface-retreat",
        "contact_loss_time",
        (cycles + 0.5) * EGM_PLANT.period,
    );
}
