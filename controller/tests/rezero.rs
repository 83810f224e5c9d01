//! Re-zeroing the sensor between passes, in simulation (`scenarios/multipass-drift.toml`: ten 50 s
//! passes at 20 N, 5 s of free air between them, the sensor drifting 0.5 N/min), run with and without
//! `[process] rezero`:
//! - without it, no re-zero happens and the per-pass mean force error grows with the drift;
//! - with it, the loop re-zeroes once in every free-air stretch, only while the process is OFF, and
//!   the zero it holds follows the sensor's true offset;
//! - in the later passes, the per-pass mean force error ([`scenario::metrics::pass_force_errors`]) is
//!   smaller with it than without it.
//!
//! `cargo test --release -p forcecell-controller --test rezero -- --nocapture` prints the per-pass
//! table (docs/rezero.md).

use controller::{RezeroOutcome, Tuning};
use hal::ProcessPhase;
use scenario::metrics::{PassError, pass_force_errors};
use scenario::run::run_watched;
use scenario::scenario::{Scenario, load_tuning};
use sim::InnerLoopModel;

/// One re-zero decision as the loop reported it.
#[derive(Clone, Copy, Debug)]
struct Seen {
    t: f64,
    outcome: RezeroOutcome,
    removed_z: f64,
    zero_z: f64,
    phase: ProcessPhase,
}

fn run(rezero: bool) -> (Vec<PassError>, Vec<Seen>, Scenario) {
    let mut scenario = Scenario::load("multipass-drift").expect("a built-in scenario");
    scenario.process.rezero = Some(rezero);
    let tuning: Tuning = load_tuning(&scenario.tuning).expect("its tuning");
    let mut seen = Vec::new();
    let ended = run_watched(&scenario, &InnerLoopModel::P1, &tuning, &mut |r, _| {
        if let Some(e) = r.rezero {
            seen.push(Seen {
                t: e.t,
                outcome: e.outcome,
                removed_z: e.offset.force.z,
                zero_z: e.zero.force.z,
                phase: r.command.process.phase,
            });
        }
    })
    .expect("the scenario runs");
    assert!(ended.fault.is_none(), "{:?}", ended.fault);
    assert_eq!(ended.aborted, None, "the program ran to its end");
    (pass_force_errors(&ended.run.rows), seen, scenario)
}

#[test]
fn rezero_between_passes_keeps_the_force_of_later_passes_nearer_the_set_point() {
    let (without, none, scenario) = run(false);
    let (with, seen, _) = run(true);
    let passes = scenario
        .program
        .as_ref()
        .unwrap()
        .segments
        .iter()
        .filter(|s| s.mode == sim::SegmentMode::Press)
        .count();
    assert_eq!(without.len(), passes, "{without:?}");
    assert_eq!(with.len(), passes, "{with:?}");
    assert!(none.is_empty(), "no re-zero unless asked: {none:?}");

    // One re-zero in each free-air stretch after a pass (none before the first), never refused
    // here, and only ever at OFF.
    let done: Vec<&Seen> = seen
        .iter()
        .filter(|s| s.outcome == RezeroOutcome::Done)
        .collect();
    assert_eq!(done.len(), seen.len(), "no refusal in free air: {seen:?}");
    assert!(
        done.len() >= passes - 1,
        "{} re-zeros: {seen:?}",
        done.len()
    );
    for s in &seen {
        assert_eq!(s.phase, ProcessPhase::Off, "{s:?}");
        assert!(
            with.iter().all(|p| s.t < p.start || s.t > p.end),
            "a re-zero during a pass: {s:?}"
        );
    }
    // The zero follows the sensor's offset (bias + drift at that time), within what its noise
    // leaves in a window's mean.
    let sensor = &scenario.sensor;
    let window = controller::RezeroParams::default().window;
    let spread = 6.0 * sensor.noise / (window / InnerLoopModel::P1.period).sqrt();
    let mut total = 0.0;
    for s in &done {
        total += s.removed_z;
        let offset = sensor.bias + sensor.drift_per_min * s.t / 60.0;
        assert!(
            (s.zero_z - offset).abs() < spread * (done.len() as f64).sqrt(),
            "zero {} N at {} s, the sensor's offset {offset} N",
            s.zero_z,
            s.t
        );
        assert!(
            (total - s.zero_z).abs() < 1e-9,
            "the zero is what was removed"
        );
    }

    println!("| pass | time (s) | mean force error without (N) | with re-zero (N) |");
    println!("|---:|---|---:|---:|");
    for (k, (a, b)) in without.iter().zip(&with).enumerate() {
        println!(
            "| {} | {:.0}–{:.0} | {:+.3} | {:+.3} |",
            k + 1,
            a.start,
            a.end,
            a.mean_error,
            b.mean_error
        );
    }
    // The later passes (from the third on, after two re-zeros): smaller error with it, every one.
    for (k, (a, b)) in without.iter().zip(&with).enumerate().skip(2) {
        assert!(
            b.mean_error.abs() < a.mean_error.abs(),
            "pass {}: {:+.3} N with re-zero, {:+.3} N without",
            k + 1,
            b.mean_error,
            a.mean_error
        );
    }
    // Without it the error grows with the drift: the last pass is off by more than the first.
    assert!(without[passes - 1].mean_error.abs() > without[0].mean_error.abs());
}
