//! The driver's errors and how they map to the HAL's kinds.

use core::fmt;
use core::time::Duration;

use hal::ErrorKind;

use crate::modbus::ModbusError;

/// Everything the FT 300 driver can report.
#[derive(Debug)]
#[non_exhaustive]
pub enum RobotiqError {
    /// No valid frame has arrived yet.
    NotReady,
    /// No byte for longer than the staleness limit, or the newest sample is older than allowed.
    Stale {
        /// Age of the newest sample (or time since the last byte when there is none).
        age: Duration,
    },
    /// No valid frame for longer than the loss limit.
    LinkLost {
        /// Time since the last valid frame (or since the stream was opened).
        since: Duration,
    },
    /// Too many frames of the recent window failed their CRC: the link is not trusted.
    Corrupt {
        /// Failed frames in the window.
        errors: u32,
        /// Window length, frames.
        window: u32,
    },
    /// Zeroing was refused: the wrench moved more than allowed over the window.
    Moving {
        /// Largest spread (max − min) of a force channel over the window, N.
        force_spread: f64,
        /// Largest spread of a torque channel, N·m.
        torque_spread: f64,
    },
    /// Zeroing did not get its samples in time.
    ZeroTimeout {
        /// Samples collected.
        got: usize,
        /// Samples wanted.
        wanted: usize,
    },
    /// The Modbus start-up failed.
    Modbus(ModbusError),
    /// Opening, reading or writing the serial port failed.
    Io {
        /// What was being done.
        context: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// Invalid settings.
    Config(String),
}

impl RobotiqError {
    pub(crate) fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io {
            context: context.into(),
            source,
        }
    }
}

impl fmt::Display for RobotiqError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotReady => write!(f, "no valid stream frame yet"),
            Self::Stale { age } => write!(f, "sensor data is stale ({:.1} ms old)", ms(*age)),
            Self::LinkLost { since } => write!(
                f,
                "sensor stream lost: no valid frame for {:.1} ms",
                ms(*since)
            ),
            Self::Corrupt { errors, window } => write!(
                f,
                "{errors} of the last {window} frames failed their CRC: the link is not trusted"
            ),
            Self::Moving {
                force_spread,
                torque_spread,
            } => write!(
                f,
                "zero refused: the wrench moved ({force_spread:.3} N, {torque_spread:.4} N·m spread over the window); hold the tool still"
            ),
            Self::ZeroTimeout { got, wanted } => {
                write!(f, "zero: only {got} of {wanted} samples arrived in time")
            }
            Self::Modbus(e) => write!(f, "Modbus: {e}"),
            Self::Io { context, source } => write!(f, "{context}: {source}"),
            Self::Config(m) => write!(f, "invalid configuration: {m}"),
        }
    }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

impl std::error::Error for RobotiqError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Modbus(e) => Some(e),
            Self::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

impl From<ModbusError> for RobotiqError {
    fn from(e: ModbusError) -> Self {
        Self::Modbus(e)
    }
}

impl hal::Error for RobotiqError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::NotReady => ErrorKind::Timeout,
            Self::Stale { .. } => ErrorKind::Stale,
            Self::LinkLost { .. } => ErrorKind::LinkLost,
            Self::Corrupt { .. } => ErrorKind::Malformed,
            Self::Moving { .. } | Self::ZeroTimeout { .. } => ErrorKind::Other,
            Self::Modbus(e) => e.kind(),
            Self::Io { .. } => ErrorKind::Io,
            Self::Config(_) => ErrorKind::Config,
        }
    }
}
