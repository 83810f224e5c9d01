//! What a real force sensor does to the truth: its own low-pass filter, white noise, bias, bias drift,
//! count quantisation, dropouts and injected non-finite samples. Seeded, so a run repeats exactly.

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
    /// Cut-off of the sensor's own low-pass filter on the force (a second-order Butterworth, as
    /// F/T boards offer), Hz; 0: none. It ticks at the sensor's own 4 kHz, on the true force
    /// interpolated between two reads, whatever the rate it is read at.
    pub bandwidth: f64,
}

impl SensorParams {
    /// How much older a force sample is than the time it is read at, s: the low-frequency group
    /// delay of the sensor's own filter, `√2/(2π·bandwidth)` (0 without one).
    pub fn delay(&self) -> f64 {
        if self.bandwidth > 0.0 {
            core::f64::consts::SQRT_2 / (core::f64::consts::TAU * self.bandwidth)
        } else {
            0.0
        }
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        for (n, v) in [
            ("noise", self.noise),
            ("quantum", self.quantum),
            ("bandwidth", self.bandwidth),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("sensor {n} must be >= 0, got {v}"));
            }
        }
        if self.bandwidth > MAX_BANDWIDTH {
            return Err(format!(
                "sensor bandwidth must be at most {MAX_BANDWIDTH} Hz, got {}: the sensor's filter ticks at 4 kHz and cannot cut off above 0.45 of that",
                self.bandwidth
            ));
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

/// The sensor's own low-pass on each force axis: a second-order Butterworth, bilinear at the sensor's
/// own period [`SENSOR_PERIOD`], ticking at its multiples on the true force interpolated linearly
/// between two reads; a read gets the output of the last tick.
#[derive(Clone, Debug)]
struct LowPass {
    /// `[b0, a1, a2]` (`b1 = 2·b0`, `b2 = b0`).
    coeffs: [f64; 3],
    /// The last read's time (s), its tick and its true force (`None`: the next read starts the filter
    /// at rest at its force).
    last: Option<(f64, u64, [f64; 3])>,
    /// Transposed direct form II state per axis, and the last tick's output.
    state: [[f64; 2]; 3],
    out: [f64; 3],
}

/// The sensor's own filter period, s (4 kHz).
const SENSOR_PERIOD: f64 = 2.5e-4;

/// The highest filter cut-off a sensor model takes, Hz: 0.45 of its 4 kHz tick (a digital filter
/// cannot cut off at or above half its own rate).
pub const MAX_BANDWIDTH: f64 = 0.45 / SENSOR_PERIOD;

impl LowPass {
    fn new(cutoff: f64) -> Self {
        let w = (core::f64::consts::PI * cutoff.min(MAX_BANDWIDTH) * SENSOR_PERIOD).tan();
        let q = core::f64::consts::FRAC_1_SQRT_2;
        let norm = 1.0 / (1.0 + w / q + w * w);
        Self {
            coeffs: [
                w * w * norm,
                2.0 * (w * w - 1.0) * norm,
                (1.0 - w / q + w * w) * norm,
            ],
            last: None,
            state: [[0.0; 2]; 3],
            out: [0.0; 3],
        }
    }

    /// The filtered force read at `t` (s), the true force being `f` (N) then.
    fn step(&mut self, t: f64, f: [f64; 3]) -> [f64; 3] {
        // The last tick at or before `t` (less a rounding's worth: 1 ms is four ticks).
        let tick = (t / SENSOR_PERIOD + 1e-6).floor().max(0.0) as u64;
        let [b0, a1, a2] = self.coeffs;
        let Some((t0, tick0, f0)) = self.last else {
            // At rest at the first read: y = x, s1 = y − b0·x, s2 = b2·x − a2·y.
            self.last = Some((t, tick, f));
            self.state = f.map(|x| [x - b0 * x, b0 * x - a2 * x]);
            self.out = f;
            return f;
        };
        if t <= t0 {
            return self.out;
        }
        self.last = Some((t, tick, f));
        for k in tick0 + 1..=tick {
            let share = ((k as f64 * SENSOR_PERIOD - t0) / (t - t0)).clamp(0.0, 1.0);
            for i in 0..3 {
                let x = f0[i] + (f[i] - f0[i]) * share;
                let [s1, s2] = self.state[i];
                let y = b0 * x + s1;
                self.state[i] = [2.0 * b0 * x - a1 * y + s2, b0 * x - a2 * y];
                self.out[i] = y;
            }
        }
        self.out
    }
}

/// A sensor model with its RNG state.
#[derive(Clone, Debug)]
pub struct SensorModel {
    params: SensorParams,
    rng: ChaCha8Rng,
    normal: Option<Normal<f64>>,
    nan_done: Vec<bool>,
    lowpass: LowPass,
}

impl SensorModel {
    /// A model from its parameters (validated by the caller).
    pub fn new(params: SensorParams) -> Self {
        let normal =
            (params.noise > 0.0).then(|| Normal::new(0.0, params.noise).expect("noise >= 0"));
        let nan_done = vec![false; params.nan_at.len()];
        let lowpass = LowPass::new(params.bandwidth);
        Self {
            rng: ChaCha8Rng::seed_from_u64(params.seed),
            params,
            normal,
            nan_done,
            lowpass,
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
        // The sensor filters on through a dropout: only its samples are lost.
        let filtered = if self.params.bandwidth > 0.0 {
            self.lowpass.step(t, f)
        } else {
            f
        };
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
        let mut out = filtered;
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

    /// A 10 N step read every millisecond through a 50 Hz filter: the first read after it shows
    /// a fraction, the reads rise over a few milliseconds with the Butterworth's 4 % overshoot, and
    /// settle at the step (the true force ramps between two reads).
    #[test]
    fn the_sensor_s_own_filter_spreads_a_step() {
        let mut m = SensorModel::new(SensorParams {
            bandwidth: 50.0,
            ..SensorParams::default()
        });
        let read = |m: &mut SensorModel, k: u32, f: f64| {
            m.measure(f64::from(k) * 1e-3, [0.0, 0.0, f]).unwrap()[2]
        };
        for k in 0..10 {
            let v = read(&mut m, k, 2.0);
            assert!((v - 2.0).abs() < 1e-12, "{v}");
        }
        let r: Vec<f64> = (10..200).map(|k| read(&mut m, k, 12.0)).collect();
        assert!(r[0] > 2.0 && r[0] < 3.0, "{}", r[0]);
        let peak = r.iter().copied().fold(0.0, f64::max);
        assert!((peak - 12.43).abs() < 0.1, "{peak}");
        assert!((r[189] - 12.0).abs() < 1e-3, "{}", r[189]);
        // Two reads at the same time: the same value.
        assert_eq!(read(&mut m, 199, 0.0), r[189]);
        // The filter runs at the sensor's own rate, not the reader's: read every 12 ms, a 200 Hz
        // filter has settled within a read (run at 12 ms, its cut-off would be held at 37.5 Hz).
        let mut m = SensorModel::new(SensorParams {
            bandwidth: 200.0,
            ..SensorParams::default()
        });
        m.measure(0.0, [0.0; 3]).unwrap();
        m.measure(0.012, [0.0, 0.0, 10.0]).unwrap();
        let settled = m.measure(0.024, [0.0, 0.0, 10.0]).unwrap()[2];
        assert!((settled - 10.0).abs() < 0.1, "{settled}");
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
