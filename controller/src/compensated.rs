//! Gravity compensation inside the control loop, without changing the loop: an [`OrientationTap`] around the
//! robot link notes the tool orientation of every cycle, and a [`CompensatedSensor`] around the force sensor
//! subtracts the tool's weight for that orientation. The two share one cell; the loop calls the robot first
//! (one cycle in) and the sensor second, so the sensor always sees the orientation of the current cycle.
//!
//! Age is counted in robot time: a cycle whose pose is not finite leaves the last good orientation in place,
//! one period older; past the compensator's `max_age` the sensor answers [`ErrorKind::Stale`] and the loop
//! holds.

use core::cell::Cell;
use core::fmt;
use std::rc::Rc;

use hal::{
    Correction, Cycle, Error as HalError, ErrorKind, ForceSensor, RobotLink, Sample, Wrench,
};

use crate::gravity::{Compensator, GravityError, Orientation};

/// The orientation shared by a tap and a compensated sensor.
pub type SharedOrientation = Rc<Cell<Option<Orientation>>>;

/// A new, empty shared orientation.
pub fn shared_orientation() -> SharedOrientation {
    Rc::new(Cell::new(None))
}

/// A robot link that records each cycle's measured tool orientation.
pub struct OrientationTap<R> {
    inner: R,
    shared: SharedOrientation,
}

impl<R> OrientationTap<R> {
    /// Tap `inner`, writing into `shared`.
    pub fn new(inner: R, shared: SharedOrientation) -> Self {
        Self { inner, shared }
    }

    /// The wrapped link.
    pub fn inner(&self) -> &R {
        &self.inner
    }

    /// The wrapped link, mutably.
    pub fn inner_mut(&mut self) -> &mut R {
        &mut self.inner
    }
}

impl<R: RobotLink> RobotLink for OrientationTap<R> {
    type Error = R::Error;

    fn next_cycle(&mut self) -> Result<Cycle, R::Error> {
        let c = self.inner.next_cycle()?;
        let q = c.actual.orientation;
        let next = if q.coords.iter().all(|v| v.is_finite()) {
            Some(Orientation {
                rotation: q,
                age: 0.0,
            })
        } else {
            self.shared.get().map(|o| Orientation {
                age: o.age + c.period,
                ..o
            })
        };
        self.shared.set(next);
        Ok(c)
    }

    fn reply(&mut self, correction: &Correction) -> Result<(), R::Error> {
        self.inner.reply(correction)
    }
}

/// Why a compensated sample is missing.
#[derive(Debug)]
pub enum CompensatedError<E> {
    /// The sensor's own error.
    Sensor(E),
    /// No usable orientation (missing, stale, non-finite): the tool's weight cannot be removed.
    Gravity(GravityError),
}

impl<E: fmt::Display> fmt::Display for CompensatedError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Sensor(e) => e.fmt(f),
            Self::Gravity(e) => write!(f, "gravity compensation: {e}"),
        }
    }
}

impl<E: HalError> HalError for CompensatedError<E> {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Sensor(e) => e.kind(),
            Self::Gravity(_) => ErrorKind::Stale,
        }
    }
}

impl<E: fmt::Debug + fmt::Display> std::error::Error for CompensatedError<E> {}

/// A force sensor whose samples have the tool's weight and the sensor bias removed.
pub struct CompensatedSensor<S> {
    inner: S,
    compensator: Compensator,
    shared: SharedOrientation,
    last_raw: Option<Wrench>,
}

impl<S> CompensatedSensor<S> {
    /// Compensate `inner` with `compensator`, reading the orientation from `shared`.
    pub fn new(inner: S, compensator: Compensator, shared: SharedOrientation) -> Self {
        Self {
            inner,
            compensator,
            shared,
            last_raw: None,
        }
    }

    /// The uncompensated wrench of the last sample read (for recordings: raw beside compensated).
    pub fn last_raw(&self) -> Option<Wrench> {
        self.last_raw
    }

    /// The wrapped sensor.
    pub fn inner(&self) -> &S {
        &self.inner
    }
}

impl<S: ForceSensor> ForceSensor for CompensatedSensor<S> {
    type Error = CompensatedError<S::Error>;

    fn read(&mut self) -> Result<Sample, Self::Error> {
        let s = self.inner.read().map_err(CompensatedError::Sensor)?;
        self.last_raw = Some(s.wrench);
        let wrench = self
            .compensator
            .compensate(&s.wrench, self.shared.get())
            .map_err(CompensatedError::Gravity)?;
        Ok(Sample { wrench, ..s })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gravity::GravityModel;
    use hal::mock::{MockRobot, MockSensor};
    use hal::{Pose, UnitQuaternion, Vector3, Wrench};
    use std::time::Duration;

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
            new_session: false,
            process: None,
        }
    }

    #[test]
    fn weight_and_bias_are_removed_for_the_cycle_orientation() {
        let shared = shared_orientation();
        let comp = tool();
        let level = UnitQuaternion::identity();
        let mut robot = MockRobot::new();
        robot
            .expect_next_cycle()
            .returning(move || Ok(cycle(level)));
        let mut sensor = MockSensor::new();
        // What the sensor reads with the tool hanging still: its weight plus the bias, plus 5 N of contact.
        let mut hanging = comp.model.tool_wrench(&level);
        hanging.force += comp.model.force_bias;
        sensor.expect_read().returning(move || {
            let mut w = hanging;
            w.force.z += 5.0;
            Ok(Sample {
                wrench: w,
                seq: 1,
                age: Duration::ZERO,
            })
        });
        let mut tap = OrientationTap::new(robot, shared.clone());
        let mut s = CompensatedSensor::new(sensor, comp, shared);
        tap.next_cycle().unwrap();
        let w = s.read().unwrap().wrench;
        assert!((w.force.z - 5.0).abs() < 1e-9, "{w:?}");
        assert!(w.force.x.abs() < 1e-9 && w.force.y.abs() < 1e-9, "{w:?}");
    }

    #[test]
    fn missing_or_stale_orientation_is_a_transient_stale_error() {
        let shared = shared_orientation();
        let mut sensor = MockSensor::new();
        sensor.expect_read().returning(|| {
            Ok(Sample {
                wrench: Wrench::default(),
                seq: 1,
                age: Duration::ZERO,
            })
        });
        let mut s = CompensatedSensor::new(sensor, tool(), shared.clone());
        let e = s.read().unwrap_err();
        assert_eq!(e.kind(), ErrorKind::Stale);
        assert!(e.kind().is_transient());
        assert!(e.to_string().contains("gravity"), "{e}");

        // A good cycle, then non-finite poses: the orientation ages by a period each cycle until stale.
        let mut robot = MockRobot::new();
        let mut n = 0;
        robot.expect_next_cycle().returning(move || {
            n += 1;
            let q = if n == 1 {
                UnitQuaternion::identity()
            } else {
                UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(f64::NAN, 0.0, 0.0, 0.0))
            };
            Ok(cycle(q))
        });
        let mut tap = OrientationTap::new(robot, shared);
        tap.next_cycle().unwrap();
        assert!(s.read().is_ok());
        tap.next_cycle().unwrap();
        tap.next_cycle().unwrap();
        assert!(s.read().is_ok(), "8 ms old is within 10 ms");
        tap.next_cycle().unwrap();
        assert_eq!(s.read().unwrap_err().kind(), ErrorKind::Stale, "12 ms old");
    }

    #[test]
    fn sensor_errors_keep_their_kind() {
        let mut sensor = MockSensor::new();
        sensor.expect_read().returning(|| Err(ErrorKind::BusOff));
        let mut s = CompensatedSensor::new(sensor, tool(), shared_orientation());
        assert_eq!(s.read().unwrap_err().kind(), ErrorKind::BusOff);
    }
}
