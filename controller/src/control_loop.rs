//! The control loop: one robot cycle in, one newest force sample, one law step, exactly one reply out.
//! Written against the HAL only; every device is a [`RobotLink`] and a [`ForceSensor`].

use core::fmt;

use hal::{Correction, Cycle, Error as _, ErrorKind, ForceSensor, RobotLink, Sample};
use serde::{Deserialize, Serialize};

use crate::law::{ForceLaw, Output};

/// How the loop maps devices onto the 1-DOF law and what it refuses to command.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopConfig {
    /// Multiplies the sensor's `F_z` to give the compressive normal force the law expects
    /// (`+1` when pressing reads positive, `−1` for the usual sensor convention where it reads negative).
    pub force_sign: f64,
    /// Largest change of the commanded normal position from one cycle to the next, m. A larger change
    /// is limited to this and reported as [`Fault::StepLimited`].
    pub max_step: f64,
    /// Largest magnitude of the commanded normal offset from the programmed path, m; beyond it the
    /// command is limited and reported as [`Fault::EnvelopeLimited`].
    pub max_offset: f64,
}

impl Default for LoopConfig {
    fn default() -> Self {
        Self {
            force_sign: 1.0,
            max_step: 1e-3,
            max_offset: 0.005,
        }
    }
}

impl LoopConfig {
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
        Ok(())
    }
}

/// Something that went wrong in one cycle but did not end the loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fault {
    /// The sensor returned an error; the loop held its last command and did not step the law.
    Sensor(ErrorKind),
    /// The sensor returned a non-finite sample; held, no step.
    NonFiniteSample,
    /// The robot reported a non-finite pose; held, no step.
    NonFinitePose,
    /// The law produced a non-finite command; held.
    NonFiniteCommand,
    /// The command moved more than `max_step` in one cycle and was limited.
    StepLimited,
    /// The command left `±max_offset` and was limited.
    EnvelopeLimited,
}

/// Counters of the loop, for diagnostics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LoopStats {
    /// Cycles answered.
    pub cycles: u64,
    /// Cycles held because the sensor returned an error.
    pub sensor_faults: u64,
    /// Cycles held because a sample or pose was not finite.
    pub nonfinite_inputs: u64,
    /// Cycles held because the law produced a non-finite command.
    pub nonfinite_commands: u64,
    /// Commands limited by `max_step` or `max_offset`.
    pub limited: u64,
    /// Transient robot-link errors the loop carried on through.
    pub robot_glitches: u64,
    /// New robot sessions (references captured again).
    pub sessions: u64,
}

/// Everything about one answered cycle, for recording and plotting.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CycleReport {
    /// The cycle as the robot sent it.
    pub cycle: Cycle,
    /// Measured normal position (tool offset from the programmed path along tool z), m.
    pub x: f64,
    /// Measured compressive normal force, N, when the sensor gave a usable sample.
    pub f: Option<f64>,
    /// The sensor's sample as read this cycle (wrench in the sensor frame, its counter and age), when
    /// it gave one, finite or not; for recordings and diagnostics.
    pub sample: Option<Sample>,
    /// The law's output (on a held cycle, the last output).
    pub out: Output,
    /// The correction sent.
    pub command: Correction,
    /// What went wrong in this cycle, if anything.
    pub fault: Option<Fault>,
}

/// Why the loop ended.
#[derive(Debug)]
pub enum LoopError<RE, SE> {
    /// The robot link failed for good (lost, closed, misconfigured).
    Robot(RE),
    /// The sensor failed for good (bus-off, link lost, misconfigured).
    Sensor(SE),
}

impl<RE: fmt::Display, SE: fmt::Display> fmt::Display for LoopError<RE, SE> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Robot(e) => write!(f, "robot link: {e}"),
            Self::Sensor(e) => write!(f, "force sensor: {e}"),
        }
    }
}

impl<RE: fmt::Debug + fmt::Display, SE: fmt::Debug + fmt::Display> std::error::Error
    for LoopError<RE, SE>
{
}

/// The loop: a robot, a sensor and a law.
pub struct ControlLoop<R, S, L> {
    robot: R,
    sensor: S,
    law: L,
    cfg: LoopConfig,
    stats: LoopStats,
    started: bool,
    last_out: Output,
    last_cmd: f64,
}

impl<R: RobotLink, S: ForceSensor, L: ForceLaw> ControlLoop<R, S, L> {
    /// A loop that has not seen its first cycle yet.
    pub fn new(robot: R, sensor: S, law: L, cfg: LoopConfig) -> Self {
        Self {
            robot,
            sensor,
            law,
            cfg,
            stats: LoopStats::default(),
            started: false,
            last_out: Output::default(),
            last_cmd: 0.0,
        }
    }

    /// Counters so far.
    pub fn stats(&self) -> LoopStats {
        self.stats
    }

    /// The law.
    pub fn law(&self) -> &L {
        &self.law
    }

    /// The robot link.
    pub fn robot(&self) -> &R {
        &self.robot
    }

    /// The robot link, mutably (to stop it, read diagnostics).
    pub fn robot_mut(&mut self) -> &mut R {
        &mut self.robot
    }

    /// The sensor.
    pub fn sensor_mut(&mut self) -> &mut S {
        &mut self.sensor
    }

    /// Take the parts back.
    pub fn into_parts(self) -> (R, S, L) {
        (self.robot, self.sensor, self.law)
    }

    /// Run one cycle: wait for the robot, read the newest sample, step the law (or hold), reply once.
    ///
    /// Bad input never reaches the command: on a sensor error, a non-finite sample or pose, the loop
    /// answers with its last command and does not step the law. A robot error that is not transient
    /// ([`ErrorKind::is_transient`]) ends the loop; so does a sensor error of kind `LinkLost`, `BusOff`
    /// or `Config` — after the loop has answered the cycle with its last command.
    pub fn cycle(&mut self) -> Result<CycleReport, LoopError<R::Error, S::Error>> {
        let cycle = loop {
            match self.robot.next_cycle() {
                Ok(c) => break c,
                Err(e) if e.kind().is_transient() => self.stats.robot_glitches += 1,
                Err(e) => return Err(LoopError::Robot(e)),
            }
        };
        let x = cycle.tool_offset().z;
        let pose_ok = cycle.actual.is_finite() && cycle.programmed.is_finite() && x.is_finite();
        if pose_ok && (!self.started || cycle.new_session) {
            if self.started {
                self.stats.sessions += 1;
            }
            self.started = true;
            self.law.start(x);
            self.last_cmd = x;
            self.last_out = Output {
                x_cmd: x,
                ..Output::default()
            };
        }

        let mut fatal_sensor = None;
        let mut sample = None;
        let (f, mut fault) = match self.sensor.read() {
            Ok(s) if s.wrench.is_finite() => {
                sample = Some(s);
                (Some(self.cfg.force_sign * s.wrench.force.z), None)
            }
            Ok(s) => {
                sample = Some(s);
                (None, Some(Fault::NonFiniteSample))
            }
            Err(e) => {
                let kind = e.kind();
                if matches!(
                    kind,
                    ErrorKind::LinkLost | ErrorKind::BusOff | ErrorKind::Config
                ) {
                    fatal_sensor = Some(e);
                }
                (None, Some(Fault::Sensor(kind)))
            }
        };
        if !pose_ok && fault.is_none() {
            fault = Some(Fault::NonFinitePose);
        }

        let mut out = self.last_out;
        let mut cmd = self.last_cmd;
        match (fault, f) {
            (None, Some(f)) if self.started => {
                let o = self.law.step(x, f, cycle.period);
                if o.x_cmd.is_finite() {
                    out = o;
                    cmd = self.limit(o.x_cmd, &mut fault);
                } else {
                    fault = Some(Fault::NonFiniteCommand);
                }
            }
            _ => {}
        }
        match fault {
            Some(Fault::Sensor(_)) => self.stats.sensor_faults += 1,
            Some(Fault::NonFiniteSample | Fault::NonFinitePose) => self.stats.nonfinite_inputs += 1,
            Some(Fault::NonFiniteCommand) => self.stats.nonfinite_commands += 1,
            Some(Fault::StepLimited | Fault::EnvelopeLimited) => self.stats.limited += 1,
            None => {}
        }

        let command = Correction::along_z(cmd);
        self.robot.reply(&command).map_err(LoopError::Robot)?;
        self.stats.cycles += 1;
        self.last_out = out;
        self.last_cmd = cmd;
        if let Some(e) = fatal_sensor {
            return Err(LoopError::Sensor(e));
        }
        Ok(CycleReport {
            cycle,
            x,
            f,
            sample,
            out,
            command,
            fault,
        })
    }

    /// End the robot's correction motion cleanly: wait for the next cycle and answer it with the last
    /// command and `stop` set. Transient robot errors are skipped as in [`cycle`](Self::cycle).
    pub fn stop(&mut self) -> Result<(), LoopError<R::Error, S::Error>> {
        loop {
            match self.robot.next_cycle() {
                Ok(_) => break,
                Err(e) if e.kind().is_transient() => self.stats.robot_glitches += 1,
                Err(e) => return Err(LoopError::Robot(e)),
            }
        }
        let command = Correction {
            stop: true,
            ..Correction::along_z(self.last_cmd)
        };
        self.robot.reply(&command).map_err(LoopError::Robot)?;
        self.stats.cycles += 1;
        Ok(())
    }

    /// Limit a finite command to the step and envelope limits, noting which one acted.
    fn limit(&self, want: f64, fault: &mut Option<Fault>) -> f64 {
        let step = self.cfg.max_step;
        let mut cmd = want.clamp(self.last_cmd - step, self.last_cmd + step);
        if cmd != want {
            *fault = Some(Fault::StepLimited);
        }
        let lim = self.cfg.max_offset;
        if cmd.abs() > lim {
            cmd = cmd.clamp(-lim, lim);
            *fault = Some(Fault::EnvelopeLimited);
        }
        cmd
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::law::ImpedanceLaw;
    use hal::mock::{MockRobot, MockSensor};
    use hal::{Pose, Sample, Vector3, Wrench};
    use mockall::Sequence;
    use std::time::Duration;

    fn cycle_at(seq: u64, x: f64) -> Cycle {
        Cycle {
            seq,
            t: seq as f64 * 0.004,
            period: 0.004,
            actual: Pose::from_position(Vector3::new(0.0, 0.0, x)),
            programmed: Pose::identity(),
            late_replies: 0,
            new_session: false,
        }
    }

    fn sample(fz: f64) -> Sample {
        Sample {
            wrench: Wrench::from_array([0.0, 0.0, fz, 0.0, 0.0, 0.0]),
            seq: 1,
            age: Duration::ZERO,
        }
    }

    fn fixed_law(x_r: f64) -> ImpedanceLaw {
        ImpedanceLaw::new(
            crate::ImpedanceParams::PAPER,
            crate::Reference::Fixed { x_r },
        )
        .unwrap()
    }

    #[test]
    fn calls_are_cycle_then_wrench_then_one_reply() {
        let mut seq = Sequence::new();
        let mut robot = MockRobot::new();
        let mut sensor = MockSensor::new();
        for k in 0..3 {
            robot
                .expect_next_cycle()
                .times(1)
                .in_sequence(&mut seq)
                .returning(move || Ok(cycle_at(k, 0.001)));
            sensor
                .expect_read()
                .times(1)
                .in_sequence(&mut seq)
                .returning(|| Ok(sample(0.0)));
            robot
                .expect_reply()
                .times(1)
                .in_sequence(&mut seq)
                .returning(|_| Ok(()));
        }
        let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.002), LoopConfig::default());
        for _ in 0..3 {
            lp.cycle().unwrap();
        }
        assert_eq!(lp.stats().cycles, 3);
    }

    #[test]
    fn sensor_timeout_holds_without_a_step_and_counts() {
        let mut robot = MockRobot::new();
        let mut sensor = MockSensor::new();
        robot
            .expect_next_cycle()
            .returning(|| Ok(cycle_at(1, 0.001)));
        let mut n = 0;
        sensor.expect_read().returning(move || {
            n += 1;
            if n == 1 {
                Ok(sample(0.0))
            } else {
                Err(ErrorKind::Timeout)
            }
        });
        let replies = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let r2 = replies.clone();
        robot.expect_reply().returning(move |c| {
            r2.lock().unwrap().push(*c);
            Ok(())
        });
        let mut lp = ControlLoop::new(robot, sensor, ImpedanceLaw::paper(), LoopConfig::default());
        let first = lp.cycle().unwrap();
        assert_eq!(first.fault, None);
        let law_before = lp.law().clone();
        let second = lp.cycle().unwrap();
        assert_eq!(second.fault, Some(Fault::Sensor(ErrorKind::Timeout)));
        assert_eq!(lp.stats().sensor_faults, 1);
        assert_eq!(
            lp.law(),
            &law_before,
            "the law must not step on a held cycle"
        );
        let r = replies.lock().unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(r[0], r[1], "a held cycle repeats the last command");
    }

    #[test]
    fn lost_robot_link_ends_the_loop_with_the_error() {
        let mut robot = MockRobot::new();
        let sensor = MockSensor::new();
        robot
            .expect_next_cycle()
            .returning(|| Err(ErrorKind::LinkLost));
        robot.expect_reply().never();
        let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.002), LoopConfig::default());
        match lp.cycle() {
            Err(LoopError::Robot(ErrorKind::LinkLost)) => {}
            other => panic!("expected the robot's LinkLost, got {other:?}"),
        }
        assert!(
            format!("{}", LoopError::<_, ErrorKind>::Robot(ErrorKind::LinkLost))
                .contains("link lost")
        );
    }

    #[test]
    fn transient_robot_errors_are_counted_and_skipped() {
        let mut robot = MockRobot::new();
        let mut sensor = MockSensor::new();
        let mut n = 0;
        robot.expect_next_cycle().returning(move || {
            n += 1;
            if n == 1 {
                Err(ErrorKind::Malformed)
            } else {
                Ok(cycle_at(2, 0.0))
            }
        });
        sensor.expect_read().returning(|| Ok(sample(0.0)));
        robot.expect_reply().times(1).returning(|_| Ok(()));
        let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.0), LoopConfig::default());
        lp.cycle().unwrap();
        assert_eq!(lp.stats().robot_glitches, 1);
    }

    #[test]
    fn nan_wrench_never_reaches_the_command() {
        let mut robot = MockRobot::new();
        let mut sensor = MockSensor::new();
        robot
            .expect_next_cycle()
            .returning(|| Ok(cycle_at(1, 0.001)));
        sensor.expect_read().returning(|| Ok(sample(f64::NAN)));
        robot
            .expect_reply()
            .withf(|c: &Correction| c.is_finite() && c.translation.z == 0.001)
            .times(2)
            .returning(|_| Ok(()));
        let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.002), LoopConfig::default());
        for _ in 0..2 {
            let r = lp.cycle().unwrap();
            assert_eq!(r.fault, Some(Fault::NonFiniteSample));
            assert!(r.command.is_finite());
        }
        assert_eq!(lp.stats().nonfinite_inputs, 2);
    }

    #[test]
    fn fatal_sensor_error_answers_then_ends() {
        let mut robot = MockRobot::new();
        let mut sensor = MockSensor::new();
        robot
            .expect_next_cycle()
            .returning(|| Ok(cycle_at(1, 0.001)));
        sensor.expect_read().returning(|| Err(ErrorKind::BusOff));
        robot.expect_reply().times(1).returning(|_| Ok(()));
        let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.002), LoopConfig::default());
        assert!(matches!(
            lp.cycle(),
            Err(LoopError::Sensor(ErrorKind::BusOff))
        ));
    }

    #[test]
    fn stop_answers_the_next_cycle_with_the_last_command_and_stop() {
        let mut robot = MockRobot::new();
        let mut sensor = MockSensor::new();
        robot
            .expect_next_cycle()
            .returning(|| Ok(cycle_at(1, 0.001)));
        sensor.expect_read().returning(|| Ok(sample(0.0)));
        let sent = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let log = sent.clone();
        robot.expect_reply().returning(move |c| {
            log.lock().unwrap().push(*c);
            Ok(())
        });
        let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.002), LoopConfig::default());
        lp.cycle().unwrap();
        lp.stop().unwrap();
        let sent = sent.lock().unwrap();
        assert_eq!(sent.len(), 2);
        assert!(!sent[0].stop && sent[1].stop);
        assert_eq!(
            sent[1].translation, sent[0].translation,
            "stop holds the last command"
        );
    }

    #[test]
    fn large_steps_are_limited_and_reported() {
        let mut robot = MockRobot::new();
        let mut sensor = MockSensor::new();
        robot.expect_next_cycle().returning(|| Ok(cycle_at(1, 0.0)));
        // A huge force error drives the fixed law hard towards x_r far away.
        sensor.expect_read().returning(|| Ok(sample(-1.0e7)));
        robot
            .expect_reply()
            .withf(|c: &Correction| c.translation.z.abs() <= 1e-4 + 1e-15)
            .returning(|_| Ok(()));
        let cfg = LoopConfig {
            max_step: 1e-4,
            ..LoopConfig::default()
        };
        let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.0), cfg);
        let r = lp.cycle().unwrap();
        assert_eq!(r.fault, Some(Fault::StepLimited));
        assert_eq!(lp.stats().limited, 1);
    }
}
