//! The feed-forward: the predictor run on the raw surface `x − f/k̂_c`, its jump test, the motion
//! tests it feeds, and the command that puts the tool on the surface predicted the delay ahead.

use super::super::Context;
use super::super::guards::VARIANCE_GUARD;
use super::super::motion::threshold;
use super::{SurfaceObserver, View};
use crate::predictor::JumpTest;

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

impl SurfaceObserver {
    /// The feed-forward in the step's context `ctx` (the cell's lag and delay, the cycle, the whole
    /// lead time of the fallback: lag, delay and conditioning); `r` holds the response's surface
    /// parameters (jerk, noise floor, dead-band, acceleration).
    pub fn feedforward(
        &mut self,
        s: &View,
        ctx: &Context,
        r: &super::super::ResponseParams,
        max_surface_speed: f64,
    ) -> FeedForward {
        let (lag, delay, cycle, lead, dt) = (ctx.lag, ctx.loop_delay, ctx.cycle, ctx.lead, ctx.dt);
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
        let ahead = self
            .pred
            .command(0.0, delay, lag, cycle, r.surface_acceleration);
        let z_f = s.xf - s.ff / k;
        let [_, v, a] = self.pred.state();
        let v_std = self.pred.velocity_std();
        if !jumped {
            // A jump says nothing about motion either way.
            let thr = threshold(max_surface_speed, &p, v_std);
            let thr_ff = threshold(p.feedforward_speed.min(max_surface_speed), &p, v_std);
            self.motion.observe(&p, v, s.v_raw, [thr, thr_ff], lead, dt);
        }
        let sv = p.motion_significance * v_std;
        let sa = p.motion_significance * self.pred.acceleration_std();
        let m2 = v * v / (sv * sv + VARIANCE_GUARD) + a * a / (sa * sa + VARIANCE_GUARD);
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
