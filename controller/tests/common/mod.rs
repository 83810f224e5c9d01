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

pub fn tuning(f_r: f64) -> Tuning {
    let mut t = load_tuning("robust").expect("shipped tuning");
    let LawConfig::Robust(p) = &mut t.law else {
        panic!("robust")
    };
    p.f_r = f_r;
    p.limits.max_force = p.limits.max_force.max(3.0 * f_r);
    t.loop_cfg.process.max_force = p.limits.max_force;
    t
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

/// The physical floor of an impact: after a stop command the tool still travels `v·(delay + one
/// cycle)` into a surface of stiffness `k`, N.
pub fn floor(k: f64, v: f64, plant: &InnerLoopModel) -> f64 {
    k * v * (plant.delay() + plant.period)
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
