//! The observer's and predictor's parameters.

use serde::{Deserialize, Serialize};

use super::super::{ResponseParams, non_negative, positive};

/// The observer's and predictor's advanced parameters (the defaults suit any cell).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObserverParams {
    /// An innovation above this fraction of the set-point's penetration `f_r/k̂_c` in one step is a
    /// jump, not motion.
    pub step_innovation: f64,
    /// Innovation of the predictor, in its own standard deviations, beyond which (and beyond the step
    /// floor) a measurement is a jump.
    pub jump_gate: f64,
    /// Innovation, in the predictor's standard deviations, beyond which a measurement below the step
    /// floor is a jump too, where the robot's own displacement in the cycle cannot explain it: far
    /// more than a cycle of motion makes (measured with an instrumented build when this was chosen:
    /// at most 46 in any shipped scenario on P1 or P2, B5's curve starting at 6.3 mm/s with a clean
    /// sensor on P1), well below a step on a soft pad (pass-tilt-step's 0.3 mm on 10 N/mm: 114 on P2,
    /// 138 on P1). Under sensor noise such a
    /// step is within it and is taken for motion, as it was before this test.
    pub step_gate: f64,
    /// How long the feed-forward stays on after real surface motion was last seen, s (it passes
    /// through zero velocity at every turn of a curved surface).
    pub motion_hold: f64,
    /// How many of the set-point's penetrations `f_r/k̂_c` the observed surface may leave its own
    /// average over `motion_hold` by before the recursion takes it for a moving one: a still surface
    /// seen through a `k̂_c` within a factor of two moves by under one (`observer/drift.rs`).
    pub drift_span: f64,
    /// How long the predictor must see surface motion without a break before it is believed, s.
    pub motion_confirm: f64,
    /// How long the robot must have moved both with and against one run of surface velocity for
    /// that run to count as real motion, s.
    pub opposed_confirm: f64,
    /// Significance, in standard deviations, at which the fed-forward motion gets half its weight, and
    /// below which a surface velocity is no motion whatever `max_surface_speed` says (noise).
    pub motion_significance: f64,
    /// The speed above which the predictor's surface motion is fed forward (the motion test's other
    /// conditions and its noise bound kept), m/s; `estimator.max_surface_speed` if that is lower. Only
    /// the feed-forward: the identification takes a slower surface than `max_surface_speed` for a
    /// still one, but for the recursion's wait on motion that began after a calm contact
    /// (`robust/motion.rs`).
    pub feedforward_speed: f64,
    /// The fallback feed-forward's dead-band is at least this many times the velocity scale of the
    /// sensor's noise seen through the observer, `σ_f̃/k̂_c·2π·surface_bandwidth` (`σ_f̃` the
    /// conditioned force's noise). The observer's velocity under noise alone has a standard deviation
    /// of 0.47 of that scale (simulated for the 20 Hz conditioning and the 8 Hz observer at 1, 4 and
    /// 12 ms cycles): 2 is about four standard deviations. On a soft surface on a slow cell the
    /// per-newton dead-band (`response.feedforward_deadband`) is far inside that noise (10 kN/m, 12 ms:
    /// 0.6 mm/s against a scale of 3.7 and a deviation of 1.7 mm/s per newton of sensor noise), and the
    /// noise fed forward over the lead time moved the tool by a newton and more.
    pub deadband_significance: f64,
    /// Damping ratio of the second-order surface tracker behind the reported `x̂_c` and the motion
    /// test, whose natural frequency is `response.surface_bandwidth`.
    pub damping: f64,
}

impl Default for ObserverParams {
    fn default() -> Self {
        Self {
            step_innovation: 0.25,
            jump_gate: 6.0,
            step_gate: 70.0,
            motion_hold: 0.5,
            drift_span: 4.0,
            motion_confirm: 0.008,
            opposed_confirm: 0.01,
            motion_significance: 3.0,
            feedforward_speed: 0.0001,
            deadband_significance: 2.0,
            damping: 0.8,
        }
    }
}

impl ObserverParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        positive("observer.step_innovation", self.step_innovation)?;
        positive("observer.jump_gate", self.jump_gate)?;
        positive("observer.step_gate", self.step_gate)?;
        positive("observer.motion_hold", self.motion_hold)?;
        positive("observer.drift_span", self.drift_span)?;
        positive("observer.motion_confirm", self.motion_confirm)?;
        positive("observer.opposed_confirm", self.opposed_confirm)?;
        positive("observer.motion_significance", self.motion_significance)?;
        positive("observer.feedforward_speed", self.feedforward_speed)?;
        non_negative("observer.deadband_significance", self.deadband_significance)?;
        positive("observer.damping", self.damping)
    }
}

impl ObserverParams {
    /// The fallback feed-forward's dead-band on the observer's velocity, m/s, under response `r` with
    /// sensor noise `sigma` (N), of which `gain` passes the conditioning, at stiffness `k` (N/m).
    /// Never below `feedforward_speed`: a surface slower than that is fed forward by neither the
    /// predictor nor this fallback (the floor was the parameter `observer.deadband_floor`, of the
    /// same 0.1 mm/s: docs/robust-law.md, "Fewer parameters").
    pub fn deadband(&self, r: &ResponseParams, sigma: f64, gain: f64, k: f64) -> f64 {
        let velocity_noise = sigma * gain / k * core::f64::consts::TAU * r.surface_bandwidth;
        (r.feedforward_deadband * sigma)
            .max(self.deadband_significance * velocity_noise)
            .max(self.feedforward_speed)
    }
}
