//! What `run` says while it runs ([`Printer`], on its own thread): a status line a few times a second — the process phase (or the law's
//! contact state), the force against the commanded force, `k̂_c`, the robot's late replies against its
//! budget, the robot cycles that never arrived, the replies this side sent late after their datagram
//! arrived, and the cycles that met a condition. On a terminal the line is rewritten in place; elsewhere
//! (a log, a pipe) a plain line is written every few seconds. Paced on the robot's own time, so a
//! recording replayed or a test gets the same lines.

use std::fmt::Write as _;

use ::scenario::telemetry::{Coded, Condition};
use controller::CycleReport;

/// Lines a second on a terminal.
pub const TERMINAL_HZ: f64 = 4.0;
/// Seconds between plain lines when not on a terminal.
pub const LOG_PERIOD: f64 = 5.0;

/// The status line's state: when it last printed and what it has counted since the start.
#[derive(Clone, Debug)]
pub struct Status {
    period: f64,
    /// The robot's late-reply budget (RSI: the ETHERNET object's `Timeout`); `None` when unknown.
    budget: Option<u32>,
    next: f64,
    cycles: u64,
    conditions: u64,
    warned_half: bool,
}

impl Status {
    /// A status every `period` s of robot time, against a late-reply `budget`.
    pub fn new(period: f64, budget: Option<u32>) -> Self {
        Self {
            period,
            budget,
            next: 0.0,
            cycles: 0,
            conditions: 0,
            warned_half: false,
        }
    }

    /// Take one answered cycle. Returns the line to show when one is due, and — once — a warning when
    /// the robot's late replies pass half its budget.
    pub fn observe(&mut self, r: &CycleReport) -> (Option<String>, Option<String>) {
        let due = self.tick(r);
        (
            due.line.then(|| self.line(r)),
            due.warning.then(|| self.warning(r.cycle.late_replies)),
        )
    }

    /// Count one answered cycle and say what is due, formatting nothing (the cycle's thread calls this
    /// on every cycle: a few comparisons, no allocation, no system call).
    pub fn tick(&mut self, r: &CycleReport) -> Due {
        self.cycles += 1;
        if Condition::of(r.fault) != Condition::None {
            self.conditions += 1;
        }
        let late = r.cycle.late_replies;
        let warning = match self.budget {
            Some(b) if !self.warned_half && 2 * late >= b && b > 0 => {
                self.warned_half = true;
                true
            }
            _ => false,
        };
        let t = r.cycle.t;
        if t + 1e-9 < self.next {
            return Due {
                line: false,
                warning,
            };
        }
        // On a grid of the period from the first line: a slow cycle does not shift the lines after it.
        while self.next <= t + 1e-9 {
            self.next += self.period;
        }
        Due {
            line: true,
            warning,
        }
    }

    /// The warning for `late` late replies against the budget.
    pub fn warning(&self, late: u32) -> String {
        format!(
            "warning: the robot counts {late} late replies of the {} its Timeout allows \
             before it stops (half used): keep other load off the cycle's CPU, check the \
             real-time settings",
            self.budget.unwrap_or(0)
        )
    }

    /// The line for the cycle `r`.
    pub fn line(&self, r: &CycleReport) -> String {
        let mut s = String::new();
        let state = match r.command.process.phase {
            hal::ProcessPhase::Off if r.cycle.process.is_none() => r.out.state.name(),
            phase => phase.name(),
        };
        let _ = write!(s, "t {:7.2} s  {state:<9}", r.cycle.t);
        match r.f {
            Some(f) => {
                let _ = write!(s, "  F {f:6.2} / {:6.2} N", r.set_point);
            }
            None => {
                let _ = write!(s, "  F    —   / {:6.2} N", r.set_point);
            }
        }
        if r.out.kc_hat.is_finite() {
            let _ = write!(s, "  k̂_c {:6.1} kN/m", r.out.kc_hat * 1e-3);
        }
        let _ = write!(s, "  x {:6.2} mm", r.command.translation.z * 1e3);
        // The robot's own count (RSI `Delay`) against its Timeout; then what the link saw: cycles the
        // robot sent that never arrived (IPOC gaps), and replies that left late after their datagram
        // arrived (the kernel's receive stamp).
        match self.budget {
            Some(b) => {
                let _ = write!(s, "  robot late {} of {b}", r.cycle.late_replies);
            }
            None => {
                let _ = write!(s, "  robot late {}", r.cycle.late_replies);
            }
        }
        let _ = write!(
            s,
            "  missed {}  replied late {}",
            r.cycle.missed, r.cycle.replied_late
        );
        let _ = write!(s, "  conditions {} of {}", self.conditions, self.cycles);
        if r.command.process.phase == hal::ProcessPhase::Fault {
            let _ = write!(s, "  FAULT {}", r.command.process.fault.name());
        }
        s
    }
}

/// What one cycle made due ([`Status::tick`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Due {
    /// A status line.
    pub line: bool,
    /// The half-budget warning (once).
    pub warning: bool,
}

/// Lines the queue to the status line's thread holds.
pub const QUEUE: usize = 16;

/// The status line's own thread. The cycle counts each report itself ([`Status::tick`]: a few
/// comparisons) and hands the thread a report only when a line or the warning is due — four times a
/// second on a terminal, once in five seconds in a log — so the cycle makes no system call for the
/// status line on the other cycles (handing every report over woke the thread, a `futex` call or two
/// each cycle). The hand-over never waits: a full queue drops the line, so a slow terminal or a full
/// pipe never holds a cycle; the thread formats and prints.
pub struct Printer {
    status: Status,
    tx: Option<std::sync::mpsc::SyncSender<(CycleReport, Status, Due)>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Printer {
    /// Start the thread: a line rewritten [`TERMINAL_HZ`] times a second when stdout is a terminal,
    /// else a plain line every [`LOG_PERIOD`] s; late replies counted against `budget`.
    pub fn spawn(budget: Option<u32>) -> std::io::Result<Self> {
        use std::io::{IsTerminal, Write};
        let terminal = std::io::stdout().is_terminal();
        let period = if terminal {
            1.0 / TERMINAL_HZ
        } else {
            LOG_PERIOD
        };
        let (tx, rx) = std::sync::mpsc::sync_channel::<(CycleReport, Status, Due)>(QUEUE);
        let thread = std::thread::Builder::new()
            .name("status".into())
            .spawn(move || {
                let mut shown = false;
                for (r, status, due) in rx {
                    if due.warning {
                        if terminal && shown {
                            println!();
                        }
                        eprintln!("{}", status.warning(r.cycle.late_replies));
                    }
                    if due.line {
                        let line = status.line(&r);
                        if terminal {
                            print!("\r{line}\x1b[K");
                            let _ = std::io::stdout().flush();
                        } else {
                            println!("{line}");
                        }
                        shown = true;
                    }
                }
                if terminal && shown {
                    println!();
                }
            })?;
        Ok(Self {
            status: Status::new(period, budget),
            tx: Some(tx),
            thread: Some(thread),
        })
    }

    /// Count one answered cycle; hand it to the thread when a line or the warning is due. Never
    /// waits, never allocates.
    pub fn offer(&mut self, r: &CycleReport) {
        let due = self.status.tick(r);
        if (due.line || due.warning)
            && let Some(tx) = &self.tx
        {
            let _ = tx.try_send((*r, self.status.clone(), due));
        }
    }

    /// Print what is queued and end the line.
    pub fn finish(&mut self) {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Printer {
    fn drop(&mut self) {
        self.finish();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use controller::law::Output;
    use hal::{Correction, Cycle, Pose};

    fn report(t: f64, f: Option<f64>, late: u32) -> CycleReport {
        counted(t, f, late, 0, 0)
    }

    fn counted(t: f64, f: Option<f64>, late: u32, missed: u64, replied_late: u64) -> CycleReport {
        CycleReport {
            cycle: Cycle {
                seq: (t * 250.0) as u64,
                t,
                period: 0.004,
                actual: Pose::identity(),
                programmed: Pose::identity(),
                late_replies: late,
                missed,
                replied_late,
                new_session: false,
                process: None,
            },
            x: 0.0,
            f,
            sample: None,
            wrench: None,
            compensated: false,
            out: Output {
                kc_hat: 70e3,
                state: Some(controller::ContactState::Contact),
                ..Output::default()
            },
            command: Correction::along_z(0.0011),
            set_point: 5.0,
            fault: None,
            rezero: None,
        }
    }

    #[test]
    fn lines_come_at_their_pace_in_robot_time_and_say_what_the_cell_does() {
        let mut s = Status::new(0.25, Some(100));
        let mut lines = Vec::new();
        for k in 0..=250 {
            let t = f64::from(k) * 0.004;
            if let (Some(l), _) = s.observe(&report(t, Some(5.01), 0)) {
                lines.push(l);
            }
        }
        assert_eq!(lines.len(), 5, "{lines:#?}"); // t = 0, 0.25, 0.5, 0.75, 1.0
        let l = &lines[1];
        for part in [
            "t    0.25 s",
            "contact",
            "F   5.01 /   5.00 N",
            "k̂_c   70.0 kN/m",
            "x   1.10 mm",
            "robot late 0 of 100",
            "missed 0",
            "replied late 0",
        ] {
            assert!(l.contains(part), "{part:?} in {l:?}");
        }
        let held = s.line(&report(1.0, None, 0));
        assert!(held.contains("F    —"), "{held}");
    }

    /// The three counts side by side, each named for who counted what.
    #[test]
    fn the_line_shows_the_robots_late_count_the_missed_cycles_and_the_late_replies() {
        let s = Status::new(0.25, Some(100));
        let l = s.line(&counted(2.0, Some(5.0), 3, 17, 42));
        assert!(
            l.contains("robot late 3 of 100  missed 17  replied late 42"),
            "{l}"
        );
        let s = Status::new(0.25, None);
        let l = s.line(&counted(2.0, Some(5.0), 3, 0, 5));
        assert!(l.contains("robot late 3  missed 0  replied late 5"), "{l}");
    }

    #[test]
    fn half_the_late_budget_warns_once() {
        let mut s = Status::new(0.25, Some(100));
        assert_eq!(s.observe(&report(0.0, Some(5.0), 49)).1, None);
        let w = s
            .observe(&report(0.004, Some(5.0), 50))
            .1
            .expect("a warning");
        assert!(w.contains("50 late replies of the 100"), "{w}");
        assert_eq!(s.observe(&report(0.008, Some(5.0), 60)).1, None, "once");
        let mut unknown = Status::new(0.25, None);
        assert_eq!(unknown.observe(&report(0.0, Some(5.0), 90)).1, None);
    }
}
