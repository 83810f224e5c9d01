//! Surface predictor: a Kalman filter on the surface's position, velocity and acceleration, and the
//! command that puts the tool on the predicted surface through the robot's inner loop.
//!
//! # Model
//! The surface `x_c` is a constant-acceleration process driven by white jerk of spectral density `q`
//! (m²/s⁵). It is measured through the pseudo-measurement `z = x − f/k̂_c` built from the measured
//! position and the *raw* force of the same instant (no conditioning lag), with variance
//! `R = (σ_f² + σ_floor²)/k̂_c²`, `σ_f` the sensor noise the law measures online. The filter's
//! bandwidth is therefore set by the noise it actually sees: about `(q/(R·dt))^{1/6}` rad/s, high with a
//! clean sensor, low under noise — no dead-band.
//!
//! A jump (a surface step, an apparent one from a stiffness change seen through a stale `k̂_c`) is an
//! innovation far outside both the filter's own prediction uncertainty and a physical floor, or one so
//! far outside the uncertainty that no cycle of motion makes it while the robot's own displacement
//! cannot explain it ([`JumpTest`]): the position is moved there without touching velocity and
//! acceleration, so a step never throws the tool. Jumps in a row of the same size are a ramp instead
//! (a surface that starts to move at its full speed, on a stiff material under a clean sensor, moves
//! by far more than the noise in every sample): the filter restarts moving at their speed. A step
//! seen through a sensor's own filter shrinks from one sample to the next and stays a jump.
//!
//! # Inversion of the inner loop
//! The robot's inner loop is a pure delay `T_d` and a first-order lag `τ` discretised at the control
//! period `dt` (`x_{k+1} = x_k + α·(u_{k−D} − x_k)`, `α = 1 − e^{−dt/τ}`). The command that makes the
//! position follow a target `X(t)` exactly is `u_k = X(t_k + T_d) + [X(t_k + T_d + dt) − X(t_k + T_d)]/α`;
//! [`SurfacePredictor::command`] evaluates it on the filter's local polynomial.

pub use jump::JumpTest;
pub use kalman::Kalman;

use nalgebra::{Matrix3, Vector3};

/// State and covariance of the surface filter.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfacePredictor {
    /// The filter on `[x_c, ẋ_c, ẍ_c]`, m, m/s, m/s².
    kf: Kalman<STATES>,
    started: bool,
    /// The innovations of the jumps in a row just before this step, the latest first (0: none), m.
    jumps: [f64; RAMP_JUMPS - 1],
}

/// The filter's states: the surface's position, velocity and acceleration.
const STATES: usize = 3;

/// Jumps in a row that are a ramp when each is within `RAMP_TOLERANCE` of the one before.
const RAMP_JUMPS: usize = 3;
/// How alike jumps in a row are to be a ramp, relative: a surface moving at a steady speed moves by
/// the same distance each cycle; a step seen through a sensor's filter shrinks by more than a tenth
/// from one sample to the next.
const RAMP_TOLERANCE: f64 = 0.1;

/// Initial standard deviation of the velocity at a (re)start, m/s: 10 mm/s, above any surface
/// speed the law follows (B5b's sine peaks at 6.3 mm/s).
const V0: f64 = 0.01;
/// Initial standard deviation of the acceleration at a (re)start, m/s²: twice the largest
/// acceleration the predictor extrapolates by default (`surface_acceleration`, 0.05 m/s²).
const A0: f64 = 0.1;

/// The constant-acceleration model of the surface at step `dt` (s): the transition `F` on
/// `[x, ẋ, ẍ]` and the covariance of white jerk of unit spectral density over the step (multiply
/// by the density `q`, m²/s⁵), `Q = [[dt⁵/20, dt⁴/8, dt³/6], [dt⁴/8, dt³/3, dt²/2], [dt³/6, dt²/2,
/// dt]]` (the integral of `e^{Aτ}·b·bᵀ·e^{Aᵀτ}` over the step, `b = [0, 0, 1]ᵀ`).
pub fn constant_acceleration(dt: f64) -> (Matrix3<f64>, Matrix3<f64>) {
    let h2 = dt * dt / 2.0;
    #[rustfmt::skip]
    let f = Matrix3::new(
        1.0, dt, h2,
        0.0, 1.0, dt,
        0.0, 0.0, 1.0,
    );
    let (d2, d3, d4, d5) = (
        dt * dt,
        dt * dt * dt,
        dt * dt * dt * dt,
        dt * dt * dt * dt * dt,
    );
    #[rustfmt::skip]
    let q = Matrix3::new(
        d5 / FACT_20, d4 / FACT_8, d3 / FACT_6,
        d4 / FACT_8, d3 / FACT_3, d2 / 2.0,
        d3 / FACT_6, d2 / 2.0, dt,
    );
    (f, q)
}

/// The denominators of the white-jerk covariance ([`constant_acceleration`]): `∫₀^dt (τ²/2)² dτ =
/// dt⁵/20`, `∫ τ·τ²/2 = dt⁴/8`, `∫ τ²/2 = dt³/6`, `∫ τ² = dt³/3` — exact.
const FACT_20: f64 = 20.0;
/// See [`FACT_20`].
const FACT_8: f64 = 8.0;
/// See [`FACT_20`].
const FACT_6: f64 = 6.0;
/// See [`FACT_20`].
const FACT_3: f64 = 3.0;

impl Default for SurfacePredictor {
    fn default() -> Self {
        Self::new()
    }
}

impl SurfacePredictor {
    /// A filter that starts at its first measurement.
    pub fn new() -> Self {
        Self {
            kf: Kalman::new(Vector3::zeros(), Matrix3::zeros()),
            started: false,
            jumps: [0.0; RAMP_JUMPS - 1],
        }
    }

    /// Forget everything: the next measurement starts the filter at rest.
    pub fn clear(&mut self) {
        self.started = false;
    }

    /// Start at `z` (m), at rest, with variance `r` (m²) on the position.
    fn start(&mut self, z: f64, r: f64) {
        self.start_moving(z, 0.0, r);
    }

    /// Start at `z` (m) moving at `v` (m/s), with variance `r` (m²) on the position.
    fn start_moving(&mut self, z: f64, v: f64, r: f64) {
        self.jumps = [0.0; RAMP_JUMPS - 1];
        self.kf = Kalman::new(
            Vector3::new(z, v, 0.0),
            Matrix3::from_diagonal(&Vector3::new(r, V0 * V0, A0 * A0)),
        );
        self.started = true;
    }

    /// Move the position estimate by `dz` (m), keeping velocity, acceleration and covariance: the
    /// measurement's model moved, not the surface (a no-op before the first measurement).
    pub fn shift(&mut self, dz: f64) {
        if self.started && dz.is_finite() {
            self.kf.x[0] += dz;
        }
    }

    /// Position, velocity and acceleration estimates.
    pub fn state(&self) -> [f64; STATES] {
        self.kf.x.into()
    }

    /// Standard deviation of the velocity estimate, m/s.
    pub fn velocity_std(&self) -> f64 {
        self.kf.p[(1, 1)].max(0.0).sqrt()
    }

    /// Standard deviation of the acceleration estimate, m/s².
    pub fn acceleration_std(&self) -> f64 {
        self.kf.p[(2, 2)].max(0.0).sqrt()
    }

    /// One step of `dt` (s) with measurement `z` (m) of variance `r` (m²), process noise `q` (m²/s⁵).
    /// An innovation that passes `jump` is a jump: the position is moved there, velocity and
    /// acceleration are kept as they were before the step (not propagated through it). Returns the
    /// jump's innovation, m (`None`: tracked as motion).
    pub fn update(&mut self, z: f64, r: f64, q: f64, dt: f64, jump: &JumpTest) -> Option<f64> {
        if !(z.is_finite() && r.is_finite() && r > 0.0 && dt.is_finite() && dt > 0.0) {
            return None;
        }
        if !self.started {
            self.start(z, r);
            return None;
        }
        // Predict: s ← F s, P ← F P Fᵀ + Q.
        let (f, qm) = constant_acceleration(dt);
        let s = self.kf.x;
        self.kf.predict(&f, &(qm * q));
        // Update on the position.
        let (y, sv) = self.kf.innovation(z, r);
        let was = self.jumps;
        self.jumps = [0.0; RAMP_JUMPS - 1];
        if jump.is_jump(y, sv) {
            // Jumps in a row of the same size are a ramp, not steps: a surface that starts to move
            // at its full speed on a stiff material with a clean sensor moves by far more than its
            // noise in one cycle. A step seen through a sensor's own filter shrinks from one sample
            // to the next.
            let mut later = y;
            let ramp = was.iter().all(|&j| {
                let same = j * later > 0.0 && (j - later).abs() <= RAMP_TOLERANCE * later.abs();
                later = j;
                same
            });
            if ramp {
                // The jumps kept the motion from before them: the ramp is that and their speed.
                self.start_moving(z, s[1] + y / dt, r);
                return None;
            }
            self.jumps[0] = y;
            self.jumps[1..].copy_from_slice(&was[..RAMP_JUMPS - 2]);
            let kf = &mut self.kf;
            kf.x[0] = z;
            // The motion is what it was before the step: a prediction the measurement contradicts is
            // no evidence of motion, and carried on it would integrate its acceleration on every jump.
            kf.x[1] = s[1];
            kf.x[2] = s[2];
            // The position is now known to the measurement's accuracy; its correlations are gone.
            kf.p[(0, 0)] = r;
            for i in 1..STATES {
                kf.p[(0, i)] = 0.0;
                kf.p[(i, 0)] = 0.0;
            }
            return Some(y);
        }
        self.kf.correct(y, sv);
        if !self.kf.is_finite() {
            self.start(z, r);
        }
        None
    }

    /// The command (m) that brings the tool to `offset` (m) beyond the surface through an inner loop of
    /// pure delay `delay` (s) and first-order lag `lag` (s) at period `dt` (s), the acceleration
    /// estimate extrapolated no larger than `max_acceleration` (m/s²; `INFINITY`: as estimated).
    ///
    /// The bound is the surface's, not the filter's: a surface that starts to move at its full speed
    /// (a velocity step) is an acceleration far beyond any real one to a constant-acceleration model,
    /// which carries it over the whole lead time and commands the tool past the surface's path.
    pub fn command(
        &self,
        offset: f64,
        delay: f64,
        lag: f64,
        dt: f64,
        max_acceleration: f64,
    ) -> f64 {
        let [x, v, a]: [f64; STATES] = self.kf.x.into();
        // The bound is a constraint on the state: the velocity and position the filter inferred
        // together with the excess acceleration go with it, by the filter's own correlations.
        let excess = a - a.clamp(-max_acceleration, max_acceleration);
        let p = &self.kf.p;
        let (x, v, a) = if excess != 0.0 && p[(2, 2)] > 0.0 {
            let g = [p[(0, 2)], p[(1, 2)]].map(|c| c / p[(2, 2)]);
            (x - g[0] * excess, v - g[1] * excess, a - excess)
        } else {
            (x, v, a - excess)
        };
        let at = |h: f64| x + v * h + a * h * h / 2.0;
        let alpha = if lag > 0.0 {
            1.0 - (-dt / lag).exp()
        } else {
            1.0
        };
        let here = at(delay);
        here + (at(delay + dt) - here) / alpha + offset
    }
}

mod jump;
pub mod kalman;
#[cfg(test)]
mod tests;
