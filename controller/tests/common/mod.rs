//! What the closed-loop range tests share: the cells, the shipped robust tuning at a set-point, a
//! scenario from its parameters, and the metrics the metric set lacks.

#![allow(dead_code)]

use controller::{LawConfig, Tuning};
use proptest::prelude::*;
use scenario::scenario::{Scenario, load_tuning};
use sim::InnerLoopModel;

/// The cells: KUKA RSI at 1 kHz (P1), an RSI-like 4 ms cycle (P2), RSI's 12 ms `#IPO` cycle with two
/// cycles of delay.
pub const CELLS: [InnerLoopModel; 3] = [
    InnerLoopModel::P1,
    InnerLoopModel::P2,
    InnerLoopModel {
        period: 0.012,
        tau: 0.010,
        delay_cycles: 2,
    },
];

/// The shipped robust tuning at set-point `f_r` (N); the force limit, the law's and the loop's,
/// follows the set-point (a 60 N limit means nothing at 50 N).
pub fn tuning(f_r: f64) -> Tuning {
    tuning_named("robust", f_r)
}

/// The shipped tuning `name` at set-point `f_r`, as [`tuning`].
pub fn tuning_named(name: &str, f_r: f64) -> Tuning {
    let mut t = load_tuning(name).expect("shipped tuning");
    let LawConfig::Robust(p) = &mut t.law else {
        panic!("robust")
    };
    p.f_r = f_r;
    p.limits.max_force = p.limits.max_force.max(3.0 * f_r);
    t.loop_cfg.process.max_force = p.limits.max_force;
    t
}

/// `cases` seeded cases, or as many as `FORCECELL_RANGE_CASES` says (a deeper search than CI's);
/// `FORCECELL_RANGE_SHRINK=0` reports a failing case as drawn, not shrunk.
pub fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases: env_or("FORCECELL_RANGE_CASES", cases),
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x0011_2026),
        failure_persistence: None,
        max_shrink_iters: env_or("FORCECELL_RANGE_SHRINK", 1024),
        ..ProptestConfig::default()
    }
}

/// The variable `name` parsed, or `default`.
pub fn env_or(name: &str, default: u32) -> u32 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The census bounds (`tests/census-bounds.toml`): what each known failure counted, which a
/// census may not exceed and a change may only lower (`tests/bounds.rs`).
pub fn bounds() -> toml::Table {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/census-bounds.toml");
    let text = std::fs::read_to_string(&path).expect("tests/census-bounds.toml");
    text.parse().expect("tests/census-bounds.toml is TOML")
}

/// The bound `key` of census `table` (a dotted path: `noisy_retreats.robust`), `None` when that
/// census has no bound for it (no criterion).
pub fn bound_opt(table: &str, key: &str) -> Option<f64> {
    let all = bounds();
    let mut t = &all;
    for part in table.split('.') {
        t = t.get(part)?.as_table()?;
    }
    match t.get(key)? {
        toml::Value::Integer(i) => Some(*i as f64),
        toml::Value::Float(f) => Some(*f),
        v => panic!("census bound {table} {key:?} is not a number: {v}"),
    }
}

/// The bound `key` of census `table`; a census without it is a mistake.
pub fn bound(table: &str, key: &str) -> f64 {
    bound_opt(table, key)
        .unwrap_or_else(|| panic!("no bound {key:?} in [{table}] of tests/census-bounds.toml"))
}

/// Run `n` seeded cases (or `FORCECELL_RANGE_CASES`) of `cases` through `misses` (a case's label
/// and the criteria it misses), print every miss and count it by the first of `kinds` it names, not
/// stopped at the first failing case as a property test is; with `n` cases, no more of each kind
/// than its bound in `[table]` of `tests/census-bounds.toml` (a kind without one is counted only).
pub fn census<S: Strategy>(
    n: u32,
    cases: S,
    kinds: &[&str],
    table: &str,
    misses: impl Fn(S::Value) -> (String, Vec<String>),
) {
    let measured: Vec<Option<f64>> = kinds.iter().map(|k| bound_opt(table, k)).collect();
    let counts = std::cell::RefCell::new(vec![0usize; kinds.len()]);
    let mut runner = proptest::test_runner::TestRunner::new(config(n));
    runner
        .run(&cases, |case| {
            let (label, missed) = misses(case);
            for miss in missed {
                println!("{label}: {miss}");
                if let Some(i) = kinds.iter().position(|k| miss.contains(k)) {
                    counts.borrow_mut()[i] += 1;
                }
            }
            Ok(())
        })
        .expect("the census itself asserts nothing");
    let counts = counts.into_inner();
    let by: Vec<String> = kinds
        .iter()
        .zip(&counts)
        .map(|(k, n)| format!("{k} {n}"))
        .collect();
    println!("misses by criterion: {}", by.join(", "));
    if env_or("FORCECELL_RANGE_CASES", n) == n {
        assert!(
            counts
                .iter()
                .zip(&measured)
                .all(|(n, m)| m.is_none_or(|m| *n as f64 <= m)),
            "{} (bounds [{table}] {measured:?})",
            by.join(", ")
        );
    }
}

/// A scenario: start 1 mm short of a surface at 10 mm.
#[allow(clippy::too_many_arguments)]
pub fn cell(
    duration: f64,
    k_c: f64,
    c_e: f64,
    k_event: Option<(f64, f64)>,
    x_step: Option<(f64, f64)>,
    noise: f64,
    seed: u64,
) -> Scenario {
    let mut text = format!(
        "name = \"range\"\nduration = {duration}\nx0 = 0.009\n[environment]\nk_c = {k_c}\nx_c = 0.010\nc_e = {c_e}\n"
    );
    if let Some((at, factor)) = k_event {
        text += &format!("k_c_events = [{{ kind = \"scale\", at = {at}, factor = {factor} }}]\n");
    }
    if let Some((at, delta)) = x_step {
        text += &format!("x_c_events = [{{ kind = \"step\", at = {at}, delta = {delta} }}]\n");
    }
    text += &format!("[sensor]\nnoise = {noise}\nseed = {seed}\n");
    Scenario::from_toml(&text, "range").expect("a valid range scenario")
}

/// A sine surface: 1 mm short of a surface at 10 mm, which moves as `amplitude·sin(2π·frequency·t)`
/// (m, Hz) from 2 s on, starting at full speed; 6 s.
pub fn sine(k_c: f64, amplitude: f64, frequency: f64) -> Scenario {
    let text = format!(
        "name = \"sine\"\nduration = 6.0\nx0 = 0.009\n[environment]\nk_c = {k_c}\nx_c = 0.010\n\
         x_c_events = [{{ kind = \"sine\", start = 2.0, amplitude = {amplitude}, frequency = {frequency} }}]\n"
    );
    Scenario::from_toml(&text, "sine").expect("a valid sine scenario")
}

/// The physical floor of an impact: after a stop command the tool still travels `v·(delay + one
/// cycle)` into a surface of stiffness `k`, N (the floor).
pub fn floor(k: f64, v: f64, plant: &InnerLoopModel) -> f64 {
    floor_after(k, v, plant, 0.0)
}

/// [`floor`] with `extra` (s) more of travel: what the floor leaves out, the inner loop's lag
/// (the tool catches up with its command) or a sensor's own delay (its force shows the contact later).
pub fn floor_after(k: f64, v: f64, plant: &InnerLoopModel, extra: f64) -> f64 {
    k * v * (plant.delay() + plant.period + extra)
}

/// The least time the search after a lost contact takes to a surface `gap` (m) away at stiffness `k`
/// (N/m) on `plant` under `tuning`, s: the law's own speeds ([`controller::robust::ContactMachine::speeds`],
/// `k̂_c` exact and known exactly, a quiet sensor) on the law's own model of the plant's cell
/// ([`controller::robust::Stopping`]): the gentle search within its margin, the fast search for the
/// rest of its fast distance, then the one that stops within `2·f_r`.
pub fn reach_time(t: &Tuning, k: f64, gap: f64, plant: &InnerLoopModel) -> f64 {
    let LawConfig::Robust(p) = &t.law else {
        panic!("robust")
    };
    let cell = scenario::run::cell_model(plant, &sim::SensorParams::default());
    let mut stop = controller::robust::Stopping::new();
    stop.update(&cell, plant.period, &p.limits);
    let machine = controller::robust::ContactMachine::new(p.contact);
    let strong = machine.thresholds(p.f_r, 0.0, 0.0).strong;
    let sp = machine.speeds(k, 0.0, p.f_r, p.limits.max_force, strong, &stop);
    // The part of [a, b) the gap covers, m.
    let part = |a: f64, b: f64| (b.min(gap) - a).max(0.0);
    let (margin, fast) = (sp.margin, p.contact.reacquire_distance);
    part(0.0, margin) / sp.gentle
        + part(margin.min(fast), fast) / sp.reacquire
        + part(margin.max(fast), f64::INFINITY) / sp.near
}

/// The relative standard deviation below which nothing can know the new stiffness after a change by
/// `factor` in an `f_r` hold under sensor noise `sigma` (N) on `plant`, from the information the
/// change brings. At the jump the position stands: the force goes to `factor·f_r`, and the samples
/// taken before the loop has moved the tool (its delay, lag and the conditioning's delay,
/// `n = lead/period`, at least one) measure the ratio `ρ = k₂/k₁` to `σ/(f_r·√n)`; the tool then
/// travels `Δx = f_r/k₂ − f_r/k₁` (measured exactly), so `k₂ = f_r·(1 − ρ)/Δx` carries that error
/// divided by `|1 − ρ|`. A steady hold adds next to nothing (the loop's answer to noise moves the
/// tool by a fraction of `σ/k`), nor does the touch-down's fit at a small set-point (a handful of
/// samples over the rise). Two seconds after the change the bound is the same: what follows the
/// transient is a hold.
pub fn change_bound(f_r: f64, factor: f64, sigma: f64, plant: &InnerLoopModel) -> f64 {
    let LawConfig::Robust(p) = tuning(f_r).law else {
        panic!("robust")
    };
    let cutoff = p.conditioning.cutoff.min(0.45 / plant.period);
    let conditioning = core::f64::consts::SQRT_2 / (core::f64::consts::TAU * cutoff);
    let lead = plant.delay() + plant.tau + conditioning;
    let n = (lead / plant.period).max(1.0);
    sigma / (f_r * (1.0 - factor).abs() * n.sqrt())
}

/// A log-uniform stiffness in [lo, hi], N/m.
pub fn stiffness(lo: f64, hi: f64) -> impl Strategy<Value = f64> {
    (lo.ln()..hi.ln()).prop_map(f64::exp)
}

/// `|mean(f − f_r)|` of the true force from `from` on, N.
pub fn mean_error(rows: &[scenario::record::Row], from: f64) -> f64 {
    let e: Vec<f64> = rows
        .iter()
        .filter(|r| r.t >= from)
        .map(|r| r.f_true - r.f_r)
        .collect();
    (e.iter().sum::<f64>() / e.len() as f64).abs()
}
