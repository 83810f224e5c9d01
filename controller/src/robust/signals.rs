//! The law's view of its inputs: the raw position and force, each force paired with the position of
//! the time it was measured (the cell's `sensor_delay` back), the same conditioning
//! ([`crate::conditioning`]) applied to both (so force and position stay in phase), and the velocities
//! of the conditioned and the raw position.

use super::cell::SENSOR_DELAY_STEPS;
use crate::conditioning::{CUTOFF_CAP, ConditioningParams, SignalFilter};

/// Noise bandwidth of the second-order Butterworth low-pass, in units of its cut-off: white noise
/// through it has the variance it has through an ideal low-pass this many cut-offs wide. Exactly
/// `(π/4)/sin(π/4) = π/(2·√2) ≈ 1.1107` (an `n`-th order Butterworth: `(π/2n)/sin(π/2n)`), rounded.
pub const NOISE_BANDWIDTH: f64 = 1.11;

/// How long a step takes to pass the conditioning, in periods of its cut-off frequency (`1/f_c`):
/// the group delay `√2/(2π·f_c) ≈ 0.23/f_c` and about two low-pass time constants `1/(2π·f_c)`
/// beyond it, `≈ 0.54/f_c`, rounded up: 30 ms at 20 Hz.
pub const STEP_TIME_PERIODS: f64 = 0.6;

/// One step's conditioned signals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Signals {
    /// Measured position of the time the force was measured, m.
    pub x: f64,
    /// Measured force, N.
    pub f: f64,
    /// Conditioned force, N.
    pub ff: f64,
    /// Conditioned position, m.
    pub xf: f64,
    /// Velocity of the conditioned position, m/s.
    pub v_x: f64,
    /// Velocity of the raw position, m/s.
    pub v_raw: f64,
}

/// Force and position conditioning with the velocities derived from them.
#[derive(Clone, Debug, PartialEq)]
pub struct Conditioner {
    p: ConditioningParams,
    force: SignalFilter,
    position: SignalFilter,
    xf_prev: Option<f64>,
    x_prev: Option<f64>,
    past: Past,
}

/// The positions of the last steps and the steps' durations, a ring with the latest at `head`.
#[derive(Clone, Debug, PartialEq)]
struct Past {
    x: [f64; SENSOR_DELAY_STEPS],
    dt: [f64; SENSOR_DELAY_STEPS],
    head: usize,
    len: usize,
}

impl Default for Past {
    fn default() -> Self {
        Self {
            x: [0.0; SENSOR_DELAY_STEPS],
            dt: [0.0; SENSOR_DELAY_STEPS],
            head: 0,
            len: 0,
        }
    }
}

impl Past {
    /// Remember position `x` (m) reached after a step of `dt` (s); the position `delay` (s) before it,
    /// interpolated between the positions remembered (the oldest, further back).
    fn pair(&mut self, x: f64, dt: f64, delay: f64) -> f64 {
        // The ring's length.
        const N: usize = SENSOR_DELAY_STEPS;
        self.head = (self.head + 1) % N;
        self.x[self.head] = x;
        self.dt[self.head] = dt;
        self.len = (self.len + 1).min(N);
        // The slot `i` steps back.
        let back_by = |i: usize| (self.head + N - i) % N;
        let mut back = delay;
        for i in 0..self.len - 1 {
            let (k, before) = (back_by(i), back_by(i + 1));
            if back <= self.dt[k] {
                return self.x[k] + (self.x[before] - self.x[k]) * (back / self.dt[k]);
            }
            back -= self.dt[k];
        }
        self.x[back_by(self.len - 1)]
    }
}

/// The position is filtered like the force, without the notch (the notch is for the tool's ringing).
fn position_params(p: ConditioningParams) -> ConditioningParams {
    ConditioningParams { notch: None, ..p }
}

impl Conditioner {
    /// Conditioning with `p`, at rest.
    pub fn new(p: ConditioningParams) -> Self {
        Self {
            p,
            force: SignalFilter::new(p),
            position: SignalFilter::new(position_params(p)),
            xf_prev: None,
            x_prev: None,
            past: Past::default(),
        }
    }

    /// Take new parameters, keeping the filters' state.
    pub fn set_params(&mut self, p: ConditioningParams) {
        self.force.set_params(p);
        self.position.set_params(position_params(p));
        self.p = p;
    }

    /// Forget everything.
    pub fn reset(&mut self) {
        self.force.clear();
        self.position.clear();
        self.xf_prev = None;
        self.x_prev = None;
        self.past = Past::default();
    }

    /// Restart the force filter at `f` (a contact is gone: forget the filter's memory of it).
    pub fn reset_force(&mut self, f: f64) {
        self.force.reset_to(f);
    }

    /// Condition one sample: position `x` (m) and force `f` (N) as they arrived after a step of `dt`
    /// (s), the force measured `sensor_delay` (s) before the position.
    pub fn step(&mut self, x: f64, f: f64, dt: f64, sensor_delay: f64) -> Signals {
        let x = if sensor_delay > 0.0 {
            self.past.pair(x, dt, sensor_delay)
        } else {
            x
        };
        let ff = self.force.step(f, dt);
        let xf = self.position.step(x, dt);
        let v_x = self.xf_prev.map_or(0.0, |p| (xf - p) / dt);
        self.xf_prev = Some(xf);
        let v_raw = self.x_prev.map_or(0.0, |p| (x - p) / dt);
        self.x_prev = Some(x);
        Signals {
            x,
            f,
            ff,
            xf,
            v_x,
            v_raw,
        }
    }

    /// The low-pass's cut-off at control period `cycle`, Hz: as configured, at most [`CUTOFF_CAP`] of
    /// the sampling rate (as [`crate::conditioning`] designs it).
    fn cutoff(&self, cycle: f64) -> f64 {
        self.p.cutoff.min(CUTOFF_CAP / cycle)
    }

    /// Low-frequency group delay of the conditioning at control period `cycle`, s.
    pub fn delay(&self, cycle: f64) -> f64 {
        core::f64::consts::SQRT_2 / (core::f64::consts::TAU * self.cutoff(cycle))
    }

    /// How much of white noise's standard deviation passes the conditioning at control period
    /// `cycle`: `√(2·B·cycle)`, `B = NOISE_BANDWIDTH·f_c` the second-order low-pass's noise bandwidth.
    pub fn noise_gain(&self, cycle: f64) -> f64 {
        let fc = self.cutoff(cycle);
        (2.0 * NOISE_BANDWIDTH * fc * cycle).sqrt().min(1.0)
    }

    /// How long a step takes to pass the conditioning, s: about two of its low-pass time constants
    /// beyond the group delay, and the cycle the step arrives in (31 ms at 20 Hz on a 1 ms cycle; on
    /// a 12 ms cycle a step still passes when 30 ms of steps have counted). Innovations that last this
    /// long are no longer a jump.
    pub fn step_time(&self, cycle: f64) -> f64 {
        STEP_TIME_PERIODS / self.cutoff(cycle) + cycle
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn velocities_start_at_rest_and_follow_a_ramp() {
        let mut c = Conditioner::new(ConditioningParams {
            cutoff: 20.0,
            notch: None,
        });
        let s = c.step(0.01, 0.0, 1e-3, 0.0);
        assert_eq!((s.v_x, s.v_raw), (0.0, 0.0));
        let mut last = s;
        for i in 1..500 {
            last = c.step(0.01 + 0.002 * i as f64 * 1e-3, 0.0, 1e-3, 0.0);
        }
        assert!((last.v_raw - 0.002).abs() < 1e-12);
        assert!((last.v_x - 0.002).abs() < 1e-6, "{}", last.v_x);
        c.reset();
        assert_eq!(c.step(0.5, 0.0, 1e-3, 0.0).v_raw, 0.0);
    }

    /// A force measured 2.5 ms before it arrives is paired with the position of that time: on a
    /// 2 mm/s ramp read every millisecond, 5 µm behind the latest; before 2.5 ms have passed, with the
    /// oldest position there is; the raw velocity is the paired position's.
    #[test]
    fn a_late_force_is_paired_with_the_position_of_its_time() {
        let mut c = Conditioner::new(ConditioningParams {
            cutoff: 20.0,
            notch: None,
        });
        let x = |i: u32| 0.01 + 0.002 * f64::from(i) * 1e-3;
        assert_eq!(c.step(x(0), 0.0, 1e-3, 0.0025).x, x(0));
        assert_eq!(c.step(x(1), 0.0, 1e-3, 0.0025).x, x(0));
        for i in 2..200 {
            let s = c.step(x(i), 0.0, 1e-3, 0.0025);
            if i >= 3 {
                assert!((s.x - (x(i) - 5e-6)).abs() < 1e-15, "{i}: {}", s.x);
                if i >= 4 {
                    assert!((s.v_raw - 0.002).abs() < 1e-9, "{}", s.v_raw);
                }
            }
        }
        // Never further back than the steps remembered.
        let far = c.step(x(200), 0.0, 1e-3, 1.0).x;
        assert_eq!(far, x(200 - SENSOR_DELAY_STEPS as u32 + 1));
    }

    #[test]
    fn delays_derive_from_the_cutoff() {
        let c = Conditioner::new(ConditioningParams {
            cutoff: 20.0,
            notch: None,
        });
        assert!((c.step_time(1e-3) - 0.031).abs() < 1e-12);
        assert!((c.delay(1e-3) - 0.011_254).abs() < 1e-5);
        // Capped at a fraction of the sampling rate on a slow cell.
        assert!(c.step_time(0.05) > c.step_time(1e-3));
    }
}
