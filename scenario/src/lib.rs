//! Scenarios (the simulated cell, a tuning and the targets it is judged by), the trace of a run and the
//! metrics computed from it: one definition shared by the application (`forcecell sim`,
//! `bench-scenarios`) and the controller's closed-loop tests.
#![cfg_attr(not(test), warn(missing_docs))]

pub mod input;
pub mod metrics;
pub mod record;
pub mod removal;
pub mod run;
pub mod scenario;
pub mod telemetry;
pub mod tuning;
