//! The SocketCAN transport (Linux, the `socketcan` crate): a raw CAN socket with a kernel filter for the
//! sensor's identifiers and error frames for bus-off and restart.

use core::time::Duration;
use std::io;

use socketcan::{
    CanDataFrame, CanErrorFrame, CanFilter, CanFrame, CanRemoteFrame, CanSocket, EmbeddedFrame,
    ExtendedId, Frame as _, Socket, SocketOptions, StandardId,
};

use crate::codec::Base;
use crate::frame::Frame;
use crate::transport::{BusError, BusEvent, CanTransport, Clock, TransportError};

/// `CAN_EFF_FLAG`, `CAN_RTR_FLAG`: part of the kernel filter so extended and remote frames are dropped.
const EFF_FLAG: u32 = 0x8000_0000;
const RTR_FLAG: u32 = 0x4000_0000;

/// A raw CAN socket on one interface.
pub struct SocketCanTransport {
    socket: CanSocket,
    clock: Clock,
}

impl SocketCanTransport {
    /// Open `iface` (e.g. `vcan0`, `can0`). Receives everything until
    /// [`accept_only`](CanTransport::accept_only); error frames for bus-off and restart are enabled.
    pub fn open(iface: &str) -> Result<Self, TransportError> {
        let socket = CanSocket::open(iface).map_err(|e| {
            TransportError::Io(io::Error::new(
                e.kind(),
                format!(
                    "cannot open CAN interface {iface}: {e} (is it up? `ip link show {iface}`)"
                ),
            ))
        })?;
        socket.set_error_filter(BusError::BUSOFF | BusError::RESTARTED)?;
        Ok(Self {
            socket,
            clock: Clock::real(),
        })
    }

    /// Write a controller error report (`CAN_ERR_FLAG` frame) with these error class bits. A real
    /// controller raises these itself; on a virtual interface this is how a test injects bus-off and
    /// restart, which every socket on the interface with an error filter then receives.
    pub fn inject_error(&self, error: BusError) -> Result<(), TransportError> {
        let frame = CanErrorFrame::new_error(error.raw, &[]).map_err(|e| {
            TransportError::Io(io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))
        })?;
        self.socket.write_frame(&frame)?;
        Ok(())
    }

    fn convert(frame: &CanFrame) -> Option<BusEvent> {
        let id = frame.raw_id();
        Some(match frame {
            CanFrame::Error(e) => BusEvent::Error(BusError::from_raw(e.error_bits())),
            CanFrame::Remote(r) => {
                BusEvent::Frame(Frame::remote(id, r.is_extended(), r.dlc() as u8)?)
            }
            CanFrame::Data(d) if d.is_extended() => BusEvent::Frame(Frame::extended(id, d.data())?),
            CanFrame::Data(d) => BusEvent::Frame(Frame::standard(id as u16, d.data())?),
        })
    }
}

impl CanTransport for SocketCanTransport {
    fn send(&mut self, frame: &Frame) -> Result<(), TransportError> {
        let invalid = || {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("cannot build frame {frame}"),
            )
        };
        let out: CanFrame = if frame.is_remote() {
            let r = if frame.is_extended() {
                ExtendedId::new(frame.id())
                    .and_then(|id| CanRemoteFrame::new_remote(id, frame.dlc().into()))
            } else {
                StandardId::new(frame.id() as u16)
                    .and_then(|id| CanRemoteFrame::new_remote(id, frame.dlc().into()))
            };
            r.ok_or_else(invalid)?.into()
        } else {
            let d = if frame.is_extended() {
                ExtendedId::new(frame.id()).and_then(|id| CanDataFrame::new(id, frame.data()))
            } else {
                StandardId::new(frame.id() as u16)
                    .and_then(|id| CanDataFrame::new(id, frame.data()))
            };
            d.ok_or_else(invalid)?.into()
        };
        self.socket.write_frame(&out)?;
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<BusEvent>, TransportError> {
        // poll(2) takes whole milliseconds: round up so a wait never ends before `timeout`.
        let ms = timeout.as_nanos().div_ceil(1_000_000);
        let timeout = Duration::from_millis(u64::try_from(ms).unwrap_or(u64::MAX));
        match self.socket.read_frame_timeout(timeout) {
            Ok(f) => Ok(Self::convert(&f)),
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
                ) =>
            {
                Ok(None)
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => Ok(None),
            Err(e) => Err(e.into()),
        }
    }

    fn accept_only(&mut self, base: Base) -> Result<(), TransportError> {
        let id = u32::from(base.get()) << 4;
        self.socket
            .set_filters(&[CanFilter::new(id, 0x7F0 | EFF_FLAG | RTR_FLAG)])?;
        Ok(())
    }

    fn clock(&self) -> Clock {
        self.clock.clone()
    }
}
