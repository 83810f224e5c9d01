//! One cycle of a loop whose robot link carries the process channels: the robot program's command
//! drives the process ([`super::process`]), which decides whether the law controls or the command
//! moves to a target.

use hal::{
    Correction, Cycle, ForceSensor, ProcessCommand, ProcessFault, ProcessMode, ProcessPhase,
    RobotLink, Wrench,
};

use super::error::{hold_code, hold_reason};
use super::process::Act;
use super::rezero::RezeroInput;
use super::{ControlLoop, CycleReport, Fault, LoopError, Reading, guard, pose_ok};
use crate::law::{CellLaw, Output};

impl<R: RobotLink, S: ForceSensor, L: CellLaw> ControlLoop<R, S, L> {
    /// One cycle of a process the robot program commands (the cycle carries a [`ProcessCommand`]):
    /// OFF returns the correction to zero, PRESS approaches, ramps and holds the program's force,
    /// RELEASE ramps down, lifts off and returns to zero; a fault latches, backs off and holds there
    /// until the program sends OFF. The loop never ends on a process fault: the program decides.
    pub(super) fn process_cycle(
        &mut self,
        cycle: Cycle,
        x: f64,
        pc: ProcessCommand,
    ) -> Result<CycleReport, LoopError<R::Error, S::Error>> {
        let pose_ok = pose_ok(&cycle, x);
        if self.begin_session(&cycle, pose_ok, x) {
            self.process = self.cfg.new_process();
            self.rezero.reset();
        }
        let Reading {
            f,
            sample,
            wrench,
            mut fault,
            fatal,
        } = self.read_sensor(pose_ok);
        if let Some(f) = f {
            self.process.observe(f, cycle.period);
        }
        self.take_process_command(&pc, &cycle, if pose_ok { x } else { self.last_cmd });
        if let Some(e) = &fatal {
            let why = || format!("force sensor: {e}");
            self.process
                .latch(ProcessFault::SensorLost, why, self.last_cmd);
        }
        if let Some(f) = f {
            self.process.back_off_further(f, self.last_cmd);
        }
        // Only at OFF, with the program commanding OFF: the law is not stepped, and the PRESS that
        // starts the next pass restarts it on the new zero.
        let rezero = self.rezero.observe(&RezeroInput {
            t: cycle.t,
            off: self.process.phase == ProcessPhase::Off && pc.mode == ProcessMode::Off,
            wrench: if fault.is_none() { wrench } else { None },
            f,
            pose: pose_ok.then_some(cycle.actual),
            contact_force: self.cfg.process.entry_force,
        });
        let (out, cmd, controlling) = match self.process.act() {
            Act::MoveTo { target } => {
                let cmd = self.move_to(target, &cycle, &mut fault);
                let out = Output {
                    x_cmd: cmd,
                    ..self.last_out
                };
                (out, cmd, false)
            }
            Act::Control => {
                let (out, cmd) = match (fault, f, wrench) {
                    (None, Some(fv), Some(w)) => self.process_law_step(&cycle, &w, fv, &mut fault),
                    _ => (self.last_out, self.last_cmd),
                };
                (out, cmd, true)
            }
        };
        self.bound_process_hold(fault, controlling, cycle.period, cmd);
        let command = Correction {
            process: self.process.state(),
            ..self.command(cmd)
        };
        self.reply(&command, out)?;
        Ok(CycleReport {
            cycle,
            x,
            f,
            sample,
            wrench,
            compensated: self.compensates(),
            out,
            command,
            set_point: self.process.recorded_set_point(),
            fault,
            rezero,
        })
    }

    /// The robot program's command `pc` to the process: a PRESS that starts force control starts the
    /// law afresh at `x` (bumpless), a command the process refuses latches a fault.
    fn take_process_command(&mut self, pc: &ProcessCommand, cycle: &Cycle, x: f64) {
        match self.process.command(pc) {
            Ok(true) => {
                self.law
                    .set_set_point(self.process.sp)
                    .expect("a checked PRESS force is a valid set-point");
                self.law.start(cycle, &Correction::along_z(x));
                self.stepped_t = None;
                self.held = 0.0;
            }
            Ok(false) => {}
            Err(why) => {
                let why = || format!("bad command: {why}");
                self.process
                    .latch(ProcessFault::BadCommand, why, self.last_cmd);
            }
        }
    }

    /// The command one cycle nearer `target` (OFF's zero, a lift or a fault's back-off), at the
    /// retract speed within the step limit, the rotation one cycle nearer zero; a back-off under a fault is reported as
    /// [`Fault::Retracting`].
    fn move_to(&mut self, target: f64, cycle: &Cycle, fault: &mut Option<Fault>) -> f64 {
        let step = self.cfg.retract_step(cycle.period);
        let cmd = self.last_cmd + (target - self.last_cmd).clamp(-step, step);
        // A rotation the law commanded (orientation following) turns back to zero meanwhile, at
        // the return rate: after a RELEASE, an OFF or a fault the tool is square to its path again.
        let turn = super::config::RETURN_TURN_RATE * cycle.period;
        let r = self.side.rotation.norm();
        if r > 0.0 {
            self.side.rotation *= if r <= turn { 0.0 } else { 1.0 - turn / r };
        }
        if cmd == target && self.side.rotation == hal::Vector3::zeros() {
            self.process.arrived();
        }

        if self.process.phase == hal::ProcessPhase::Fault {
            self.stats.retract_cycles += 1;
            *fault = fault.or(Some(Fault::Retracting));
        }
        cmd
    }

    /// The law's step under the process at its set-point (the ramp's step, or one the process
    /// changed after the last law step: a contact the law took back restarts the ramp at the entry
    /// force), and the process's checks of it: a check that fails latches its fault, a release ramp
    /// that is done lifts off. Returns the law's output and the command.
    fn process_law_step(
        &mut self,
        cycle: &Cycle,
        wrench: &Wrench,
        f: f64,
        fault: &mut Option<Fault>,
    ) -> (Output, f64) {
        let dt = self.law_dt(cycle);
        self.process.ramp_step(dt);
        if self.law.set_point() != self.process.sp {
            self.law
                .set_set_point(self.process.sp)
                .expect("a ramp between checked forces is a valid set-point");
        }
        let Some((o, cmd)) = self.step_law(cycle, wrench, dt, fault) else {
            return (self.last_out, self.last_cmd);
        };
        let cmd = cmd.min(self.process.guard.search_limit(&self.cfg.process, &o));
        if let Err((code, why)) = self.process.after_step(&o, f, dt) {
            self.process.latch(code, || why, cmd);
        } else if *fault == Some(Fault::EnvelopeLimited) {
            let (code, why) = guard::envelope(self.cfg.max_offset);
            self.process.latch(code, || why, cmd);
        } else if self.process.release_ramp_done() {
            self.process.lift_off(cmd);
        }
        (o, cmd)
    }

    /// Every hold is bounded: a fault that held the command under control (`controlling`) for
    /// longer than `max_hold` latches its process fault, backing off from `cmd`.
    fn bound_process_hold(
        &mut self,
        fault: Option<Fault>,
        controlling: bool,
        period: f64,
        cmd: f64,
    ) {
        let held = self.count(fault) && controlling;
        self.held = if held { self.held + period } else { 0.0 };
        // Only a fault holds the command (`count`), so a hold that lasted has one.
        if self.held > self.cfg.max_hold
            && let Some(last) = fault
        {
            let code = hold_code(last);
            let held = self.held;
            self.process.latch(code, || hold_reason(held, last), cmd);
            self.held = 0.0;
        }
    }
}
