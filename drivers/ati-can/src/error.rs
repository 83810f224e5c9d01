//! The driver's errors, each mapped to a [`hal::ErrorKind`] and worded to say what to do.

use core::fmt;
use core::time::Duration;

use hal::ErrorKind;

use crate::calibration::CalibrationError;
use crate::codec::{CodecError, Status};
use crate::transport::TransportError;

/// Why the start-up sequence did not complete.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StartupProblem {
    /// A required request got no valid answer after every attempt.
    NoAnswer {
        /// Which request.
        step: &'static str,
    },
    /// The board echoed another calibration slot than the one selected.
    SlotEcho {
        /// The slot selected.
        requested: u8,
        /// The slot echoed.
        echoed: u8,
    },
    /// A unit code outside 1..=6.
    UnitCode {
        /// Force unit code.
        force: u8,
        /// Torque unit code.
        torque: u8,
    },
    /// The calibration read from the board cannot be used.
    Calibration(CalibrationError),
}

impl StartupProblem {
    /// `Timeout` when the board did not answer, `Config` when it answered something unusable.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Self::NoAnswer { .. } => ErrorKind::Timeout,
            _ => ErrorKind::Config,
        }
    }
}

impl fmt::Display for StartupProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoAnswer { step } => write!(
                f,
                "no valid answer to the {step} request: check power, wiring, termination, bit rate and base id"
            ),
            Self::SlotEcho { requested, echoed } => write!(
                f,
                "selected calibration slot {requested} but the board echoed {echoed}: does the slot exist?"
            ),
            Self::UnitCode { force, torque } => {
                write!(f, "unknown unit codes force {force}, torque {torque}")
            }
            Self::Calibration(e) => write!(f, "unusable calibration: {e}"),
        }
    }
}

/// Why a bias was refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BiasError {
    /// The driver has no usable samples (start-up, timeout, bus-off …).
    NotReady,
    /// A gauge was saturated during the window.
    Saturated,
    /// The board reported a critical status during the window.
    DeviceFault(Status),
    /// A poll got no valid answer during the window.
    NoAnswer,
    /// A gauge moved more than allowed during the window: the sensor is moving or in contact.
    Moving {
        /// Gauge index 0..=5.
        gauge: usize,
        /// Largest minus smallest count seen.
        spread: u32,
        /// Allowed spread.
        allowed: u16,
    },
    /// A bias is already being taken.
    Busy,
    /// The window was invalid (zero samples).
    EmptyWindow,
}

impl fmt::Display for BiasError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotReady => f.write_str("bias refused: the sensor has no usable samples yet"),
            Self::Saturated => {
                f.write_str("bias refused: a gauge is saturated (unload the sensor)")
            }
            Self::DeviceFault(s) => write!(f, "bias refused: the sensor reports status {s}"),
            Self::NoAnswer => f.write_str("bias refused: samples were missing during the window"),
            Self::Moving {
                gauge,
                spread,
                allowed,
            } => write!(
                f,
                "bias refused: gauge {gauge} varied by {spread} counts (> {allowed}) — hold the tool still, out of contact"
            ),
            Self::Busy => f.write_str("bias refused: a bias is already being taken"),
            Self::EmptyWindow => {
                f.write_str("bias refused: the window must hold at least one sample")
            }
        }
    }
}

impl std::error::Error for BiasError {}

/// An error of the ATI CAN driver.
#[derive(Debug)]
pub enum AtiError {
    /// Start-up has not finished; `problem` says what the last attempt ran into.
    NotReady {
        /// The last start-up problem, if any.
        problem: Option<StartupProblem>,
    },
    /// Start-up failed.
    Startup(StartupProblem),
    /// Several polls in a row got no valid answer.
    Timeout,
    /// The newest sample is older than the staleness limit.
    Stale {
        /// Its age.
        age: Duration,
    },
    /// The board reports a critical status; its samples are withheld.
    DeviceFault(Status),
    /// A gauge is saturated; the samples are withheld.
    Saturated,
    /// The CAN controller is bus-off.
    BusOff,
    /// The transport is closed or the poller has ended.
    LinkLost,
    /// The driver's configuration is invalid.
    Config(String),
    /// A request could not be encoded.
    Codec(CodecError),
    /// The transport failed.
    Transport(TransportError),
    /// A bias was refused.
    Bias(BiasError),
}

impl fmt::Display for AtiError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotReady { problem: None } => f.write_str("ATI sensor: start-up not finished"),
            Self::NotReady { problem: Some(p) } => {
                write!(f, "ATI sensor: start-up not finished, last attempt: {p}")
            }
            Self::Startup(p) => write!(f, "ATI sensor start-up failed: {p}"),
            Self::Timeout => f.write_str("ATI sensor: no valid answer to several polls in a row"),
            Self::Stale { age } => write!(f, "ATI sensor: newest sample is {age:?} old"),
            Self::DeviceFault(s) => write!(f, "ATI sensor reports status {s}"),
            Self::Saturated => f.write_str("ATI sensor: a gauge is saturated (overload)"),
            Self::BusOff => {
                f.write_str("CAN controller is bus-off: check wiring, termination and bit rate")
            }
            Self::LinkLost => f.write_str("ATI sensor: the CAN transport is closed"),
            Self::Config(m) => write!(f, "ATI driver configuration: {m}"),
            Self::Codec(e) => write!(f, "ATI codec: {e}"),
            Self::Transport(e) => write!(f, "{e}"),
            Self::Bias(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for AtiError {}

impl hal::Error for AtiError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::NotReady { problem } => problem.map_or(ErrorKind::Timeout, |p| p.kind()),
            Self::Startup(p) => p.kind(),
            Self::Timeout => ErrorKind::Timeout,
            Self::Stale { .. } => ErrorKind::Stale,
            Self::DeviceFault(_) => ErrorKind::DeviceFault,
            Self::Saturated => ErrorKind::Saturated,
            Self::BusOff => ErrorKind::BusOff,
            Self::LinkLost | Self::Transport(TransportError::Closed) => ErrorKind::LinkLost,
            Self::Config(_) => ErrorKind::Config,
            Self::Codec(_) => ErrorKind::Malformed,
            Self::Transport(TransportError::Io(_)) => ErrorKind::Io,
            Self::Bias(_) => ErrorKind::Other,
        }
    }
}

impl From<TransportError> for AtiError {
    fn from(e: TransportError) -> Self {
        Self::Transport(e)
    }
}

impl From<CodecError> for AtiError {
    fn from(e: CodecError) -> Self {
        Self::Codec(e)
    }
}

impl From<BiasError> for AtiError {
    fn from(e: BiasError) -> Self {
        Self::Bias(e)
    }
}
