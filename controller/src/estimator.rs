//! Online identification of the environment `f = k_c·(x − x_c)` by recursive least squares with
//! forgetting, well scaled, gated and projected.
//!
//! # Why not the paper's gradient law
//! The paper adapts `[k_c, K_c = k_c·x_c]` on the regressor `[x, −1]` with `x ≈ 0.01 m`, so the stiffness
//! channel moves at `r1·x² ≈ 5·10⁻⁴ s⁻¹` and never learns anything. Here the model is written around a
//! reference position `x₀` captured at contact onset and the position is scaled by `s = f_r/k̂_c(0)` (the
//! expected penetration), so both regressor entries are of order one:
//!
//! `f = θ₀·φ₀ + θ₁`, `φ₀ = (x − x₀)/s`, `θ₀ = k_c·s` (N), `θ₁ = k_c·(x₀ − x_c)` (N).
//!
//! # Safeguards
//! * **excitation gate** — update only while the position moves by more than a force-equivalent
//!   threshold from its slow average (`kc_max·|x − x̄| ≥ excitation`) *and* the force moves from its own
//!   (`|f − f̄| ≥ excitation`): a static contact carries no information about `k_c`, and adapting on it
//!   lets bias drift (which the closed loop turns into a correlated position drift) pull `k̂_c` away;
//!   a moving surface under a held force moves the position alone;
//! * **dead-zone** on the prediction error;
//! * **forgetting** with a time constant counted in *adapting* time only, so the covariance cannot wind
//!   up while the gate is closed, plus a covariance ceiling;
//! * **projection** of `k̂_c` into `[kc_min, kc_max]`, reported every time it acts.
//!
//! The estimator uses the raw (unfiltered) force and the measured position of the same instant: the
//! output noise of a force sensor does not bias least squares, a filter's lag would.

use serde::{Deserialize, Serialize};

/// Estimator configuration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimatorParams {
    /// Initial stiffness estimate `k̂_c(0)`, N/m.
    pub kc0: f64,
    /// Lower bound of `k̂_c`, N/m.
    pub kc_min: f64,
    /// Upper bound of `k̂_c`, N/m.
    pub kc_max: f64,
    /// Forgetting time constant, s of adapting time.
    pub memory: f64,
    /// Excitation needed to adapt, N: the conditioned force must leave its slow average by this much, and
    /// the position by this much at `kc_max` (`kc_max·|x − x̄|`).
    pub excitation: f64,
    /// Time constant of the slow position average `x̄` the excitation is measured from, s.
    pub excitation_window: f64,
    /// Dead-zone on the prediction error, N.
    pub dead_zone: f64,
    /// Initial relative uncertainty of `k̂_c` at each contact onset (1 = ±100 %).
    pub initial_uncertainty: f64,
    /// Adapt only while the observed surface moves slower than this, m/s (see
    /// [`surface_moving`]): on a moving surface the position follows the surface under a steady force,
    /// and the regression learns the motion instead of the stiffness.
    pub max_surface_speed: f64,
}

impl EstimatorParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |n: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("estimator.{n} must be > 0, got {v}"))
            }
        };
        let nonneg = |n: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(format!("estimator.{n} must be >= 0, got {v}"))
            }
        };
        pos("kc0", self.kc0)?;
        pos("kc_min", self.kc_min)?;
        pos("kc_max", self.kc_max)?;
        pos("memory", self.memory)?;
        pos("excitation_window", self.excitation_window)?;
        pos("initial_uncertainty", self.initial_uncertainty)?;
        pos("max_surface_speed", self.max_surface_speed)?;
        nonneg("excitation", self.excitation)?;
        nonneg("dead_zone", self.dead_zone)?;
        if self.kc_min > self.kc_max {
            return Err(format!(
                "estimator.kc_min {} N/m is above kc_max {} N/m",
                self.kc_min, self.kc_max
            ));
        }
        if !(self.kc_min..=self.kc_max).contains(&self.kc0) {
            return Err(format!(
                "estimator.kc0 {} N/m is outside [kc_min, kc_max] = [{}, {}] N/m",
                self.kc0, self.kc_min, self.kc_max
            ));
        }
        Ok(())
    }
}

/// What one estimator update did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Update {
    /// The estimate moved.
    pub adapted: bool,
    /// `k̂_c` had to be projected back into its bounds.
    pub projected: bool,
}

/// Whether the surface observer reports real surface motion rather than the apparent motion a wrong
/// `k̂_c` produces.
///
/// The observer sees `x̃_c = x − f/k̂_c`. With a still surface and `k̂_c ≠ k_c` it reports
/// `(1 − k_c/k̂_c)·ẋ`: opposite to the robot's velocity when `k̂_c` is too low, smaller than it when too
/// high. A surface that really moves shows an observed velocity that leads the robot's (the robot
/// follows it) or comes while the robot is still. `v_c` is the observed surface velocity, `v_x` the
/// robot's (same filtering), m/s.
pub fn surface_moving(v_c: f64, v_x: f64, max_surface_speed: f64) -> bool {
    v_c.abs() > max_surface_speed
        && (v_c * v_x >= 0.0 || v_x.abs() < 0.1 * v_c.abs())
        && v_c.abs() >= 0.85 * v_x.abs()
}

/// Recursive least squares on `f = k_c·(x − x_c(t))`, with the surface locally linear in time.
#[derive(Clone, Debug, PartialEq)]
pub struct StiffnessEstimator {
    p: EstimatorParams,
    /// Position scale `s`, m.
    scale: f64,
    /// `[k_c·s, k_c·(x₀ − x_c(t₀)), −k_c·ẋ_c·memory]`, N.
    theta: [f64; 3],
    /// Covariance, symmetric.
    cov: [[f64; 3]; 3],
    /// Reference position `x₀`, m.
    x0: f64,
    /// Time since the reference `t₀`, s.
    t: f64,
    /// Slow average of the position, m.
    x_slow: f64,
    /// Slow average of the force, N.
    f_slow: f64,
    /// The last raw sample `(x, f)` the recursion was given in this contact, m and N.
    last: (f64, f64),
    /// `θ₀` at the contact onset: the prior [`seed`](Self::seed) combines a fit with, N.
    prior: f64,
    /// Variance of `θ₀` after the last [`seed`](Self::seed), N².
    seed_var: f64,
}

/// Covariance given to the intercept and the surface-velocity term at each contact onset.
const INTERCEPT_UNCERTAINTY: f64 = 100.0;
/// Multiple of `excitation` above which a force transient is informative on a moving surface too.
const STRONG_EXCITATION: f64 = 10.0;
/// Standard deviations of the force's noise the excitation must stand out by, whatever `excitation`.
const EXCITATION_SIGNIFICANCE: f64 = 4.0;
/// Largest relative rate at which `k̂_c` rises, 1/s: a stiffer estimate makes a slower loop.
const MAX_RATE: f64 = 30.0;
/// Largest relative rate at which `k̂_c` falls, 1/s: ×1/e in 0.1 s. A softer estimate makes a more
/// aggressive loop, and one below half the stiffness makes the surface observer feed the tool's own
/// motion back with a gain above one, so large falls are left to the re-fits, judged by their own
/// consistency and against a moving surface. At 30/s a surface approaching 500 kN/m at 1.3 mm/s on
/// the 12 ms cell took `k̂_c` from 487 to 101 kN/m in five steps, and the force went to 262 N before
/// the trip's back-off (`moving_surfaces`; now a trip at 60.2 N). Rising stays fast: a doubling that
/// bounces the loop at once leaves no re-fit window, and the recursion alone must catch up (B7 at
/// 48 ms of delay with `k̂_c(0)` 200 kN/m faulted at 480 N with both rates at 5/s); and a fall at
/// 5/s left a noisy touch-down on 12.6 kN/m at f_r 43 N on P2 ringing with `k̂_c` still 36 kN/m.
const MAX_FALL_RATE: f64 = 10.0;
/// Ceiling of any diagonal covariance entry.
const COV_MAX: f64 = 1.0e4;

impl StiffnessEstimator {
    /// An estimator at `k̂_c(0)` with position scale `scale` (m, typically `f_r/k̂_c(0)`).
    pub fn new(p: EstimatorParams, scale: f64) -> Self {
        Self {
            scale,
            theta: [p.kc0 * scale, 0.0, 0.0],
            cov: [[0.0; 3]; 3],
            x0: 0.0,
            t: 0.0,
            x_slow: 0.0,
            f_slow: 0.0,
            last: (0.0, 0.0),
            prior: p.kc0 * scale,
            seed_var: f64::INFINITY,
            p,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &EstimatorParams {
        &self.p
    }

    /// Change the configuration keeping the estimate (projected into the new bounds).
    pub fn set_params(&mut self, p: EstimatorParams) {
        self.p = p;
        let k = self.kc().clamp(p.kc_min, p.kc_max);
        self.theta[0] = k * self.scale;
    }

    /// Start over at `k̂_c(0)`, as [`new`](Self::new) left it: no fit's variance survives (it would
    /// claim the tuning's guess known to that fit's precision).
    pub fn reset(&mut self) {
        *self = Self::new(self.p, self.scale);
    }

    /// Contact begins at measured position `x` (m) with measured force `f` (N): re-anchor the model there
    /// and open the covariance (the stiffness estimate is kept, its uncertainty restored).
    pub fn begin_contact(&mut self, x: f64, f: f64) {
        self.x0 = x;
        self.t = 0.0;
        self.x_slow = x;
        self.f_slow = f;
        self.last = (x, f);
        self.theta[1] = f;
        self.theta[2] = 0.0;
        self.prior = self.theta[0];
        let u = self.p.initial_uncertainty * self.theta[0];
        self.cov = [
            [u * u, 0.0, 0.0],
            [0.0, INTERCEPT_UNCERTAINTY, 0.0],
            [0.0, 0.0, INTERCEPT_UNCERTAINTY],
        ];
    }

    /// Keep the stiffness's uncertainty within `rel_sd` of `k̂_c` (relative standard deviation).
    pub fn limit_uncertainty(&mut self, rel_sd: f64) {
        let u = rel_sd * self.theta[0];
        if u * u < self.cov[0][0] {
            self.cov[0][0] = u * u;
        }
    }

    /// Take a line fit `f = a + b·(x − x₀)/s` of the current contact (anchored where
    /// [`begin_contact`](Self::begin_contact) anchored it, same scale `s`) as the estimate, combined with
    /// the current stiffness estimate at its initial uncertainty; `x` (m) and `f_gate` (N) restart the
    /// excitation averages. Returns whether `k̂_c` had to be projected into its bounds.
    pub fn seed(&mut self, fit: &crate::onset::LineFit, x: f64, f_gate: f64) -> bool {
        let prior = self.prior;
        let u = self.p.initial_uncertainty * prior;
        let var_prior = (u * u).max(1e-30);
        let w = var_prior / (var_prior + fit.var_b);
        let b = prior + w * (fit.b - prior);
        let var_b = w * fit.var_b;
        // The intercept moves with the slope along the fit's own correlation.
        let a = fit.a + fit.cov_ab / fit.var_b.max(1e-30) * (b - fit.b);
        let k = (b / self.scale).clamp(self.p.kc_min, self.p.kc_max);
        let projected = k * self.scale != b;
        if !(b.is_finite() && a.is_finite() && var_b.is_finite()) {
            return false;
        }
        self.theta = [k * self.scale, a, 0.0];
        self.t = 0.0;
        // The covariance stays the one of a contact onset: the fit sets the estimate, the recursion
        // keeps its agility for what changes later (a stiffness step must not meet a confident
        // estimator).
        self.seed_var = var_b;
        let u = self.p.initial_uncertainty * self.theta[0];
        self.cov = [
            [u * u, 0.0, 0.0],
            [0.0, INTERCEPT_UNCERTAINTY, 0.0],
            [0.0, 0.0, INTERCEPT_UNCERTAINTY],
        ];
        self.x_slow = x;
        self.f_slow = f_gate;
        projected
    }

    /// Variance of the scaled stiffness `θ₀ = k̂_c·s` the last [`seed`](Self::seed) left, N².
    pub fn seed_variance(&self) -> f64 {
        self.seed_var
    }

    /// Position scale `s`, m.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Set `k̂_c` (N/m, projected into the bounds) keeping the predicted force at `x` (m).
    pub fn set_kc(&mut self, k: f64, x: f64) {
        if !k.is_finite() {
            return;
        }
        let k = k.clamp(self.p.kc_min, self.p.kc_max);
        let phi = self.regressor(x);
        let f_here = self.predict(x);
        self.theta[0] = k * self.scale;
        self.theta[1] = f_here - self.theta[0] * phi[0] - self.theta[2] * phi[2];
    }

    /// Stiffness estimate, N/m.
    pub fn kc(&self) -> f64 {
        self.theta[0] / self.scale
    }

    /// Surface position estimate now, m.
    pub fn xc(&self) -> f64 {
        self.x0 - (self.theta[1] + self.theta[2] * self.t / self.p.memory) / self.kc()
    }

    fn regressor(&self, x: f64) -> [f64; 3] {
        [(x - self.x0) / self.scale, 1.0, self.t / self.p.memory]
    }

    /// Predicted force at `x` now, N.
    pub fn predict(&self, x: f64) -> f64 {
        let phi = self.regressor(x);
        (0..3).map(|i| self.theta[i] * phi[i]).sum()
    }

    /// One update in contact with measured `x` (m), raw measured force `f` (N), step `dt` (s), and
    /// whether the surface is moving (see [`surface_moving`]).
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
            self.theta[1] += self.theta[2] * self.t / self.p.memory;
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
        let floor = self.p.dead_zone.max(noise);
        let contradicts = dx * df < 0.0 && df.abs() > floor && self.p.kc_max * dx.abs() > floor;
        let excited = excited && !contradicts;
        let phi = self.regressor(x);
        let err = f - self.predict(x);
        // A strong force transient (an impact, a stiffness change) is informative even when the observer,
        // misled by a wrong k̂_c itself, reports a moving surface.
        let strong = (f_gate - self.f_slow).abs() >= STRONG_EXCITATION * excitation;
        let still = !moving || strong;
        if !excited || !still || err.abs() <= self.p.dead_zone {
            return up;
        }
        let lambda = (-dt / self.p.memory).exp();
        let c = self.cov;
        let mut pphi = [0.0; 3];
        for (i, v) in pphi.iter_mut().enumerate() {
            *v = (0..3).map(|j| c[i][j] * phi[j]).sum();
        }
        let denom = lambda + (0..3).map(|i| phi[i] * pphi[i]).sum::<f64>();
        let mut n = [[0.0; 3]; 3];
        for i in 0..3 {
            self.theta[i] += pphi[i] / denom * err;
            for j in 0..3 {
                n[i][j] = (c[i][j] - pphi[i] * pphi[j] / denom) / lambda;
            }
        }
        // Symmetric, with a bounded, non-negative diagonal.
        for i in 0..3 {
            n[i][i] = n[i][i].clamp(0.0, COV_MAX);
            for j in 0..i {
                let v = 0.5 * (n[i][j] + n[j][i]);
                let lim = (n[i][i] * n[j][j]).sqrt();
                n[i][j] = v.clamp(-lim, lim);
                n[j][i] = n[i][j];
            }
        }
        self.cov = n;
        up.adapted = true;
        // No single step moves k̂_c by more than MAX_RATE·dt relative up or MAX_FALL_RATE·dt down: a
        // burst of biased samples (a surface starting to move, an impact) cannot throw the estimate
        // across its range at once.
        let k_before = self.theta[0] - pphi[0] / denom * err;
        let (rise, fall) = (
            MAX_RATE * dt * k_before.abs(),
            MAX_FALL_RATE * dt * k_before.abs(),
        );
        let step = self.theta[0] - k_before;
        if step > rise || step < -fall {
            let k_lim = k_before + step.clamp(-fall, rise);
            let f_here = self.predict(x);
            self.theta[0] = k_lim;
            self.theta[1] = f_here - self.theta[0] * phi[0] - self.theta[2] * phi[2];
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
            self.theta[0] = kp * self.scale;
            self.theta[1] = f_here - self.theta[0] * phi[0] - self.theta[2] * phi[2];
        }
        if !self.theta.iter().all(|v| v.is_finite()) {
            self.begin_contact(x, f);
        }
        up
    }
}

/// Least squares of a steady contact under sensor noise: `f = θ₀·(x − x₀)/s + θ₁ + θ₂·t/T`, with
/// forgetting over `T` (s) and the measured noise as the measurement variance.
///
/// In a steady contact the only motion is the loop's answer to sensor noise. The position measured at
/// an instant depends on commands sent before it, through the robot's delay, never on the noise sample
/// of that instant, so the regression of the raw force on the position is unbiased; a bias drifting
/// linearly is the `θ₂` term. The motion is small (a micrometre for 0.5 N of noise at 70 kN/m) and the
/// estimate gains its accuracy over minutes: it refines what the contact transient identified, and it
/// learns nothing where there is no noise to learn from (its uncertainty then stays where it started).
#[derive(Clone, Debug, PartialEq)]
pub struct SteadyEstimator {
    theta: [f64; 3],
    cov: [[f64; 3]; 3],
    x0: f64,
    scale: f64,
    /// Time since the start, s.
    t: f64,
    /// Forgetting time `T`, s.
    memory: f64,
    active: bool,
}

/// Initial variance of the steady estimator's intercept and drift terms, N².
const STEADY_INTERCEPT_VAR: f64 = 100.0;

impl SteadyEstimator {
    /// An inactive estimator with forgetting time `memory` (s).
    pub fn new(memory: f64) -> Self {
        Self {
            theta: [0.0; 3],
            cov: [[0.0; 3]; 3],
            x0: 0.0,
            scale: 1.0,
            t: 0.0,
            memory,
            active: false,
        }
    }

    /// Start at position `x0` (m) with force `f0` (N) there, scaled stiffness `theta0` (N per unit of
    /// `(x − x₀)/s`) of variance `var0` (N²), scale `scale` (m).
    pub fn start(&mut self, x0: f64, f0: f64, theta0: f64, var0: f64, scale: f64) {
        if !(x0.is_finite() && f0.is_finite() && theta0.is_finite() && scale > 0.0) {
            self.active = false;
            return;
        }
        self.theta = [theta0, f0, 0.0];
        let v0 = if var0.is_finite() {
            var0.max(0.0)
        } else {
            theta0 * theta0
        };
        self.cov = [
            [v0, 0.0, 0.0],
            [0.0, STEADY_INTERCEPT_VAR, 0.0],
            [0.0, 0.0, STEADY_INTERCEPT_VAR],
        ];
        self.x0 = x0;
        self.scale = scale;
        self.t = 0.0;
        self.active = true;
    }

    /// Stop until the next [`start`](Self::start).
    pub fn stop(&mut self) {
        self.active = false;
    }

    /// Whether it runs.
    pub fn active(&self) -> bool {
        self.active
    }

    /// Time since the start, s.
    pub fn age(&self) -> f64 {
        if self.active { self.t } else { 0.0 }
    }

    /// One sample: measured position `x` (m), raw force `f` (N) of variance `r` (N²), step `dt` (s).
    pub fn update(&mut self, x: f64, f: f64, r: f64, dt: f64) {
        if !(self.active && x.is_finite() && f.is_finite() && r > 0.0 && dt > 0.0) {
            return;
        }
        self.t += dt;
        let phi = [(x - self.x0) / self.scale, 1.0, self.t / self.memory];
        let lambda = (-dt / self.memory).exp();
        let mut c = self.cov;
        for row in c.iter_mut() {
            for v in row.iter_mut() {
                *v /= lambda;
            }
        }
        let mut pphi = [0.0; 3];
        for (i, v) in pphi.iter_mut().enumerate() {
            *v = (0..3).map(|j| c[i][j] * phi[j]).sum();
        }
        let sv = r + (0..3).map(|i| phi[i] * pphi[i]).sum::<f64>();
        let err = f - (0..3).map(|i| self.theta[i] * phi[i]).sum::<f64>();
        let mut theta = self.theta;
        for i in 0..3 {
            theta[i] += pphi[i] / sv * err;
            for j in 0..3 {
                c[i][j] -= pphi[i] * pphi[j] / sv;
            }
        }
        for i in 0..3 {
            c[i][i] = c[i][i].clamp(0.0, COV_MAX * COV_MAX);
            for j in 0..i {
                let v = 0.5 * (c[i][j] + c[j][i]);
                let lim = (c[i][i] * c[j][j]).sqrt();
                c[i][j] = v.clamp(-lim, lim);
                c[j][i] = c[i][j];
            }
        }
        if theta
            .iter()
            .chain(c.iter().flatten())
            .all(|v| v.is_finite())
        {
            self.theta = theta;
            self.cov = c;
        } else {
            self.active = false;
        }
    }

    /// Stiffness estimate (N/m) and its relative standard deviation.
    pub fn estimate(&self) -> Option<(f64, f64)> {
        if !self.active || self.theta[0] <= 0.0 {
            return None;
        }
        Some((
            self.theta[0] / self.scale,
            self.cov[0][0].max(0.0).sqrt() / self.theta[0],
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> EstimatorParams {
        EstimatorParams {
            kc0: 50_000.0,
            kc_min: 10_000.0,
            kc_max: 500_000.0,
            memory: 0.5,
            excitation: 0.1,
            excitation_window: 0.05,
            dead_zone: 0.0,
            initial_uncertainty: 1.0,
            max_surface_speed: 1e-3,
        }
    }

    /// A re-contact's recursion kept to the confidence its estimate earned moves less on a misleading
    /// transient (a moving surface reads as a softer one) than one reopened to the initial
    /// uncertainty (50 µm in 0.3 s, two 5 N penetrations at 200 kN/m, read at half the stiffness, slow
    /// enough that the rate limit does not decide it); a limit above that uncertainty changes nothing.
    #[test]
    fn a_limited_uncertainty_keeps_the_estimate() {
        let k = 200_000.0;
        let run = |limit: Option<f64>| {
            let mut e = StiffnessEstimator::new(params(), 2.5e-5);
            e.set_kc(k, 0.0);
            e.begin_contact(0.01, 0.0);
            if let Some(rel) = limit {
                e.limit_uncertainty(rel);
            }
            for i in 1..300 {
                let t = i as f64 * 1e-3;
                let x = 0.01 + 0.00005 * t / 0.3;
                let f = 0.5 * k * (x - 0.01);
                e.update(x, f, f, 0.0, 1e-3, false);
            }
            e.kc()
        };
        let (agile, kept, loose) = (run(None), run(Some(0.1)), run(Some(10.0)));
        assert!(
            agile < 0.8 * k,
            "the agile recursion learns the transient: {agile}"
        );
        assert!(k - kept < 0.5 * (k - agile), "kept {kept}, agile {agile}");
        assert_eq!(loose, agile);
    }

    /// One sample that asks for half the stiffness moves `k̂_c` down by [`MAX_FALL_RATE`]·dt at most;
    /// one that asks for twice by up to [`MAX_RATE`]·dt.
    #[test]
    fn the_estimate_falls_slower_than_it_rises() {
        let step = |factor: f64| {
            let mut e = StiffnessEstimator::new(params(), 1e-4);
            e.begin_contact(0.0100, 0.0);
            e.update(0.0100, 0.0, 0.0, 0.0, 1e-3, false);
            let x = 0.0101;
            let f = factor * 50_000.0 * (x - 0.0100);
            e.update(x, f, f, 0.0, 1e-3, false);
            e.kc() / 50_000.0 - 1.0
        };
        let (down, up) = (step(0.5), step(2.0));
        assert!(
            (-MAX_FALL_RATE * 1e-3 - 1e-9..0.0).contains(&down),
            "{down}"
        );
        assert!(up > 0.0 && up <= MAX_RATE * 1e-3 + 1e-9, "{up}");
        assert!(-down < 0.5 * up, "falls {down}, rises {up}");
    }

    #[test]
    fn learns_stiffness_and_surface_from_a_transient() {
        let (k, xc) = (70_000.0, 0.010);
        let mut e = StiffnessEstimator::new(params(), 1e-4);
        e.begin_contact(0.01001, k * 0.00001);
        for i in 0..300 {
            let t = i as f64 * 1e-3;
            let x = 0.01001 + 0.00006 * (1.0 - (-t / 0.02).exp()) + 1e-5 * (t * 30.0).sin();
            e.update(x, k * (x - xc), k * (x - xc), 0.0, 1e-3, false);
        }
        assert!((e.kc() - k).abs() / k < 0.01, "k̂ {}", e.kc());
        assert!((e.xc() - xc).abs() < 1e-6, "x̂ {}", e.xc());
    }

    #[test]
    fn apparent_motion_from_a_wrong_stiffness_is_not_surface_motion() {
        let v = 0.002;
        // k̂ too low by 4: the observer moves against the robot.
        assert!(!surface_moving(-3.0 * v, v, 1e-3));
        // k̂ too high by 2: it moves with the robot, but slower.
        assert!(!surface_moving(0.5 * v, v, 1e-3));
        // A ramp the robot follows, and one it has not started to follow.
        assert!(surface_moving(v, v, 1e-3));
        assert!(surface_moving(v, 0.0, 1e-3));
        // Slow enough to ignore.
        assert!(!surface_moving(0.0005, 0.0, 1e-3));
    }

    #[test]
    fn a_surface_moving_in_after_a_re_contact_is_no_stiffness() {
        // B5b's re-contact: the tool came in on a still surface, and now backs off at 1 mm/s while the
        // surface moves in at 6 mm/s, so the force rises as the position falls. Against the slow averages, which still
        // remember the tool coming in, both stand "the same way"; step by step they contradict a
        // still surface. The same positions with the force of a still, stiffer surface are learnt.
        let run = |moving_in: bool| {
            let mut e = StiffnessEstimator::new(
                EstimatorParams {
                    kc0: 70_000.0,
                    ..params()
                },
                1e-4,
            );
            let (k, mut x, mut xc) = (70_000.0, 0.01003, 0.01);
            e.begin_contact(x, k * (x - xc));
            for i in 0..40 {
                let v = if i < 10 { 4e-3 } else { -1e-3 };
                x += v * 1e-3;
                let f = if moving_in {
                    if i >= 10 {
                        xc -= 6e-6;
                    }
                    k * (x - xc)
                } else {
                    2.0 * k * (x - 0.010015)
                };
                e.update(x, f, f, 0.0, 1e-3, false);
            }
            e.kc()
        };
        assert!(
            (run(true) - 70_000.0).abs() < 0.02 * 70_000.0,
            "{}",
            run(true)
        );
        assert!(
            run(false) > 80_000.0,
            "a still stiffer surface is learnt: {}",
            run(false)
        );
    }

    #[test]
    fn static_contact_does_not_adapt() {
        let mut e = StiffnessEstimator::new(params(), 1e-4);
        e.begin_contact(0.0101, 5.0);
        for i in 0..1000 {
            // Drifting force at a still position: bias drift, no information about k_c.
            let f = 5.0 + i as f64 * 1e-3;
            let up = e.update(0.0101, f, f, 0.0, 1e-3, false);
            assert!(!up.adapted);
        }
        assert_eq!(e.kc(), 50_000.0);
    }

    #[test]
    fn an_excursion_within_the_noise_is_no_excitation() {
        // Position and force move together by 0.2 N-equivalent steps over a second: excitation for
        // a clean sensor (`excitation` 0.1 N), none within four deviations of 0.5 N of noise.
        let run = |noise_sd: f64| {
            let mut e = StiffnessEstimator::new(params(), 1e-4);
            e.begin_contact(0.0101, 5.0);
            let mut adapted = false;
            for i in 0..1000 {
                let x = 0.0101 + 2e-6 * (i as f64 * 0.05).sin();
                let f = 5.0 + 80_000.0 * (x - 0.0101);
                adapted |= e.update(x, f, f, noise_sd, 1e-3, false).adapted;
            }
            adapted
        };
        assert!(run(0.0));
        assert!(!run(0.5));
    }

    #[test]
    fn projection_holds_the_bounds_and_says_so() {
        let mut e = StiffnessEstimator::new(params(), 1e-4);
        e.begin_contact(0.0, 0.0);
        let mut projected = false;
        for i in 0..200 {
            let x = 1e-4 * (i as f64 * 0.1).sin();
            // A "stiffness" of 5 MN/m, far above kc_max.
            let up = e.update(x, 5.0e6 * x, 5.0e6 * x, 0.0, 1e-3, false);
            projected |= up.projected;
            assert!(e.kc() <= 500_000.0 + 1e-6);
        }
        assert!(projected);
    }
    #[test]
    fn steady_contact_learns_from_noise_driven_motion_despite_drift() {
        // A micrometre of position wander (the loop's answer to earlier noise), 0.5 N of white sensor
        // noise and a bias drifting 0.5 N/min; the prior is 20 % low.
        let (k, xc, s, dt) = (70_000.0, 0.010, 1e-4, 1e-3);
        let mut e = SteadyEstimator::new(3600.0);
        let prior = 0.8 * k * s;
        e.start(0.010071, 5.0, prior, (0.2 * prior) * (0.2 * prior), s);
        let mut seed: u64 = 7;
        let mut uniform = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut wander = 0.0;
        for i in 0..200_000 {
            let t = i as f64 * dt;
            wander = 0.99 * wander + 5e-7 * uniform();
            let x = 0.010071 + wander;
            let noise = 0.5 * 12f64.sqrt() * uniform();
            let f = k * (x - xc) + noise + 0.5 / 60.0 * t;
            e.update(x, f, 0.25, dt);
        }
        let (kc, rel) = e.estimate().unwrap();
        assert!((kc - k).abs() / k < 0.03, "k̂ {kc} ± {rel}");
        assert!(rel < 0.03, "relative std {rel}");
    }

    #[test]
    fn steady_contact_without_motion_keeps_its_prior() {
        let (s, dt) = (1e-4, 1e-3);
        let mut e = SteadyEstimator::new(3600.0);
        let prior = 50_000.0 * s;
        e.start(0.0101, 5.0, prior, prior * prior, s);
        for _ in 0..10_000 {
            e.update(0.0101, 5.0, 4e-4, dt);
        }
        let (kc, rel) = e.estimate().unwrap();
        assert!((kc - 50_000.0).abs() < 1.0, "k̂ {kc}");
        assert!(rel > 0.9, "relative std {rel}");
    }
}
