//! Gravity compensation as a stage of the control loop: each cycle, [`Gravity::observe`] takes the
//! tool orientation from the robot's cycle, and [`Gravity::apply`] removes the tool's weight and the
//! sensor bias for that orientation from the raw wrench. The loop owns the stage
//! ([`ControlLoop::with_gravity`](crate::ControlLoop::with_gravity)); nothing is shared between the
//! robot link and the sensor.
//!
//! Age is counted in robot time: a cycle whose orientation is not finite leaves the last good one in
//! place, one period older; past the compensator's `max_age` the wrench cannot be compensated, and the
//! loop holds as it does for a stale sample ([`hal::ErrorKind::Stale`]).

use hal::{Cycle, Wrench};

use crate::gravity::{Compensator, GravityError, Orientation};

/// The gravity-compensation stage: the compensator and the orientation of the current cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gravity {
    compensator: Compensator,
    orientation: Option<Orientation>,
}

impl Gravity {
    /// A stage that has seen no cycle yet.
    pub fn new(compensator: Compensator) -> Self {
        Self {
            compensator,
            orientation: None,
        }
    }

    /// Take the cycle's measured tool orientation (or age the last good one by a period).
    pub fn observe(&mut self, cycle: &Cycle) {
        let q = cycle.actual.orientation;
        self.orientation = if q.coords.iter().all(|v| v.is_finite()) {
            Some(Orientation {
                rotation: q,
                age: 0.0,
            })
        } else {
            self.orientation.map(|o| Orientation {
                age: o.age + cycle.period,
                ..o
            })
        };
    }

    /// The contact wrench for the orientation last observed, or why it cannot be computed.
    pub fn apply(&self, raw: &Wrench) -> Result<Wrench, GravityError> {
        self.compensator.compensate(raw, self.orientation)
    }

    /// Forget the orientation (a new robot session).
    pub fn reset(&mut self) {
        self.orientation = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gravity::GravityModel;
    use hal::{Pose, UnitQuaternion, Vector3};

    fn tool() -> Compensator {
        Compensator {
            model: GravityModel {
                signed_mass: 2.0,
                mass_moment: Vector3::zeros(),
                force_bias: Vector3::new(0.5, 0.0, 0.0),
                torque_bias: Vector3::zeros(),
            },
            mount: UnitQuaternion::identity(),
            max_age: 0.01,
        }
    }

    fn cycle(q: UnitQuaternion<f64>) -> Cycle {
        Cycle {
            seq: 1,
            t: 0.0,
            period: 0.004,
            actual: Pose {
                position: Vector3::zeros(),
                orientation: q,
            },
            programmed: Pose::identity(),
            late_replies: 0,
            missed: 0,
            replied_late: 0,
            new_session: false,
            process: None,
        }
    }

    #[test]
    fn weight_and_bias_are_removed_for_the_cycle_orientation() {
        let comp = tool();
        let level = UnitQuaternion::identity();
        let mut g = Gravity::new(comp);
        // What the sensor reads with the tool hanging still: its weight plus the bias, plus 5 N of contact.
        let mut w = comp.model.tool_wrench(&level);
        w.force += comp.model.force_bias;
        w.force.z += 5.0;
        g.observe(&cycle(level));
        let c = g.apply(&w).unwrap();
        assert!((c.force.z - 5.0).abs() < 1e-9, "{c:?}");
        assert!(c.force.x.abs() < 1e-9 && c.force.y.abs() < 1e-9, "{c:?}");
    }

    #[test]
    fn missing_or_stale_orientation_cannot_be_compensated() {
        let mut g = Gravity::new(tool());
        let w = Wrench::default();
        assert_eq!(g.apply(&w), Err(GravityError::OrientationMissing));
        // A good cycle, then non-finite poses: the orientation ages by a period each cycle until stale.
        g.observe(&cycle(UnitQuaternion::identity()));
        assert!(g.apply(&w).is_ok());
        let bad = UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0));
        g.observe(&cycle(bad));
        g.observe(&cycle(bad));
        assert!(g.apply(&w).is_ok(), "8 ms old is within 10 ms");
        g.observe(&cycle(bad));
        assert!(
            matches!(g.apply(&w), Err(GravityError::OrientationStale { .. })),
            "12 ms old"
        );
        g.reset();
        assert_eq!(g.apply(&w), Err(GravityError::OrientationMissing));
    }
}
