//! The control loop: one robot cycle in, one newest force sample, one law step, exactly one reply out.
//! Written against the HAL only; every device is a [`RobotLink`] and a [`ForceSensor`].

use core::fmt;

use hal::{
    Correction, Cycle, Error as _, ErrorKind, ForceSensor, ProcessCommand, ProcessFault, RobotLink,
    Sample,
};
use serde::{Deserialize, Serialize};

use crate::law::{ForceLaw, Output};

mod process;
use process::{Act, Process, Release};
pub use process::{ProcessConfig, Refusal};

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
    /// Longest robot time, s, the loop may hold its last command without a usable sample or pose (a
    /// silent, saturated or failing sensor). Beyond it the loop retracts and ends with
    /// [`LoopError::HoldTimeout`]: it never presses blind for longer than this.
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
    /// The loop is backing off after a fault that ends it (hold timeout, failed sensor); the law is
    /// no longer stepped.
    Retracting,
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
    /// Cycles answered while backing off after a fault.
    pub retract_cycles: u64,
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
    /// The correction sent (with the process state reported to the robot program).
    pub command: Correction,
    /// The force set-point in effect, N: the law's, or the process's active one (0 while no force
    /// control runs).
    pub set_point: f64,
    /// What went wrong in this cycle, if anything.
    pub fault: Option<Fault>,
}

/// Why the loop ended.
#[derive(Debug)]
pub enum LoopError<RE, SE> {
    /// The robot link failed for good (lost, closed, misconfigured).
    Robot(RE),
    /// The sensor failed for good (bus-off, link lost, misconfigured); the loop has backed off first.
    Sensor(SE),
    /// The loop held its last command longer than `max_hold` (no usable sample or pose); it has backed
    /// off first. `last` is the fault of the last held cycle.
    HoldTimeout {
        /// Robot time held, s.
        held: f64,
        /// Why the last held cycle was held.
        last: Fault,
    },
}

impl<RE: fmt::Display, SE: fmt::Display> fmt::Display for LoopError<RE, SE> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Robot(e) => write!(f, "robot link: {e}"),
            Self::Sensor(e) => write!(f, "force sensor: {e} (the tool backed off)"),
            Self::HoldTimeout { held, last } => write!(
                f,
                "held the last command for {:.0} ms without a usable input (last: {last:?}); the tool backed off",
                held * 1e3
            ),
        }
    }
}

/// A fault that ends the loop once the tool has backed off.
enum Ending<SE> {
    Sensor(SE),
    HoldTimeout { held: f64, last: Fault },
}

impl<SE> Ending<SE> {
    fn into_error<RE>(self) -> LoopError<RE, SE> {
        match self {
            Self::Sensor(e) => LoopError::Sensor(e),
            Self::HoldTimeout { held, last } => LoopError::HoldTimeout { held, last },
        }
    }
}

/// One sensor read, classified.
struct Reading<SE> {
    f: Option<f64>,
    sample: Option<Sample>,
    fault: Option<Fault>,
    fatal: Option<SE>,
}

/// What the loop is doing.
enum Phase<SE> {
    /// Force control (or holding within `max_hold`).
    Control,
    /// Backing off towards `target`; then the loop ends with `end`.
    Retract { target: f64, end: Ending<SE> },
    /// Backed off after a fault that was reported: every further cycle holds the backed-off command.
    Halted,
}

impl<RE: fmt::Debug + fmt::Display, SE: fmt::Debug + fmt::Display> std::error::Error
    for LoopError<RE, SE>
{
}

/// The loop: a robot, a sensor and a law.
pub struct ControlLoop<R, S: ForceSensor, L> {
    robot: R,
    sensor: S,
    law: L,
    cfg: LoopConfig,
    stats: LoopStats,
    started: bool,
    last_out: Output,
    last_cmd: f64,
    /// Robot time held since the law's last step, s.
    held: f64,
    phase: Phase<S::Error>,
    /// Robot time of the law's last step, s (`None` right after a start).
    stepped_t: Option<f64>,
    process: Process,
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
            held: 0.0,
            phase: Phase::Control,
            stepped_t: None,
            process: Process::new(cfg.process),
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
    /// answers with its last command and does not step the law — for at most `max_hold` of robot time.
    /// A longer hold, or a sensor error of kind `LinkLost`, `BusOff` or `Config`, makes the loop back
    /// off by `retract_distance` at `retract_speed` (answering every cycle meanwhile, reported as
    /// [`Fault::Retracting`]) and then end with [`LoopError::HoldTimeout`] or [`LoopError::Sensor`].
    /// A robot error that is not transient ([`ErrorKind::is_transient`]) ends the loop at once: there is
    /// no link left to back off through.
    pub fn cycle(&mut self) -> Result<CycleReport, LoopError<R::Error, S::Error>> {
        let cycle = loop {
            match self.robot.next_cycle() {
                Ok(c) => break c,
                Err(e) if e.kind().is_transient() => self.stats.robot_glitches += 1,
                Err(e) => return Err(LoopError::Robot(e)),
            }
        };
        let x = cycle.tool_offset().z;
        if let Some(pc) = cycle.process {
            return self.process_cycle(cycle, x, pc);
        }
        match self.phase {
            Phase::Control => {}
            Phase::Retract { target, .. } => return self.retract(cycle, x, target),
            Phase::Halted => return self.retract(cycle, x, self.last_cmd),
        }
        let pose_ok = cycle.actual.is_finite() && cycle.programmed.is_finite() && x.is_finite();
        if pose_ok && (!self.started || cycle.new_session) {
            if self.started {
                self.stats.sessions += 1;
            }
            self.begin_session(x);
            self.law.start(x);
            self.stepped_t = None;
        }

        let Reading {
            f,
            sample,
            mut fault,
            fatal: fatal_sensor,
        } = self.read_sensor(pose_ok);

        let mut out = self.last_out;
        let mut cmd = self.last_cmd;
        match (fault, f) {
            (None, Some(f)) if self.started => {
                let dt = self.law_dt(&cycle);
                let o = self.law.step(x, f, dt);
                if o.x_cmd.is_finite() {
                    out = o;
                    cmd = self.limit(o.x_cmd, &mut fault);
                } else {
                    fault = Some(Fault::NonFiniteCommand);
                }
            }
            _ => {}
        }
        let held = self.count(fault);
        self.held = if held { self.held + cycle.period } else { 0.0 };

        let command = Correction::along_z(cmd);
        self.robot.reply(&command).map_err(LoopError::Robot)?;
        self.stats.cycles += 1;
        self.last_out = out;
        self.last_cmd = cmd;
        let end = match (fatal_sensor, fault) {
            (Some(e), _) => Some(Ending::Sensor(e)),
            (None, Some(last)) if self.held > self.cfg.max_hold => Some(Ending::HoldTimeout {
                held: self.held,
                last,
            }),
            _ => None,
        };
        if let Some(end) = end {
            let target = (cmd - self.cfg.retract_distance).max(-self.cfg.max_offset);
            self.phase = Phase::Retract { target, end };
        }
        Ok(CycleReport {
            cycle,
            x,
            f,
            sample,
            out,
            command,
            set_point: self.law.set_point(),
            fault,
        })
    }

    /// A robot session starts with the tool at `x`: the command stands there (bumpless).
    fn begin_session(&mut self, x: f64) {
        self.started = true;
        self.last_cmd = x;
        self.last_out = Output {
            x_cmd: x,
            ..Output::default()
        };
    }

    /// Read the newest sample and classify it: a usable force, a non-finite sample, a sensor error
    /// (fatal for `LinkLost`, `BusOff`, `Config`), or an unusable pose.
    fn read_sensor(&mut self, pose_ok: bool) -> Reading<S::Error> {
        let mut fatal = None;
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
                    fatal = Some(e);
                }
                (None, Some(Fault::Sensor(kind)))
            }
        };
        if !pose_ok && fault.is_none() {
            fault = Some(Fault::NonFinitePose);
        }
        Reading {
            f,
            sample,
            fault,
            fatal,
        }
    }

    /// The law's step: the robot time since its last step (held and skipped cycles included), from
    /// the cycle's own timestamp; the nominal period on the first step or when the stamps are unusable.
    fn law_dt(&mut self, cycle: &Cycle) -> f64 {
        let dt = match self.stepped_t {
            Some(t0) => cycle.t - t0,
            None => cycle.period,
        };
        self.stepped_t = Some(cycle.t);
        // A stamp that goes back or leaps past a hold the loop would have ended is not a clock.
        if !(dt.is_finite() && dt > 0.0 && dt <= self.cfg.max_hold + 2.0 * cycle.period) {
            return cycle.period;
        }
        // Whole robot cycles: the stamps count interpolation cycles (RSI's IPOC in ms), so the
        // time between two steps is a whole number of periods; rounding keeps the stamps' jitter
        // and float error out of the law.
        if cycle.period > 0.0 {
            (dt / cycle.period).round().max(1.0) * cycle.period
        } else {
            dt
        }
    }

    /// One cycle of a process the robot program commands (the cycle carries a [`ProcessCommand`]):
    /// OFF returns the correction to zero, PRESS approaches, ramps and holds the program's force,
    /// RELEASE ramps down, lifts off and returns to zero; a fault latches, backs off and holds there
    /// until the program sends OFF. The loop never ends on a process fault: the program decides.
    fn process_cycle(
        &mut self,
        cycle: Cycle,
        x: f64,
        pc: ProcessCommand,
    ) -> Result<CycleReport, LoopError<R::Error, S::Error>> {
        let pose_ok = cycle.actual.is_finite() && cycle.programmed.is_finite() && x.is_finite();
        if pose_ok && (!self.started || cycle.new_session) {
            if self.started {
                self.stats.sessions += 1;
            }
            self.begin_session(x);
            self.process = Process::new(self.cfg.process);
        }
        let Reading {
            f,
            sample,
            mut fault,
            fatal,
        } = self.read_sensor(pose_ok);
        if let Some(f) = f {
            self.process.observe(f, cycle.period);
        }
        let lift = self.cfg.retract_distance;
        let floor = -self.cfg.max_offset;
        match self.process.command(&pc) {
            Ok(true) => {
                // A fresh start of force control at the measured position (bumpless).
                self.law
                    .set_set_point(self.process.sp)
                    .expect("a checked PRESS force is a valid set-point");
                self.law.start(if pose_ok { x } else { self.last_cmd });
                self.stepped_t = None;
                self.held = 0.0;
            }
            Ok(false) => {}
            Err(why) => self.process.latch(
                ProcessFault::BadCommand,
                || format!("bad command: {why}"),
                self.last_cmd,
                lift,
                floor,
            ),
        }
        if let Some(e) = &fatal {
            self.process.latch(
                ProcessFault::SensorLost,
                || format!("force sensor: {e}"),
                self.last_cmd,
                lift,
                floor,
            );
        }

        let mut out = self.last_out;
        let mut cmd = self.last_cmd;
        let controlling = match self.process.act() {
            Act::MoveTo { target } => {
                let step = (self.cfg.retract_speed * cycle.period).min(self.cfg.max_step);
                cmd = self.last_cmd + (target - self.last_cmd).clamp(-step, step);
                if cmd == target {
                    self.process.arrived();
                }
                out.x_cmd = cmd;
                if self.process.phase == hal::ProcessPhase::Fault {
                    self.stats.retract_cycles += 1;
                    fault = fault.or(Some(Fault::Retracting));
                }
                false
            }
            Act::Control => {
                if let (None, Some(fv)) = (fault, f) {
                    let dt = self.law_dt(&cycle);
                    if self.process.ramp_step(dt) {
                        self.law
                            .set_set_point(self.process.sp)
                            .expect("a ramp between checked forces is a valid set-point");
                    }
                    let o = self.law.step(x, fv, dt);
                    if o.x_cmd.is_finite() {
                        out = o;
                        cmd = self.limit(o.x_cmd, &mut fault);
                        if let Err((code, why)) = self.process.after_step(&o, fv, dt) {
                            self.process.latch(code, || why, cmd, lift, floor);
                        } else if fault == Some(Fault::EnvelopeLimited) {
                            self.process.latch(
                                ProcessFault::CorrectionLimit,
                                || {
                                    format!(
                                        "correction reached its envelope of {:.1} mm",
                                        self.cfg.max_offset * 1e3
                                    )
                                },
                                cmd,
                                lift,
                                floor,
                            );
                        } else if self.process.release_ramp_done() {
                            self.process.release = Release::Lift {
                                target: (cmd - lift).max(floor),
                            };
                        }
                    } else {
                        fault = Some(Fault::NonFiniteCommand);
                    }
                }
                true
            }
        };
        let held = self.count(fault) && controlling;
        self.held = if held { self.held + cycle.period } else { 0.0 };
        if self.held > self.cfg.max_hold {
            let code = match fault {
                Some(Fault::Sensor(_) | Fault::NonFiniteSample) => ProcessFault::SensorLost,
                _ => ProcessFault::HoldTimeout,
            };
            let held = self.held;
            let why = || {
                format!(
                    "held the last command for {:.0} ms without a usable input (last: {fault:?})",
                    held * 1e3
                )
            };
            self.process.latch(code, why, cmd, lift, floor);
            self.held = 0.0;
        }

        let command = Correction {
            process: self.process.state(),
            ..Correction::along_z(cmd)
        };
        self.robot.reply(&command).map_err(LoopError::Robot)?;
        self.stats.cycles += 1;
        self.last_out = out;
        self.last_cmd = cmd;
        Ok(CycleReport {
            cycle,
            x,
            f,
            sample,
            out,
            command,
            set_point: self.process.recorded_set_point(),
            fault,
        })
    }

    /// The process's state as last reported to the robot program (OFF on links without process
    /// channels).
    pub fn process_state(&self) -> hal::ProcessState {
        self.process.state()
    }

    /// Why the process's fault latched, while it is latched.
    pub fn process_fault_reason(&self) -> Option<&str> {
        self.process.reason.as_deref()
    }

    /// Count a cycle's fault; true when the cycle held its last command.
    fn count(&mut self, fault: Option<Fault>) -> bool {
        match fault {
            Some(Fault::Sensor(_)) => {
                self.stats.sensor_faults += 1;
                true
            }
            Some(Fault::NonFiniteSample | Fault::NonFinitePose) => {
                self.stats.nonfinite_inputs += 1;
                true
            }
            Some(Fault::NonFiniteCommand) => {
                self.stats.nonfinite_commands += 1;
                true
            }
            Some(Fault::StepLimited | Fault::EnvelopeLimited) => {
                self.stats.limited += 1;
                false
            }
            Some(Fault::Retracting) | None => false,
        }
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
            process: self.process.state(),
            ..Correction::along_z(self.last_cmd)
        };
        self.robot.reply(&command).map_err(LoopError::Robot)?;
        self.stats.cycles += 1;
        Ok(())
    }

    /// One cycle of the back-off after a fault: step the command towards `target` at `retract_speed`
    /// (within `max_step`) and reply; once there, end the loop with the fault (reported once; later
    /// cycles hold the backed-off command).
    fn retract(
        &mut self,
        cycle: Cycle,
        x: f64,
        target: f64,
    ) -> Result<CycleReport, LoopError<R::Error, S::Error>> {
        let step = (self.cfg.retract_speed * cycle.period).min(self.cfg.max_step);
        let cmd = (self.last_cmd - step).max(target);
        let command = Correction::along_z(cmd);
        self.robot.reply(&command).map_err(LoopError::Robot)?;
        self.stats.cycles += 1;
        self.stats.retract_cycles += 1;
        self.last_cmd = cmd;
        self.last_out.x_cmd = cmd;
        if cmd <= target
            && let Phase::Retract { end, .. } = core::mem::replace(&mut self.phase, Phase::Halted)
        {
            return Err(end.into_error());
        }
        Ok(CycleReport {
            cycle,
            x,
            f: None,
            // The sensor is not read while backing off: its reading no longer matters.
            sample: None,
            out: self.last_out,
            command,
            set_point: self.law.set_point(),
            fault: Some(Fault::Retracting),
        })
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
            process: None,
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

    /// Runs cycles until the loop ends; returns the corrections sent and the error it ended with.
    fn run_until_end(
        lp: &mut MockLoop,
        sent: &std::sync::Mutex<Vec<Correction>>,
    ) -> (Vec<Correction>, LoopError<ErrorKind, ErrorKind>) {
        for _ in 0..10_000 {
            if let Err(e) = lp.cycle() {
                return (sent.lock().unwrap().clone(), e);
            }
        }
        panic!("the loop never ended")
    }

    type MockLoop = ControlLoop<MockRobot, MockSensor, ImpedanceLaw>;
    type SentLog = std::sync::Arc<std::sync::Mutex<Vec<Correction>>>;

    /// A robot at a fixed pose whose replies are logged, and a sensor that answers `read` in turn.
    fn logged(
        mut read: impl FnMut(u64) -> Result<Sample, ErrorKind> + Send + 'static,
    ) -> (MockLoop, SentLog) {
        let mut robot = MockRobot::new();
        let mut sensor = MockSensor::new();
        let mut k = 0;
        robot.expect_next_cycle().returning(move || {
            k += 1;
            Ok(cycle_at(k, 0.001))
        });
        let mut n = 0;
        sensor.expect_read().returning(move || {
            n += 1;
            read(n)
        });
        let sent = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let log = sent.clone();
        robot.expect_reply().returning(move |c| {
            log.lock().unwrap().push(*c);
            Ok(())
        });
        let lp = ControlLoop::new(robot, sensor, fixed_law(0.001), LoopConfig::default());
        (lp, sent)
    }

    /// The commands after `from` only ever back off (−z), by no more than the retract speed allows per
    /// cycle, and end `retract_distance` below the command at `from`.
    fn assert_backed_off(sent: &[Correction], from: usize) {
        let cfg = LoopConfig::default();
        let per_cycle = cfg.retract_speed * 0.004 + 1e-12;
        let z: Vec<f64> = sent.iter().map(|c| c.translation.z).collect();
        for w in z[from..].windows(2) {
            assert!(w[1] <= w[0] && w[0] - w[1] <= per_cycle, "{w:?}");
        }
        let backed = z[from] - z[z.len() - 1];
        assert!(
            (backed - cfg.retract_distance).abs() < 1e-12,
            "backed off {backed} m"
        );
    }

    #[test]
    fn fatal_sensor_error_backs_off_then_ends() {
        let (mut lp, sent) = logged(|n| {
            if n < 3 {
                Ok(sample(0.0))
            } else {
                Err(ErrorKind::BusOff)
            }
        });
        let (sent, end) = run_until_end(&mut lp, &sent);
        assert!(
            matches!(end, LoopError::Sensor(ErrorKind::BusOff)),
            "{end:?}"
        );
        assert!(end.to_string().contains("backed off"), "{end}");
        // The failing cycle (the third) is answered with the last command; then the back-off.
        assert_eq!(sent[2], sent[1]);
        assert_backed_off(&sent, 2);
        assert_eq!(lp.stats().retract_cycles as usize, sent.len() - 3);
    }

    #[test]
    fn a_hold_is_bounded_in_time_then_the_tool_backs_off() {
        // Two good samples, then the sensor only times out: the loop may hold 0.1 s (25 cycles of 4 ms).
        let (mut lp, sent) = logged(|n| {
            if n <= 2 {
                Ok(sample(0.0))
            } else {
                Err(ErrorKind::Timeout)
            }
        });
        let (sent, end) = run_until_end(&mut lp, &sent);
        let LoopError::HoldTimeout { held, last } = end else {
            panic!("expected a hold timeout, got {end:?}")
        };
        assert_eq!(last, Fault::Sensor(ErrorKind::Timeout));
        let cfg = LoopConfig::default();
        assert!(
            held > cfg.max_hold && held <= cfg.max_hold + 0.004 + 1e-9,
            "{held}"
        );
        let held_cycles = (held / 0.004).round() as usize;
        // Every held cycle repeated the last good command.
        for c in &sent[2..2 + held_cycles] {
            assert_eq!(c, &sent[1]);
        }
        assert_backed_off(&sent, 1 + held_cycles);
        // After the fault was reported, the loop keeps answering at the backed-off position.
        let r = lp.cycle().expect("a halted loop still answers");
        assert_eq!(r.fault, Some(Fault::Retracting));
        assert_eq!(r.command, *sent.last().unwrap());
    }

    #[test]
    fn a_hold_shorter_than_max_hold_resumes_control() {
        // A 20-cycle (80 ms) dropout, under the 100 ms bound: the law resumes, nothing backs off.
        let (mut lp, sent) = logged(|n| {
            if (3..23).contains(&n) {
                Err(ErrorKind::Timeout)
            } else {
                Ok(sample(0.0))
            }
        });
        for _ in 0..60 {
            lp.cycle().expect("a short hold does not end the loop");
        }
        assert_eq!(lp.stats().retract_cycles, 0);
        assert_eq!(lp.stats().sensor_faults, 20);
        assert_eq!(sent.lock().unwrap().len(), 60);
    }

    #[test]
    fn hold_and_retract_limits_are_validated() {
        for bad in [
            LoopConfig {
                max_hold: 0.0,
                ..LoopConfig::default()
            },
            LoopConfig {
                max_hold: f64::NAN,
                ..LoopConfig::default()
            },
            LoopConfig {
                max_hold: 5.0,
                ..LoopConfig::default()
            },
            LoopConfig {
                retract_distance: -0.001,
                ..LoopConfig::default()
            },
            LoopConfig {
                retract_speed: f64::INFINITY,
                ..LoopConfig::default()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
        assert!(LoopConfig::default().validate().is_ok());
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

    /// A law that records the `dt` of every step.
    #[derive(Default)]
    struct DtLaw(Vec<f64>);

    impl ForceLaw for DtLaw {
        fn start(&mut self, _x: f64) {}
        fn step(&mut self, x: f64, _f: f64, dt: f64) -> Output {
            self.0.push(dt);
            Output {
                x_cmd: x,
                ..Output::default()
            }
        }
        fn set_point(&self) -> f64 {
            0.0
        }
        fn set_set_point(&mut self, _f_r: f64) -> Result<(), String> {
            Ok(())
        }
    }

    #[test]
    fn the_laws_clock_is_the_robots_stamps_held_and_skipped_cycles_included() {
        let mut robot = MockRobot::new();
        // Cycles 0, 1, 2, then the robot skips 3 and 4 (a late PC), then 5, 6 (sensor timeout), 7.
        let seqs = std::sync::Mutex::new(vec![0u64, 1, 2, 5, 6, 7].into_iter());
        robot
            .expect_next_cycle()
            .returning(move || Ok(cycle_at(seqs.lock().unwrap().next().unwrap(), 0.001)));
        robot.expect_reply().returning(|_| Ok(()));
        let mut sensor = MockSensor::new();
        let mut n = 0;
        sensor.expect_read().returning(move || {
            n += 1;
            if n == 5 {
                Err(ErrorKind::Timeout)
            } else {
                Ok(sample(1.0))
            }
        });
        let mut lp = ControlLoop::new(robot, sensor, DtLaw::default(), LoopConfig::default());
        for _ in 0..6 {
            lp.cycle().unwrap();
        }
        let steps: Vec<u64> = lp
            .law()
            .0
            .iter()
            .map(|dt| (dt / 0.004).round() as u64)
            .collect();
        assert_eq!(steps, [1, 1, 1, 3, 2], "periods per step: {:?}", lp.law().0);
        // Whole periods, exactly: the stamps' float error stays out of the law.
        let whole = lp
            .law()
            .0
            .iter()
            .zip(&steps)
            .all(|(dt, n)| *dt == *n as f64 * 0.004);
        assert!(whole, "{:?}", lp.law().0);
    }
}
