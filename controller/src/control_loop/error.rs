//! What goes wrong: a cycle's fault that the loop carries on through, and why the loop ended.

use core::fmt;

use hal::{ErrorKind, ProcessFault};

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
    /// Force control tripped the guard (the force limit, a correction limit, a contact lost too
    /// long) on a link without process channels; the loop has backed off first.
    Guard {
        /// The fault's code in the process contract.
        code: ProcessFault,
        /// Why, for the operator.
        reason: String,
    },
}

impl<RE, SE> LoopError<RE, SE> {
    /// The fault's code in the process contract (`FcState.Fault`), as reported to the robot while
    /// backing off and with `Stop`; `None` for a failed robot link (no one left to report to).
    pub fn code(&self) -> Option<ProcessFault> {
        match self {
            Self::Robot(_) => None,
            Self::Sensor(_) => Some(ProcessFault::SensorLost),
            Self::HoldTimeout { last, .. } => Some(hold_code(*last)),
            Self::Guard { code, .. } => Some(*code),
        }
    }
}

/// Why a hold of `held` s ended the loop or latched a fault, with the last cycle's fault.
pub(super) fn hold_reason(held: f64, last: Fault) -> String {
    format!(
        "held the last command for {:.0} ms without a usable input (last: {last:?})",
        held * 1e3
    )
}

/// The code of a hold that lasted too long: the sensor's, when it was the sensor that failed.
pub(super) fn hold_code(last: Fault) -> ProcessFault {
    match last {
        Fault::Sensor(_) | Fault::NonFiniteSample => ProcessFault::SensorLost,
        _ => ProcessFault::HoldTimeout,
    }
}

impl<RE: fmt::Display, SE: fmt::Display> LoopError<RE, SE> {
    /// Why the loop ended, without the code.
    pub fn reason(&self) -> String {
        match self {
            Self::Robot(e) => format!("robot link: {e}"),
            Self::Sensor(e) => format!("force sensor: {e}"),
            Self::HoldTimeout { held, last } => hold_reason(*held, *last),
            Self::Guard { reason, .. } => reason.clone(),
        }
    }
}

impl<RE: fmt::Display, SE: fmt::Display> fmt::Display for LoopError<RE, SE> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.code() {
            Some(code) => write!(
                f,
                "fault {} ({}): {}; the tool backed off",
                code.code(),
                code.name(),
                self.reason()
            ),
            None => f.write_str(&self.reason()),
        }
    }
}

/// A fault that ends the loop once the tool has backed off: a [`LoopError`] that is never the
/// robot's (there is a link to back off through).
pub(super) type Ending<SE> = LoopError<core::convert::Infallible, SE>;

impl<SE> Ending<SE> {
    /// The same error, typed for the loop's robot.
    pub(super) fn widen<RE>(self) -> LoopError<RE, SE> {
        match self {
            Self::Robot(never) => match never {},
            Self::Sensor(e) => LoopError::Sensor(e),
            Self::HoldTimeout { held, last } => LoopError::HoldTimeout { held, last },
            Self::Guard { code, reason } => LoopError::Guard { code, reason },
        }
    }
}

impl<RE: fmt::Debug + fmt::Display, SE: fmt::Debug + fmt::Display> std::error::Error
    for LoopError<RE, SE>
{
}
