//! The last guard before the wire: the correction envelope and the per-cycle rate limit, in SI.

use hal::{Correction, Vector3};

use crate::diag::Counters;

/// What the driver lets through, in SI, tool frame. The envelope bounds the **norm** of the total
/// translation and of the total rotation vector (so every axis, and the overall correction that
/// POSCORRMON watches, stays inside); the rate limit bounds each component's change per reply.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Largest norm of the total translation, m.
    pub max_translation: f64,
    /// Largest norm of the total rotation vector, rad.
    pub max_rotation: f64,
    /// Largest change of a translation component from one reply to the next, m.
    pub max_translation_step: f64,
    /// Largest change of a rotation component from one reply to the next, rad.
    pub max_rotation_step: f64,
}

impl Default for Limits {
    /// 4.5 mm and 4.5° (inside the default POSCORR ±5 mm, 5° and POSCORRMON 6 mm, 6°), 0.25 mm and
    /// 0.25° per cycle.
    fn default() -> Self {
        Self {
            max_translation: 0.0045,
            max_rotation: 4.5f64.to_radians(),
            max_translation_step: 0.000_25,
            max_rotation_step: 0.25f64.to_radians(),
        }
    }
}

/// A pair of robot-side limits in SI: POSCORR (clamps silently, per axis) or POSCORRMON (stops RSI
/// when the overall correction exceeds it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoscorrLimits {
    /// Per-axis translation limit, m (default 5 mm).
    pub translation: f64,
    /// Rotation limit, rad (default 5°).
    pub rotation: f64,
}

impl Default for PoscorrLimits {
    fn default() -> Self {
        Self {
            translation: 0.005,
            rotation: 5f64.to_radians(),
        }
    }
}

impl PoscorrLimits {
    /// POSCORRMON's defaults: 6 mm, 6°.
    pub const MONITOR_DEFAULT: Self = Self {
        translation: 0.006,
        rotation: 6.0 * core::f64::consts::PI / 180.0,
    };
}

impl Limits {
    /// Check the limits are positive and inside POSCORR and POSCORRMON (rotation with a 10 % margin:
    /// a rotation vector maps onto A, B, C only to first order).
    pub fn validate(&self, robot: &PoscorrLimits, monitor: &PoscorrLimits) -> Result<(), String> {
        let robot = &PoscorrLimits {
            translation: robot.translation.min(monitor.translation),
            rotation: robot.rotation.min(monitor.rotation),
        };
        for (name, v) in [
            ("max_translation", self.max_translation),
            ("max_rotation", self.max_rotation),
            ("max_translation_step", self.max_translation_step),
            ("max_rotation_step", self.max_rotation_step),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} must be finite and >= 0, got {v}"));
            }
        }
        if self.max_translation > robot.translation {
            return Err(format!(
                "max_translation {} m exceeds the robot's POSCORR/POSCORRMON limit {} m",
                self.max_translation, robot.translation
            ));
        }
        if self.max_rotation > 0.9 * robot.rotation {
            return Err(format!(
                "max_rotation {} rad must stay within 90 % of the robot's POSCORR/POSCORRMON limit {} rad",
                self.max_rotation, robot.rotation
            ));
        }
        Ok(())
    }
}

/// Holds the last total sent and shapes every new one against it.
#[derive(Clone, Debug)]
pub(crate) struct Shaper {
    limits: Limits,
    /// Per component: may the robot receive it at all (is it configured)?
    enabled: [bool; 6],
    last: [f64; 6],
}

impl Shaper {
    pub(crate) fn new(limits: Limits, enabled: [bool; 6]) -> Self {
        Self {
            limits,
            enabled,
            last: [0.0; 6],
        }
    }

    /// A new session: rate-limit the next command against the correction the robot reports to be in
    /// effect (`RIst − RSol`, `[tx, ty, tz, rx, ry, rz]` m and rad; zero at a real `RSI_ON`), so the first
    /// reply can neither jump nor drag the tool back towards the path. Non-finite components count as 0.
    pub(crate) fn reset_to(&mut self, in_effect: [f64; 6]) {
        let mut ignored = false;
        self.last = self.envelope(
            in_effect.map(|v| if v.is_finite() { v } else { 0.0 }),
            &mut ignored,
        );
    }

    /// The total `[tx, ty, tz, rx, ry, rz]` (m, rad) to send for `c`; always finite.
    pub(crate) fn shape(&mut self, c: &Correction, n: &mut Counters) -> [f64; 6] {
        if !c.is_finite() {
            n.nonfinite_held += 1;
            return self.last;
        }
        let want = [
            c.translation.x,
            c.translation.y,
            c.translation.z,
            c.rotation.x,
            c.rotation.y,
            c.rotation.z,
        ];
        let (mut env, mut rate) = (false, false);
        let mut out = self.envelope(want, &mut env);
        for (i, v) in out.iter_mut().enumerate() {
            let step = if i < 3 {
                self.limits.max_translation_step
            } else {
                self.limits.max_rotation_step
            };
            let r = v.clamp(self.last[i] - step, self.last[i] + step);
            rate |= r != *v;
            *v = r;
        }
        // Rate-limiting between two points inside the envelope can leave it by a hair: clamp again.
        let mut again = false;
        out = self.envelope(out, &mut again);
        env |= again;
        n.envelope_limited += u64::from(env);
        n.rate_limited += u64::from(rate);
        self.last = out;
        out
    }
}

impl Shaper {
    /// Zero the unconfigured components and scale translation and rotation into their norm limits.
    fn envelope(&self, v: [f64; 6], limited: &mut bool) -> [f64; 6] {
        let mut out = v;
        for (i, o) in out.iter_mut().enumerate() {
            if !self.enabled[i] && *o != 0.0 {
                *o = 0.0;
                *limited = true;
            }
        }
        for (range, lim) in [
            (0..3, self.limits.max_translation),
            (3..6, self.limits.max_rotation),
        ] {
            let norm = out[range.clone()].iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > lim {
                let k = lim / norm;
                out[range].iter_mut().for_each(|x| *x *= k);
                *limited = true;
            }
        }
        out
    }
}

/// Split a shaped total into translation and rotation vectors.
pub(crate) fn split(v: [f64; 6]) -> (Vector3<f64>, Vector3<f64>) {
    (
        Vector3::new(v[0], v[1], v[2]),
        Vector3::new(v[3], v[4], v[5]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_then_rate() {
        let mut s = Shaper::new(Limits::default(), [true; 6]);
        let mut n = Counters::default();
        let out = s.shape(&Correction::along_z(0.1), &mut n);
        assert_eq!(out[2], 0.000_25, "rate-limited from 0");
        assert_eq!((n.envelope_limited, n.rate_limited), (1, 1));
        for _ in 0..100 {
            s.shape(&Correction::along_z(0.1), &mut n);
        }
        assert_eq!(s.shape(&Correction::along_z(0.1), &mut n)[2], 0.0045);
        let back = s.shape(&Correction::along_z(-1.0), &mut n)[2];
        assert!((back - 0.004_25).abs() < 1e-15, "{back}");
    }

    #[test]
    fn nonfinite_holds_the_last_total() {
        let mut s = Shaper::new(Limits::default(), [true; 6]);
        let mut n = Counters::default();
        let a = s.shape(&Correction::along_z(0.0001), &mut n);
        let b = s.shape(&Correction::along_z(f64::NAN), &mut n);
        assert_eq!(a, b);
        assert_eq!(n.nonfinite_held, 1);
    }

    #[test]
    fn unconfigured_components_stay_zero() {
        let mut s = Shaper::new(Limits::default(), [false, false, true, false, false, false]);
        let mut n = Counters::default();
        let mut c = Correction::along_z(0.0001);
        c.translation.x = 0.0001;
        let out = s.shape(&c, &mut n);
        assert_eq!(out[0], 0.0);
        assert_eq!(n.envelope_limited, 1);
        assert_eq!(out[2], 0.0001);
    }

    #[test]
    fn limits_must_stay_inside_poscorr() {
        let robot = PoscorrLimits::default();
        let mon = PoscorrLimits {
            translation: 0.006,
            rotation: 6f64.to_radians(),
        };
        assert!(Limits::default().validate(&robot, &mon).is_ok());
        let wide = Limits {
            max_translation: 0.006,
            ..Limits::default()
        };
        assert!(wide.validate(&robot, &mon).unwrap_err().contains("POSCORR"));
        let tight_mon = PoscorrLimits {
            translation: 0.004,
            ..mon
        };
        assert!(Limits::default().validate(&robot, &tight_mon).is_err());
    }
}
