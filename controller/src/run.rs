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
//! After an early end — a fault, the robot program's abort, the operator's stop — while the link
//! stands, the correction first returns to the programmed path ([`Cycler::unwind`]: at the retract
//! speed, never towards the part; every cycle of it goes to the sink). Wherever the link still
//! stands, the robot's correction motion is then ended cleanly with [`Cycler::stop`] (one more cycle answered with `stop` set, carrying the latched fault where the link
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
    /// After an early end, while the link stands: answer one cycle stepping the correction back
    /// towards the programmed path (never towards the part); `Ok(None)` once it is there (default:
    /// a cycler that commands nothing is always there).
    fn unwind(&mut self) -> Result<Option<CycleReport>, Self::Error> {
        Ok(None)
    }
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
    fn unwind(&mut self) -> Result<Option<CycleReport>, Self::Error> {
        ControlLoop::unwind(self)
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
    /// Take one cycle of the return to the programmed path after the run ended early
    /// ([`Cycler::unwind`]): it happened and is recorded, but it is no longer the run's control
    /// (default: [`record`](Self::record) it, its verdict ignored).
    fn unwound(&mut self, report: &CycleReport) {
        self.record(report);
    }
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

/// The most cycles the return after an early end answers (over half an hour at 4 ms): a cycler that
/// never reports home is cut off here and `Stop` is sent where it stands.
pub const MAX_UNWIND_CYCLES: u64 = 500_000;

/// After an early end, bring the correction back to the programmed path before `Stop`: every cycle
/// of the return goes to `sink` as any other (its result is not a verdict: the run has ended).
/// An error when the link failed on the way (no `Stop` can follow); `Ok` when it is home (or
/// [`MAX_UNWIND_CYCLES`] passed).
fn unwind<C: Cycler>(cycler: &mut C, sink: &mut dyn Sink) -> Result<(), C::Error> {
    for _ in 0..MAX_UNWIND_CYCLES {
        match cycler.unwind()? {
            Some(r) => sink.unwound(&r),
            None => return Ok(()),
        }
    }
    Ok(())
}

impl<E: fmt::Display> Outcome<E> {
    /// The real reason the `Stop` was or was not sent, for the end message: `sent`, or `not sent`
    /// and why (no cycle was ever answered, the robot was gone, or the stop's own error, e.g. a
    /// configuration without a `Stop` channel).
    pub fn stop_note(&self) -> String {
        match &self.stop {
            Some(Ok(())) => "sent".into(),
            _ if self.cycles == 0 => "not sent (no robot cycle to answer)".into(),
            Some(Err(e)) => format!("not sent: {e}"),
            None => match &self.end {
                End::RobotEnded(_) => {
                    "not sent (the robot had ended its session: no cycle left to answer)".into()
                }
                _ => "not sent (the robot link was gone: no cycle left to answer)".into(),
            },
        }
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
                let long_enough = limits.duration.is_some_and(|d| r.cycle.t >= d) && !robot_owns;
                if !more || cycler.done() || long_enough {
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
        End::Fault(_) | End::Program(Some(_)) | End::Stopped(_) => match unwind(cycler, sink) {
            Ok(()) => Some(cycler.stop()),
            Err(e) => Some(Err(e)),
        },
        End::Done | End::Program(None) => Some(cycler.stop()),
    };
    Outcome {
        end,
        stop,
        cycles: cycler.cycles(),
    }
}

#[cfg(test)]
mod stop_note_tests {
    use super::*;

    #[test]
    fn the_stop_note_gives_the_stops_own_reason_once_cycles_were_answered() {
        let o = |stop, cycles| Outcome::<&str> {
            end: End::Done,
            stop,
            cycles,
        };
        // A configuration without a Stop channel after 3001 answered cycles: that is the reason.
        let n = o(
            Some(Err("cannot stop: this configuration has no Stop channel")),
            3001,
        )
        .stop_note();
        assert!(n.contains("no Stop channel"), "{n}");
        assert!(!n.contains("no robot cycle"), "{n}");
        assert_eq!(o(Some(Ok(())), 5).stop_note(), "sent");
        let n = o(Some(Err("no cycle")), 0).stop_note();
        assert!(n.contains("no robot cycle to answer"), "{n}");
        let gone = Outcome::<&str> {
            end: End::LinkLost("silent"),
            stop: None,
            cycles: 10,
        };
        assert!(gone.stop_note().contains("link was gone"));
        // Interrupted before the first datagram: nothing was ever answered.
        let never = Outcome::<&str> {
            end: End::Stopped(Some("silent")),
            stop: None,
            cycles: 0,
        };
        assert_eq!(never.stop_note(), "not sent (no robot cycle to answer)");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::law::Output;
    use hal::{Correction, Cycle, Pose, ProcessCommand, ProcessMode};

    /// What a scripted cycle does.
    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Step {
        Ok,
        /// Answered, carrying a process command.
        Process,
        /// The robot link is gone.
        Gone,
        /// A fault that backed the tool off (the link stands).
        Fault,
    }

    #[derive(Debug, PartialEq)]
    enum Err {
        Gone,
        Fault,
    }

    impl fmt::Display for Err {
        fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            write!(f, "{self:?}")
        }
    }

    /// A cycler that plays a script (then answers `Ok` forever), 4 ms a cycle.
    struct Script {
        steps: Vec<Step>,
        k: usize,
        answered: u64,
        stops: u32,
        stop_fails: bool,
        /// Cycles the return to the path takes once asked (then it is home).
        away: u32,
        /// The return's cycles answered, and whether each came before any `Stop`.
        unwound: Vec<bool>,
    }

    impl Script {
        fn new(steps: &[Step]) -> Self {
            Self {
                steps: steps.to_vec(),
                k: 0,
                answered: 0,
                stops: 0,
                stop_fails: false,
                away: 0,
                unwound: Vec::new(),
            }
        }
    }

    fn report(k: usize, process: bool) -> CycleReport {
        CycleReport {
            cycle: Cycle {
                seq: k as u64,
                t: k as f64 * 0.004,
                period: 0.004,
                actual: Pose::identity(),
                programmed: Pose::identity(),
                late_replies: 0,
                missed: 0,
                replied_late: 0,
                new_session: k == 0,
                process: process.then_some(ProcessCommand {
                    mode: ProcessMode::Press,
                    force: 10.0,
                    ramp: 0.0,
                    segment: 1,
                }),
            },
            x: 0.0,
            f: Some(0.0),
            sample: None,
            wrench: None,
            compensated: false,
            out: Output::default(),
            command: Correction::default(),
            set_point: 0.0,
            fault: None,
            rezero: None,
        }
    }

    impl Cycler for Script {
        type Error = Err;
        fn cycle(&mut self) -> Result<CycleReport, Err> {
            let step = self.steps.get(self.k).copied().unwrap_or(Step::Ok);
            let k = self.k;
            self.k += 1;
            match step {
                Step::Gone => Err(Err::Gone),
                Step::Fault => {
                    self.answered += 1;
                    Err(Err::Fault)
                }
                Step::Ok | Step::Process => {
                    self.answered += 1;
                    Ok(report(k, step == Step::Process))
                }
            }
        }
        fn stop(&mut self) -> Result<(), Err> {
            self.stops += 1;
            if self.stop_fails {
                return Err(Err::Gone);
            }
            self.answered += 1;
            Ok(())
        }
        fn robot_gone(e: &Err) -> bool {
            *e == Err::Gone
        }
        fn cycles(&self) -> u64 {
            self.answered
        }
        fn unwind(&mut self) -> Result<Option<CycleReport>, Err> {
            if self.away == 0 {
                return Ok(None);
            }
            self.away -= 1;
            self.answered += 1;
            self.unwound.push(self.stops == 0);
            Ok(Some(report(self.k, false)))
        }
    }

    fn limits(cycles: Option<u64>) -> RunLimits<'static> {
        RunLimits {
            cycles,
            ..RunLimits::default()
        }
    }

    #[test]
    fn a_cycle_count_runs_that_many_cycles_then_stops_the_robot_once() {
        let mut c = Script::new(&[]);
        let mut seen = Vec::new();
        let o = run(&mut c, limits(Some(5)), &mut seen);
        assert!(matches!(o.end, End::Done), "{}", o.end);
        assert_eq!(seen.len(), 5);
        assert_eq!((c.stops, o.cycles), (1, 6), "5 cycles and the Stop cycle");
        assert!(o.stopped() && !o.end.is_early());
    }

    #[test]
    fn a_duration_ends_after_the_cycle_that_reaches_it() {
        let mut c = Script::new(&[]);
        let mut seen = Vec::new();
        let l = RunLimits {
            duration: Some(0.010),
            ..RunLimits::default()
        };
        let o = run(&mut c, l, &mut seen);
        assert!(matches!(o.end, End::Done));
        // t = 0, 4, 8, 12 ms: the fourth cycle reaches 10 ms.
        assert_eq!(seen.len(), 4);
        assert_eq!(c.stops, 1);
    }

    #[test]
    fn the_operators_stop_ends_before_the_next_cycle_with_a_stop() {
        let flag = AtomicBool::new(false);
        let mut c = Script::new(&[]);
        let mut n = 0;
        let l = RunLimits {
            stop: Some(&flag),
            ..RunLimits::default()
        };
        let o = run(
            &mut c,
            l,
            &mut Each(|_: &CycleReport| {
                n += 1;
                if n == 3 {
                    flag.store(true, Ordering::Relaxed);
                }
                true
            }),
        );
        assert!(matches!(o.end, End::Stopped(None)), "{}", o.end);
        assert_eq!(n, 3);
        assert!(o.stopped());
    }

    #[test]
    fn a_wait_the_stop_interrupted_sends_no_stop_to_a_gone_link() {
        let flag = AtomicBool::new(true);
        // The flag is checked before the cycle: set it during the wait instead.
        struct Interrupted<'a>(Script, &'a AtomicBool);
        impl Cycler for Interrupted<'_> {
            type Error = Err;
            fn cycle(&mut self) -> Result<CycleReport, Err> {
                self.1.store(true, Ordering::Relaxed);
                Err(Err::Gone)
            }
            fn stop(&mut self) -> Result<(), Err> {
                self.0.stop()
            }
            fn robot_gone(e: &Err) -> bool {
                Script::robot_gone(e)
            }
            fn cycles(&self) -> u64 {
                self.0.cycles()
            }
        }
        flag.store(false, Ordering::Relaxed);
        let mut c = Interrupted(Script::new(&[]), &flag);
        let l = RunLimits {
            stop: Some(&flag),
            ..RunLimits::default()
        };
        let o = run(&mut c, l, &mut ());
        assert!(matches!(o.end, End::Stopped(Some(Err::Gone))), "{}", o.end);
        assert!(o.stop.is_none());
        assert_eq!(c.0.stops, 0);
    }

    #[test]
    fn a_lost_link_is_an_early_end_without_stop_unless_the_robot_owns_the_session() {
        let mut c = Script::new(&[Step::Ok, Step::Ok, Step::Gone]);
        let o = run(&mut c, limits(Some(10)), &mut ());
        assert!(matches!(o.end, End::LinkLost(Err::Gone)));
        assert!(o.end.is_early() && o.stop.is_none());
        assert_eq!(c.stops, 0);

        let mut c = Script::new(&[Step::Ok, Step::Ok, Step::Gone]);
        let l = RunLimits {
            robot_session: RobotSession::Robot,
            ..RunLimits::default()
        };
        let o = run(&mut c, l, &mut ());
        assert!(matches!(o.end, End::RobotEnded(Err::Gone)), "{}", o.end);
        assert!(!o.end.is_early() && o.stop.is_none());

        // Silent from the first cycle: never a session, so a lost link even when the robot owns it.
        let mut c = Script::new(&[Step::Gone]);
        let o = run(&mut c, l, &mut ());
        assert!(matches!(o.end, End::LinkLost(_)), "{}", o.end);
    }

    /// After a fault, a program's abort or the operator's stop the correction returns to the path
    /// (every cycle of it to the sink) before `Stop`; a run that ends normally stops where it is.
    #[test]
    fn an_early_end_returns_to_the_path_before_the_stop() {
        struct Aborts(usize, Vec<CycleReport>);
        impl Sink for Aborts {
            fn record(&mut self, r: &CycleReport) -> bool {
                self.1.push(*r);
                true
            }
            fn program(&mut self) -> Program {
                if self.1.len() >= self.0 {
                    Program::Aborted("FAULT 5".into())
                } else {
                    Program::Running
                }
            }
        }
        let mut c = Script::new(&[Step::Ok, Step::Ok, Step::Fault]);
        c.away = 4;
        let mut seen = Vec::new();
        let o = run(&mut c, limits(Some(10)), &mut seen);
        assert!(matches!(o.end, End::Fault(Err::Fault)), "{}", o.end);
        assert_eq!(
            c.unwound, [true; 4],
            "four return cycles, all before the Stop"
        );
        assert_eq!((seen.len(), c.stops), (2 + 4, 1));
        assert_eq!(o.cycles, 3 + 4 + 1);

        let mut c = Script::new(&[]);
        c.away = 2;
        let mut sink = Aborts(3, Vec::new());
        let o = run(&mut c, limits(Some(10)), &mut sink);
        assert!(matches!(o.end, End::Program(Some(_))), "{}", o.end);
        assert_eq!((sink.1.len(), c.unwound.len(), c.stops), (5, 2, 1));

        let stop = AtomicBool::new(true);
        let mut c = Script::new(&[]);
        c.away = 3;
        let l = RunLimits {
            stop: Some(&stop),
            ..limits(None)
        };
        let o = run(&mut c, l, &mut ());
        assert!(matches!(o.end, End::Stopped(None)), "{}", o.end);
        assert_eq!((c.unwound.len(), c.stops), (3, 1));

        // A normal end: no return.
        let mut c = Script::new(&[]);
        c.away = 3;
        let o = run(&mut c, limits(Some(5)), &mut ());
        assert!(matches!(o.end, End::Done));
        assert_eq!((c.unwound.len(), c.stops, o.cycles), (0, 1, 6));
    }

    #[test]
    fn a_robot_running_its_own_process_outlasts_the_cycle_count() {
        let mut script = vec![Step::Process; 8];
        script.push(Step::Gone);
        let mut c = Script::new(&script);
        let mut seen = Vec::new();
        let l = RunLimits {
            cycles: Some(3),
            robot_session: RobotSession::RobotWhenProcess,
            ..RunLimits::default()
        };
        let o = run(&mut c, l, &mut seen);
        assert!(matches!(o.end, End::RobotEnded(_)), "{}", o.end);
        assert_eq!(seen.len(), 8);

        // Without process commands the count applies.
        let mut c = Script::new(&[]);
        let o = run(&mut c, l, &mut ());
        assert!(matches!(o.end, End::Done));
        assert_eq!(o.cycles, 4);
    }

    #[test]
    fn a_fault_ends_early_and_the_robot_still_gets_its_stop() {
        let mut c = Script::new(&[Step::Ok, Step::Fault]);
        let o = run(&mut c, limits(Some(10)), &mut ());
        assert!(matches!(o.end, End::Fault(Err::Fault)));
        assert!(o.end.is_early() && o.stopped());

        let mut c = Script::new(&[Step::Fault]);
        c.stop_fails = true;
        let o = run(&mut c, limits(Some(10)), &mut ());
        assert!(matches!(o.stop, Some(Err(Err::Gone))));
        assert!(!o.stopped());
    }

    #[test]
    fn the_program_and_the_sink_end_the_run() {
        struct Prog(u32, Option<&'static str>);
        impl Sink for Prog {
            fn record(&mut self, _: &CycleReport) -> bool {
                self.0 += 1;
                true
            }
            fn program(&mut self) -> Program {
                match (self.0, self.1) {
                    (0..3, _) => Program::Running,
                    (_, None) => Program::Done,
                    (_, Some(why)) => Program::Aborted(why.into()),
                }
            }
        }
        let mut c = Script::new(&[]);
        let o = run(&mut c, limits(Some(10)), &mut Prog(0, None));
        assert!(matches!(o.end, End::Program(None)));
        assert!(!o.end.is_early() && o.stopped());
        let mut c = Script::new(&[]);
        let o = run(&mut c, limits(Some(10)), &mut Prog(0, Some("timeout")));
        assert!(matches!(&o.end, End::Program(Some(w)) if w == "timeout"));
        assert!(o.end.is_early());
        assert_eq!(o.end.to_string(), "the robot program aborted: timeout");

        let mut c = Script::new(&[]);
        let mut n = 0;
        let o = run(
            &mut c,
            limits(Some(10)),
            &mut Each(|_: &CycleReport| {
                n += 1;
                n < 2
            }),
        );
        assert!(matches!(o.end, End::Done));
        assert_eq!(n, 2);
    }
}
