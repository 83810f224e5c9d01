//! Robotiq FT 300 (and FT 150) six-axis force/torque sensor: Modbus RTU registers and the raw 100 Hz stream.
//!
//! Layers, each usable alone:
//! * [`codec`] — the stream frame, the resynchronising stream decoder, CRC-16, the register map and the
//!   one conversion from device units to SI; no I/O;
//! * [`link`] — health and counters of a stream as a pure state machine (bytes and times in), and the
//!   raw stream reader over any `std::io::Read`;
//! * [`modbus`] — the start-up over tokio-modbus (identity, a register read of the wrench, the write to
//!   register 410 that starts the stream) and the stop bytes;
//! * [`sensor`] — [`Ft300`]: start-up, a background reader, the HAL's non-blocking `read`, host-side zero.
//!
//! Units: samples are N and N·m in the sensor frame, zero removed. Gravity compensation is not done here
//! (the FT 300 has no orientation of its own): see `controller::gravity`. The port path is configuration:
//! the driver never scans or probes ports.
#![cfg_attr(not(test), warn(missing_docs))]

pub mod codec;
pub mod error;
pub mod link;
pub mod modbus;
pub mod sensor;

pub use codec::{Counts, DecoderCounters, Event, FrameError, Identity, StreamDecoder};
pub use error::RobotiqError;
pub use link::{Counters, Health, LinkConfig, LinkState, RawReader};
pub use modbus::{ModbusError, Startup};
pub use sensor::{Config, Ft300, Lockstep, ZeroConfig};
