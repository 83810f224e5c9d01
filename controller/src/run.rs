//! The one run loop: start, cycle, end conditions, stop policy, and the hand-over of every cycle's
//! report to a sink. `forcecell sim`, `run`, `calibrate`, `bench-scenarios` and the closed-loop tests
//! are configurations of [`run`], not copies of it.
//!
//! What is stepped each cycle is a [`Cycler`]: the [`ControlLoop`] (force control), or a calibration
//! collector that answers zero corrections. The runner knows nothing of either beyond that trait.
//!
//! # End conditions, checked in this order
//! 1. **the operator's stop** ([`RunLimits::stop`], SIGINT/SIGTERM) — checked before each cycle;
//! 2. **the robot program's end** ([`Sink::program`], a simulated program's `RSI_OFF`) — before each cycle;
//! 3. **the length** — a number of cycles ([`RunLimits::cycles`]) before each cycle, a span of robot time
//!    ([`RunLimits::duration`]) after each answered cycle, or the sink's own verdict ([`Sink::record`]);
//! 4. **the loop's own end** — a fault that backed the tool off ([`Cycler::cycle`] errs, the link
//!    stands), or the robot link failing (errs, the link is gone).
//!
//! # Stop policy
//! Wherever the link still stands, the robot's correction motion is ended cleanly with
//! [`Cycler::stop`] (one more cycle answered with `stop` set, carrying the latched fault where the link
//! has process channels). A failed robot link has no one left to tell. A robot link that falls silent
//! after its first cycle is the normal end of a run whose robot owns the session
//! ([`RunLimits::robot_session`]); everywhere else it is [`End::LinkLost`].

use core::fmt;
use std::sync::atomic::{AtomicBool, Ordering};

use hal::{ForceSensor, RobotLink};

use crate::control_loop::{ControlLoop, CycleReport, LoopError};
use crate::law::CellLaw;

/// One cycle's work for the runner: answer the robot exactly once and report what happened.
pub trait Cycler {
    /// Why a cycle could not be answered or the loop ended.
    type Error: fmt::Display;
    /// Wait for the robot's next cycle and answer it.
    fn cycle(&mut self) -> Result<CycleReport, Self::Error>;
    /// End the robot's correction motion cleanly: answer the next cycle with `stop` set.
    fn stop(&mut self) -> Result<(), Self::Error>;
    /// True when `e` means the robot link is gone (nothing left to answer, no `Stop` to send).
    fn robot_gone(e: &Self::Error) -> bool;
    /// Cycles answered so far.
    fn cycles(&self) -> u64;
    /// True when the cycler's own work is done (a calibration that has its poses): the run then
    /// ends normally after the cycle just answered.
    fn done(&self) -> bool {
        false
    }
}

impl<R: RobotLink, S: ForceSensor, L: CellLaw> Cycler for ControlLoop<R, S, L> {
    type Error = LoopError<R::Error, S::Error>;
    fn cycle(&mut self) -> Result<CycleReport, Self::Error> {
        ControlLoop::cycle(self)
    }
    fn stop(&mut self) -> Result<(), Self::Error> {
        ControlLoop::stop(self)
    }
    fn robot_gone(e: &Self::Error) -> bool {
        matches!(e, LoopError::Robot(_))
    }
    fn cycles(&self) -> u64 {
        self.stats().cycles
    }
}

/// A robot program's state, for runs whose robot program the runner can see (a simulation).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Program {
    /// Running (or no program is watched).
    Running,
    /// Ended normally (its `RSI_OFF`).
    Done,
    /// Ended early, with the reason.
    Aborted(String),
}

/// Where every answered cycle goes, and what the application watches between cycles.
pub trait Sink {
    /// Take one answered cycle's report. Return `false` to end the run normally after this cycle
    /// (the sink's own length: a calibration that has its poses).
    fn record(&mut self, report: &CycleReport) -> bool;
    /// The robot program's state, checked before each cycle (default: none watched).
    fn program(&mut self) -> Program {
        Program::Running
    }
}

/// A sink that keeps nothing.
impl Sink for () {
    fn record(&mut self, _: &CycleReport) -> bool {
        true
    }
}

/// Every report of a run, in order.
impl Sink for Vec<CycleReport> {
    fn record(&mut self, report: &CycleReport) -> bool {
        self.push(*report);
        true
    }
}

/// A closure as a sink: called with every report; `false` ends the run after that cycle.
pub struct Each<F>(pub F);

impl<F: FnMut(&CycleReport) -> bool> Sink for Each<F> {
    fn record(&mut self, report: &CycleReport) -> bool {
        (self.0)(report)
    }
}

/// How long a run lasts, and who may end it.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunLimits<'a> {
    /// At most this many cycles (checked before each cycle); `None`: no count.
    pub cycles: Option<u64>,
    /// Until the robot's time reaches this many seconds (checked after each answered cycle).
    pub duration: Option<f64>,
    /// The operator's stop flag.
    pub stop: Option<&'a AtomicBool>,
    /// Who owns the robot session.
    pub robot_session: RobotSession,
}

/// Whether the robot falling silent is the normal end of the run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RobotSession {
    /// The run owns it: the robot falling silent is [`End::LinkLost`].
    #[default]
    Run,
    /// The robot owns it: falling silent after its first cycle ends the run normally.
    Robot,
    /// The robot owns it once it sends process commands (an outside robot running its own program):
    /// from then on the cycle count no longer applies and its silence ends the run normally.
    RobotWhenProcess,
}

/// Why a run ended.
#[derive(Debug)]
pub enum End<E> {
    /// The length was done: the cycle count, the robot-time duration, or the sink's own verdict.
    Done,
    /// The robot program ended; `Some` with the reason when it aborted.
    Program(Option<String>),
    /// The robot ended a session it owns ([`RobotSession`]): the error its link reported.
    RobotEnded(E),
    /// The operator's stop. `Some` with the error when it interrupted a wait for the robot.
    Stopped(Option<E>),
    /// The loop ended on a fault after backing the tool off (the link still stands).
    Fault(E),
    /// The robot link failed.
    LinkLost(E),
}

impl<E> End<E> {
    /// True for the ends a user did not ask for: a fault, a lost link, an aborted program.
    pub fn is_early(&self) -> bool {
        matches!(
            self,
            Self::Fault(_) | Self::LinkLost(_) | Self::Program(Some(_))
        )
    }
}

impl<E: fmt::Display> fmt::Display for End<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Done => f.write_str("the run's length was done"),
            Self::Program(None) => f.write_str("the robot program ended"),
            Self::Program(Some(why)) => write!(f, "the robot program aborted: {why}"),
            Self::RobotEnded(e) => write!(f, "the robot ended its session ({e})"),
            Self::Stopped(None) => f.write_str("stopped by the operator"),
            Self::Stopped(Some(e)) => write!(f, "stopped by the operator: {e}"),
            Self::Fault(e) | Self::LinkLost(e) => write!(f, "{e}"),
        }
    }
}

/// What a run did.
#[derive(Debug)]
pub struct Outcome<E> {
    /// Why it ended.
    pub end: End<E>,
    /// The clean `Stop` at the end: `None` when none was due (the link was gone), else whether it
    /// went out.
    pub stop: Option<Result<(), E>>,
    /// Cycles answered (the `Stop` cycle included).
    pub cycles: u64,
}

impl<E> Outcome<E> {
    /// True when the robot got its `Stop`.
    pub fn stopped(&self) -> bool {
        matches!(self.stop, Some(Ok(())))
    }
}

/// Run `cycler` until an end condition holds, hand every answered cycle to `sink`, and end the
/// robot's correction motion cleanly wherever the link still stands.
pub fn run<C: Cycler>(
    cycler: &mut C,
    limits: RunLimits<'_>,
    sink: &mut dyn Sink,
) -> Outcome<C::Error> {
    let stopped = || limits.stop.is_some_and(|s| s.load(Ordering::Relaxed));
    let mut robot_owns = limits.robot_session == RobotSession::Robot;
    let mut k = 0u64;
    let end = loop {
        if stopped() {
            break End::Stopped(None);
        }
        match sink.program() {
            Program::Running => {}
            Program::Done => break End::Program(None),
            Program::Aborted(why) => break End::Program(Some(why)),
        }
        if limits.cycles.is_some_and(|n| k >= n) && !robot_owns {
            break End::Done;
        }
        k += 1;
        match cycler.cycle() {
            Ok(r) => {
                if limits.robot_session == RobotSession::RobotWhenProcess {
                    robot_owns = r.cycle.process.is_some();
                }
                let more = sink.record(&r);
                if !more || cycler.done() || limits.duration.is_some_and(|d| r.cycle.t >= d) {
                    break End::Done;
                }
            }
            Err(e) if stopped() => break End::Stopped(Some(e)),
            Err(e) if C::robot_gone(&e) => {
                break if robot_owns && cycler.cycles() > 0 {
                    End::RobotEnded(e)
                } else {
                    End::LinkLost(e)
                };
            }
            Err(e) => break End::Fault(e),
        }
    };
    let stop = match &end {
        End::RobotEnded(_) | End::LinkLost(_) => None,
        End::Stopped(Some(e)) if C::robot_gone(e) => None,
        _ => Some(cycler.stop()),
    };
    Outcome {
        end,
        stop,
        cycles: cycler.cycles(),
    }
}
