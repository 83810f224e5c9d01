//! The force process the robot program commands (RSI `FcCmd` → `FcState`): OFF, PRESS and RELEASE with
//! ramps, latched faults that retract and re-arm on OFF. Contract: the process channels in `docs/wire-rsi.md`.
//!
//! The loop runs this only on cycles that carry a [`ProcessCommand`]; without one it keeps its old
//! behaviour (force control from the first cycle at the tuning's set-point).

use hal::{ProcessCommand, ProcessFault, ProcessMode, ProcessPhase, ProcessState};
use serde::{Deserialize, Serialize};

use super::guard::{Guard, Touch, Tripped, back_off_target};
use super::rezero::RezeroParams;
use crate::law::Output;

/// The default of [`ProcessConfig::search_depth`], m: the lost surface is searched for a few
/// millimetres beyond where it was (docs/deploying.md, "Leaving the part").
pub const SEARCH_DEPTH: f64 = 0.005;
/// The largest [`ProcessConfig::search_depth`] accepted, m.
pub const MAX_SEARCH_DEPTH: f64 = 0.02;

/// How the process reacts to the program's commands. Forces in N, times in s.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ProcessConfig {
    /// `PRESSING` is reported once the measured force is within this fraction of `F` (and the ramp is
    /// done).
    pub tolerance: f64,
    /// The force limit: a commanded `F` must lie below it, a measured force above it is a fault.
    pub max_force: f64,
    /// The set-point an entry ramp starts from before contact (the ramp then runs from the force at
    /// contact to `F`), N.
    pub entry_force: f64,
    /// Rate of a set-point change when the program asks for `Ramp = 0`, N/s.
    pub default_rate: f64,
    /// Longest loss of contact while pressing before it is a fault, s.
    pub contact_loss_time: f64,
    /// Time constant of the force filter behind the `PRESSING` test and `FcState.F`, s.
    pub force_filter: f64,
    /// How far beyond where contact was lost (the law's last command in contact) the search for the
    /// lost surface may command, m; beyond it is a fault (code 5), and the tool backs off. A pass
    /// that runs off the part's edge or over a hole otherwise follows the surface that is not there,
    /// at search speed, until `contact_loss_time` ends it (18 mm in 0.5 s at 36 mm/s).
    pub search_depth: f64,
    /// Re-zero the force sensor in free air between passes (OFF, tool still, out of contact), when
    /// the check of `zeroing` passes (`control_loop::rezero`; docs/rezero.md).
    pub rezero: bool,
    /// The re-zero check's parameters.
    pub zeroing: RezeroParams,
}

impl Default for ProcessConfig {
    fn default() -> Self {
        Self {
            tolerance: 0.05,
            max_force: 60.0,
            entry_force: 2.0,
            default_rate: 50.0,
            contact_loss_time: 0.5,
            force_filter: 0.01,
            search_depth: SEARCH_DEPTH,
            rezero: false,
            zeroing: RezeroParams::default(),
        }
    }
}

impl ProcessConfig {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!(
                    "process.{name} must be a finite number > 0, got {v}"
                ))
            }
        };
        pos("tolerance", self.tolerance)?;
        if self.tolerance >= 1.0 {
            return Err(format!(
                "process.tolerance is a fraction of F below 1, got {}",
                self.tolerance
            ));
        }
        pos("max_force", self.max_force)?;
        pos("entry_force", self.entry_force)?;
        pos("default_rate", self.default_rate)?;
        pos("contact_loss_time", self.contact_loss_time)?;
        pos("force_filter", self.force_filter)?;
        pos("search_depth", self.search_depth)?;
        if self.search_depth > MAX_SEARCH_DEPTH {
            return Err(format!(
                "process.search_depth is at most {} mm (the search for a lost surface must stay near \
                 it), got {} mm",
                MAX_SEARCH_DEPTH * 1e3,
                self.search_depth * 1e3
            ));
        }
        self.zeroing.validate()
    }

    /// Why the program's command is refused, if it is: an undefined mode, or a PRESS whose force or
    /// ramp the contract does not allow. No allocation: the program may repeat a bad command every cycle.
    pub fn check(&self, c: &ProcessCommand) -> Result<(), Refusal> {
        match c.mode {
            ProcessMode::Unknown(m) => Err(Refusal::UndefinedMode(m)),
            ProcessMode::Press if !(c.force.is_finite() && c.force > 0.0) => {
                Err(Refusal::Force(c.force))
            }
            ProcessMode::Press if c.force >= self.max_force => Err(Refusal::AtLimit {
                force: c.force,
                limit: self.max_force,
            }),
            ProcessMode::Press if !(c.ramp.is_finite() && (0.0..=60.0).contains(&c.ramp)) => {
                Err(Refusal::Ramp(c.ramp))
            }
            _ => Ok(()),
        }
    }
}

/// Why a program's command is refused (fault 4, "bad command").
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Refusal {
    /// A mode number the contract does not define.
    UndefinedMode(i64),
    /// A PRESS force that is not a finite number > 0 N.
    Force(f64),
    /// A PRESS force at or above the force limit.
    AtLimit {
        /// Commanded, N.
        force: f64,
        /// The limit, N.
        limit: f64,
    },
    /// A ramp outside 0..60 s.
    Ramp(f64),
}

impl core::fmt::Display for Refusal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::UndefinedMode(m) => write!(f, "undefined mode {m}"),
            Self::Force(v) => write!(f, "PRESS needs F > 0 N, got {v}"),
            Self::AtLimit { force, limit } => {
                write!(
                    f,
                    "PRESS with F = {force} N at or above the force limit {limit} N"
                )
            }
            Self::Ramp(r) => write!(f, "Ramp must be 0..60 s, got {r}"),
        }
    }
}

/// Where a RELEASE is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Release {
    /// The set-point ramps down while the law holds contact.
    RampDown,
    /// The command backs off towards `target`.
    Lift { target: f64 },
    /// The command returns to zero.
    Return,
}

/// What the loop does with the command this cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Act {
    /// Step the law with set-point `sp`.
    Control,
    /// Move the command towards `target` at the retract speed; the law is not stepped.
    MoveTo { target: f64 },
}

/// The process's state.
#[derive(Clone, Debug)]
pub(super) struct Process {
    pub cfg: ProcessConfig,
    pub phase: ProcessPhase,
    pub fault: ProcessFault,
    /// Why the fault latched, for the operator.
    pub reason: Option<String>,
    /// Active set-point handed to the law, N.
    pub sp: f64,
    /// The program's `F`, N.
    pub target: f64,
    /// Rate of the running ramp, N/s.
    pub rate: f64,
    /// The program's `Ramp`, s.
    pub ramp: f64,
    /// The force filter and the contact watch.
    pub guard: Guard,
    pub release: Release,
    /// Where a fault's back-off ends, m.
    pub retract_target: f64,
    /// How far a fault backs off beyond the command (the loop's `retract_distance`), and the
    /// envelope's floor it never passes (`−max_offset`), m.
    lift: f64,
    floor: f64,
}

impl Process {
    /// At OFF; a fault backs off `lift` (m) beyond the command, never beyond `floor` (m).
    pub fn new(cfg: ProcessConfig, lift: f64, floor: f64) -> Self {
        Self {
            cfg,
            phase: ProcessPhase::Off,
            fault: ProcessFault::None,
            reason: None,
            sp: 0.0,
            target: 0.0,
            rate: cfg.default_rate,
            ramp: 0.0,
            guard: Guard::default(),
            release: Release::Return,
            retract_target: 0.0,
            lift,
            floor,
        }
    }

    /// The state reported to the program.
    pub fn state(&self) -> ProcessState {
        ProcessState {
            phase: self.phase,
            force: if self.guard.f_filt.is_finite() {
                self.guard.f_filt
            } else {
                0.0
            },
            fault: self.fault,
        }
    }

    /// The set-point to record: the active one while force control runs, else 0.
    pub fn recorded_set_point(&self) -> f64 {
        match self.phase {
            ProcessPhase::Approach | ProcessPhase::Ramp | ProcessPhase::Pressing => self.sp,
            ProcessPhase::Release if self.release == Release::RampDown => self.sp,
            _ => 0.0,
        }
    }

    /// Filter a usable force sample.
    pub fn observe(&mut self, f: f64, dt: f64) {
        self.guard.observe(&self.cfg, f, dt);
    }

    /// Latch a fault (the first one stands), backing off from `cmd`, within the floor. `why` is only
    /// formatted when the fault latches, not on every cycle a latched condition persists.
    pub fn latch(&mut self, fault: ProcessFault, why: impl FnOnce() -> String, cmd: f64) {
        if self.phase == ProcessPhase::Fault {
            return;
        }
        self.phase = ProcessPhase::Fault;
        self.fault = fault;
        self.reason = Some(why());
        self.retract_target = (cmd - self.lift).max(self.floor);
    }

    /// While a latched fault backs off: its target moves on while force `f` shows the tool still
    /// touching ([`back_off_target`]).
    pub fn back_off_further(&mut self, f: f64, cmd: f64) {
        if self.phase == ProcessPhase::Fault {
            self.retract_target = back_off_target(
                self.retract_target,
                Some(f),
                self.cfg.entry_force,
                cmd,
                self.lift,
                self.floor,
            );
        }
    }

    /// The rate of a ramp from `from` to `to` over the program's `Ramp`: never faster than
    /// `default_rate` (the law's own set-point rate), so the set-point handed on is the one in effect.
    fn ramp_rate(&self, from: f64, to: f64) -> f64 {
        if self.ramp > 0.0 {
            ((to - from).abs() / self.ramp)
                .max(1e-9)
                .min(self.cfg.default_rate)
        } else {
            self.cfg.default_rate
        }
    }

    /// Take the program's command. Returns `true` when force control (re)starts: the loop restarts
    /// the law at the measured position with set-point `sp`.
    pub fn command(&mut self, c: &ProcessCommand) -> Result<bool, Refusal> {
        self.cfg.check(c)?;
        match c.mode {
            ProcessMode::Off => {
                if self.phase != ProcessPhase::Off {
                    // OFF re-arms a latched fault and ends anything else: back to zero.
                    self.phase = ProcessPhase::Off;
                    self.fault = ProcessFault::None;
                    self.reason = None;
                }
                Ok(false)
            }
            ProcessMode::Press => match self.phase {
                ProcessPhase::Fault => Ok(false),
                ProcessPhase::Off | ProcessPhase::Release => {
                    self.phase = ProcessPhase::Approach;
                    self.target = c.force;
                    self.ramp = c.ramp;
                    self.sp = if c.ramp > 0.0 {
                        self.cfg.entry_force.min(c.force)
                    } else {
                        c.force
                    };
                    self.rate = self.ramp_rate(self.sp, c.force);
                    self.guard.reset();
                    Ok(true)
                }
                _ => {
                    if c.force != self.target || c.ramp != self.ramp {
                        self.ramp = c.ramp;
                        self.rate = self.ramp_rate(self.sp, c.force);
                        if c.force != self.target && self.phase == ProcessPhase::Pressing {
                            self.phase = ProcessPhase::Ramp;
                        }
                        self.target = c.force;
                    }
                    Ok(false)
                }
            },
            ProcessMode::Release => {
                match self.phase {
                    ProcessPhase::Approach | ProcessPhase::Ramp | ProcessPhase::Pressing => {
                        self.phase = ProcessPhase::Release;
                        self.ramp = c.ramp.max(0.0);
                        self.release = if self.guard.had_contact {
                            let floor = self.cfg.entry_force.min(self.sp);
                            self.rate = self.ramp_rate(self.sp, floor);
                            Release::RampDown
                        } else {
                            Release::Return
                        };
                    }
                    _ => {}
                }
                Ok(false)
            }
            ProcessMode::Unknown(_) => unreachable!("refused by check"),
        }
    }

    /// Move the set-point one step along its ramp (none before contact).
    pub fn ramp_step(&mut self, dt: f64) {
        let to = match (self.phase, self.release) {
            (ProcessPhase::Release, Release::RampDown) => self.cfg.entry_force.min(self.target),
            (ProcessPhase::Approach, _) => return,
            _ => self.target,
        };
        let d = self.rate * dt;
        self.sp += (to - self.sp).clamp(-d, d);
    }

    /// What to do with the command this cycle.
    pub fn act(&self) -> Act {
        match (self.phase, self.release) {
            (ProcessPhase::Off, _) => Act::MoveTo { target: 0.0 },
            (ProcessPhase::Fault, _) => Act::MoveTo {
                target: self.retract_target,
            },
            (ProcessPhase::Release, Release::Lift { target }) => Act::MoveTo { target },
            (ProcessPhase::Release, Release::Return) => Act::MoveTo { target: 0.0 },
            _ => Act::Control,
        }
    }

    /// After a law step: contact, ramp end, `PRESSING`, contact loss. `Err` is a fault to latch.
    pub fn after_step(&mut self, out: &Output, f: f64, dt: f64) -> Result<(), Tripped> {
        let touch = self.guard.check(&self.cfg, out, f, self.target, dt)?;
        match (self.phase, touch) {
            (ProcessPhase::Ramp | ProcessPhase::Pressing, Touch::Approach) => {
                // The law took the contact back (a touch-down that bounced before its stiffness was
                // known, a noise spike in free air) and approaches again: so does the pass, and a
                // ramp starts over from the next contact.
                self.phase = ProcessPhase::Approach;
                if self.ramp > 0.0 {
                    self.sp = self.cfg.entry_force.min(self.target);
                    self.rate = self.ramp_rate(self.sp, self.target);
                }
            }
            (ProcessPhase::Approach, Touch::Contact) => {
                self.phase = ProcessPhase::Ramp;
                if self.ramp > 0.0 {
                    self.sp = f.clamp(self.sp.min(self.target), self.target);
                    self.rate = self.ramp_rate(self.sp, self.target);
                }
            }
            (ProcessPhase::Ramp, _)
                if self.sp == self.target
                    && (self.guard.f_filt - self.target).abs()
                        <= self.cfg.tolerance * self.target =>
            {
                self.phase = ProcessPhase::Pressing;
            }
            _ => {}
        }
        Ok(())
    }

    /// A RELEASE whose set-point has ramped down lifts off: `lift` beyond the command `cmd`, within
    /// the floor.
    pub fn lift_off(&mut self, cmd: f64) {
        self.release = Release::Lift {
            target: (cmd - self.lift).max(self.floor),
        };
    }

    /// True once a RELEASE's set-point has ramped down: the tool lifts off next.
    pub fn release_ramp_done(&self) -> bool {
        self.phase == ProcessPhase::Release
            && self.release == Release::RampDown
            && self.sp <= self.cfg.entry_force.min(self.target)
    }

    /// A move of the command reached its target: the next stage.
    pub fn arrived(&mut self) {
        if self.phase == ProcessPhase::Release {
            match self.release {
                Release::Lift { .. } => self.release = Release::Return,
                Release::Return => self.phase = ProcessPhase::Off,
                Release::RampDown => {}
            }
        }
    }
}

#[cfg(test)]
mod tests;
