//! The whole simulated cell in lockstep over RSI: control loop → KUKA RSI driver → loopback UDP →
//! simulated KRC → shared world → simulated sensor, against the same cell with the in-process robot
//! (`cargo bench --bench rsi_cell`), and with the ATI sensor wire as well. Prints cycles per second
//! first, then divan's timings.

use divan::Bencher;
use forcecell::args::{RobotBackend, RsiArgs};
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
        process_channels: false,
        ethernet_config: None,
        sensor_link: None,
    }
}

fn cycles_per_second(plant: &str, robot: RobotBackend) -> f64 {
    let s = spec(plant);
    let (run, _) = forcecell::rsi::run(&s, &args(robot), &mut |_| {}).unwrap();
    run.rows.len() as f64 / run.wall.as_secs_f64()
}

/// Both wires: RSI over loopback UDP for the robot, the ATI driver over the in-memory CAN bus.
fn both_wires_cycles_per_second(plant: &str) -> f64 {
    let s = spec(plant);
    let robot = forcecell::rsi::RobotSide::start(&s, &args(RobotBackend::Rsi)).unwrap();
    let (run, _) = forcecell::ati::run_sim_with(robot, None, &mut |_| {}).unwrap();
    run.rows.len() as f64 / run.wall.as_secs_f64()
}

fn main() {
    for plant in ["p0", "p2"] {
        let steps = spec(plant).steps();
        let rsi = cycles_per_second(plant, RobotBackend::Rsi);
        let inproc = cycles_per_second(plant, RobotBackend::Inproc);
        let both = both_wires_cycles_per_second(plant);
        println!(
            "paper-fig9 on {plant} ({steps} cycles): RSI lockstep over loopback {rsi:.0} cycles/s, \
             RSI + ATI (in-memory CAN) {both:.0} cycles/s, in-process {inproc:.0} cycles/s"
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
