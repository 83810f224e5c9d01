//! The forcecell application library: scenarios, the runner that wires backends to the controller,
//! recording, metrics and plots. The `forcecell` binary is a thin CLI over it.
#![cfg_attr(not(test), warn(missing_docs))]

pub mod args;
pub mod ati;
pub mod bench;
pub mod candump;
pub mod cell;
pub mod check;
pub mod egm;
pub mod live;
pub mod output;
pub mod plot;
pub mod provenance;
pub mod readout;
pub mod recorder;
pub mod report;
pub mod rig;
pub mod robot;
pub mod robotiq;
pub mod rsi;
pub mod rt;
pub mod runner;
pub mod status;
pub mod stop;
pub mod tune;

pub use ::scenario::{input, metrics, record, scenario};
