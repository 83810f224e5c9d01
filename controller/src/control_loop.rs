//! The control loop: one robot cycle in, one newest force sample, one law step, exactly one reply out.
//! Written against the HAL only; every device is a [`RobotLink`] and a [`ForceSensor`].

use hal::{Correction, Cycle, Error as _, ErrorKind, ForceSensor, RobotLink, Sample, Wrench};

use crate::compensated::Gravity;
use crate::gravity::Compensator;
use crate::law::{AlongNormal, CellLaw, ForceLaw, Output};

mod config;
mod error;
mod guard;
mod process;
mod process_cycle;
mod rezero;
pub use config::LoopConfig;
use error::Ending;
pub use error::{Fault, LoopError};
use guard::Guard;
use process::Process;
pub use process::{ProcessConfig, Refusal};
pub use rezero::{Rezero, RezeroEvent, RezeroInput, RezeroOutcome, RezeroParams};

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
    /// The sensor's sample as read this cycle (the raw wrench in the sensor frame, its counter and
    /// age), when it gave one, finite or not; for recordings and diagnostics.
    pub sample: Option<Sample>,
    /// The wrench the loop used: the sample's, with the tool's weight and the sensor bias removed
    /// where the loop compensates gravity ([`ControlLoop::with_gravity`]); `None` when there was none
    /// usable (no sample, not finite, not compensable).
    pub wrench: Option<Wrench>,
    /// True when the loop compensates gravity or re-zeroes the sensor (then `wrench` differs from
    /// the raw `sample`).
    pub compensated: bool,
    /// The law's output (on a held cycle, the last output).
    pub out: Output,
    /// The correction sent (with the process state reported to the robot program).
    pub command: Correction,
    /// The force set-point in effect, N: the law's, or the process's active one (0 while no force
    /// control runs).
    pub set_point: f64,
    /// What went wrong in this cycle, if anything.
    pub fault: Option<Fault>,
    /// A re-zero of the sensor in this cycle, or a refusal to (`[process] rezero`; its zero applies
    /// from the next cycle on).
    pub rezero: Option<RezeroEvent>,
}

/// One sensor read, classified.
struct Reading<SE> {
    f: Option<f64>,
    sample: Option<Sample>,
    wrench: Option<Wrench>,
    fault: Option<Fault>,
    fatal: Option<SE>,
}

/// Whether the robot's pose in `cycle` and the tool's offset `x` along the normal are usable.
fn pose_ok(cycle: &Cycle, x: f64) -> bool {
    cycle.actual.is_finite() && cycle.programmed.is_finite() && x.is_finite()
}

/// What the loop is doing.
enum Phase<SE> {
    /// Force control (or holding within `max_hold`).
    Control,
    /// Backing off towards `target`; then the loop ends with `end`.
    Retract { target: f64, end: Ending<SE> },
    /// Backed off after a fault that was reported: every further cycle holds the backed-off command
    /// (or backs off further towards `target` while the tool still touches).
    Halted { target: f64 },
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
    /// Force limit, correction limit and contact watch of a loop without process channels.
    guard: Guard,
    /// The gravity-compensation stage, where the cell compensates.
    gravity: Option<Gravity>,
    /// The law's last correction off the tool normal (tangential translation, rotation), limited;
    /// held while the loop backs off along the normal.
    side: Correction,
    /// The sensor's zero, re-taken in free air between passes where `[process] rezero` asks.
    rezero: Rezero,
}

impl<R: RobotLink, S: ForceSensor, L: ForceLaw> ControlLoop<R, S, AlongNormal<L>> {
    /// A loop running the 1-DOF `law` along the tool normal ([`AlongNormal`], with the loop's
    /// `force_sign`) that has not seen its first cycle yet.
    pub fn new(robot: R, sensor: S, law: L, cfg: LoopConfig) -> Self {
        Self::with_law(robot, sensor, AlongNormal::new(law, cfg.force_sign), cfg)
    }
}

impl<R: RobotLink, S: ForceSensor, L: CellLaw> ControlLoop<R, S, L> {
    /// A loop running `law` that has not seen its first cycle yet.
    pub fn with_law(robot: R, sensor: S, law: L, cfg: LoopConfig) -> Self {
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
            process: cfg.new_process(),
            guard: Guard::default(),
            gravity: None,
            side: Correction::default(),
            rezero: Rezero::new(cfg.process.rezero, cfg.process.zeroing),
        }
    }

    /// Compensate gravity: every cycle, the tool's weight for the cycle's measured orientation and
    /// the sensor bias are removed from the sample before anything uses it. A wrench that cannot be
    /// compensated (no orientation, or one older than the compensator's `max_age`) is held as a
    /// stale sample is ([`Fault::Sensor`] with [`ErrorKind::Stale`]).
    pub fn with_gravity(mut self, compensator: Compensator) -> Self {
        self.gravity = Some(Gravity::new(compensator));
        self
    }

    /// Counters so far.
    pub fn stats(&self) -> LoopStats {
        self.stats
    }

    /// The law.
    pub fn law(&self) -> &L {
        &self.law
    }

    /// The zero the loop removes from every wrench (after gravity compensation), N and N·m: zero
    /// unless `[process] rezero` re-took it between passes.
    pub fn sensor_zero(&self) -> Wrench {
        self.rezero.zero()
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
        if let Some(g) = &mut self.gravity {
            g.observe(&cycle);
        }
        let x = cycle.tool_offset().z;
        if let Some(pc) = cycle.process {
            return self.process_cycle(cycle, x, pc);
        }
        match self.phase {
            Phase::Control => {}
            Phase::Retract { .. } | Phase::Halted { .. } => return self.retract(cycle, x),
        }
        let pose_ok = pose_ok(&cycle, x);
        if self.begin_session(&cycle, pose_ok, x) {
            self.law.start(&cycle, &Correction::along_z(x));
            self.stepped_t = None;
            self.guard.reset();
        }

        let Reading {
            f,
            sample,
            wrench,
            mut fault,
            fatal: fatal_sensor,
        } = self.read_sensor(pose_ok);

        let mut out = self.last_out;
        let mut cmd = self.last_cmd;
        let mut tripped = None;
        match (fault, f, wrench) {
            (None, Some(f), Some(w)) if self.started => {
                let dt = self.law_dt(&cycle);
                self.guard.observe(&self.cfg.process, f, dt);
                if let Some((o, c)) = self.step_law(&cycle, &w, dt, &mut fault) {
                    out = o;
                    let f_r = self.law.set_point();
                    cmd = c.min(self.guard.search_limit(&self.cfg.process, &o));
                    tripped = match self.guard.check(&self.cfg.process, &o, f, f_r, dt) {
                        Err(t) => Some(t),
                        Ok(_) if fault == Some(Fault::EnvelopeLimited) => {
                            Some(guard::envelope(self.cfg.max_offset))
                        }
                        Ok(_) => None,
                    };
                }
            }
            _ => {}
        }
        let held = self.count(fault);
        self.held = if held { self.held + cycle.period } else { 0.0 };

        let command = self.command(cmd);
        self.reply(&command, out)?;
        let end = match (fatal_sensor, fault, tripped) {
            (Some(e), _, _) => Some(Ending::Sensor(e)),
            (None, Some(last), _) if self.held > self.cfg.max_hold => Some(Ending::HoldTimeout {
                held: self.held,
                last,
            }),
            (None, _, Some((code, reason))) => Some(Ending::Guard { code, reason }),
            _ => None,
        };
        if let Some(end) = end {
            let target = (cmd - self.cfg.retract_distance).max(-self.cfg.max_offset);
            // Reported as FAULT with its code while backing off and with `Stop`, on links that
            // carry process channels (the program is not using them, but the integrator sees it).
            let code = end.code().expect("an ending is never the robot's");
            self.process.latch(code, || end.reason(), cmd);
            self.phase = Phase::Retract { target, end };
        }
        Ok(CycleReport {
            cycle,
            x,
            f,
            sample,
            wrench,
            compensated: self.compensates(),
            out,
            command,
            set_point: self.law.set_point(),
            fault,
            rezero: None,
        })
    }

    /// A robot session starts (the first usable pose, or the robot's new session) with the tool at
    /// `x`: the command stands there (bumpless). Returns whether it did.
    fn begin_session(&mut self, cycle: &Cycle, pose_ok: bool, x: f64) -> bool {
        if !(pose_ok && (!self.started || cycle.new_session)) {
            return false;
        }
        if self.started {
            self.stats.sessions += 1;
        }
        self.started = true;
        self.last_cmd = x;
        self.side = Correction::default();
        self.last_out = Output {
            x_cmd: x,
            ..Output::default()
        };
        true
    }

    /// The law's step on the cycle and the wrench over `dt`, its command within the loop's limits (a
    /// limit that acted is noted in `fault`); `None` and [`Fault::NonFiniteCommand`] when the law gave
    /// no finite correction. Returns the output and the command along the normal; the law's
    /// correction off the normal is kept, limited, for [`command`](Self::command).
    fn step_law(
        &mut self,
        cycle: &Cycle,
        wrench: &Wrench,
        dt: f64,
        fault: &mut Option<Fault>,
    ) -> Option<(Output, f64)> {
        let s = self.law.step(cycle, wrench, dt);
        if s.correction.is_finite() {
            let cmd = self.limit(s.correction.translation.z, fault);
            self.limit_side(&s.correction, fault);
            Some((s.out, cmd))
        } else {
            *fault = Some(Fault::NonFiniteCommand);
            None
        }
    }

    /// The correction to send for the normal command `z`: the law's last correction off the normal
    /// (zero for a 1-DOF law) with `z` along it.
    fn command(&self, z: f64) -> Correction {
        let mut c = self.side;
        c.translation.z = z;
        c
    }

    /// Keep the law's tangential translation and rotation, the translation within the same step and
    /// envelope limits as the normal command (a limit that acted is noted in `fault`).
    fn limit_side(&mut self, want: &Correction, fault: &mut Option<Fault>) {
        let (step, lim) = (self.cfg.max_step, self.cfg.max_offset);
        for i in 0..2 {
            let last = self.side.translation[i];
            let v = want.translation[i].clamp(last - step, last + step);
            let v = v.clamp(-lim, lim);
            if v != want.translation[i] {
                *fault = fault.or(Some(Fault::StepLimited));
            }
            self.side.translation[i] = v;
        }
        self.side.rotation = want.rotation;
    }

    /// Answer the robot with `command`, the law's output `out` behind it.
    fn reply(
        &mut self,
        command: &Correction,
        out: Output,
    ) -> Result<(), LoopError<R::Error, S::Error>> {
        self.robot.reply(command).map_err(LoopError::Robot)?;
        self.stats.cycles += 1;
        self.last_out = out;
        self.last_cmd = command.translation.z;
        Ok(())
    }

    /// Read the newest sample and classify it: a usable force, a non-finite sample, a sensor error
    /// (fatal for `LinkLost`, `BusOff`, `Config`), or an unusable pose.
    fn read_sensor(&mut self, pose_ok: bool) -> Reading<S::Error> {
        let mut fatal = None;
        let mut sample = None;
        let mut wrench = None;
        let (f, mut fault) = match self.sensor.read() {
            Ok(s) if s.wrench.is_finite() => {
                sample = Some(s);
                match self.compensate(&s.wrench) {
                    Some(w) => {
                        wrench = Some(w);
                        (Some(self.cfg.force_sign * w.force.z), None)
                    }
                    None => (None, Some(Fault::Sensor(ErrorKind::Stale))),
                }
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
            wrench,
            fault,
            fatal,
        }
    }

    /// Whether the wrench the loop uses may differ from the raw sample: it compensates gravity, or
    /// re-zeroes the sensor.
    pub(super) fn compensates(&self) -> bool {
        self.gravity.is_some() || self.rezero.enabled()
    }

    /// The wrench with gravity removed where the loop compensates and the sensor's zero removed
    /// (`None`: it cannot be compensated, now).
    fn compensate(&self, raw: &Wrench) -> Option<Wrench> {
        let w = match &self.gravity {
            Some(g) => g.apply(raw).ok()?,
            None => *raw,
        };
        Some(self.rezero.apply(&w))
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
            ..self.command(self.last_cmd)
        };
        self.robot.reply(&command).map_err(LoopError::Robot)?;
        self.stats.cycles += 1;
        Ok(())
    }

    /// After the run ended early (a fault, the program's abort, the operator's stop), while the robot
    /// still cycles: answer one cycle with the correction stepped back towards the programmed path —
    /// the normal command towards zero at `retract_speed` (within `max_step`), but never towards the
    /// part (a command already backed off behind the path stays), the tangential translation
    /// likewise, the rotation in step with them (`LoopConfig::return_cycles`). `Ok(None)` once the
    /// correction is there (no cycle answered): `Stop` follows. The law is not stepped.
    pub fn unwind(&mut self) -> Result<Option<CycleReport>, LoopError<R::Error, S::Error>> {
        let home = self.last_cmd <= 0.0
            && self.side.translation.x == 0.0
            && self.side.translation.y == 0.0
            && self.side.rotation.iter().all(|r| *r == 0.0);
        if home || !self.started {
            return Ok(None);
        }
        let cycle = loop {
            match self.robot.next_cycle() {
                Ok(c) => break c,
                Err(e) if e.kind().is_transient() => self.stats.robot_glitches += 1,
                Err(e) => return Err(LoopError::Robot(e)),
            }
        };
        let x = cycle.tool_offset().z;
        let step = self.cfg.retract_step(cycle.period);
        let toward = |v: f64, to: f64| {
            if v > to {
                (v - step).max(to)
            } else {
                (v + step).min(to)
            }
        };
        let z = if self.last_cmd > 0.0 {
            toward(self.last_cmd, 0.0)
        } else {
            self.last_cmd
        };
        let left = self
            .cfg
            .return_cycles(self.last_cmd.max(0.0), &self.side, cycle.period);
        for i in 0..2 {
            self.side.translation[i] = toward(self.side.translation[i], 0.0);
        }
        self.side.rotation *= if left > 1.0 { 1.0 - 1.0 / left } else { 0.0 };
        let reading = self.read_backing_off();
        self.reply_backing_off(cycle, x, z, reading).map(Some)
    }

    /// One cycle of the back-off after a fault: step the command towards the phase's target at
    /// `retract_speed` (within `max_step`) and reply; once there, end the loop with the fault
    /// (reported once; later cycles hold the backed-off command). The target moves on while the
    /// sensor shows the tool still touching ([`guard::back_off_target`]).
    fn retract(
        &mut self,
        cycle: Cycle,
        x: f64,
    ) -> Result<CycleReport, LoopError<R::Error, S::Error>> {
        let reading = self.read_backing_off();
        let f = reading.2;
        let floor = -self.cfg.max_offset;
        let step = self.cfg.retract_step(cycle.period);
        let target = match &mut self.phase {
            Phase::Retract { target, .. } | Phase::Halted { target } => {
                *target = guard::back_off_target(
                    *target,
                    f,
                    self.cfg.process.entry_force,
                    self.last_cmd,
                    self.cfg.retract_distance,
                    floor,
                );
                *target
            }
            Phase::Control => unreachable!("retract() runs only after a fault"),
        };
        let cmd = (self.last_cmd - step).max(target);
        let report = self.reply_backing_off(cycle, x, cmd, reading)?;
        if cmd <= target
            && let Phase::Retract { end, .. } =
                core::mem::replace(&mut self.phase, Phase::Halted { target })
        {
            return Err(end.widen());
        }
        Ok(report)
    }

    /// A sample read while backing off: the wrench (compensated) where usable, the raw sample, the
    /// normal force.
    fn read_backing_off(&mut self) -> (Option<Wrench>, Option<Sample>, Option<f64>) {
        let (wrench, sample) = match self.sensor.read() {
            Ok(s) if s.wrench.is_finite() => (self.compensate(&s.wrench), Some(s)),
            Ok(s) => (None, Some(s)),
            Err(_) => (None, None),
        };
        let f = wrench.map(|w| self.cfg.force_sign * w.force.z);
        (wrench, sample, f)
    }

    /// Answer a cycle of a back-off or of the return to the path with the normal command `z` (the
    /// law not stepped), and report it with `reading`.
    fn reply_backing_off(
        &mut self,
        cycle: Cycle,
        x: f64,
        z: f64,
        (wrench, sample, f): (Option<Wrench>, Option<Sample>, Option<f64>),
    ) -> Result<CycleReport, LoopError<R::Error, S::Error>> {
        let command = Correction {
            process: self.process.state(),
            ..self.command(z)
        };
        let out = Output {
            x_cmd: z,
            ..self.last_out
        };
        self.reply(&command, out)?;
        self.stats.retract_cycles += 1;
        Ok(CycleReport {
            cycle,
            x,
            f,
            sample,
            wrench,
            compensated: self.compensates(),
            out: self.last_out,
            command,
            set_point: self.law.set_point(),
            fault: Some(Fault::Retracting),
            rezero: None,
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
mod tests;
