//! The other side of every wire: the contact plant (physical truth), the robot's inner position loop,
//! a sensor model, and the simulated peers that speak to forcecell's drivers.
#![cfg_attr(not(test), warn(missing_docs))]

pub mod ati_node;
pub mod ft300;
pub mod geometry;
pub mod inner;
pub mod irc5;
pub mod krc;
pub mod plant;
pub mod program;
pub mod rws;
pub mod sensor_model;
pub mod vcan_env;
pub mod world;

pub use geometry::{Axis, Contact, ContactState, Geometry, Shape};
pub use inner::{InnerLoop, InnerLoopModel};
pub use irc5::{Irc5, Irc5Config, Irc5End, Irc5Report, RapidVariables};
pub use krc::{Krc, KrcConfig, KrcEnd, KrcReport, Mechanism, RigidArm, Timing};
pub use plant::{ContactPlant, Event, Schedule};
pub use program::{Program, ProgramRunner, Segment, SegmentMode, SurfaceForm};
pub use sensor_model::{SensorModel, SensorParams, Window};
pub use world::{InProcRobot, InProcSensor, SharedWorld, Truth, World};
