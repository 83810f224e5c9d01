//! ABB Externally Guided Motion (EGM), path correction, for forcecell.
//!
//! * [`msg`] — the prost codec: hand-written message structs of the project's own `proto/egm.proto`.
//! * [`session`] — [`EgmSession`], the external-device side without I/O: source filtering, sessions and
//!   sequence numbers, backlog, watchdog, correction shaping, diagnostics, on a time the caller passes.
//! * [`link`] — [`EgmLink`], a [`hal::RobotLink`]: the session over a real UDP socket, two system calls
//!   per cycle.
//! * [`process`] — the force process's command in `RAPIDfromRobot`, and the state's way back.
//! * [`limits`] — the envelope and rate limit inside the robot's configured range.
//! * [`rapid`] — the robot controller's side as text: UDPUC entry, settings, the RAPID module.
//! * [`rws`], [`rws_channel`] — the process state back to RAPID over Robot Web Services 2.0 (HTTPS):
//!   the requests and responses without I/O, and the writer thread with its pinned TLS.
//! * [`wire`] — the one place SI becomes mm and ms and the tool frame becomes the sensor frame.
//!
//! The simulated IRC5 in `forcecell-sim` uses the same codec for the opposite direction. None of it
//! has met a real IRC5 or RobotStudio.
#![cfg_attr(not(test), warn(missing_docs))]

pub mod diag;
pub mod limits;
pub mod link;
pub mod msg;
pub mod process;
pub mod rapid;
pub mod rws;
pub mod rws_channel;
pub mod session;
pub mod wire;

pub use diag::{Counters, Diagnostics, Latency, RobotStatus};
pub use limits::{CorrectionRange, Limits};
pub use link::{EgmLink, LinkConfig, LinkError, RobotFilter};
pub use process::{CommandSlots, ProcessError, StateChannel};
pub use rws_channel::{RwsChannel, RwsConfig, RwsReport};
pub use session::{EgmSession, Malformed, Outgoing, Rejected};
pub use wire::SensorFrame;
