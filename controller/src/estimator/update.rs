//! The recursion's step: the excitation gate, the forgetting least-squares update, the rate limit and
//! the projection.

use super::{StiffnessEstimator, Update};

/// Multiple of `excitation` above which a force transient is informative on a moving surface too.
const STRONG_EXCITATION: f64 = 10.0;
/// Standard deviations of the force's noise the excitation must stand out by, whatever `excitation`.
const EXCITATION_SIGNIFICANCE: f64 = 4.0;
/// Largest relative rate at which `k̂_c` rises, 1/s: a stiffer estimate makes a slower loop.
pub(super) const MAX_RATE: f64 = 30.0;
/// Largest relative rate at which `k̂_c` falls, 1/s: ×1/e in 0.1 s. A softer estimate makes a more
/// aggressive loop, and one below half the stiffness makes the surface observer feed the tool's own
/// motion back with a gain above one, so large falls are left to the re-fits, judged by their own
/// consistency and against a moving surface. At 30/s a surface approaching 500 kN/m at 1.3 mm/s on
/// the 12 ms cell took `k̂_c` from 487 to 101 kN/m in five steps, and the force went to 262 N before
/// the trip's back-off (`moving_surfaces`; now a trip at 60.2 N). Rising stays fast: a doubling that
/// bounces the loop at once leaves no re-fit window, and the recursion alone must catch up (B7 at
/// 48 ms of delay with `k̂_c(0)` 200 kN/m faulted at 480 N with both rates at 5/s); and a fall at
/// 5/s left a noisy touch-down on 12.6 kN/m at f_r 43 N on P2 ringing with `k̂_c` still 36 kN/m.
pub(super) const MAX_FALL_RATE: f64 = 10.0;

impl StiffnessEstimator {
    /// One update in contact with measured `x` (m), raw measured force `f` (N), step `dt` (s), and
    /// whether the surface is moving (see [`surface_moving`](super::surface_moving)).
    ///
    /// `f_gate` is the force the excitation gate looks at — the robust law passes its conditioned force,
    /// so that sensor noise alone never opens the gate — while the regression itself uses the raw `f`.
    pub fn update(
        &mut self,
        x: f64,
        f: f64,
        f_gate: f64,
        noise_sd: f64,
        dt: f64,
        moving: bool,
    ) -> Update {
        self.t += dt;
        if self.t > self.p.memory {
            // Re-anchor the time origin so the regressor stays of order one.
            self.rls.theta[1] += self.rls.theta[2] * self.t / self.p.memory;
            self.t = 0.0;
        }
        let a = (dt / self.p.excitation_window).min(1.0);
        self.x_slow += a * (x - self.x_slow);
        self.f_slow += a * (f_gate - self.f_slow);
        let mut up = Update::default();
        // Excited only when position *and* force move against their slow averages: a moving force at a
        // still position (bias drift) carries no information about the stiffness, nor does a position
        // following a moving surface under a steady force.
        // The position criterion is taken at the stiffest expected surface: with k̂_c still too low it
        // would otherwise hide exactly the transients that correct it.
        // The thresholds stand out of the force's noise (`noise_sd`, N): the loop's answer to noise
        // moves position and force together too.
        let noise = EXCITATION_SIGNIFICANCE * noise_sd;
        let excitation = self.p.excitation.max(noise);
        let excited = self.p.kc_max * (x - self.x_slow).abs() >= excitation
            && (f_gate - self.f_slow).abs() >= excitation
            // …and the same way, as a positive stiffness against a still surface makes them: a force
            // falling while the position advances is a surface moving away, not information on k_c.
            && (f_gate - self.f_slow) * (x - self.x_slow) > 0.0;
        // …and the last step does not contradict it: against a still surface force and position move
        // together, and a force rising while the position falls (both beyond the noise, the position
        // at the stiffest expected surface) is a surface moving in, which the slow averages still
        // call "the same way" just after a re-contact (B5b's sine start re-acquired its surface moving
        // in, and `k̂_c` fell from 70 to 37 kN/m on P1 within 30 ms).
        let (dx, df) = (x - self.last.0, f - self.last.1);
        self.last = (x, f);
        let floor = self.noise_floor.max(noise);
        let contradicts = dx * df < 0.0 && df.abs() > floor && self.p.kc_max * dx.abs() > floor;
        let excited = excited && !contradicts;
        let phi = self.regressor(x);
        let err = f - self.predict(x);
        // A strong force transient (an impact, a stiffness change) is informative even when the observer,
        // misled by a wrong k̂_c itself, reports a moving surface.
        let strong = (f_gate - self.f_slow).abs() >= STRONG_EXCITATION * excitation;
        let still = !moving || strong;
        if !excited || !still || err.abs() <= self.noise_floor {
            return up;
        }
        let lambda = (-dt / self.p.memory).exp();
        // Normalised RLS (unit measurement variance): the forgetting alone scales the covariance.
        let fit = self.rls.update(&phi, f, 1.0, lambda);
        up.adapted = true;
        // No single step moves k̂_c by more than MAX_RATE·dt relative up or MAX_FALL_RATE·dt down: a
        // burst of biased samples (a surface starting to move, an impact) cannot throw the estimate
        // across its range at once.
        let k_before = self.rls.theta[0] - fit.gain[0] * fit.err;
        let (rise, fall) = (
            MAX_RATE * dt * k_before.abs(),
            MAX_FALL_RATE * dt * k_before.abs(),
        );
        let step = self.rls.theta[0] - k_before;
        if step > rise || step < -fall {
            let k_lim = k_before + step.clamp(-fall, rise);
            let f_here = self.predict(x);
            let theta = &mut self.rls.theta;
            theta[0] = k_lim;
            theta[1] = f_here - theta[0] * phi[0] - theta[2] * phi[2];
        }
        let k = self.kc();
        if !(k.is_finite() && (self.p.kc_min..=self.p.kc_max).contains(&k)) {
            up.projected = true;
            let kp = if k.is_finite() {
                k.clamp(self.p.kc_min, self.p.kc_max)
            } else {
                self.p.kc0
            };
            // Keep the prediction at the current position unchanged while moving the slope.
            let f_here = if k.is_finite() { self.predict(x) } else { f };
            let theta = &mut self.rls.theta;
            theta[0] = kp * self.scale;
            theta[1] = f_here - theta[0] * phi[0] - theta[2] * phi[2];
        }
        if !self.rls.theta.iter().all(|v| v.is_finite()) {
            self.begin_contact(x, f);
        }
        up
    }
}
