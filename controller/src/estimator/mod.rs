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

mod params;
pub mod rls;
mod steady;
#[cfg(test)]
mod tests;
mod update;

pub use params::EstimatorParams;
pub use rls::{Rls, RlsStep};

use nalgebra::{Matrix3, Vector3};

use crate::robust::guards::VARIANCE_GUARD;
pub use steady::SteadyEstimator;

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
        && (v_c * v_x >= 0.0 || v_x.abs() < STILL_ROBOT * v_c.abs())
        && v_c.abs() >= LEADING_SPEED * v_x.abs()
}

/// The robot counts as still beside an observed surface motion when it moves at less than a tenth of
/// it: a too-low `k̂_c` shows the robot's own motion opposed, as `(1 − k_c/k̂_c)·ẋ`, which is ten times
/// the robot's speed only when `k̂_c < k_c/11`.
const STILL_ROBOT: f64 = 0.1;

/// The least observed surface speed, as a share of the robot's, that is real motion: a too-high `k̂_c`
/// shows the robot's own motion as `(1 − k_c/k̂_c)·ẋ`, which reaches 0.85 of it only when `k̂_c` is
/// more than `1/0.15 ≈ 6.7` times the true stiffness.
const LEADING_SPEED: f64 = 0.85;

/// Recursive least squares on `f = k_c·(x − x_c(t))`, with the surface locally linear in time.
#[derive(Clone, Debug, PartialEq)]
pub struct StiffnessEstimator {
    p: EstimatorParams,
    /// The least force noise assumed, N: the dead-zone on the prediction error and the floor of the
    /// contradiction test (`response.noise_floor`, the predictor's; it was the parameter
    /// `estimator.dead_zone`, of the same 0.02 N: docs/robust-law.md, "Fewer parameters").
    noise_floor: f64,
    /// Position scale `s`, m.
    scale: f64,
    /// The recursion on `θ = [k_c·s, k_c·(x₀ − x_c(t₀)), −k_c·ẋ_c·memory]` (N) and its covariance
    /// (unit measurement variance).
    rls: Rls<PARAMS>,
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

/// The recursion's parameters: the scaled stiffness, the intercept and the surface's drift.
const PARAMS: usize = 3;

/// Covariance given to the intercept and the surface-velocity term at each contact onset.
const INTERCEPT_UNCERTAINTY: f64 = 100.0;
/// Ceiling of any diagonal covariance entry of the recursion, N² (its square: the steady estimator's,
/// [`STEADY_COV_MAX`]). The recursion forgets over adapting time only, but a regressor that excites
/// one direction lets forgetting wind the others up; the ceiling bounds that (`θ₀`'s deviation at
/// 100 N, i.e. `k̂_c` unsure by 100 N over the scale `s`).
const COV_MAX: f64 = 1.0e4;

/// Ceiling of the steady estimator's diagonal covariance entries, N²: [`COV_MAX`] squared. Its
/// measurement variance is the measured noise (not 1), so its covariance is in N² of the parameters
/// themselves and starts at the onset fit's variance, which the recursion's ceiling would clip. Kept
/// as it was measured with; no sweep has chosen either value.
const STEADY_COV_MAX: f64 = COV_MAX * COV_MAX;

impl StiffnessEstimator {
    /// An estimator at `k̂_c(0)` with position scale `scale` (m, typically `f_r/k̂_c(0)`), taking
    /// force errors within `noise_floor` (N) for noise.
    pub fn new(p: EstimatorParams, scale: f64, noise_floor: f64) -> Self {
        Self {
            scale,
            noise_floor,
            rls: Rls::new(
                Vector3::new(p.kc0 * scale, 0.0, 0.0),
                Matrix3::zeros(),
                COV_MAX,
            ),
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
    pub fn set_params(&mut self, p: EstimatorParams, noise_floor: f64) {
        self.p = p;
        self.noise_floor = noise_floor;
        let k = self.kc().clamp(p.kc_min, p.kc_max);
        self.rls.theta[0] = k * self.scale;
    }

    /// Start over at `k̂_c(0)`, as [`new`](Self::new) left it: no fit's variance survives (it would
    /// claim the tuning's guess known to that fit's precision).
    pub fn reset(&mut self) {
        *self = Self::new(self.p, self.scale, self.noise_floor);
    }

    /// Contact begins at measured position `x` (m) with measured force `f` (N): re-anchor the model there
    /// and open the covariance (the stiffness estimate is kept, its uncertainty restored).
    pub fn begin_contact(&mut self, x: f64, f: f64) {
        self.x0 = x;
        self.t = 0.0;
        self.x_slow = x;
        self.f_slow = f;
        self.last = (x, f);
        self.rls.theta[1] = f;
        self.rls.theta[2] = 0.0;
        self.prior = self.rls.theta[0];
        self.rls.p = self.onset_covariance();
    }

    /// Keep the stiffness's uncertainty within `rel_sd` of `k̂_c` (relative standard deviation).
    pub fn limit_uncertainty(&mut self, rel_sd: f64) {
        let u = rel_sd * self.rls.theta[0];
        if u * u < self.rls.p[(0, 0)] {
            self.rls.p[(0, 0)] = u * u;
        }
    }

    /// Take a line fit `f = a + b·(x − x₀)/s` of the current contact (anchored where
    /// [`begin_contact`](Self::begin_contact) anchored it, same scale `s`) as the estimate, combined with
    /// the current stiffness estimate at its initial uncertainty; `x` (m) and `f_gate` (N) restart the
    /// excitation averages. Returns whether `k̂_c` had to be projected into its bounds.
    pub fn seed(&mut self, fit: &crate::onset::LineFit, x: f64, f_gate: f64) -> bool {
        let prior = self.prior;
        let u = self.p.initial_uncertainty * prior;
        let var_prior = (u * u).max(VARIANCE_GUARD);
        let w = var_prior / (var_prior + fit.var_b);
        let b = prior + w * (fit.b - prior);
        let var_b = w * fit.var_b;
        // The intercept moves with the slope along the fit's own correlation.
        let a = fit.a + fit.cov_ab / fit.var_b.max(VARIANCE_GUARD) * (b - fit.b);
        let k = (b / self.scale).clamp(self.p.kc_min, self.p.kc_max);
        let projected = k * self.scale != b;
        if !(b.is_finite() && a.is_finite() && var_b.is_finite()) {
            return false;
        }
        self.rls.theta = Vector3::new(k * self.scale, a, 0.0);
        self.t = 0.0;
        // The covariance stays the one of a contact onset: the fit sets the estimate, the recursion
        // keeps its agility for what changes later (a stiffness step must not meet a confident
        // estimator).
        self.seed_var = var_b;
        self.rls.p = self.onset_covariance();
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
        let theta = &mut self.rls.theta;
        theta[0] = k * self.scale;
        theta[1] = f_here - theta[0] * phi[0] - theta[2] * phi[2];
    }

    /// The covariance of a contact onset: the stiffness at its initial uncertainty, the intercept and
    /// the surface-velocity term at [`INTERCEPT_UNCERTAINTY`], uncorrelated.
    fn onset_covariance(&self) -> Matrix3<f64> {
        let u = self.p.initial_uncertainty * self.rls.theta[0];
        Matrix3::from_diagonal(&Vector3::new(
            u * u,
            INTERCEPT_UNCERTAINTY,
            INTERCEPT_UNCERTAINTY,
        ))
    }

    /// Stiffness estimate, N/m.
    pub fn kc(&self) -> f64 {
        self.rls.theta[0] / self.scale
    }

    /// Surface position estimate now, m.
    pub fn xc(&self) -> f64 {
        self.x0 - (self.rls.theta[1] + self.rls.theta[2] * self.t / self.p.memory) / self.kc()
    }

    fn regressor(&self, x: f64) -> Vector3<f64> {
        Vector3::new((x - self.x0) / self.scale, 1.0, self.t / self.p.memory)
    }

    /// Predicted force at `x` now, N.
    pub fn predict(&self, x: f64) -> f64 {
        self.rls.predict(&self.regressor(x))
    }
}
