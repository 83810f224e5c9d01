//! The steady contact's least squares under sensor noise.

use nalgebra::{Matrix3, Vector3};

use super::{PARAMS, Rls, STEADY_COV_MAX};

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
    /// The least squares on `θ = [k_c·s, intercept, drift]`, N, with the measured noise's variance.
    rls: Rls<PARAMS>,
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
            rls: Rls::new(Vector3::zeros(), Matrix3::zeros(), STEADY_COV_MAX),
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
        self.rls.theta = Vector3::new(theta0, f0, 0.0);
        let v0 = if var0.is_finite() {
            var0.max(0.0)
        } else {
            theta0 * theta0
        };
        self.rls.p = Matrix3::from_diagonal(&Vector3::new(
            v0,
            STEADY_INTERCEPT_VAR,
            STEADY_INTERCEPT_VAR,
        ));
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
        let phi = Vector3::new((x - self.x0) / self.scale, 1.0, self.t / self.memory);
        let lambda = (-dt / self.memory).exp();
        let mut next = self.rls;
        next.update(&phi, f, r, lambda);
        if next.is_finite() {
            self.rls = next;
        } else {
            self.active = false;
        }
    }

    /// Stiffness estimate (N/m) and its relative standard deviation.
    pub fn estimate(&self) -> Option<(f64, f64)> {
        let theta0 = self.rls.theta[0];
        if !self.active || theta0 <= 0.0 {
            return None;
        }
        Some((
            theta0 / self.scale,
            self.rls.p[(0, 0)].max(0.0).sqrt() / theta0,
        ))
    }
}
