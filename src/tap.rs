//! Recording for loops that are not the [`controller::ControlLoop`] — `forcecell calibrate`, whose
//! collector drives the robot and the sensor itself: a robot link that remembers each cycle and a
//! sensor that hands each sample, with that cycle, to the recorder. Same queue, same channels; no
//! set-point while calibrating (`f_r` 0, the command is the zero correction).

use std::cell::Cell;
use std::rc::Rc;

use hal::{Correction, Cycle, ForceSensor, RobotLink, Sample};

use crate::record::Row;
use crate::recorder::{Record, Recorder};

/// A robot link that shares each cycle it receives with a [`TapSensor`].
pub struct TapRobot<R> {
    inner: R,
    last: Rc<Cell<Option<Cycle>>>,
}

/// A sensor that records each sample with the robot's latest cycle.
pub struct TapSensor<S> {
    inner: S,
    last: Rc<Cell<Option<Cycle>>>,
    recorder: Recorder,
}

/// Tap `robot` and `sensor`, recording to `recorder`.
pub fn tap<R, S>(robot: R, sensor: S, recorder: Recorder) -> (TapRobot<R>, TapSensor<S>) {
    let last = Rc::new(Cell::new(None));
    (
        TapRobot {
            inner: robot,
            last: last.clone(),
        },
        TapSensor {
            inner: sensor,
            last,
            recorder,
        },
    )
}

impl<R: RobotLink> RobotLink for TapRobot<R> {
    type Error = R::Error;

    fn next_cycle(&mut self) -> Result<Cycle, Self::Error> {
        let c = self.inner.next_cycle()?;
        self.last.set(Some(c));
        Ok(c)
    }

    fn reply(&mut self, correction: &Correction) -> Result<(), Self::Error> {
        self.inner.reply(correction)
    }
}

impl<S: ForceSensor> ForceSensor for TapSensor<S> {
    type Error = S::Error;

    fn read(&mut self) -> Result<Sample, Self::Error> {
        let s = self.inner.read()?;
        if let Some(c) = self.last.get() {
            let x = c.tool_offset().z;
            let mut rec = Record::from_row(
                Row {
                    t: c.t,
                    f: s.wrench.force.z,
                    f_true: f64::NAN,
                    f_r: 0.0,
                    x,
                    x_cmd: 0.0,
                    x_r: f64::NAN,
                    kc_hat: f64::NAN,
                    xc_hat: f64::NAN,
                    k_c: f64::NAN,
                    x_c: f64::NAN,
                    condition: 0,
                    ..Row::default()
                }
                .no_process(),
            );
            rec.wrench = s.wrench.to_array();
            rec.sensor_seq = s.seq;
            rec.sensor_age = s.age.as_secs_f64();
            rec.robot_seq = c.seq;
            rec.period = c.period;
            rec.late_replies = u64::from(c.late_replies);
            self.recorder.push(rec);
        }
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recorder::{Full, queue};
    use crate::rig::Spring;

    #[test]
    fn each_sample_is_recorded_with_the_cycle_it_belongs_to() {
        let spring = Spring::new(1_000.0, 0.0, 0.002, 1.0);
        let (robot, sensor) = spring.devices(0.004);
        let (tx, mut rx) = queue(16, Full::Drop);
        let (mut robot, mut sensor) = tap(robot, sensor, tx);
        for _ in 0..3 {
            let c = robot.next_cycle().unwrap();
            let s = sensor.read().unwrap();
            robot.reply(&Correction::along_z(0.0)).unwrap();
            let rec = rx.pop().unwrap();
            assert_eq!(rec.robot_seq, c.seq);
            assert_eq!(rec.row.t, c.t);
            assert_eq!(rec.wrench, s.wrench.to_array());
            assert_eq!(rec.row.f, s.wrench.force.z);
            assert_eq!(rec.row.f_r, 0.0);
        }
        assert!(rx.pop().is_err(), "one record per sample");
    }
}
