//! The force process's contract (`hal::process`) over EGM.
//!
//! # Command: RAPID program → forcecell, in `EgmRobot.RAPIDfromRobot.dnum`
//! Four numbers from a configured index on ([`CommandSlots`], default 0): `dnum[i]` mode (0 OFF,
//! 1 PRESS, 2 RELEASE), `dnum[i+1]` force in N, `dnum[i+2]` ramp in s, `dnum[i+3]` segment number. The
//! RAPID program sets them with `EGMSetupUC`'s data exchange (RobotWare versions with `RAPIDfromRobot`;
//! older layouts lack field 13 and cannot carry the command). Bad input is never a default: fewer numbers
//! than needed, a NaN or infinite one, a fractional mode or segment, a negative ramp → the datagram is
//! malformed. A whole mode outside 0..2 is delivered as [`ProcessMode::Unknown`] (the process faults with
//! "bad command").
//!
//! # State: forcecell → RAPID program, NOT in the path correction
//! `EgmSensorPathCorr` has a header and the correction and nothing else: the reply cannot carry data to
//! RAPID (`RAPIDtoRobot` exists only in `EgmSensor`, position guidance, which a path-correction session
//! does not read). The state therefore goes back on a second channel, on change only: a
//! [`StateChannel`] the link calls from `reply` whenever the state differs from the one last published,
//! before the correction is sent. Its numbers for RAPID are [`state_to_numbers`]: phase code, force in
//! N, fault code. To a controller they go over Robot Web Services 2.0 (RobotWare 7, HTTPS:
//! [`crate::rws`], [`crate::rws_channel`]), written to three `PERS num` that the program's bounded
//! `WaitUntil`s read (a request takes milliseconds, well inside a phase change but nothing for every
//! cycle). The simulated IRC5 serves the same requests (`forcecell-sim`'s `rws` module) and also takes
//! the channel in process as its RAPID variables.

use core::fmt;

use hal::{ProcessCommand, ProcessFault, ProcessMode, ProcessPhase, ProcessState};

/// Where the command lies in `RAPIDfromRobot.dnum` (default: from index 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct CommandSlots {
    /// Index of the mode; force, ramp and segment follow.
    pub first: usize,
}

/// Numbers of the command.
pub const COMMAND_NUMBERS: usize = 4;
/// Numbers of the state.
pub const STATE_NUMBERS: usize = 3;
/// Largest magnitude of a mode or segment number accepted (exactly representable in a double).
const MAX_INTEGER: f64 = 9.0e15;

/// A command or state that breaks the contract.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ProcessError {
    /// `dnum` holds fewer numbers than the slots need.
    Missing {
        /// Numbers needed (index of the last + 1).
        need: usize,
        /// Numbers received.
        got: usize,
    },
    /// A number is NaN or infinite.
    NonFinite,
    /// The mode or segment is not a whole number.
    NotWhole(f64),
    /// A negative ramp time.
    NegativeRamp(f64),
    /// A phase code the contract does not define (robot side).
    BadState(f64),
    /// A fault code the contract does not define (robot side).
    BadFault(f64),
}

impl fmt::Display for ProcessError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Missing { need, got } => write!(
                f,
                "RAPIDfromRobot.dnum has {got} numbers; the process command needs {need}"
            ),
            Self::NonFinite => f.write_str("a process number is NaN or infinite"),
            Self::NotWhole(v) => write!(f, "process mode/segment {v} is not a whole number"),
            Self::NegativeRamp(v) => write!(f, "process ramp {v} s is negative"),
            Self::BadState(v) => write!(f, "process phase {v} is not one of 0 1 2 3 4 9"),
            Self::BadFault(v) => write!(f, "process fault {v} is not one of 0..6"),
        }
    }
}

impl std::error::Error for ProcessError {}

fn whole(v: f64) -> Result<i64, ProcessError> {
    if !v.is_finite() {
        Err(ProcessError::NonFinite)
    } else if v.fract() != 0.0 || v.abs() > MAX_INTEGER {
        Err(ProcessError::NotWhole(v))
    } else {
        Ok(v as i64)
    }
}

impl CommandSlots {
    /// Numbers `dnum` must hold.
    pub fn needs(&self) -> usize {
        self.first + COMMAND_NUMBERS
    }

    /// The command in `dnum` (SI: N, s).
    pub fn decode(&self, dnum: &[f64]) -> Result<ProcessCommand, ProcessError> {
        let Some(v) = dnum.get(self.first..self.needs()) else {
            return Err(ProcessError::Missing {
                need: self.needs(),
                got: dnum.len(),
            });
        };
        if !v.iter().all(|x| x.is_finite()) {
            return Err(ProcessError::NonFinite);
        }
        if v[2] < 0.0 {
            return Err(ProcessError::NegativeRamp(v[2]));
        }
        Ok(ProcessCommand {
            mode: ProcessMode::from_code(whole(v[0])?),
            force: v[1],
            ramp: v[2],
            segment: whole(v[3])?,
        })
    }

    /// Write `cmd` into `dnum` (grown with zeros as needed): the robot side.
    pub fn encode(&self, cmd: &ProcessCommand, dnum: &mut Vec<f64>) {
        if dnum.len() < self.needs() {
            dnum.resize(self.needs(), 0.0);
        }
        dnum[self.first..self.needs()].copy_from_slice(&[
            cmd.mode.code() as f64,
            cmd.force,
            cmd.ramp,
            cmd.segment as f64,
        ]);
    }
}

/// The state as the RAPID program reads it: phase code, force in N (0 when unknown: never NaN), fault code.
pub fn state_to_numbers(s: &ProcessState) -> [f64; STATE_NUMBERS] {
    let force = if s.force.is_finite() { s.force } else { 0.0 };
    [s.phase.code() as f64, force, s.fault.code() as f64]
}

/// The state from RAPID's three numbers (the robot side judges what it was given).
pub fn state_from_numbers(v: [f64; STATE_NUMBERS]) -> Result<ProcessState, ProcessError> {
    if !v.iter().all(|x| x.is_finite()) {
        return Err(ProcessError::NonFinite);
    }
    let phase = ProcessPhase::from_code(whole(v[0])?).ok_or(ProcessError::BadState(v[0]))?;
    let fault = ProcessFault::from_code(whole(v[2])?).ok_or(ProcessError::BadFault(v[2]))?;
    Ok(ProcessState {
        phase,
        force: v[1],
        fault,
    })
}

/// Where the link publishes the process state for the RAPID program: called from `reply`, only when
/// the state changed, before the correction is sent. Slow transports are fine (a phase changes a few
/// times per pass); an error is reported by the link and the same state is tried again next cycle.
pub trait StateChannel: Send {
    /// Publish `state`.
    fn publish(&mut self, state: &ProcessState) -> Result<(), String>;

    /// One line on what the channel did, for the end of a run (`None`: nothing to say).
    fn report(&self) -> Option<String> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn press() -> ProcessCommand {
        ProcessCommand {
            mode: ProcessMode::Press,
            force: 20.0,
            ramp: 0.5,
            segment: 3,
        }
    }

    #[test]
    fn command_round_trips_at_any_offset() {
        for first in [0, 2] {
            let s = CommandSlots { first };
            let mut dnum = vec![7.0];
            s.encode(&press(), &mut dnum);
            assert_eq!(dnum.len(), first + 4);
            assert_eq!(s.decode(&dnum), Ok(press()));
        }
        assert_eq!(
            CommandSlots::default()
                .decode(&[5.0, 0.0, 0.0, 1.0])
                .unwrap()
                .mode,
            ProcessMode::Unknown(5)
        );
    }

    #[test]
    fn a_bad_command_is_an_error_never_a_default() {
        let s = CommandSlots::default();
        assert_eq!(
            s.decode(&[1.0, 20.0, 0.5]),
            Err(ProcessError::Missing { need: 4, got: 3 })
        );
        assert_eq!(
            s.decode(&[1.5, 20.0, 0.5, 1.0]),
            Err(ProcessError::NotWhole(1.5))
        );
        assert_eq!(
            s.decode(&[1.0, f64::NAN, 0.5, 1.0]),
            Err(ProcessError::NonFinite)
        );
        assert_eq!(
            s.decode(&[1.0, 20.0, -1.0, 1.0]),
            Err(ProcessError::NegativeRamp(-1.0))
        );
        assert_eq!(
            s.decode(&[1.0, 20.0, 0.5, 1e300]),
            Err(ProcessError::NotWhole(1e300))
        );
    }

    #[test]
    fn state_numbers_round_trip_and_nan_force_is_zero() {
        let s = ProcessState {
            phase: ProcessPhase::Fault,
            force: f64::NAN,
            fault: ProcessFault::ForceLimit,
        };
        let n = state_to_numbers(&s);
        assert_eq!(n, [9.0, 0.0, 2.0]);
        let back = state_from_numbers(n).unwrap();
        assert_eq!(
            (back.phase, back.fault, back.force),
            (s.phase, s.fault, 0.0)
        );
        assert_eq!(
            state_from_numbers([5.0, 0.0, 0.0]),
            Err(ProcessError::BadState(5.0))
        );
        assert_eq!(
            state_from_numbers([0.0, 0.0, 7.0]),
            Err(ProcessError::BadFault(7.0))
        );
    }
}
