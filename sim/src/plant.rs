//! The contact plant: the physical truth every simulated peer answers from.
//!
//! 1-DOF along the tool's normal axis, `x` growing into the workpiece, SI units:
//! `f = k_c(t)·(x − x_c(t)) + c_e·ẋ` while `x > x_c(t)`, else 0, and never negative (no adhesion).

use serde::{Deserialize, Serialize};

/// A change applied to a scheduled value from a point in time on.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Event {
    /// Add `delta` from `at` on.
    Step {
        /// Time of the step, s.
        at: f64,
        /// Change, in the value's unit.
        delta: f64,
    },
    /// Multiply by `factor` from `at` on.
    Scale {
        /// Time of the change, s.
        at: f64,
        /// Factor (> 0).
        factor: f64,
    },
    /// Add `rate·(t − start)` between `start` and `end` (held after `end`).
    Ramp {
        /// Start, s.
        start: f64,
        /// End, s (open-ended when absent).
        #[serde(default)]
        end: Option<f64>,
        /// Rate, unit per second.
        rate: f64,
    },
    /// Add `amplitude·sin(2π·frequency·(t − start))` from `start` on.
    Sine {
        /// Start, s.
        #[serde(default)]
        start: f64,
        /// Amplitude, in the value's unit.
        amplitude: f64,
        /// Frequency, Hz.
        frequency: f64,
    },
}

impl Event {
    fn validate(&self) -> Result<(), String> {
        let finite = |name: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(format!("event {name} must be finite, got {v}"))
            }
        };
        match *self {
            Self::Step { at, delta } => {
                finite("at", at)?;
                finite("delta", delta)
            }
            Self::Scale { at, factor } => {
                finite("at", at)?;
                finite("factor", factor)?;
                if factor > 0.0 {
                    Ok(())
                } else {
                    Err(format!("scale factor must be > 0, got {factor}"))
                }
            }
            Self::Ramp { start, end, rate } => {
                finite("start", start)?;
                finite("rate", rate)?;
                if let Some(e) = end {
                    finite("end", e)?;
                    if e < start {
                        return Err(format!("ramp end {e} s is before its start {start} s"));
                    }
                }
                Ok(())
            }
            Self::Sine {
                start,
                amplitude,
                frequency,
            } => {
                finite("start", start)?;
                finite("amplitude", amplitude)?;
                finite("frequency", frequency)?;
                if frequency >= 0.0 {
                    Ok(())
                } else {
                    Err(format!("sine frequency must be >= 0, got {frequency}"))
                }
            }
        }
    }
}

/// A value over time: a base and a list of events applied in order.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct Schedule {
    /// Value at t = 0 before any event.
    pub base: f64,
    /// Changes, applied in this order.
    pub events: Vec<Event>,
}

impl Schedule {
    /// A constant.
    pub fn constant(base: f64) -> Self {
        Self {
            base,
            events: Vec::new(),
        }
    }

    /// With one more event.
    pub fn with(mut self, e: Event) -> Self {
        self.events.push(e);
        self
    }

    /// The value at time `t`, s.
    pub fn at(&self, t: f64) -> f64 {
        let mut v = self.base;
        for e in &self.events {
            match *e {
                Event::Step { at, delta } if t >= at => v += delta,
                Event::Scale { at, factor } if t >= at => v *= factor,
                Event::Ramp { start, end, rate } if t >= start => {
                    let t_end = end.map_or(t, |e| t.min(e));
                    v += rate * (t_end - start);
                }
                Event::Sine {
                    start,
                    amplitude,
                    frequency,
                } if t >= start => {
                    v += amplitude * (core::f64::consts::TAU * frequency * (t - start)).sin();
                }
                _ => {}
            }
        }
        v
    }

    /// Checks every value is finite.
    pub fn validate(&self, name: &str) -> Result<(), String> {
        if !self.base.is_finite() {
            return Err(format!("{name} must be finite, got {}", self.base));
        }
        for e in &self.events {
            e.validate().map_err(|m| format!("{name}: {m}"))?;
        }
        Ok(())
    }
}

/// Spring (+ optional damper) workpiece with scheduled stiffness and surface position.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactPlant {
    /// Stiffness `k_c`, N/m.
    pub k_c: Schedule,
    /// Surface position `x_c`, m (along the tool normal, from the programmed path).
    pub x_c: Schedule,
    /// Damping `c_e`, N·s/m.
    pub c_e: f64,
}

impl ContactPlant {
    /// A pure spring of constant stiffness and position.
    pub fn spring(k_c: f64, x_c: f64) -> Self {
        Self {
            k_c: Schedule::constant(k_c),
            x_c: Schedule::constant(x_c),
            c_e: 0.0,
        }
    }

    /// Checks the schedules and that the stiffness stays positive at the events.
    pub fn validate(&self) -> Result<(), String> {
        self.k_c.validate("k_c")?;
        self.x_c.validate("x_c")?;
        if !(self.c_e.is_finite() && self.c_e >= 0.0) {
            return Err(format!("c_e must be >= 0, got {}", self.c_e));
        }
        if self.k_c.base <= 0.0 {
            return Err(format!("k_c must be > 0 N/m, got {}", self.k_c.base));
        }
        Ok(())
    }

    /// Contact force, N, at time `t` for tool position `x` (m) and velocity `v` (m/s).
    pub fn force(&self, t: f64, x: f64, v: f64) -> f64 {
        let pen = x - self.x_c.at(t);
        if pen <= 0.0 {
            return 0.0;
        }
        (self.k_c.at(t).max(0.0) * pen + self.c_e * v).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_events_compose() {
        let s = Schedule::constant(70_000.0)
            .with(Event::Step {
                at: 1.0,
                delta: -30_000.0,
            })
            .with(Event::Scale {
                at: 2.0,
                factor: 2.0,
            });
        assert_eq!(s.at(0.5), 70_000.0);
        assert_eq!(s.at(1.0), 40_000.0);
        assert_eq!(s.at(2.5), 80_000.0);
        let r = Schedule::constant(0.01).with(Event::Ramp {
            start: 1.0,
            end: Some(2.0),
            rate: 0.002,
        });
        assert!((r.at(1.5) - 0.011).abs() < 1e-12);
        assert!((r.at(5.0) - 0.012).abs() < 1e-12);
        let w = Schedule::constant(0.0).with(Event::Sine {
            start: 0.0,
            amplitude: 1.0,
            frequency: 0.5,
        });
        assert!((w.at(0.5) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn force_has_no_adhesion() {
        let mut p = ContactPlant::spring(70_000.0, 0.01);
        assert_eq!(p.force(0.0, 0.009, 0.0), 0.0);
        assert!((p.force(0.0, 0.0101, 0.0) - 7.0).abs() < 1e-9);
        p.c_e = 1000.0;
        // Pulling out fast: the damper would pull, the surface cannot.
        assert_eq!(p.force(0.0, 0.0101, -1.0), 0.0);
    }

    #[test]
    fn invalid_values_are_named() {
        let p = ContactPlant::spring(f64::NAN, 0.01);
        assert!(p.validate().unwrap_err().contains("k_c"));
        let bad = Schedule::constant(1.0).with(Event::Scale {
            at: 0.0,
            factor: -1.0,
        });
        assert!(bad.validate("k_c").unwrap_err().contains("factor"));
    }
}
