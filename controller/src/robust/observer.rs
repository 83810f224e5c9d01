//! The surface, observed and predicted, and the feed-forward built on it.
//!
//! * The *observer* is a second-order tracker on the conditioned surface `x̃_c = x̄ − f̃/k̂_c`: it gives
//!   the reported `x̂_c`, the estimator's motion test and the fallback feed-forward. A jump (a surface
//!   step, a stiffness change seen through a stale `k̂_c`) moves it without a velocity kick; what keeps
//!   jumping for longer than the conditioning takes to pass a step is motion.
//! * The *predictor* ([`crate::predictor`]) runs on the raw pseudo-measurement `x − f/k̂_c` and puts the
//!   tool on the surface predicted the inner loop's delay ahead, through its inverted lag. Its weight is
//!   0 until real surface motion is established (the apparent motion of a stale `k̂_c` is tied to the
//!   robot's), then `m²/(m² + 1)` with `m` the estimated motion in units of its own uncertainty.

mod params;
pub use params::ObserverParams;

use super::motion::{Motion, threshold};
use crate::estimator::surface_moving;
use crate::predictor::{JumpTest, SurfacePredictor};

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

/// The surface model's part of the command: `w·(ahead − x̃_c) + (1 − w)·fallback`.
#[derive(Clone, Copy, Debug)]
pub struct FeedForward {
    /// Weight `w` of the prediction (0: no real surface motion established).
    pub weight: f64,
    /// The predicted surface through the inverted inner loop, less the conditioned one, m.
    pub predicted: f64,
    /// The conditioned observer's velocity over the lead time, outside the noise dead-band, m.
    pub fallback: f64,
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

    /// Whether anything moved or jumped lately (the steady-contact estimator waits for calm).
    pub fn disturbed(&self) -> bool {
        !self.motion.still() || self.jump_time > 0.0 || self.pred_jump_time > 0.0
    }

    /// Run the motion holds for a step; `v_x` is the conditioned position's velocity. Returns whether
    /// the estimator is to take the surface for a moving one.
    pub fn hold(&mut self, v_x: f64, max_surface_speed: f64, in_contact: bool, dt: f64) -> bool {
        let thr = threshold(max_surface_speed, &self.p, self.pred.velocity_std());
        let moving = surface_moving(self.vc, v_x, thr) && self.passing <= 0.0;
        self.motion.hold(&self.p, moving && in_contact, dt) || moving
    }

    /// Track the conditioned surface with natural frequency `bandwidth` (Hz) and the damping ratio
    /// `observer.damping`.
    pub fn track(&mut self, s: &View, bandwidth: f64, dt: f64) {
        let w = (core::f64::consts::TAU * bandwidth).min(0.5 / dt);
        let z = s.xf - s.ff / s.k;
        let e = z - self.zc;
        let jump = e.abs() > self.p.step_innovation * s.force_scale / s.k;
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
    }

    /// The feed-forward for a cell of `lag` and `delay` (s) at `cycle` (s); `lead` is the whole lead
    /// time of the fallback (lag, delay and conditioning), `jerk`, `noise_floor` and `deadband` the
    /// response's surface parameters.
    #[allow(clippy::too_many_arguments)]
    pub fn feedforward(
        &mut self,
        s: &View,
        r: &super::ResponseParams,
        max_surface_speed: f64,
        lag: f64,
        delay: f64,
        cycle: f64,
        lead: f64,
        dt: f64,
    ) -> FeedForward {
        let (p, k, floor) = (self.p, s.k, r.noise_floor);
        let var = (s.noise_var + floor * floor) / (k * k);
        // A jump: beyond a share of the set-point's penetration, or far beyond a cycle of motion and
        // the robot's own displacement (a stale k̂_c within ×2 of k_c shows at most that). A jump
        // that lasts longer than the conditioning takes to pass one is motion.
        let test = if self.pred_jump_time <= s.step_time {
            JumpTest {
                gate: p.jump_gate,
                floor: p.step_innovation * s.force_scale / k,
                step_gate: p.step_gate,
                step_floor: s.v_raw.abs() * dt,
            }
        } else {
            JumpTest::gated(p.jump_gate, f64::INFINITY)
        };
        let jump = self
            .pred
            .update(s.x - s.f / k, var, r.surface_jerk, dt, &test);
        let jumped = jump.is_some();
        if let Some(y) = jump {
            // A step seen raw starts passing the conditioning now (and is the start of a jump).
            self.jump_started |= self.pred_jump_time == 0.0;
            self.passing = s.step_time;
            if y.abs() <= test.floor {
                // The observer took this step's start for motion: undone.
                self.passing_small = s.step_time;
                self.vc = self.vc_before;
                self.zc = s.xf - s.ff / k;
            }
        }
        self.pred_jump_time = if jumped {
            self.pred_jump_time + dt
        } else {
            0.0
        };
        let ahead = self.pred.command(0.0, delay, lag, cycle, 1.0, 1.0);
        let z_f = s.xf - s.ff / k;
        let [_, v, a] = self.pred.state();
        let v_std = self.pred.velocity_std();
        if !jumped {
            // A jump says nothing about motion either way.
            let thr = threshold(max_surface_speed, &p, v_std);
            self.motion.observe(&p, v, s.v_raw, thr, dt);
        }
        let sv = p.motion_significance * v_std;
        let sa = p.motion_significance * self.pred.acceleration_std();
        let m2 = v * v / (sv * sv + 1e-30) + a * a / (sa * sa + 1e-30);
        let weight = if self.motion.established() {
            m2 / (m2 + 1.0)
        } else {
            0.0
        };
        let deadband = p.deadband(r, s.noise_var.sqrt(), s.noise_gain, k);
        let v_ff = self.vc.signum() * (self.vc.abs() - deadband).max(0.0);
        FeedForward {
            weight,
            predicted: ahead - z_f,
            fallback: lead * v_ff,
        }
    }
}

#[cfg(test)]
mod tests;
