//! The sensor noise, measured online: the mean square of the raw force's second difference over six
//! (white noise of variance σ² gives σ²; ramps give nothing, smooth motion little), averaged over a
//! window — over every sample so far while there is less than a window of them, so the estimate is the
//! noise's from the first samples on (the approach's contact detector scales with it: an estimate still
//! rising from zero would let a noise spike pass for contact). Each difference is clipped at three of
//! its own standard deviations (plus a floor), so impacts and steps — rare, large — cannot pass for
//! noise; true noise still builds the estimate up.

use serde::{Deserialize, Serialize};

use super::positive;

/// Variance of the second difference `f_k − 2·f_{k−1} + f_{k−2}` of white noise, in units of the
/// noise's variance: `1² + 2² + 1² = 6`, exactly.
const SECOND_DIFFERENCE_GAIN: f64 = 6.0;

/// The clip on a second difference, in its own standard deviations: three: 0.27 % of Gaussian noise's
/// differences are clipped, which biases the variance down by 0.5 %, and an impact or a step cannot
/// pass for noise.
const CLIP_DEVIATIONS: f64 = 3.0;

/// The noise meter's parameters (advanced: the defaults suit any cell).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseParams {
    /// Time constant of the estimate, s.
    pub window: f64,
    /// Floor of the clipping level, N.
    pub clip_floor: f64,
}

impl Default for NoiseParams {
    fn default() -> Self {
        Self {
            window: 1.0,
            clip_floor: 0.05,
        }
    }
}

impl NoiseParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        positive("noise.window", self.window)?;
        positive("noise.clip_floor", self.clip_floor)
    }
}

/// The noise meter's output: what it has measured so far.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseEstimate {
    /// The noise variance, N².
    pub var: f64,
    /// The noise standard deviation, N.
    pub std: f64,
    /// How long the noise has been measured since the reset, s.
    pub age: f64,
}

/// Online estimate of the force sensor's noise variance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseMeter {
    p: NoiseParams,
    /// The previous raw force and the one before it, N.
    prev: Option<(f64, Option<f64>)>,
    var: f64,
    /// Time measured since the reset, s.
    age: f64,
}

impl NoiseMeter {
    /// A meter that has measured nothing.
    pub fn new(p: NoiseParams) -> Self {
        Self {
            p,
            prev: None,
            var: 0.0,
            age: 0.0,
        }
    }

    /// Take new parameters, keeping the estimate.
    pub fn set_params(&mut self, p: NoiseParams) {
        self.p = p;
    }

    /// Forget everything.
    pub fn reset(&mut self) {
        self.prev = None;
        self.var = 0.0;
        self.age = 0.0;
    }

    /// Count one raw force sample `f` after a step of `dt`; returns the estimate.
    pub fn step(&mut self, f: f64, dt: f64) -> NoiseEstimate {
        if let Some((p1, Some(p2))) = self.prev {
            // The first second difference is taken whole: there is no estimate yet to clip it at.
            let clip = if self.age == 0.0 {
                f64::INFINITY
            } else {
                CLIP_DEVIATIONS * (SECOND_DIFFERENCE_GAIN * self.var).sqrt() + self.p.clip_floor
            };
            self.age += dt;
            let a = (dt / self.age.min(self.p.window)).min(1.0);
            let d2 = (f - 2.0 * p1 + p2).clamp(-clip, clip);
            self.var += a * (d2 * d2 / SECOND_DIFFERENCE_GAIN - self.var);
        }
        self.prev = Some((f, self.prev.map(|p| p.0)));
        self.estimate()
    }

    /// What has been measured so far.
    pub fn estimate(&self) -> NoiseEstimate {
        NoiseEstimate {
            var: self.var,
            std: self.var.sqrt(),
            age: self.age,
        }
    }

    /// The noise variance, N².
    pub fn var(&self) -> f64 {
        self.var
    }

    /// How long the noise has been measured since the reset, s.
    pub fn age(&self) -> f64 {
        self.age
    }

    /// The noise standard deviation, N.
    pub fn std(&self) -> f64 {
        self.var.sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn measures_white_noise_and_ignores_ramps_and_steps() {
        let mut m = NoiseMeter::new(NoiseParams::default());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = Normal::new(0.0, 0.5).unwrap();
        for i in 0..5000 {
            m.step(5.0 + 0.01 * i as f64 + n.sample(&mut rng), 1e-3);
        }
        assert!((m.std() - 0.5).abs() < 0.05, "{}", m.std());
        let mut m = NoiseMeter::new(NoiseParams::default());
        for i in 0..3000 {
            m.step(if i < 1500 { 0.002 * i as f64 } else { 40.0 }, 1e-3);
        }
        assert!(
            m.std() < 0.03,
            "a ramp and a step are not noise: {}",
            m.std()
        );
        m.reset();
        assert_eq!(m.var(), 0.0);
    }

    /// A sensor noisy from the start is measured within the first fifth of a window (the approach's
    /// contact detector scales with it from there on).
    #[test]
    fn the_noise_is_measured_from_the_first_samples() {
        let mut m = NoiseMeter::new(NoiseParams::default());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let n = Normal::new(0.0, 0.9).unwrap();
        for _ in 0..50 {
            m.step(n.sample(&mut rng), 4e-3);
        }
        assert!((m.std() - 0.9).abs() < 0.25, "{} N after 0.2 s", m.std());
    }
}
