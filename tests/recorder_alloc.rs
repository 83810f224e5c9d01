//! The control loop with the recorder attached does not touch the heap: each cycle's record goes into
//! the preallocated ring, and a full ring drops and counts. A counting global allocator
//! (`stats_alloc`) in a test binary of its own, with the ring's consumer idle during the measured
//! region (the writer thread's allocations are off the loop and not what is measured here).

use std::alloc::System;

use controller::{ControlLoop, ForceLaw, Tuning};
use forcecell::recorder::{self, Full, Record};
use forcecell::rig::Spring;
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

#[test]
fn the_loop_with_the_recorder_attached_does_not_allocate() {
    let t: Tuning = toml::from_str(include_str!("../tunings/robust.toml")).unwrap();
    let law = t.law.build().unwrap();
    let f_r = law.set_point();
    let spring = Spring::new(70_000.0, 0.010, 0.009, t.loop_cfg.force_sign);
    let (robot, sensor) = spring.devices(0.004);
    let mut lp = ControlLoop::new(robot, sensor, law, t.loop_cfg);
    let capacity = 4_096;
    let (mut tx, mut rx) = recorder::queue(capacity, Full::Drop);
    let cycles = 10_000u64;
    let mut pushed = 0u64;
    let mut states = 0u32;
    // The least of three runs: the test harness's own thread allocates now and then while a region
    // is open (see controller/tests/no_alloc.rs); a cycle that allocates does so in every run.
    let mut least = u64::MAX;
    for run in 0..3 {
        while rx.pop().is_ok() {}
        let region = Region::new(GLOBAL);
        for _ in 0..cycles {
            let r = lp.cycle().unwrap();
            let rec = Record::from_report(&r, f_r);
            states |= 1 << rec.state.min(7);
            pushed += u64::from(tx.push(rec));
        }
        let c = region.change();
        least = least.min((c.allocations + c.reallocations) as u64);
        assert_eq!(
            pushed,
            capacity as u64 * (run + 1),
            "the ring holds {capacity} records, the rest are dropped"
        );
    }
    assert_eq!(least, 0, "the loop with the recorder allocated");
    assert_eq!(tx.dropped(), 3 * cycles - pushed, "every drop counted");
    assert!(
        states & 0b11 == 0b11,
        "approach and contact visited: {states:b}"
    );
    // What the ring holds is what the loop recorded: the last run's first cycles, in order.
    let first = rx.pop().unwrap();
    let second = rx.pop().unwrap();
    assert_eq!(second.robot_seq, first.robot_seq + 1);
    assert_eq!(first.row.f_r, f_r);
    assert!(first.wrench[2].is_finite());
}
