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
