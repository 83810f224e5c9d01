//! Force signal conditioning: a second-order Butterworth low-pass and an optional notch, both biquads
//! discretised with the bilinear transform (cut-off pre-warped) for the step the loop actually runs at.
//!
//! Coefficients are recomputed only when `dt` changes, so a loop at a fixed period pays for them once;
//! the step itself is five multiplications per section, no allocation.

use core::f64::consts::PI;

use serde::{Deserialize, Serialize};

/// The highest frequency a filter is designed for, as a fraction of the sampling rate `1/dt`: a
/// cut-off above `CUTOFF_CAP/dt` is lowered to it. The bilinear transform's pre-warp `tan(π·f·dt)`
/// diverges at Nyquist (`f = 1/(2·dt)`); at 0.45 it is `tan(0.45·π) ≈ 6.3`, a finite, well-conditioned
/// biquad, and the low-pass still passes everything the loop can act on. The same cap gives the
/// conditioning's delay, noise bandwidth and step time ([`crate::robust::Conditioner`]).
pub const CUTOFF_CAP: f64 = 0.45;

/// A notch (band-stop) section, e.g. against a spindle or tool resonance.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NotchParams {
    /// Centre frequency, Hz.
    pub frequency: f64,
    /// Quality factor (centre frequency over −3 dB bandwidth), > 0.
    pub q: f64,
}

/// How the measured normal force is conditioned before the control law uses it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConditioningParams {
    /// Cut-off of the second-order Butterworth low-pass, Hz. Above the Nyquist frequency of the loop it
    /// is limited to [`CUTOFF_CAP`] of the sampling rate.
    pub cutoff: f64,
    /// Optional notch.
    #[serde(default)]
    pub notch: Option<NotchParams>,
}

impl ConditioningParams {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.cutoff.is_finite() && self.cutoff > 0.0) {
            return Err(format!(
                "conditioning.cutoff must be > 0 Hz, got {}",
                self.cutoff
            ));
        }
        if let Some(n) = self.notch {
            if !(n.frequency.is_finite() && n.frequency > 0.0) {
                return Err(format!(
                    "conditioning.notch.frequency must be > 0 Hz, got {}",
                    n.frequency
                ));
            }
            if !(n.q.is_finite() && n.q > 0.0) {
                return Err(format!("conditioning.notch.q must be > 0, got {}", n.q));
            }
        }
        Ok(())
    }
}

/// Normalised biquad coefficients (`a0 = 1`).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Coeffs {
    b0: f64,
    b1: f64,
    b2: f64,
    a1: f64,
    a2: f64,
}

impl Coeffs {
    /// The section that passes its input unchanged.
    const IDENTITY: Self = Self {
        b0: 1.0,
        b1: 0.0,
        b2: 0.0,
        a1: 0.0,
        a2: 0.0,
    };

    /// Pre-warped analogue frequency `tan(π·f·dt)`, with `f` limited below Nyquist.
    fn warp(f: f64, dt: f64) -> f64 {
        let f = f.min(CUTOFF_CAP / dt);
        (PI * f * dt).tan()
    }

    fn butterworth_lowpass(fc: f64, dt: f64) -> Self {
        let k = Self::warp(fc, dt);
        let q = core::f64::consts::FRAC_1_SQRT_2;
        let norm = 1.0 / (1.0 + k / q + k * k);
        let b0 = k * k * norm;
        Self {
            b0,
            b1: 2.0 * b0,
            b2: b0,
            a1: 2.0 * (k * k - 1.0) * norm,
            a2: (1.0 - k / q + k * k) * norm,
        }
    }

    fn notch(f0: f64, q: f64, dt: f64) -> Self {
        if f0 >= 1.0 / (2.0 * dt) {
            // Above Nyquist the loop cannot see it; nothing to remove.
            return Self::IDENTITY;
        }
        let k = Self::warp(f0, dt);
        let norm = 1.0 / (1.0 + k / q + k * k);
        let b0 = (1.0 + k * k) * norm;
        Self {
            b0,
            b1: 2.0 * (k * k - 1.0) * norm,
            b2: b0,
            a1: 2.0 * (k * k - 1.0) * norm,
            a2: (1.0 - k / q + k * k) * norm,
        }
    }

    /// DC gain.
    fn dc(&self) -> f64 {
        (self.b0 + self.b1 + self.b2) / (1.0 + self.a1 + self.a2)
    }
}

/// One biquad section in transposed direct form II.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Biquad {
    c: Coeffs,
    s1: f64,
    s2: f64,
}

impl Biquad {
    fn new() -> Self {
        Self {
            c: Coeffs::IDENTITY,
            s1: 0.0,
            s2: 0.0,
        }
    }

    /// Set the state to the steady state of a constant input `v`.
    fn reset(&mut self, v: f64) {
        let y = self.c.dc() * v;
        self.s1 = y - self.c.b0 * v;
        self.s2 = self.c.b2 * v - self.c.a2 * y;
    }

    fn step(&mut self, v: f64) -> f64 {
        let c = &self.c;
        let y = c.b0 * v + self.s1;
        self.s1 = c.b1 * v - c.a1 * y + self.s2;
        self.s2 = c.b2 * v - c.a2 * y;
        y
    }
}

/// A conditioner: notch (when configured), then low-pass. Used on the force, and on the position the
/// surface observer pairs with it (so both carry the same lag).
#[derive(Clone, Debug, PartialEq)]
pub struct SignalFilter {
    params: ConditioningParams,
    dt: f64,
    lowpass: Biquad,
    notch: Biquad,
    primed: bool,
    last: f64,
}

impl SignalFilter {
    /// A filter that primes itself with its first input.
    pub fn new(params: ConditioningParams) -> Self {
        Self {
            params,
            dt: f64::NAN,
            lowpass: Biquad::new(),
            notch: Biquad::new(),
            primed: false,
            last: 0.0,
        }
    }

    /// Change the parameters keeping the state (bumpless for a steady signal).
    pub fn set_params(&mut self, params: ConditioningParams) {
        self.params = params;
        self.dt = f64::NAN;
    }

    /// Forget the past: the next input primes the filter.
    pub fn clear(&mut self) {
        self.primed = false;
    }

    /// Set the filter to the steady state of the constant input `v`.
    pub fn reset_to(&mut self, v: f64) {
        self.notch.reset(v);
        self.lowpass.reset(v);
        self.primed = true;
        self.last = v;
    }

    fn design(&mut self, dt: f64) {
        self.dt = dt;
        self.lowpass.c = Coeffs::butterworth_lowpass(self.params.cutoff, dt);
        self.notch.c = match self.params.notch {
            Some(n) => Coeffs::notch(n.frequency, n.q, dt),
            None => Coeffs::IDENTITY,
        };
    }

    /// Filter one sample taken `dt` after the previous one.
    pub fn step(&mut self, v: f64, dt: f64) -> f64 {
        if dt != self.dt {
            self.design(dt);
            if self.primed {
                // New coefficients: restart from the last output as a steady state, no jump.
                self.reset_to(self.last);
            }
        }
        if !self.primed {
            self.reset_to(v);
        }
        let n = self.notch.step(v);
        self.last = self.lowpass.step(n);
        self.last
    }

    /// The last output.
    pub fn value(&self) -> f64 {
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gain_at(params: ConditioningParams, f: f64, dt: f64) -> f64 {
        let mut filt = SignalFilter::new(params);
        let n = (20.0 / (f * dt)).round() as usize; // 20 periods
        let mut peak: f64 = 0.0;
        for k in 0..n {
            let t = k as f64 * dt;
            let y = filt.step((2.0 * PI * f * t).sin(), dt);
            if k > n / 2 {
                peak = peak.max(y.abs());
            }
        }
        peak
    }

    #[test]
    fn lowpass_passes_dc_and_is_minus_3db_at_cutoff() {
        let p = ConditioningParams {
            cutoff: 20.0,
            notch: None,
        };
        let mut f = SignalFilter::new(p);
        let mut y = 0.0;
        for _ in 0..2000 {
            y = f.step(5.0, 1e-3);
        }
        assert!((y - 5.0).abs() < 1e-9);
        let g = gain_at(p, 20.0, 1e-3);
        assert!((g - core::f64::consts::FRAC_1_SQRT_2).abs() < 0.02, "{g}");
        assert!(gain_at(p, 200.0, 1e-3) < 0.02);
    }

    #[test]
    fn notch_removes_its_frequency_only() {
        let p = ConditioningParams {
            cutoff: 400.0,
            notch: Some(NotchParams {
                frequency: 50.0,
                q: 2.0,
            }),
        };
        assert!(gain_at(p, 50.0, 1e-3) < 0.02);
        assert!(gain_at(p, 5.0, 1e-3) > 0.97);
    }

    #[test]
    fn first_sample_primes_without_a_transient() {
        let mut f = SignalFilter::new(ConditioningParams {
            cutoff: 10.0,
            notch: None,
        });
        assert!((f.step(3.0, 4e-3) - 3.0).abs() < 1e-12);
        assert!((f.step(3.0, 4e-3) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn validation_names_the_field() {
        let e = ConditioningParams {
            cutoff: -1.0,
            notch: None,
        }
        .validate()
        .unwrap_err();
        assert!(e.contains("cutoff"), "{e}");
    }
}
