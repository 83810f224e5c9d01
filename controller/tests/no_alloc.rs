//! B11: the laws' steps do not touch the heap (the robust law, and the paper's and fixed-reference laws). A counting global allocator (`stats_alloc`) in a
//! test binary of its own, so no other test's allocations are counted.

use std::alloc::System;

use controller::{
    ForceLaw, ImpedanceLaw, ImpedanceParams, LawConfig, Reference, RobustLaw, Tuning,
};
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, Stats, StatsAlloc};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

/// Allocations during `run`, the least of three runs: a deterministic step that allocates does so on
/// every run, while the test harness's own thread allocates now and then while a region is open (seen
/// as 4 allocations, 900 bytes, in about a third of the runs, before and after this law changed).
fn allocations(mut run: impl FnMut()) -> Stats {
    (0..3)
        .map(|_| {
            let region = Region::new(GLOBAL);
            run();
            region.change()
        })
        .min_by_key(|c| c.allocations + c.reallocations)
        .expect("three runs")
}

#[test]
fn robust_step_does_not_allocate() {
    let t: Tuning = toml::from_str(include_str!("../../tunings/robust.toml")).unwrap();
    let LawConfig::Robust(mut p) = t.law else {
        panic!("robust tuning")
    };
    // A sensor whose force is 2.25 ms old: the pairing with past positions runs too.
    p.cell.sensor_delay = 0.00225;
    let mut law = RobustLaw::new(*p).unwrap();
    let mut states = 0u32;
    let change = allocations(|| {
        law.start(0.009);
        // Drive it through approach, contact, lift-off, re-acquire and back against a spring.
        let (k, mut xc): (f64, f64) = (70_000.0, 0.010);
        let mut x = 0.009;
        for i in 0..20_000 {
            if i == 8_000 {
                xc += 0.001;
            }
            if i == 14_000 {
                xc -= 0.0015;
            }
            let f = (k * (x - xc)).max(0.0);
            let out = law.step(x, f, 1e-3);
            states |= 1 << out.state.map_or(7, |s| s.code());
            x += 0.1 * (out.x_cmd - x);
        }
        let _ = law.step(f64::NAN, 1.0, 1e-3);
    });
    assert_eq!(
        change.allocations + change.reallocations,
        0,
        "the step allocated: {change:?}"
    );
    paper_and_fixed_laws_step_without_allocating();
    oriented_step_does_not_allocate();
    assert_eq!(
        states & 0b111,
        0b111,
        "approach, contact and re-acquire visited: {states:b}"
    );
}

/// Called from the one test above: a second `#[test]` could run in parallel and allocate in the region.
fn paper_and_fixed_laws_step_without_allocating() {
    let mut paper = ImpedanceLaw::paper();
    let mut fixed =
        ImpedanceLaw::new(ImpedanceParams::PAPER, Reference::Fixed { x_r: 0.0101 }).unwrap();
    let mut x = 0.0091;
    let change = allocations(|| {
        paper.start(0.0091);
        fixed.start(0.0091);
        x = 0.0091;
        for k in 0..10_000 {
            let k_c = if k < 5_000 { 70_000.0 } else { 40_000.0 };
            let f = (k_c * (x - 0.01f64)).max(0.0);
            x = paper.step(x, f, 1e-3).x_cmd;
            std::hint::black_box(fixed.step(x, f, 1e-3));
        }
    });
    assert_eq!(change.allocations + change.reallocations, 0, "{change:?}");
    assert!(x.is_finite());
}

/// The robust law with orientation following around it (tunings/robust-curved.toml's stage), on a
/// cycle and a tilted wrench; called from the one test above.
fn oriented_step_does_not_allocate() {
    use controller::{CellLaw, OrientationParams, Oriented};
    use hal::{Correction, Cycle, Pose, Vector3, Wrench};
    let t: Tuning = toml::from_str(include_str!("../../tunings/robust.toml")).unwrap();
    let o: OrientationParams = toml::from_str(
        "tool_length = 0.1\npad_radius = 0.02\ngain = 15.0\nmax_rate = 1.0\nmax_angle = 0.21\n\
         poscorr = 0.26\nmax_moment = 3.0\nmin_force = 2.0\nstiffness = 10000.0\n",
    )
    .unwrap();
    let mut law = Oriented::new(
        controller::AlongNormal::new(t.law.build().unwrap(), 1.0),
        Some(o),
        1.0,
    );
    let mut cycle = Cycle {
        seq: 0,
        t: 0.0,
        period: 0.004,
        actual: Pose::identity(),
        programmed: Pose::identity(),
        late_replies: 0,
        missed: 0,
        replied_late: 0,
        new_session: false,
        process: None,
    };
    let mut turned = 0.0;
    let change = allocations(|| {
        law.start(&cycle, &Correction::default());
        for k in 0..5_000 {
            cycle.seq = k;
            cycle.t = k as f64 * 0.004;
            let w = Wrench {
                force: Vector3::new(1.0, -0.5, 20.0),
                torque: Vector3::new(0.1, -0.05, 0.0),
            };
            turned = law.step(&cycle, &w, 0.004).correction.rotation.norm();
        }
        let bad = Wrench::from_array([0.0, 0.0, 20.0, f64::NAN, 0.0, 0.0]);
        std::hint::black_box(law.step(&cycle, &bad, 0.004));
    });
    assert_eq!(change.allocations + change.reallocations, 0, "{change:?}");
    assert!(turned > 0.0, "the stage turned the tool");
}
