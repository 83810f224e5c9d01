//! The steady contact's least squares under sensor noise.

use super::COV_MAX;

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
