//! What a real force sensor does to the truth: white noise, bias, bias drift, count quantisation,
//! dropouts and injected non-finite samples. Seeded, so a run repeats exactly.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// A time window, s.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Window {
    /// Start, s.
    pub at: f64,
    /// Length, s.
    pub duration: f64,
}

impl Window {
    fn contains(&self, t: f64) -> bool {
        t >= self.at && t < self.at + self.duration
    }
}

/// Sensor imperfections. The default is a perfect sensor.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorParams {
    /// Standard deviation of white noise on each force axis, N.
    pub noise: f64,
    /// Constant bias on each force axis, N.
    pub bias: f64,
    /// Bias drift, N per minute.
    pub drift_per_min: f64,
    /// Resolution, N (0: continuous). ATI-like sensors quantise to 1/counts-per-unit.
    pub quantum: f64,
    /// Windows with no sample at all (the read times out).
    pub dropouts: Vec<Window>,
    /// Times at which one NaN sample is delivered (the first sample at or after each).
    pub nan_at: Vec<f64>,
    /// RNG seed.
    pub seed: u64,
}

impl SensorParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        for (n, v) in [("noise", self.noise), ("quantum", self.quantum)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("sensor {n} must be >= 0, got {v}"));
            }
        }
        for (n, v) in [("bias", self.bias), ("drift_per_min", self.drift_per_min)] {
            if !v.is_finite() {
                return Err(format!("sensor {n} must be finite, got {v}"));
            }
        }
        for w in &self.dropouts {
            if !(w.at.is_finite() && w.duration.is_finite() && w.duration >= 0.0) {
                return Err(format!("bad dropout window {w:?}"));
            }
        }
        Ok(())
    }
}

/// Why a measurement produced nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dropout;

/// A sensor model with its RNG state.
#[derive(Clone, Debug)]
pub struct SensorModel {
    params: SensorParams,
    rng: ChaCha8Rng,
    normal: Option<Normal<f64>>,
    nan_done: Vec<bool>,
}

impl SensorModel {
    /// A model from its parameters (validated by the caller).
    pub fn new(params: SensorParams) -> Self {
        let normal =
            (params.noise > 0.0).then(|| Normal::new(0.0, params.noise).expect("noise >= 0"));
        let nan_done = vec![false; params.nan_at.len()];
        Self {
            rng: ChaCha8Rng::seed_from_u64(params.seed),
            params,
            normal,
            nan_done,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &SensorParams {
        &self.params
    }

    /// The offset (bias + drift) at time `t`, N.
    pub fn offset(&self, t: f64) -> f64 {
        self.params.bias + self.params.drift_per_min * t / 60.0
    }

    /// Measure the true force vector `f` (N) at time `t`.
    pub fn measure(&mut self, t: f64, f: [f64; 3]) -> Result<[f64; 3], Dropout> {
        if self.params.dropouts.iter().any(|w| w.contains(t)) {
            return Err(Dropout);
        }
        for (i, &at) in self.params.nan_at.iter().enumerate() {
            if !self.nan_done[i] && t >= at {
                self.nan_done[i] = true;
                return Ok([f64::NAN; 3]);
            }
        }
        let off = self.offset(t);
        let mut out = f;
        for v in &mut out {
            *v += off;
            if let Some(n) = &self.normal {
                *v += n.sample(&mut self.rng);
            }
            if self.params.quantum > 0.0 {
                *v = (*v / self.params.quantum).round() * self.params.quantum;
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_samples() {
        let p = SensorParams {
            noise: 0.5,
            seed: 7,
            ..SensorParams::default()
        };
        let mut a = SensorModel::new(p.clone());
        let mut b = SensorModel::new(p);
        for k in 0..100 {
            let t = k as f64 * 1e-3;
            assert_eq!(a.measure(t, [0.0, 0.0, 5.0]), b.measure(t, [0.0, 0.0, 5.0]));
        }
    }

    #[test]
    fn drift_dropout_nan_and_quantisation() {
        let mut m = SensorModel::new(SensorParams {
            drift_per_min: 0.6,
            quantum: 0.01,
            dropouts: vec![Window {
                at: 1.0,
                duration: 0.02,
            }],
            nan_at: vec![55.0],
            ..SensorParams::default()
        });
        let r = m.measure(60.0 - 10.0, [0.0, 0.0, 5.0]);
        // 50 s of 0.6 N/min = 0.5 N.
        assert!((r.unwrap()[2] - 5.5).abs() < 1e-9);
        assert_eq!(m.measure(1.01, [0.0; 3]), Err(Dropout));
        assert!(m.measure(55.0, [0.0; 3]).unwrap()[2].is_nan());
        assert!(
            m.measure(55.001, [0.0; 3]).unwrap()[2].is_finite(),
            "one NaN only"
        );
        let q = m.measure(0.0, [0.0, 0.0, 1.234_56]).unwrap()[2];
        assert!((q - 1.23).abs() < 1e-12);
    }
}
