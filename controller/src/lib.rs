//! forcecell's force controller, written against the HAL only.
//!
//! * [`law`] — the paper's adaptive position-based impedance law (and the fixed-reference law it improves
//!   on) as a pure `step` over an injected `dt`;
//! * [`control_loop`] — the loop that wires any [`hal::RobotLink`] and [`hal::ForceSensor`] to a law,
//!   gating bad input so it never reaches the command;
//! * [`robust`] — forcecell's robust law (with [`estimator`] and [`conditioning`]): what holds the force
//!   on a cell with sampling, lag, delay and a noisy sensor;
//! * [`predictor`] — the surface predictor the robust law feeds forward through the inverted inner loop;
//! * [`tune`] — damping ratio and delay margin of impedance parameters, proposals, verdicts;
//! * [`orientation`] — orientation following on curved parts, a stage around the law along the normal;
//! * [`gravity`] — tool weight and sensor bias: least-squares identification and run-time compensation.
#![cfg_attr(not(test), warn(missing_docs))]

pub mod calibration;
pub mod compensated;
pub mod conditioning;
pub mod config;
pub mod control_loop;
pub mod estimator;
pub mod gravity;
pub mod law;
pub mod onset;
pub mod orientation;
pub mod predictor;
pub mod robust;
pub mod run;
pub mod tune;

pub use config::{LawConfig, Overrides, TunedLaw, Tuning};
pub use control_loop::{
    ControlLoop, CycleReport, Fault, LoopConfig, LoopError, LoopStats, ProcessConfig, RezeroEvent,
    RezeroOutcome, RezeroParams,
};
pub use law::{
    AdaptiveParams, AlongNormal, CellLaw, ContactState, EventCounts, Events, ForceLaw,
    ImpedanceLaw, ImpedanceParams, LawStep, Output, Reference, fixed_reference_steady_state_error,
};
pub use orientation::{OrientationParams, Oriented};
pub use robust::{CellParams, ContactParams, LimitParams, ResponseParams, RobustLaw, RobustParams};
