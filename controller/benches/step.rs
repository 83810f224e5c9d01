//! B11: cost of one control step (target ≤ 1 µs). `cargo bench -p forcecell-controller`.

use controller::{ForceLaw, ImpedanceLaw, LawConfig, RobustLaw, Tuning};
use divan::{Bencher, black_box};

fn main() {
    divan::main();
}

fn robust_law() -> RobustLaw {
    let t: Tuning = toml::from_str(include_str!("../../tunings/robust.toml")).unwrap();
    let LawConfig::Robust(p) = t.law else {
        panic!("robust tuning")
    };
    RobustLaw::new(*p).unwrap()
}

/// One step of a law in contact with a spring, the plant folded in so the law sees realistic input.
fn in_contact<L: ForceLaw>(bencher: Bencher, mut law: L) {
    law.start(0.0100714);
    let mut x: f64 = 0.0100714;
    // Reach contact first.
    for _ in 0..2000 {
        let f = (70_000.0 * (x - 0.010)).max(0.0);
        x += 0.3 * (law.step(x, f, 1e-3).x_cmd - x);
    }
    bencher.bench_local(|| {
        let f = (70_000.0 * (x - 0.010)).max(0.0);
        let out = law.step(black_box(x), black_box(f), black_box(1e-3));
        x += 0.3 * (out.x_cmd - x);
        out.x_cmd
    });
}

#[divan::bench]
fn robust_step(bencher: Bencher) {
    in_contact(bencher, robust_law());
}

#[divan::bench]
fn paper_step(bencher: Bencher) {
    in_contact(bencher, ImpedanceLaw::paper());
}

/// The robust law with orientation following around it: one step on a cycle and a tilted wrench
/// (the stage's moment, tilt estimate, normal force and rotation update included).
#[divan::bench]
fn robust_oriented_step(bencher: Bencher) {
    use controller::{AlongNormal, CellLaw, OrientationParams, Oriented};
    use hal::{Correction, Cycle, Pose, Vector3, Wrench};
    let t: Tuning = toml::from_str(include_str!("../../tunings/robust.toml")).unwrap();
    let o: OrientationParams = toml::from_str(
        "tool_length = 0.1\npad_radius = 0.02\ngain = 15.0\nmax_rate = 1.0\nmax_angle = 0.21\n\
         poscorr = 0.26\nmax_moment = 3.0\nmin_force = 2.0\nstiffness = 10000.0\n",
    )
    .unwrap();
    let mut law = Oriented::new(AlongNormal::new(t.law.build().unwrap(), 1.0), Some(o), 1.0);
    let mut cycle = Cycle {
        seq: 0,
        t: 0.0,
        period: 0.001,
        actual: Pose::identity(),
        programmed: Pose::identity(),
        late_replies: 0,
        missed: 0,
        replied_late: 0,
        new_session: false,
        process: None,
    };
    law.start(&cycle, &Correction::default());
    let mut x: f64 = 0.0100714;
    let mut step = |law: &mut Oriented<_>, cycle: &mut Cycle| {
        cycle.seq += 1;
        cycle.t += 0.001;
        cycle.actual.position.z = x;
        let f = (70_000.0 * (x - 0.010)).max(0.0);
        let w = Wrench {
            force: Vector3::new(0.02 * f, 0.0, f),
            torque: Vector3::new(0.0, -0.01, 0.0),
        };
        let s = law.step(black_box(cycle), black_box(&w), black_box(1e-3));
        x += 0.3 * (s.correction.translation.z - x);
        s.correction.rotation.y
    };
    for _ in 0..2000 {
        step(&mut law, &mut cycle);
    }
    bencher.bench_local(|| step(&mut law, &mut cycle));
}
