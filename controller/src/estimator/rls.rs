//! The one recursive least squares of the law: `y = θᵀ·φ + e`, with exponential forgetting and a
//! measurement variance, on nalgebra fixed-size matrices (no allocation).
//!
//! One step with regressor `φ`, measurement `y` of variance `r` and forgetting factor `λ = e^{−dt/T}`
//! (`T` the memory): the textbook update written so that `λ` divides once, at the end,
//!
//! `s = λ·r + φᵀPφ`, `K = Pφ/s`, `θ ← θ + K·(y − θᵀφ)`, `P ← (P − PφφᵀP/s)/λ`,
//!
//! which is the Kalman form with the covariance inflated by `1/λ` first (`P⁻ = P/λ`,
//! `s⁻ = r + φᵀP⁻φ`, `K = P⁻φ/s⁻`, `P ← P⁻ − K·φᵀP⁻`) multiplied out. `r = 1` is the classic
//! normalised RLS (the recursion of [`StiffnessEstimator`](super::StiffnessEstimator)); `r` the
//! measured noise variance makes `P` the covariance of `θ` in the measurement's units (the steady
//! contact's [`SteadyEstimator`](super::SteadyEstimator)).
//!
//! After each step `P` is made symmetric with a diagonal in `[0, ceiling]` and correlations within
//! ±1 (rounding, and forgetting with a regressor that does not excite every direction, would let it
//! drift out of the positive semi-definite cone and wind up).

use nalgebra::{SMatrix, SVector};

/// Recursive least squares on `N` parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rls<const N: usize> {
    /// The parameter estimate `θ`.
    pub theta: SVector<f64, N>,
    /// Its covariance `P` (with `r = 1`: up to the measurement's variance), symmetric.
    pub p: SMatrix<f64, N, N>,
    /// Ceiling of every diagonal entry of `P`.
    pub ceiling: f64,
}

/// What one [`Rls::update`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RlsStep<const N: usize> {
    /// The prediction error before the update, `y − θᵀφ`.
    pub err: f64,
    /// The gain `K`: the update moved `θ` by `K·err`.
    pub gain: SVector<f64, N>,
}

impl<const N: usize> Rls<N> {
    /// At `theta` with covariance `p`, diagonal ceiling `ceiling`.
    pub fn new(theta: SVector<f64, N>, p: SMatrix<f64, N, N>, ceiling: f64) -> Self {
        Self { theta, p, ceiling }
    }

    /// The prediction `θᵀφ`.
    pub fn predict(&self, phi: &SVector<f64, N>) -> f64 {
        self.theta.dot(phi)
    }

    /// One step: regressor `phi`, measurement `y` of variance `r`, forgetting factor `lambda` in
    /// `(0, 1]`.
    pub fn update(&mut self, phi: &SVector<f64, N>, y: f64, r: f64, lambda: f64) -> RlsStep<N> {
        let err = y - self.predict(phi);
        let pphi = self.p * phi;
        let s = lambda * r + phi.dot(&pphi);
        let gain = pphi / s;
        self.theta += gain * err;
        self.p = (self.p - pphi * pphi.transpose() / s) / lambda;
        condition(&mut self.p, self.ceiling);
        RlsStep { err, gain }
    }

    /// Whether `θ` and `P` are finite.
    pub fn is_finite(&self) -> bool {
        self.theta
            .iter()
            .chain(self.p.iter())
            .all(|v| v.is_finite())
    }
}

/// Make `p` symmetric with its diagonal in `[0, ceiling]` and every correlation within ±1.
///
/// This is not a projection onto the covariances: a diagonal entry clipped at the ceiling with its
/// row left as it was, or three correlations each within ±1, can leave `p` indefinite. The
/// recursions start well below the ceiling and the law's figures were measured with this
/// conditioning, so it stays; scaling the clipped entry's row and column with it is the textbook
/// alternative, to be measured before it replaces this.
fn condition<const N: usize>(p: &mut SMatrix<f64, N, N>, ceiling: f64) {
    for i in 0..N {
        p[(i, i)] = p[(i, i)].clamp(0.0, ceiling);
        for j in 0..i {
            let v = (p[(i, j)] + p[(j, i)]) / 2.0;
            let lim = (p[(i, i)] * p[(j, j)]).sqrt();
            p[(i, j)] = v.clamp(-lim, lim);
            p[(j, i)] = p[(i, j)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, Vector3};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal, Uniform};

    type V3 = Vector3<f64>;

    /// On noise-free data with an exciting regressor and no forgetting, the estimate reaches the true
    /// parameters exactly (to rounding) after a few samples, from a wide prior.
    #[test]
    fn converges_exactly_on_noise_free_data() {
        let truth = V3::new(70.0, -3.0, 0.5);
        let mut rls = Rls::new(V3::zeros(), Matrix3::identity() * 1e8, f64::INFINITY);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let u = Uniform::new(-1.0, 1.0).unwrap();
        for _ in 0..20 {
            let phi = V3::new(u.sample(&mut rng), 1.0, u.sample(&mut rng));
            rls.update(&phi, truth.dot(&phi), 1.0, 1.0);
        }
        let e = (rls.theta - truth).abs().max();
        assert!(e < 1e-6, "{} against {truth}", rls.theta);
    }

    /// With forgetting, a parameter that changes is followed: after a step of the truth the estimate
    /// is at the new one within a few memories.
    #[test]
    fn forgetting_follows_a_change() {
        // Started below the ceiling: a diagonal clipped at it while the off-diagonal terms are not
        // scaled with it is no longer a covariance (see `condition`), and the start would be off.
        let mut rls = Rls::new(V3::zeros(), Matrix3::identity() * 1e2, 1e4);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let u = Uniform::new(-1.0, 1.0).unwrap();
        let lambda = (-1e-3f64 / 0.05).exp();
        for k in 0..2000 {
            let truth = if k < 1000 {
                V3::new(1.0, 2.0, 3.0)
            } else {
                V3::new(2.0, 2.0, 1.0)
            };
            let phi = V3::new(u.sample(&mut rng), 1.0, u.sample(&mut rng));
            rls.update(&phi, truth.dot(&phi), 1.0, lambda);
        }
        assert!(
            (rls.theta - V3::new(2.0, 2.0, 1.0)).abs().max() < 1e-6,
            "{}",
            rls.theta
        );
    }

    /// On noisy data with the noise's variance as `r` and no forgetting, `P` is the covariance of the
    /// estimate's error: over many seeded runs the normalised estimation error squared
    /// `(θ̂ − θ)ᵀP⁻¹(θ̂ − θ)` averages `N` = 3, within the two-sided 99 % bounds of a χ²(3·runs)/runs.
    #[test]
    fn the_covariance_is_consistent_on_noisy_data() {
        let truth = V3::new(70.0, -3.0, 0.5);
        let (runs, sigma) = (400, 0.5);
        let mut nees = 0.0;
        for seed in 0..runs {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let u = Uniform::new(-1.0, 1.0).unwrap();
            let n = Normal::new(0.0, sigma).unwrap();
            // A proper prior: the start is drawn from it.
            let p0: f64 = 100.0;
            let prior = Normal::new(0.0, p0.sqrt()).unwrap();
            let start = truth + V3::from_fn(|_, _| prior.sample(&mut rng));
            let mut rls = Rls::new(start, Matrix3::identity() * p0, f64::INFINITY);
            for _ in 0..200 {
                let phi = V3::new(u.sample(&mut rng), 1.0, u.sample(&mut rng));
                rls.update(
                    &phi,
                    truth.dot(&phi) + n.sample(&mut rng),
                    sigma * sigma,
                    1.0,
                );
            }
            let e = rls.theta - truth;
            nees += (e.transpose() * rls.p.try_inverse().unwrap() * e)[0];
        }
        let mean = nees / runs as f64;
        // χ²(1200)/400: mean 3, sd √(2·1200)/400 = 0.122; 99 % two-sided: ±2.58 sd.
        let (lo, hi) = (3.0 - 2.58 * 0.1225, 3.0 + 2.58 * 0.1225);
        assert!(
            (lo..=hi).contains(&mean),
            "NEES {mean} outside [{lo}, {hi}]"
        );
    }

    /// The covariance stays symmetric with its diagonal under the ceiling, whatever the regressor.
    #[test]
    fn the_covariance_is_conditioned() {
        let mut rls = Rls::new(V3::zeros(), Matrix3::identity() * 10.0, 50.0);
        for k in 0..500 {
            // Only the first direction is excited: forgetting winds the others up to the ceiling.
            let phi = V3::new(if k % 2 == 0 { 1.0 } else { -1.0 }, 0.0, 0.0);
            rls.update(&phi, 0.3 * phi[0], 1.0, 0.9);
        }
        assert!(
            rls.p.diagonal().iter().all(|&v| (0.0..=50.0).contains(&v)),
            "{}",
            rls.p
        );
        assert_eq!(rls.p, rls.p.transpose());
        assert!((rls.theta[0] - 0.3).abs() < 1e-9);
    }
}
