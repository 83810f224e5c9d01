//! The whole simulated cell in lockstep over RSI: control loop → KUKA RSI driver → loopback UDP →
//! simulated KRC → shared world → simulated sensor, against the same cell with the in-process robot
//! (`cargo bench --bench rsi_cell`). Prints cycles per second first, then divan's timings.

use divan::Bencher;
use forcecell::rsi::{RobotBackend, RsiArgs};
use forcecell::runner::RunSpec;
use forcecell::scenario::Scenario;

fn spec(plant: &str) -> RunSpec {
    RunSpec::new(Scenario::load("paper-fig9").unwrap(), Some(plant), None).unwrap()
}

fn args(robot: RobotBackend) -> RsiArgs {
    RsiArgs {
        robot,
        realtime: false,
        external_robot: None,
    }
}

fn cycles_per_second(plant: &str, robot: RobotBackend) -> f64 {
    let s = spec(plant);
    let (run, _) = forcecell::rsi::run(&s, &args(robot), &mut |_| {}).unwrap();
    run.rows.len() as f64 / run.wall.as_secs_f64()
}

fn main() {
    for plant in ["p0", "p2"] {
        let steps = spec(plant).steps();
        let rsi = cycles_per_second(plant, RobotBackend::Rsi);
        let inproc = cycles_per_second(plant, RobotBackend::Inproc);
        println!(
            "paper-fig9 on {plant} ({steps} cycles): RSI lockstep over loopback {rsi:.0} cycles/s, in-process {inproc:.0} cycles/s"
        );
    }
    divan::main();
}

/// paper-fig9 on P0 (2000 cycles) over RSI in lockstep.
#[divan::bench(sample_count = 10)]
fn cell_rsi_lockstep(b: Bencher) {
    let s = spec("p0");
    b.bench(|| forcecell::rsi::run(&s, &args(RobotBackend::Rsi), &mut |_| {}).unwrap());
}

/// The same with the in-process robot.
#[divan::bench(sample_count = 10)]
fn cell_inproc(b: Bencher) {
    let s = spec("p0");
    b.bench(|| forcecell::rsi::run(&s, &args(RobotBackend::Inproc), &mut |_| {}).unwrap());
}
