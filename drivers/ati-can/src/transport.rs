//! The one small trait every CAN transport implements (SocketCAN, the in-memory bus), and the clock the
//! driver reads time from.

use core::fmt;
use core::time::Duration;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use crate::codec::Base;
use crate::frame::Frame;

/// Something that happened on the bus.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BusEvent {
    /// A frame that passed the transport's filter.
    Frame(Frame),
    /// A CAN controller error report (SocketCAN error frame).
    Error(BusError),
}

/// A controller error report. Only the two conditions the driver acts on are decoded; `raw` keeps the
/// SocketCAN error class bits (`CAN_ERR_*` in the identifier) for diagnostics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct BusError {
    /// The controller went bus-off: it can neither send nor receive until restarted.
    pub bus_off: bool,
    /// The controller was restarted after bus-off.
    pub restarted: bool,
    /// The error class bits.
    pub raw: u32,
}

impl BusError {
    /// SocketCAN `CAN_ERR_BUSOFF`.
    pub const BUSOFF: u32 = 0x0000_0040;
    /// SocketCAN `CAN_ERR_RESTARTED`.
    pub const RESTARTED: u32 = 0x0000_0100;

    /// Decode SocketCAN error class bits.
    pub fn from_raw(raw: u32) -> Self {
        Self {
            bus_off: raw & Self::BUSOFF != 0,
            restarted: raw & Self::RESTARTED != 0,
            raw,
        }
    }
}

/// A transport failure.
#[derive(Debug)]
pub enum TransportError {
    /// The operating system refused (socket, interface down, buffer full …).
    Io(std::io::Error),
    /// The bus or socket is gone.
    Closed,
}

impl fmt::Display for TransportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(e) => write!(f, "CAN I/O error: {e}"),
            Self::Closed => f.write_str("CAN transport closed"),
        }
    }
}

impl std::error::Error for TransportError {}

impl From<std::io::Error> for TransportError {
    fn from(e: std::io::Error) -> Self {
        Self::Io(e)
    }
}

/// A monotonic clock as a duration since its origin. `Real` reads the system's monotonic clock;
/// `Virtual` only moves when something advances it (the in-memory bus, while nobody would answer), so a
/// simulation can run faster than real time and stay deterministic.
#[derive(Clone, Debug)]
pub enum Clock {
    /// Wall time since an origin.
    Real(Instant),
    /// Nanoseconds, advanced explicitly.
    Virtual(Arc<AtomicU64>),
}

impl Clock {
    /// A real clock starting now.
    pub fn real() -> Self {
        Self::Real(Instant::now())
    }

    /// A virtual clock at zero.
    pub fn virtual_at_zero() -> Self {
        Self::Virtual(Arc::new(AtomicU64::new(0)))
    }

    /// Time since the origin.
    pub fn now(&self) -> Duration {
        match self {
            Self::Real(origin) => origin.elapsed(),
            Self::Virtual(ns) => Duration::from_nanos(ns.load(Ordering::Acquire)),
        }
    }

    /// Move a virtual clock forward to `t` (never backwards). No effect on a real clock.
    pub fn advance_to(&self, t: Duration) {
        if let Self::Virtual(ns) = self {
            let t = u64::try_from(t.as_nanos()).unwrap_or(u64::MAX);
            ns.fetch_max(t, Ordering::AcqRel);
        }
    }

    /// True for a virtual clock.
    pub fn is_virtual(&self) -> bool {
        matches!(self, Self::Virtual(_))
    }
}

/// A CAN transport: send a frame, wait a bounded time for the next event.
///
/// Frames this endpoint sends are not delivered back to it (SocketCAN's default). After
/// [`accept_only`](CanTransport::accept_only) only standard data frames of that base and error reports
/// arrive; extended, remote and other bases' frames are dropped below the driver.
pub trait CanTransport {
    /// Queue one frame for sending. Does not wait for the bus.
    fn send(&mut self, frame: &Frame) -> Result<(), TransportError>;

    /// The next event, waiting at most `timeout` (zero: only what is already there). `Ok(None)` when
    /// nothing arrived in time.
    fn recv(&mut self, timeout: Duration) -> Result<Option<BusEvent>, TransportError>;

    /// Deliver only standard data frames with identifiers `base << 4 | 0..=15`, and error reports.
    fn accept_only(&mut self, base: Base) -> Result<(), TransportError>;

    /// The clock this transport's waits are measured on.
    fn clock(&self) -> Clock;
}

impl<T: CanTransport + ?Sized> CanTransport for Box<T> {
    fn send(&mut self, frame: &Frame) -> Result<(), TransportError> {
        (**self).send(frame)
    }
    fn recv(&mut self, timeout: Duration) -> Result<Option<BusEvent>, TransportError> {
        (**self).recv(timeout)
    }
    fn accept_only(&mut self, base: Base) -> Result<(), TransportError> {
        (**self).accept_only(base)
    }
    fn clock(&self) -> Clock {
        (**self).clock()
    }
}

/// True when `frame` passes the filter of [`CanTransport::accept_only`]`(base)`.
pub fn filter_accepts(base: Base, frame: &Frame) -> bool {
    !frame.is_extended() && !frame.is_remote() && frame.id() >> 4 == u32::from(base.get())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn virtual_clock_only_moves_forward() {
        let c = Clock::virtual_at_zero();
        assert_eq!(c.now(), Duration::ZERO);
        c.advance_to(Duration::from_millis(5));
        c.advance_to(Duration::from_millis(3));
        assert_eq!(c.now(), Duration::from_millis(5));
        assert!(c.is_virtual() && !Clock::real().is_virtual());
    }

    #[test]
    fn error_class_bits() {
        let e = BusError::from_raw(BusError::BUSOFF | 0x4);
        assert!(e.bus_off && !e.restarted);
        assert!(BusError::from_raw(BusError::RESTARTED).restarted);
    }

    #[test]
    fn filter_semantics() {
        let b = Base::DEFAULT;
        assert!(filter_accepts(b, &Frame::standard(0x20F, &[]).unwrap()));
        assert!(!filter_accepts(b, &Frame::standard(0x210, &[]).unwrap()));
        assert!(!filter_accepts(b, &Frame::extended(0x200, &[]).unwrap()));
        assert!(!filter_accepts(b, &Frame::remote(0x200, false, 0).unwrap()));
    }
}
