//! The driver's envelope and rate limit for path corrections, inside the robot's configured range.
//!
//! A path correction is a translation: the envelope bounds its norm, the rate limit bounds its change
//! per cycle, both in m in the tool frame (before the conversion to the wire). A non-finite command holds
//! the last total sent. Axes the link does not carry stay zero.

use hal::Vector3;

use crate::diag::Counters;

/// The driver's limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Largest total correction (norm of the translation), m.
    pub max_translation: f64,
    /// Largest change of the total per cycle (norm), m.
    pub max_translation_step: f64,
}

impl Default for Limits {
    /// 4.5 mm, 0.25 mm per cycle (62.5 mm/s at 4 ms).
    fn default() -> Self {
        Self {
            max_translation: 0.0045,
            max_translation_step: 0.000_25,
        }
    }
}

/// The largest path correction the robot is configured to accept, m (the robot side clamps to it; the
/// driver's envelope must lie inside).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CorrectionRange {
    /// Per-axis bound of the path correction, m.
    pub translation: f64,
}

impl Default for CorrectionRange {
    /// 5 mm per axis.
    fn default() -> Self {
        Self { translation: 0.005 }
    }
}

impl Limits {
    /// Check the values and that the envelope lies inside the robot's range.
    pub fn validate(&self, range: &CorrectionRange) -> Result<(), String> {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        if !ok(self.max_translation) || !ok(self.max_translation_step) || !ok(range.translation) {
            return Err(format!(
                "limits must be finite and > 0: max_translation {} m, max_translation_step {} m, robot range {} m",
                self.max_translation, self.max_translation_step, range.translation
            ));
        }
        if self.max_translation > range.translation {
            return Err(format!(
                "the driver's envelope {} mm exceeds the robot's configured path-correction range {} mm: \
                 the robot would clamp what the driver believes it sent",
                self.max_translation * 1e3,
                range.translation * 1e3
            ));
        }
        Ok(())
    }
}

/// Shapes each total before it is sent: non-finite held, unconfigured axes zeroed, envelope, rate limit.
#[derive(Clone, Debug)]
pub struct Shaper {
    limits: Limits,
    axes: [bool; 3],
    last: Vector3<f64>,
}

impl Shaper {
    /// A shaper for the carried `axes` (x, y, z of the tool frame), starting from zero.
    pub fn new(limits: Limits, axes: [bool; 3]) -> Self {
        Self {
            limits,
            axes,
            last: Vector3::zeros(),
        }
    }

    /// Restart the rate limit from `total` (a new session: the correction the robot reports in effect).
    pub fn restart(&mut self, total: Vector3<f64>) {
        let mut limited = false;
        self.last = if total.iter().all(|v| v.is_finite()) {
            self.envelope(total, &mut limited)
        } else {
            Vector3::zeros()
        };
    }

    /// The total to send for the asked `wanted` (m, tool frame).
    pub fn shape(&mut self, wanted: &Vector3<f64>, n: &mut Counters) -> Vector3<f64> {
        if !wanted.iter().all(|v| v.is_finite()) {
            n.nonfinite_held += 1;
            return self.last;
        }
        let mut env = false;
        let mut out = self.envelope(*wanted, &mut env);
        let step = out - self.last;
        let rate = step.norm() > self.limits.max_translation_step;
        if rate {
            out = self.last + step * (self.limits.max_translation_step / step.norm());
        }
        let mut again = false;
        out = self.envelope(out, &mut again);
        n.envelope_limited += u64::from(env || again);
        n.rate_limited += u64::from(rate);
        self.last = out;
        out
    }

    fn envelope(&self, v: Vector3<f64>, limited: &mut bool) -> Vector3<f64> {
        let mut out = v;
        for (o, on) in out.iter_mut().zip(self.axes) {
            if !on && *o != 0.0 {
                *o = 0.0;
                *limited = true;
            }
        }
        let norm = out.norm();
        if norm > self.limits.max_translation {
            out *= self.limits.max_translation / norm;
            *limited = true;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_then_rate_and_nonfinite_holds() {
        let mut s = Shaper::new(Limits::default(), [true; 3]);
        let mut n = Counters::default();
        let out = s.shape(&Vector3::new(0.0, 0.0, 0.1), &mut n);
        assert!((out.z - 0.000_25).abs() < 1e-15, "rate-limited from 0");
        assert_eq!((n.envelope_limited, n.rate_limited), (1, 1));
        for _ in 0..100 {
            s.shape(&Vector3::new(0.0, 0.0, 0.1), &mut n);
        }
        assert!((s.shape(&Vector3::new(0.0, 0.0, 0.1), &mut n).z - 0.0045).abs() < 1e-15);
        let held = s.shape(&Vector3::new(f64::NAN, 0.0, 0.0), &mut n);
        assert!((held.z - 0.0045).abs() < 1e-15);
        assert_eq!(n.nonfinite_held, 1);
    }

    #[test]
    fn axes_not_carried_stay_zero_and_restart_starts_there() {
        let mut s = Shaper::new(Limits::default(), [false, false, true]);
        let mut n = Counters::default();
        let out = s.shape(&Vector3::new(0.0001, 0.0, 0.0001), &mut n);
        assert_eq!(out, Vector3::new(0.0, 0.0, 0.0001));
        assert_eq!(n.envelope_limited, 1);
        s.restart(Vector3::new(0.0, 0.0, 0.003));
        let out = s.shape(&Vector3::new(0.0, 0.0, 0.003), &mut n);
        assert_eq!(out.z, 0.003, "no rate limit from the restart point");
    }

    #[test]
    fn the_envelope_must_lie_inside_the_robot_range() {
        let r = CorrectionRange::default();
        assert!(Limits::default().validate(&r).is_ok());
        let wide = Limits {
            max_translation: 0.006,
            ..Limits::default()
        };
        assert!(wide.validate(&r).unwrap_err().contains("range"));
        let nan = Limits {
            max_translation_step: f64::NAN,
            ..Limits::default()
        };
        assert!(nan.validate(&r).is_err());
    }
}
