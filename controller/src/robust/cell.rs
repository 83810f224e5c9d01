//! The cell's inner loop as the law models it: the robot's interface cycle, the first-order lag of its
//! position loop and its pure delay — properties of the cell (configured from the robot's interface, or
//! the cycle measured from the robot's own timestamps), not numbers fitted to one plant.
//!
//! The control step `dt` is *not* the cycle: a held or skipped cycle gives a `dt` of two or more cycles,
//! and the inner loop's delay does not grow with it.

use serde::{Deserialize, Serialize};

use super::non_negative;

/// The inner loop `P(s) = e^{−sT_d}/(τs + 1)` of the robot and its interface.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CellParams {
    /// The robot interface's cycle, s; 0: measured from the steps' `dt` (see [`CycleMeter`]).
    #[serde(default)]
    pub cycle: f64,
    /// First-order lag `τ` of the robot's position loop, s (inverted by the feed-forward).
    pub lag: f64,
    /// Pure delay `T_d` of the inner loop and the interface, s, from the command sent to the position
    /// moving (e.g. RSI: the delay cycles times the `#IPO` cycle).
    pub delay: f64,
    /// How much older the force sample is than the position it comes with, s: the sensor's own
    /// filter (a second-order Butterworth at `f_c` delays by `√2/(2π·f_c)`: 2.25 ms at 100 Hz) and
    /// its transport. The law pairs each force with the position of that time (interpolated in the
    /// positions it was given, at most [`SENSOR_DELAY_STEPS`] steps back). 0: simultaneous.
    #[serde(default)]
    pub sensor_delay: f64,
}

/// The most steps back the position paired with a force is looked up.
pub const SENSOR_DELAY_STEPS: usize = 128;

impl Default for CellParams {
    /// KUKA RSI at 1 kHz (`P1`): 10 ms lag, 4 ms delay, cycle measured.
    fn default() -> Self {
        Self {
            cycle: 0.0,
            lag: 0.010,
            delay: 0.004,
            sensor_delay: 0.0,
        }
    }
}

impl CellParams {
    /// The loop's pure delay, s: from a command sent to the force it causes reaching the law, the
    /// robot's `delay` and the sensor's `sensor_delay` (the law pairs each force with the position of
    /// its time, and that pair is this old).
    pub fn loop_delay(&self) -> f64 {
        self.delay + self.sensor_delay
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        non_negative("cell.cycle", self.cycle)?;
        non_negative("cell.lag", self.lag)?;
        non_negative("cell.delay", self.delay)?;
        non_negative("cell.sensor_delay", self.sensor_delay)?;
        if self.sensor_delay > 0.1 {
            return Err(format!(
                "cell.sensor_delay {} s is not a force sensor's (at most 0.1 s)",
                self.sensor_delay
            ));
        }
        if self.cycle > 1.0 || self.lag > 10.0 || self.delay > 10.0 {
            return Err(format!(
                "cell: cycle {} s, lag {} s, delay {} s are not a robot's inner loop (at most 1 s, 10 s, 10 s)",
                self.cycle, self.lag, self.delay
            ));
        }
        Ok(())
    }
}

/// The robot interface's cycle: configured, or measured from the steps' `dt` as the running level of
/// the ordinary steps (a step longer than 1.5 cycles is a held or skipped cycle and is not counted).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CycleMeter {
    configured: f64,
    cycle: f64,
}

/// Steps over which the measured cycle follows a change of the interface's cycle.
const CYCLE_STEPS: f64 = 20.0;

/// The longest step, in measured cycles, that still counts towards the cycle: halfway between one
/// cycle and two. A longer step is a held or skipped cycle (two or more), which the interface's cycle
/// does not become.
const HELD_CYCLE: f64 = 1.5;

impl CycleMeter {
    /// A meter for `p` (nothing measured yet).
    pub fn new(p: &CellParams) -> Self {
        Self {
            configured: p.cycle,
            cycle: p.cycle,
        }
    }

    /// Forget what was measured (a configured cycle stays).
    pub fn reset(&mut self) {
        self.cycle = self.configured;
    }

    /// Take a new configuration (what was measured stays when the cycle is still measured).
    pub fn set_params(&mut self, p: &CellParams) {
        if p.cycle > 0.0 || self.configured > 0.0 {
            self.cycle = p.cycle;
        }
        self.configured = p.cycle;
    }

    /// Count one step of `dt` and return the cycle, s.
    pub fn step(&mut self, dt: f64) -> f64 {
        if self.configured > 0.0 {
            return self.configured;
        }
        if self.cycle <= 0.0 || dt < self.cycle {
            // The first step, or a shorter one: the cycle is at most this.
            self.cycle = if self.cycle <= 0.0 {
                dt
            } else {
                self.cycle + (dt - self.cycle) / CYCLE_STEPS.sqrt()
            };
        } else if dt <= HELD_CYCLE * self.cycle {
            self.cycle += (dt - self.cycle) / CYCLE_STEPS;
        }
        self.cycle
    }

    /// The cycle, s (0 before the first step when measured).
    pub fn cycle(&self) -> f64 {
        self.cycle
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_configured_cycle_is_the_cycle_whatever_the_steps() {
        let mut m = CycleMeter::new(&CellParams {
            cycle: 0.004,
            ..CellParams::default()
        });
        assert_eq!(m.step(0.008), 0.004);
        assert_eq!(m.step(0.001), 0.004);
    }

    #[test]
    fn a_measured_cycle_ignores_held_cycles_and_follows_a_new_cycle() {
        let mut m = CycleMeter::new(&CellParams::default());
        assert_eq!(m.step(0.004), 0.004);
        for i in 0..200 {
            // Every tenth cycle is held: the next step is two cycles long.
            m.step(if i % 10 == 9 { 0.008 } else { 0.004 });
        }
        assert!((m.cycle() - 0.004).abs() < 1e-12, "{}", m.cycle());
        for _ in 0..200 {
            m.step(0.012);
        }
        assert!(
            (m.cycle() - 0.004).abs() < 1e-12,
            "3× longer: held, not a new cycle"
        );
        for _ in 0..200 {
            m.step(0.001);
        }
        assert!((m.cycle() - 0.001).abs() < 1e-6, "{}", m.cycle());
        m.reset();
        assert_eq!(m.cycle(), 0.0);
    }

    #[test]
    fn a_cell_is_validated() {
        let p = CellParams {
            cycle: 0.012,
            lag: 0.010,
            delay: 0.024,
            sensor_delay: 0.00225,
        };
        assert!(p.validate().is_ok());
        assert!((p.loop_delay() - 0.02625).abs() < 1e-15);
        assert!(
            CellParams { delay: -1.0, ..p }
                .validate()
                .unwrap_err()
                .contains("cell.delay")
        );
        for sensor_delay in [-1e-3, 0.5, f64::NAN] {
            assert!(
                CellParams { sensor_delay, ..p }
                    .validate()
                    .unwrap_err()
                    .contains("cell.sensor_delay")
            );
        }
    }
}
