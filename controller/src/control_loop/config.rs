//! The loop's configuration: how it maps devices onto the 1-DOF law and what it refuses to command.

use serde::{Deserialize, Serialize};

use super::process::{Process, ProcessConfig};

/// The rate at which a rotation the law commanded (orientation following) returns to zero after an
/// early end, and while the process moves the command to a target (a RELEASE's lift, OFF, a
/// fault's back-off), rad/s.
pub const RETURN_TURN_RATE: f64 = 0.2;

/// How the loop maps devices onto the 1-DOF law and what it refuses to command.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopConfig {
    /// Multiplies the sensor's `F_z` to give the compressive normal force the law expects
    /// (`+1` when pressing reads positive, `−1` for the usual sensor convention where it reads negative).
    pub force_sign: f64,
    /// Largest change of the commanded normal position from one cycle to the next, m. A larger change
    /// is limited to this and reported as [`Fault::StepLimited`](super::Fault::StepLimited).
    pub max_step: f64,
    /// Largest magnitude of the commanded normal offset from the programmed path, m; beyond it the
    /// command is limited and reported as [`Fault::EnvelopeLimited`](super::Fault::EnvelopeLimited).
    pub max_offset: f64,
    /// Longest robot time, s, the loop may hold its last command without a usable sample or pose (a
    /// silent, saturated or failing sensor). Beyond it the loop retracts and ends with
    /// [`LoopError::HoldTimeout`](super::LoopError::HoldTimeout): it never presses blind for longer than this.
    pub max_hold: f64,
    /// How far, m, the tool backs off along −z from its last command when the loop ends on a fault
    /// (hold timeout, failed sensor), before the loop reports the fault.
    pub retract_distance: f64,
    /// Speed of that back-off, m/s (never faster than `max_step` per cycle).
    pub retract_speed: f64,
    /// The force process the robot program commands, on links that carry process channels.
    pub process: ProcessConfig,
}

impl Default for LoopConfig {
    fn default() -> Self {
        Self {
            force_sign: 1.0,
            max_step: 1e-3,
            max_offset: 0.005,
            max_hold: 0.1,
            retract_distance: 0.002,
            retract_speed: 0.02,
            process: ProcessConfig::default(),
        }
    }
}

impl LoopConfig {
    /// How far a back-off, a lift or a return moves the command in one cycle of `period` (s): at
    /// `retract_speed`, within `max_step`, m.
    pub(super) fn retract_step(&self, period: f64) -> f64 {
        (self.retract_speed * period).min(self.max_step)
    }

    /// How many cycles of `period` (s) the return to the programmed path takes at `retract_speed`
    /// from the normal command `z` (m, towards the part) and the off-normal correction `side`: the
    /// longest of the translations' returns, and of the rotation's at [`RETURN_TURN_RATE`] (at least
    /// one cycle while anything is off the path).
    pub(super) fn return_cycles(&self, z: f64, side: &hal::Correction, period: f64) -> f64 {
        let step = self.retract_step(period);
        let far = z
            .max(side.translation.x.abs())
            .max(side.translation.y.abs());
        let turn = side.rotation.norm() / (RETURN_TURN_RATE * period);
        (far / step).max(turn).ceil()
    }

    /// A process at OFF whose faults back off `retract_distance`, within the envelope.
    pub(super) fn new_process(&self) -> Process {
        Process::new(self.process, self.retract_distance, -self.max_offset)
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        if self.force_sign != 1.0 && self.force_sign != -1.0 {
            return Err(format!(
                "force_sign must be 1 or -1, got {}",
                self.force_sign
            ));
        }
        if !(self.max_step.is_finite() && self.max_step > 0.0) {
            return Err(format!("max_step must be > 0 m, got {}", self.max_step));
        }
        if !(self.max_offset.is_finite() && self.max_offset > 0.0) {
            return Err(format!("max_offset must be > 0 m, got {}", self.max_offset));
        }
        // A hold is pressing blind: beyond a second no force controller should keep a tool there.
        if !(self.max_hold > 0.0 && self.max_hold <= 1.0) {
            return Err(format!(
                "max_hold must be > 0 and ≤ 1 s (holding the last command is pressing blind), got {}",
                self.max_hold
            ));
        }
        if !(self.retract_distance > 0.0 && self.retract_distance <= 0.05) {
            return Err(format!(
                "retract_distance must be > 0 and ≤ 0.05 m, got {}",
                self.retract_distance
            ));
        }
        if !(self.retract_speed > 0.0 && self.retract_speed <= 0.5) {
            return Err(format!(
                "retract_speed must be > 0 and ≤ 0.5 m/s, got {}",
                self.retract_speed
            ));
        }
        self.process.validate()
    }
}
