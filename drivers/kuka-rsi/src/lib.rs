//! KUKA RSI (Robot Sensor Interface) for forcecell.
//!
//! * [`codec`] — sans-IO, allocation-free parsing and writing of `<Rob>` and `<Sen>`, one codec for
//!   both directions, driven by a [`Schema`] derived from the robot's Ethernet config.
//! * [`config`] — the Ethernet config (`RSI_EthernetConfig.xml`): read, validate, write.
//! * [`session`] — [`RsiSession`], the PC side without I/O: source filtering, sessions and IPOC,
//!   backlog, watchdog, correction shaping, diagnostics, all on a time the caller passes.
//! * [`link`] — [`RsiLink`], a [`hal::RobotLink`]: the session over a real UDP socket, two system
//!   calls per cycle.
//! * [`process`] — the process channels `FcCmd` (robot program → PC) and `FcState` (PC → robot).
//! * [`wire`] — the one place SI becomes mm and degrees.
//! * [`krl`] — the robot-side files that match a configuration.
//!
//! The simulated controller in `forcecell-sim` uses the same codec for the opposite direction.
#![cfg_attr(not(test), warn(missing_docs))]

pub mod codec;
pub mod config;
pub mod diag;
pub mod krl;
pub mod layout;
pub mod limits;
pub mod link;
pub mod process;
pub mod rsix;
pub mod session;
pub mod wire;
mod xml;

pub use codec::{Direction, Frame, Ipoc, Schema, ValueType, WriteError};
pub use config::{ConfigElement, ConfigError, EthernetConfig, Indx};
pub use diag::{Counters, Diagnostics, Latency, Measured, RejectClass, RejectDue, RejectLog};
pub use krl::{ProcessIo, ProcessSetup, RobotSetup, Segment};
pub use layout::Layout;
pub use limits::{Limits, PoscorrLimits};
pub use link::{CorrectionMode, LinkConfig, LinkError, RobotFilter, RsiLink};
pub use process::{CommandSlots, ProcessChannels, ProcessError, StateSlots};
pub use session::{Outgoing, Rejected, RsiSession};
pub use xml::{MAX_ATTRIBUTES, ParseError};
