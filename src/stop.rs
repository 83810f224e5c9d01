//! How a run ends: the operator's stop (SIGINT, SIGTERM or SIGHUP — `ctrlc` with its `termination`
//! feature), the exit statuses the binary returns, and a robot link whose wait for the robot's first
//! datagram ends when a stop is asked for or the robot's process is gone.
//!
//! Exit statuses (docs/cli.md, "Exit statuses", lists them for users):
//! [`OK`], [`CHECK_FAILED`], [`ERROR`], [`ENDED_EARLY`], [`FAULT`], [`INTERRUPTED`].

use std::fmt;
use std::sync::Once;
use std::sync::atomic::{AtomicBool, Ordering};

use hal::{Correction, Cycle, Error as _, ErrorKind, RobotLink};

/// The run did everything it was asked to.
pub const OK: u8 = 0;
/// `--check` (or `tune`): a target was missed, or the tuning is unsafe.
pub const CHECK_FAILED: u8 = 1;
/// Bad input or a device that could not be used: one `error:` line says why; nothing was run.
pub const ERROR: u8 = 2;
/// The run ended before its end because the robot ended it: its link was lost (it fell silent past
/// its watchdog, or with the process still on), or its program aborted; what ran is recorded.
pub const ENDED_EARLY: u8 = 3;
/// The run ended on a fault of forcecell's own guard (force limit, correction limit, contact lost, a
/// hold too long, a failed sensor): the tool was backed off and returned to the path, the robot got
/// `Stop` where the link stood; what ran is recorded.
pub const FAULT: u8 = 4;
/// Stopped by SIGINT (Ctrl-C), SIGTERM or SIGHUP: the robot got `Stop` if it was sending, what ran is
/// recorded (128 + SIGINT, as shells report an interrupted command).
pub const INTERRUPTED: u8 = 130;

static STOP: AtomicBool = AtomicBool::new(false);

/// The process-wide stop flag, set by the signal handler [`install`] puts in place.
pub fn flag() -> &'static AtomicBool {
    &STOP
}

/// Whether SIGINT, SIGTERM or SIGHUP arrived.
pub fn requested() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// Make SIGINT, SIGTERM and SIGHUP set [`flag`] instead of killing the process (once per process).
pub fn install() -> anyhow::Result<()> {
    static ONCE: Once = Once::new();
    let mut result = Ok(());
    ONCE.call_once(|| {
        result = ctrlc::set_handler(|| STOP.store(true, Ordering::Relaxed))
            .map_err(|e| anyhow::anyhow!("cannot install the SIGINT/SIGTERM handler: {e}"));
    });
    result
}

/// What an [`Interruptible`] calls with its link after a wait that found no cycle.
type OnWait<'a, R> = Option<Box<dyn FnMut(&mut R) + 'a>>;

/// A robot link whose waits end: a wait for the first datagram (the link's `first_contact_timeout`
/// returns a transient timeout now and then) ends with [`Interrupted::Stopped`] once `stop` is set,
/// or [`Interrupted::PeerGone`] once `alive` says the robot's process has ended.
pub struct Interruptible<'a, R> {
    inner: R,
    stop: &'a AtomicBool,
    alive: Option<Box<dyn Fn() -> bool + 'a>>,
    waiting: OnWait<'a, R>,
}

impl<'a, R> Interruptible<'a, R> {
    /// Wrap `inner`, watching `stop`.
    pub fn new(inner: R, stop: &'a AtomicBool) -> Self {
        Self {
            inner,
            stop,
            alive: None,
            waiting: None,
        }
    }

    /// Call `waiting` with the link at each end of a wait for the robot that found no cycle (to say
    /// what the link saw meanwhile).
    pub fn while_waiting(mut self, waiting: impl FnMut(&mut R) + 'a) -> Self {
        self.waiting = Some(Box::new(waiting));
        self
    }

    /// Also end a wait once `alive` returns false (the simulated controller's thread has ended).
    pub fn with_peer(mut self, alive: impl Fn() -> bool + 'a) -> Self {
        self.alive = Some(Box::new(alive));
        self
    }

    /// The wrapped link.
    pub fn inner(&self) -> &R {
        &self.inner
    }
}

/// The error of an [`Interruptible`] link.
#[derive(Debug)]
pub enum Interrupted<E> {
    /// The link's own error.
    Link(E),
    /// A stop was asked for while waiting for the robot.
    Stopped,
    /// The robot's process ended while the link waited for it.
    PeerGone,
}

impl<E: fmt::Display> fmt::Display for Interrupted<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Link(e) => e.fmt(f),
            Self::Stopped => write!(
                f,
                "stopped while waiting for the robot (no cycle to answer)"
            ),
            Self::PeerGone => write!(
                f,
                "the robot's process ended before it sent a cycle (see its message above)"
            ),
        }
    }
}

impl<E: fmt::Debug + fmt::Display> std::error::Error for Interrupted<E> {}

impl<E: hal::Error> hal::Error for Interrupted<E> {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Link(e) => e.kind(),
            Self::Stopped => ErrorKind::Other,
            Self::PeerGone => ErrorKind::LinkLost,
        }
    }
}

impl<R: RobotLink> RobotLink for Interruptible<'_, R> {
    type Error = Interrupted<R::Error>;

    fn next_cycle(&mut self) -> Result<Cycle, Self::Error> {
        match self.inner.next_cycle() {
            Ok(c) => Ok(c),
            Err(e) if e.kind() == ErrorKind::Timeout => {
                if let Some(w) = &mut self.waiting {
                    w(&mut self.inner);
                }
                if self.stop.load(Ordering::Relaxed) {
                    Err(Interrupted::Stopped)
                } else if self.alive.as_ref().is_some_and(|alive| !alive()) {
                    Err(Interrupted::PeerGone)
                } else {
                    Err(Interrupted::Link(e))
                }
            }
            Err(e) => Err(Interrupted::Link(e)),
        }
    }

    fn reply(&mut self, correction: &Correction) -> Result<(), Self::Error> {
        self.inner.reply(correction).map_err(Interrupted::Link)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A link that never sees the robot: every wait times out.
    struct Silent;

    impl RobotLink for Silent {
        type Error = ErrorKind;
        fn next_cycle(&mut self) -> Result<Cycle, ErrorKind> {
            Err(ErrorKind::Timeout)
        }
        fn reply(&mut self, _: &Correction) -> Result<(), ErrorKind> {
            Err(ErrorKind::Other)
        }
    }

    #[test]
    fn a_wait_for_the_robot_ends_on_stop_or_when_the_peer_is_gone() {
        use hal::Error as _;
        let stop = AtomicBool::new(false);
        let mut link = Interruptible::new(Silent, &stop);
        let e = link.next_cycle().unwrap_err();
        assert!(e.kind().is_transient(), "keeps waiting: {e}");
        stop.store(true, Ordering::Relaxed);
        let e = link.next_cycle().unwrap_err();
        assert!(matches!(e, Interrupted::Stopped) && !e.kind().is_transient());
        let go = AtomicBool::new(false);
        let mut link = Interruptible::new(Silent, &go).with_peer(|| false);
        let e = link.next_cycle().unwrap_err();
        assert_eq!(e.kind(), ErrorKind::LinkLost);
    }
}
