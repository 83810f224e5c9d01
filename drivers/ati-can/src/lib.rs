//! ATI NETCANOEM six-axis force/torque sensor over CAN (ATI Mini45/Mini58-CAN, Schunk FTM/FTN-CAN).
//!
//! Layers, each usable alone:
//! * [`codec`] — every request and answer of the opcode table, both directions, no I/O;
//! * [`calibration`] — counts to SI, in one place;
//! * [`transport`] — the small [`CanTransport`] trait, with [`SocketCanTransport`] (feature `socketcan`)
//!   and the in-memory [`MemBus`];
//! * [`driver`] — start-up, polling with request generations, health with hysteresis, counters, bias;
//! * [`sensor`] — [`AtiSensor`] (background poller, the HAL's non-blocking `read`) and [`Lockstep`]
//!   (one exchange per `read`, for simulations that own the clock).
//!
//! Units: samples are N and N·m in the sensor frame, bias removed. Gravity compensation is not done
//! here (it needs the robot's orientation): see `controller::gravity`.
#![cfg_attr(not(test), warn(missing_docs))]

pub mod calibration;
pub mod codec;
pub mod driver;
pub mod error;
pub mod frame;
pub mod mem;
pub mod sensor;
#[cfg(feature = "socketcan")]
pub mod socket;
pub mod transport;

pub use calibration::{Calibration, Converter, ForceUnit, TorqueUnit};
pub use codec::{Answer, Base, CodecError, Firmware, Gauges, Request, Status};
pub use driver::{BiasConfig, Config, Counters, DeviceInfo, Driver, Health, Outcome};
pub use error::{AtiError, BiasError, StartupProblem};
pub use frame::Frame;
pub use mem::{MemBus, MemPort, Responder};
pub use sensor::{AtiSensor, Lockstep};
#[cfg(feature = "socketcan")]
pub use socket::SocketCanTransport;
pub use transport::{BusError, BusEvent, CanTransport, Clock, TransportError};
