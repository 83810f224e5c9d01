//! Real surface motion, told from the apparent motion of a stale `k̂_c` (which is tied to the robot's):
//! * the motion test ([`surface_moving`]) on the predictor's velocity and the robot's raw velocity,
//!   passed without a break for `motion_confirm` (a stale `k̂_c` passes it briefly where the robot turns);
//! * a run of surface velocity that keeps its sign while the robot has moved both with it and against
//!   it for `opposed_confirm` each (a stale `k̂_c`'s turns when the robot turns).
//!
//! Either holds the feed-forward on for `motion_hold` (a curved surface passes through zero velocity
//! at every turn); the second also holds the estimator off the moving surface.

use super::observer::ObserverParams;
use crate::estimator::surface_moving;

/// The fewest samples a surface motion is confirmed on, whatever the cycle.
const MIN_SAMPLES: f64 = 2.0;

/// The motion tests' state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Motion {
    /// Time left during which the surface counts as moving (feed-forward on), s.
    hold: f64,
    /// How long the predictor has seen surface motion without a break, s.
    time: f64,
    /// Sign of the current run of surface velocity (0: none), and how long within it the robot moved
    /// with it and against it, s.
    run_sign: f64,
    run_with: f64,
    run_against: f64,
    /// Time left during which the estimator takes the surface for a moving one, s.
    est_hold: f64,
}

impl Motion {
    /// Forget everything.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// A new contact or a new `k̂_c`: the runs start over, the holds run on.
    pub fn restart(&mut self) {
        self.time = 0.0;
        self.run_sign = 0.0;
    }

    /// Whether no motion is established.
    pub fn still(&self) -> bool {
        self.hold <= 0.0 && self.est_hold <= 0.0
    }

    /// Whether the feed-forward may act.
    pub fn established(&self) -> bool {
        self.hold > 0.0
    }

    /// Run the holds for a step; `seen`: the conditioned motion test passed in contact. Returns
    /// whether the estimator is to take the surface for a moving one.
    pub fn hold(&mut self, p: &ObserverParams, seen: bool, dt: f64) -> bool {
        self.hold = if seen {
            p.motion_hold
        } else {
            (self.hold - dt).max(0.0)
        };
        self.est_hold = (self.est_hold - dt).max(0.0);
        self.est_hold > 0.0
    }

    /// Test the predictor's surface velocity `v` against the robot's raw velocity `v_raw` (m/s), with
    /// `thr` the speed below which a surface counts as still.
    pub fn observe(&mut self, p: &ObserverParams, v: f64, v_raw: f64, thr: f64, dt: f64) {
        // Confirmed over `motion_confirm`, and never on fewer than `MIN_SAMPLES` samples: on a slow
        // cycle one noisy sample would otherwise be a motion (half a cycle of margin for the sum's
        // rounding).
        let confirm = p.motion_confirm.max((MIN_SAMPLES - 0.5) * dt);
        if surface_moving(v, v_raw, thr) {
            self.time += dt;
            if self.time >= confirm {
                self.hold = p.motion_hold;
            }
        } else {
            self.time = 0.0;
        }
        if v.abs() > thr {
            if v.signum() != self.run_sign {
                self.run_sign = v.signum();
                self.run_with = 0.0;
                self.run_against = 0.0;
            }
            if v_raw.abs() > thr {
                if v_raw * v > 0.0 {
                    self.run_with += dt;
                } else {
                    self.run_against += dt;
                }
            }
            let opposed = p.opposed_confirm.max((MIN_SAMPLES - 0.5) * dt);
            if self.run_with >= opposed && self.run_against >= opposed {
                self.est_hold = p.motion_hold;
                self.hold = p.motion_hold;
            }
        } else {
            self.run_sign = 0.0;
        }
    }
}

/// The speed above which the surface counts as moving, m/s: `max_surface_speed`, and never within
/// `motion_significance` standard deviations `v_std` (m/s) of what the sensor's noise makes of a still
/// surface's velocity (on a slow cell on a soft surface the noise alone shows a millimetre a second).
pub fn threshold(max_surface_speed: f64, p: &ObserverParams, v_std: f64) -> f64 {
    max_surface_speed.max(p.motion_significance * v_std)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motion_with_the_robot_at_rest_is_real_and_held() {
        let p = ObserverParams::default();
        let mut m = Motion::default();
        for _ in 0..20 {
            m.observe(&p, 0.005, 0.0, 0.001, 1e-3);
        }
        assert!(m.established() && !m.still());
        // Held through a turn, then released.
        for _ in 0..400 {
            m.hold(&p, false, 1e-3);
        }
        assert!(m.established());
        for _ in 0..200 {
            m.hold(&p, false, 1e-3);
        }
        assert!(m.still());
    }

    #[test]
    fn velocity_that_keeps_its_sign_while_the_robot_turns_holds_the_estimator_off() {
        let p = ObserverParams::default();
        let mut m = Motion::default();
        // The robot moves with the surface, then against it: the surface's own motion.
        for i in 0..40 {
            let v_raw = if i < 20 { 0.01 } else { -0.01 };
            m.observe(&p, 0.003, v_raw, 0.001, 1e-3);
        }
        assert!(m.hold(&p, false, 1e-3), "the estimator is held off");
        m.reset();
        assert!(m.still());
    }
}
