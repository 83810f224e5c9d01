//! The surface, observed and predicted, and the feed-forward built on it.
//!
//! * The *observer* is a second-order tracker on the conditioned surface `x̃_c = x̄ − f̃/k̂_c`: it gives
//!   the reported `x̂_c`, the estimator's motion test and the fallback feed-forward. A jump (a surface
//!   step, a stiffness change seen through a stale `k̂_c`) moves it without a velocity kick; what keeps
//!   jumping for longer than the conditioning takes to pass a step is motion.
//! * The *predictor* ([`crate::predictor`]) runs on the raw pseudo-measurement `x − f/k̂_c` and puts the
//!   tool on the surface predicted the inner loop's delay ahead, through its inverted lag. Its weight is
//!   0 until real surface motion is established (the apparent motion of a stale `k̂_c` is tied to the
//!   robot's), then `m²/(m² + 1)` with `m` the estimated motion in units of its own uncertainty
//!   (`observer/feedforward.rs`).
//! * The *drift test* (`observer/drift.rs`) holds the recursion off a surface the observer saw go
//!   further than a still one can appear to, at any speed.

mod drift;
mod feedforward;
mod params;
pub use feedforward::FeedForward;
pub use params::ObserverParams;

use super::motion::{Motion, threshold};
use crate::estimator::surface_moving;
use crate::predictor::SurfacePredictor;
use drift::Drift;

/// The fastest natural frequency the surface tracker runs at, in radians per step (`ω·dt`): its
/// semi-implicit Euler discretisation is stable for `ω·dt` below 2 when undamped; at a quarter of
/// that the discrete tracker stays near the continuous one, whatever the configured bandwidth.
const MAX_OMEGA_DT: f64 = 0.5;

/// What the observer needs from the rest of the law in one contact step.
#[derive(Clone, Copy, Debug)]
pub struct View {
    /// Measured position, m.
    pub x: f64,
    /// Raw force, N.
    pub f: f64,
    /// Conditioned position, m.
    pub xf: f64,
    /// Conditioned force, N.
    pub ff: f64,
    /// Velocity of the raw position, m/s.
    pub v_raw: f64,
    /// Stiffness estimate, N/m.
    pub k: f64,
    /// Force scale of a jump (the set-point, at least the contact force), N.
    pub force_scale: f64,
    /// Sensor noise variance, N².
    pub noise_var: f64,
    /// The share of the noise's deviation that passes the conditioning.
    pub noise_gain: f64,
    /// How long a step takes to pass the conditioning, s.
    pub step_time: f64,
}

/// The observer's output for a step ([`SurfaceObserver::hold`]): what it knows of the surface's motion.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SurfaceStatus {
    /// The estimator is to take the surface for a moving one.
    pub moving: bool,
    /// No surface motion is established.
    pub still: bool,
    /// The observed surface went further than a still one can appear to ([`SurfaceObserver::drifted`]).
    pub drifted: bool,
    /// Anything moved or jumped lately ([`SurfaceObserver::disturbed`]).
    pub disturbed: bool,
    /// Motion is held that began after a calm contact ([`SurfaceObserver::moving_after_calm`]).
    pub moving_after_calm: bool,
    /// A jump started at the last step on a still surface ([`SurfaceObserver::jump_on_still_surface`]).
    pub jump_on_still_surface: bool,
}

impl View {
    /// The view of conditioned signals `s` through stiffness `k` (N/m) with the identified damping
    /// `c_e` (N·s/m) taken out of the force, in the step's context.
    pub fn new(s: &crate::robust::Signals, k: f64, c_e: f64, ctx: &crate::robust::Context) -> Self {
        Self {
            x: s.x,
            f: s.f - c_e * s.v_raw,
            xf: s.xf,
            ff: s.ff - c_e * s.v_x,
            v_raw: s.v_raw,
            k,
            force_scale: ctx.force_scale,
            noise_var: ctx.noise.var,
            noise_gain: ctx.noise_gain,
            step_time: ctx.step_time,
        }
    }
}

/// Surface observer, predictor and motion tests.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceObserver {
    p: ObserverParams,
    zc: f64,
    vc: f64,
    jump_time: f64,
    jump_started: bool,
    pred: SurfacePredictor,
    pred_jump_time: f64,
    /// Time left for a jump the raw predictor saw to pass the conditioning, s: the conditioned
    /// surface moves meanwhile, and that is no motion.
    passing: f64,
    /// The same for a jump below the observer's floor: it moves the surface there, no velocity, s.
    passing_small: f64,
    /// The observer's velocity before its last step (undone when that step was a small jump), m/s.
    vc_before: f64,
    motion: Motion,
    drift: Drift,
    /// The `k̂_c` the surface was last observed through, N/m (NaN: none since the restart).
    k_seen: f64,
    /// The conditioned surface measured at the last step, m (NaN: none since the restart or a new
    /// `k̂_c`).
    z_last: f64,
}

impl SurfaceObserver {
    /// An observer that has seen nothing.
    pub fn new(p: ObserverParams) -> Self {
        let mut o = Self {
            p,
            zc: f64::NAN,
            vc: 0.0,
            jump_time: 0.0,
            jump_started: false,
            pred: SurfacePredictor::new(),
            pred_jump_time: 0.0,
            passing: 0.0,
            passing_small: 0.0,
            vc_before: 0.0,
            motion: Motion::default(),
            drift: Drift::default(),
            k_seen: f64::NAN,
            z_last: f64::NAN,
        };
        o.reset();
        o
    }

    /// Take new parameters, keeping the state.
    pub fn set_params(&mut self, p: ObserverParams) {
        self.p = p;
    }

    /// Forget everything.
    pub fn reset(&mut self) {
        self.restart(f64::NAN);
        self.motion.reset();
    }

    /// Restart at rest on the surface `z` (a new contact, a new `k̂_c`), keeping what was learnt about
    /// motion.
    pub fn restart(&mut self, z: f64) {
        self.zc = z;
        self.vc = 0.0;
        self.jump_time = 0.0;
        self.jump_started = false;
        self.pred.clear();
        self.pred_jump_time = 0.0;
        self.passing = 0.0;
        self.passing_small = 0.0;
        self.vc_before = 0.0;
        self.motion.restart();
        self.drift.restart(z);
        self.k_seen = f64::NAN;
        self.z_last = f64::NAN;
    }

    /// Whether the observed surface went further than a still one can appear to (`observer/drift.rs`):
    /// the recursion takes it for a moving one.
    pub fn drifted(&self) -> bool {
        self.drift.moved()
    }

    /// Observed surface, m (NaN before the first contact).
    pub fn surface(&self) -> f64 {
        self.zc
    }

    /// Observed surface velocity away from the tool (for the search after a lift-off), m/s.
    pub fn receding(&self) -> f64 {
        self.vc.max(0.0)
    }

    /// Whether the observed surface started a jump at the last step while no motion was established
    /// (on a still surface: the environment changed under a steady contact).
    pub fn jump_on_still_surface(&self) -> bool {
        self.jump_started && self.motion.still()
    }

    /// Whether no surface motion is established.
    pub fn still(&self) -> bool {
        self.motion.still()
    }

    /// Whether motion is held that began after a calm contact under the same `k̂_c`
    /// ([`Motion::after_calm`]).
    pub fn moving_after_calm(&self) -> bool {
        self.motion.after_calm()
    }

    /// Whether anything moved or jumped lately (the steady-contact estimator waits for calm).
    pub fn disturbed(&self) -> bool {
        !self.motion.still() || self.jump_time > 0.0 || self.pred_jump_time > 0.0
    }

    /// Run the motion holds for a step; `v_x` is the conditioned position's velocity. Returns what the
    /// observer knows of the surface's motion for the rest of the step.
    pub fn hold(
        &mut self,
        v_x: f64,
        max_surface_speed: f64,
        in_contact: bool,
        dt: f64,
    ) -> SurfaceStatus {
        let thr = threshold(max_surface_speed, &self.p, self.pred.velocity_std());
        let moving = surface_moving(self.vc, v_x, thr) && self.passing <= 0.0;
        let moving = self.motion.hold(&self.p, moving && in_contact, dt) || moving;
        SurfaceStatus {
            moving,
            still: self.still(),
            drifted: self.drifted(),
            disturbed: self.disturbed(),
            moving_after_calm: self.moving_after_calm(),
            jump_on_still_surface: self.jump_on_still_surface(),
        }
    }

    /// A new `k̂_c` moves the observed surface `x − f/k̂_c` by the force times the change of `1/k̂_c`:
    /// a change of the model, not a motion of the surface, so the observer, the predictor and the
    /// drift test move with it instead of reading it as a velocity. The recursion falls up to 10/s,
    /// 12 % a cycle on a 12 ms cell: at 48 N on 300 kN/m that is 22 µm a cycle, which the predictor
    /// read as the surface running at the tool and fed forward (a sine receding at 0.79 mm/s, f_r
    /// 50 N, 12 ms cell: the command ran 0.2 mm back, the loop rang, and the prediction of its
    /// ringing pressed 457 N before the trip).
    fn rebase(&mut self, s: &View) {
        if self.k_seen.is_finite() && s.k != self.k_seen {
            let d = 1.0 / s.k - 1.0 / self.k_seen;
            self.zc -= s.ff * d;
            self.drift.shift(-s.ff * d);
            self.pred.shift(-s.f * d);
            self.z_last = f64::NAN;
        }
        self.k_seen = s.k;
    }

    /// Track the conditioned surface with natural frequency `bandwidth` (Hz) and the damping ratio
    /// `observer.damping`.
    pub fn track(&mut self, s: &View, bandwidth: f64, dt: f64) {
        let w = (core::f64::consts::TAU * bandwidth).min(MAX_OMEGA_DT / dt);
        self.rebase(s);
        let z = s.xf - s.ff / s.k;
        let e = z - self.zc;
        // A jump is the surface away from the tracker by more than a share of the set-point's
        // penetration. Where the measurement stayed put, a cycle of the tracker's own motion more:
        // that much is its velocity contradicted, which it must learn from (taken for jumps, a
        // velocity that carried the tracker one threshold a cycle off a still surface was never
        // corrected: a 12 ms cell's hold at f_r 2 N on 500 kN/m through a filtered sensor stood at
        // 5.3 N for seconds, the velocity's feed-forward cancelling the proportional correction).
        let threshold = self.p.step_innovation * s.force_scale / s.k;
        let still = (z - self.z_last).abs() <= threshold;
        self.z_last = z;
        let own = if still { self.vc.abs() * dt } else { 0.0 };
        let jump = e.abs() > threshold + own;
        self.jump_started = jump && self.jump_time == 0.0;
        self.jump_time = if jump { self.jump_time + dt } else { 0.0 };
        self.passing = (self.passing - dt).max(0.0);
        self.passing_small = (self.passing_small - dt).max(0.0);
        self.vc_before = self.vc;
        if (jump && self.jump_time <= s.step_time) || self.passing_small > 0.0 {
            self.zc = z;
        } else {
            self.vc += dt * w * w * e;
            self.zc += dt * (self.vc + 2.0 * self.p.damping * w * e);
        }
        self.drift.step(&self.p, self.zc, s.force_scale / s.k, dt);
    }
}

#[cfg(test)]
mod tests;
