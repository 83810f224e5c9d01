//! KUKA RSI (Robot Sensor Interface) for forcecell.
//!
//! * [`codec`] — sans-IO, allocation-free parsing and writing of `<Rob>` and `<Sen>`, one codec for
//!   both directions, driven by a [`Schema`] derived from the robot's Ethernet config.
//! * [`config`] — the Ethernet config (`RSI_EthernetConfig.xml`): read, validate, write.
//! * [`link`] — [`RsiLink`], a [`hal::RobotLink`] over a real UDP socket: source filtering,
//!   backlog draining, watchdog, correction shaping, diagnostics.
//! * [`wire`] — the one place SI becomes mm and degrees.
//! * [`krl`] — the robot-side files that match a configuration.
//!
//! The simulated controller in `forcecell-sim` uses the same codec for the opposite direction.
#![cfg_attr(not(test), warn(missing_docs))]

pub mod codec;
pub mod config;
pub mod diag;
pub mod krl;
pub mod limits;
pub mod link;
pub mod wire;
mod xml;

pub use codec::{Direction, Frame, Ipoc, Schema, ValueType, WriteError};
pub use config::{ConfigElement, ConfigError, EthernetConfig, Indx};
pub use diag::{Counters, Diagnostics, Latency};
pub use krl::RobotSetup;
pub use limits::{Limits, PoscorrLimits};
pub use link::{CorrectionMode, LinkConfig, LinkError, RobotFilter, RsiLink};
pub use xml::ParseError;
