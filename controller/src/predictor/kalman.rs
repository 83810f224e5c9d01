//! The one Kalman filter of the law: a linear state `x` of `N` entries whose first entry is measured,
//! on nalgebra fixed-size matrices (no allocation).
//!
//! Predict with the transition `F` and the process noise's covariance `Q`:
//! `x ← F·x`, `P ← F·P·Fᵀ + Q`. Measure the first entry, `z = x₀ + v`, `v ~ N(0, r)`: the
//! innovation `y = z − x₀` of variance `s = P₀₀ + r` ([`Kalman::innovation`]); correct with the gain
//! `K = P·e₀/s`: `x ← x + K·y`, `P ← P − K·(e₀ᵀP)` ([`Kalman::correct`]), then make `P` symmetric with
//! a non-negative diagonal (rounding). The two halves are apart so that the caller may test the
//! innovation first (the surface predictor takes an outlier for a jump, [`super::JumpTest`]).

use nalgebra::{SMatrix, SVector};

/// A Kalman filter on `N` states, measuring the first.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kalman<const N: usize> {
    /// The state estimate.
    pub x: SVector<f64, N>,
    /// Its covariance, symmetric.
    pub p: SMatrix<f64, N, N>,
}

impl<const N: usize> Kalman<N> {
    /// At `x` with covariance `p`.
    pub fn new(x: SVector<f64, N>, p: SMatrix<f64, N, N>) -> Self {
        Self { x, p }
    }

    /// The time update through transition `f` with process noise covariance `q`.
    pub fn predict(&mut self, f: &SMatrix<f64, N, N>, q: &SMatrix<f64, N, N>) {
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + q;
    }

    /// The innovation of a measurement `z` of the first state with variance `r`, and its variance.
    pub fn innovation(&self, z: f64, r: f64) -> (f64, f64) {
        (z - self.x[0], self.p[(0, 0)] + r)
    }

    /// The measurement update with innovation `y` of variance `s` (from
    /// [`innovation`](Self::innovation)).
    pub fn correct(&mut self, y: f64, s: f64) {
        let k = self.p.column(0) / s;
        self.x += k * y;
        let row = self.p.row(0).into_owned();
        self.p -= k * row;
        for i in 0..N {
            self.p[(i, i)] = self.p[(i, i)].max(0.0);
            for j in 0..i {
                let v = (self.p[(i, j)] + self.p[(j, i)]) / 2.0;
                self.p[(i, j)] = v;
                self.p[(j, i)] = v;
            }
        }
    }

    /// Whether the state and the covariance are finite.
    pub fn is_finite(&self) -> bool {
        self.x.iter().chain(self.p.iter()).all(|v| v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::super::constant_acceleration;
    use super::*;
    use nalgebra::{Matrix3, Vector3};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// On a noise-free constant-acceleration trajectory, measured exactly (a tiny `r`) without process
    /// noise, the filter recovers position, velocity and acceleration after a few samples.
    #[test]
    fn converges_exactly_on_noise_free_data() {
        let dt = 1e-3;
        let (f, _) = constant_acceleration(dt);
        let truth =
            |t: f64| Vector3::new(0.002 + 0.01 * t + 0.5 * 0.3 * t * t, 0.01 + 0.3 * t, 0.3);
        let mut kf = Kalman::new(
            Vector3::new(0.002, 0.0, 0.0),
            Matrix3::from_diagonal(&Vector3::new(1e-6, 1.0, 100.0)),
        );
        for k in 1..=50 {
            kf.predict(&f, &Matrix3::zeros());
            let (y, s) = kf.innovation(truth(k as f64 * dt)[0], 1e-20);
            kf.correct(y, s);
        }
        let e = kf.x - truth(50.0 * dt);
        assert!(
            e[0].abs() < 1e-12 && e[1].abs() < 1e-8 && e[2].abs() < 1e-4,
            "{e}"
        );
    }

    /// On data drawn from the filter's own model (white jerk of density `q`, measurement noise `r`),
    /// the covariance is consistent: over many seeded runs the normalised estimation error squared
    /// `(x̂ − x)ᵀP⁻¹(x̂ − x)` averages 3, within the two-sided 99 % bounds of a χ²(3·runs)/runs; and
    /// the normalised innovation squared `y²/s` averages 1 within those of χ²(steps·runs).
    #[test]
    fn the_covariance_is_consistent_on_noisy_data() {
        let (dt, q, r): (f64, f64, f64) = (1e-3, 1e-3, 1e-10);
        let (f, qm) = constant_acceleration(dt);
        let qd = qm * q;
        let chol = qd.cholesky().expect("Q is positive definite").l();
        let (runs, steps) = (300, 400);
        let (mut nees, mut nis) = (0.0, 0.0);
        for seed in 0..runs {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let n = Normal::new(0.0, 1.0).unwrap();
            let p0: Matrix3<f64> = Matrix3::from_diagonal(&Vector3::new(r, 1e-6, 1e-4));
            // The truth starts drawn from the prior.
            let mut x = Vector3::new(
                p0[(0, 0)].sqrt() * n.sample(&mut rng),
                p0[(1, 1)].sqrt() * n.sample(&mut rng),
                p0[(2, 2)].sqrt() * n.sample(&mut rng),
            );
            let mut kf = Kalman::new(Vector3::zeros(), p0);
            for _ in 0..steps {
                let w: Vector3<f64> = Vector3::from_fn(|_, _| n.sample(&mut rng));
                x = f * x + chol * w;
                kf.predict(&f, &qd);
                let z = x[0] + r.sqrt() * n.sample(&mut rng);
                let (y, s) = kf.innovation(z, r);
                nis += y * y / s;
                kf.correct(y, s);
            }
            let e = kf.x - x;
            nees += (e.transpose() * kf.p.try_inverse().unwrap() * e)[0];
        }
        let mean = nees / runs as f64;
        let sd = (2.0 * 3.0 * runs as f64).sqrt() / runs as f64;
        assert!(
            (mean - 3.0).abs() <= 2.58 * sd,
            "NEES {mean}, 99 % bounds 3 ± {}",
            2.58 * sd
        );
        let m = (runs * steps) as f64;
        let mean = nis / m;
        let sd = (2.0 * m).sqrt() / m;
        assert!(
            (mean - 1.0).abs() <= 2.58 * sd,
            "NIS {mean}, 99 % bounds 1 ± {}",
            2.58 * sd
        );
    }
}
