//! Hardware abstraction for forcecell: the two things a force-controlled cell needs from hardware.
//!
//! * [`ForceSensor`] — a six-axis force/torque sensor (ATI over CAN, Robotiq over Modbus, a simulated node).
//! * [`RobotLink`] — a robot's cyclic position-correction interface (KUKA RSI over UDP, a simulated controller).
//!
//! The crate does no I/O. It holds the traits, the value types that cross them and a small error
//! vocabulary in the embedded-hal style: every driver error maps to an [`ErrorKind`] so code written against
//! the HAL (the controller, the control loop) can react to *what* went wrong without knowing the driver.
//!
//! # Units and frames
//! SI everywhere: metres, radians, newtons, newton-metres, seconds. Device units (mm, degrees, counts) exist
//! only inside drivers, at the wire.
//!
//! # Who owns the clock
//! The robot. A robot controller sends one cycle per interpolation period whether or not it was answered, and
//! expects exactly one reply per cycle within that period. A control loop therefore calls
//! [`RobotLink::next_cycle`], then reads the newest force sample with [`ForceSensor::read`] (which never waits
//! for the bus), computes, and answers with exactly one [`RobotLink::reply`].
#![cfg_attr(not(test), warn(missing_docs))]

use core::fmt;
use core::time::Duration;

pub use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

mod latency;
pub mod process;
pub use latency::Latency;
pub use process::{ProcessCommand, ProcessFault, ProcessMode, ProcessPhase, ProcessState};

/// What kind of failure a driver error is. Non-exhaustive: match with a wildcard arm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ErrorKind {
    /// No answer within the deadline (a sensor request, a robot cycle). Usually transient.
    Timeout,
    /// Data arrived but is older than the configured limit.
    Stale,
    /// The peer is gone: the robot fell silent past its watchdog, the bus went off, the socket closed.
    /// A control loop must stop.
    LinkLost,
    /// A frame, packet or datagram was malformed and was dropped.
    Malformed,
    /// The sensor reports a saturated gauge; the sample is unusable.
    Saturated,
    /// The device reports an internal error (status word, exception code).
    DeviceFault,
    /// The CAN controller is bus-off.
    BusOff,
    /// The configuration is invalid or does not match the device.
    Config,
    /// An operating-system I/O error.
    Io,
    /// Anything else; the driver's error says more.
    Other,
}

impl ErrorKind {
    /// True when the condition may clear by itself and the loop should hold and carry on.
    pub fn is_transient(self) -> bool {
        matches!(
            self,
            Self::Timeout | Self::Stale | Self::Malformed | Self::Saturated | Self::DeviceFault
        )
    }
}

impl fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = match self {
            Self::Timeout => "timed out",
            Self::Stale => "data is stale",
            Self::LinkLost => "link lost",
            Self::Malformed => "malformed data",
            Self::Saturated => "sensor saturated",
            Self::DeviceFault => "device reports a fault",
            Self::BusOff => "CAN bus-off",
            Self::Config => "invalid configuration",
            Self::Io => "I/O error",
            Self::Other => "other error",
        };
        f.write_str(s)
    }
}

/// A driver error: anything printable that can say which [`ErrorKind`] it is.
pub trait Error: fmt::Debug + fmt::Display {
    /// The kind of this error.
    fn kind(&self) -> ErrorKind;
}

impl Error for ErrorKind {
    fn kind(&self) -> ErrorKind {
        *self
    }
}

impl std::error::Error for ErrorKind {}

/// Force (N) and torque (N·m), both in the frame the producer documents (the sensor frame for a raw sensor,
/// the tool frame after compensation).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Wrench {
    /// Force, N.
    pub force: Vector3<f64>,
    /// Torque, N·m.
    pub torque: Vector3<f64>,
}

impl Wrench {
    /// A wrench from `[fx, fy, fz, tx, ty, tz]` in N and N·m.
    pub fn from_array(v: [f64; 6]) -> Self {
        Self {
            force: Vector3::new(v[0], v[1], v[2]),
            torque: Vector3::new(v[3], v[4], v[5]),
        }
    }

    /// `[fx, fy, fz, tx, ty, tz]`.
    pub fn to_array(&self) -> [f64; 6] {
        [
            self.force.x,
            self.force.y,
            self.force.z,
            self.torque.x,
            self.torque.y,
            self.torque.z,
        ]
    }

    /// True when all six components are finite.
    pub fn is_finite(&self) -> bool {
        self.to_array().iter().all(|v| v.is_finite())
    }
}

/// One force/torque measurement as returned by [`ForceSensor::read`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// The measured wrench, N and N·m, sensor frame, bias removed if the driver holds a bias.
    pub wrench: Wrench,
    /// Measurement counter of the driver; increases by at least one for every new measurement.
    /// A repeated `seq` means the same measurement was returned twice.
    pub seq: u64,
    /// Age of the measurement when `read` returned it.
    pub age: Duration,
}

/// A rigid pose: position in metres and orientation, in the robot's base frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Position, m.
    pub position: Vector3<f64>,
    /// Orientation.
    pub orientation: UnitQuaternion<f64>,
}

impl Default for Pose {
    fn default() -> Self {
        Self::identity()
    }
}

impl Pose {
    /// The origin with no rotation.
    pub fn identity() -> Self {
        Self {
            position: Vector3::zeros(),
            orientation: UnitQuaternion::identity(),
        }
    }

    /// A pure translation.
    pub fn from_position(position: Vector3<f64>) -> Self {
        Self {
            position,
            orientation: UnitQuaternion::identity(),
        }
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.position.iter().all(|v| v.is_finite())
            && self.orientation.coords.iter().all(|v| v.is_finite())
    }

    /// As a nalgebra isometry.
    pub fn to_isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::from(self.position), self.orientation)
    }
}

/// One robot interpolation cycle as delivered by [`RobotLink::next_cycle`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cycle {
    /// The robot's cycle stamp as received (RSI: IPOC). Increases within a session.
    pub seq: u64,
    /// Robot time, s, since the start of the session, derived from the robot's own stamp.
    pub t: f64,
    /// Nominal cycle period, s (RSI: 0.004 or 0.012).
    pub period: f64,
    /// Measured tool pose (RSI: `RIst`).
    pub actual: Pose,
    /// Programmed path pose, without any correction (RSI: `RSol`).
    pub programmed: Pose,
    /// The robot's own late-reply counter (RSI: `Delay`); anything above zero is an alarm.
    pub late_replies: u32,
    /// Robot cycles lost before this one in the session so far (gaps in the robot's cycle stamps, as the
    /// driver counts them); 0 where the link cannot tell.
    pub missed: u64,
    /// Replies the link sent later than its late bound after the robot's datagram arrived (RSI: from
    /// the kernel's receive stamp), so far, up to the reply before this cycle's; 0 where the link
    /// cannot tell.
    pub replied_late: u64,
    /// True on the first cycle of a new robot session: references captured from earlier cycles are void.
    pub new_session: bool,
    /// The robot program's process command, when the link carries process channels (RSI: `FcCmd`).
    /// `None`: no process channels; force control runs from the first cycle as configured.
    pub process: Option<ProcessCommand>,
}

impl Cycle {
    /// Where the measured tool is relative to the programmed path, in the programmed tool frame, m.
    /// `z` of this is the displacement along the tool's normal axis that a 1-DOF force controller acts on.
    pub fn tool_offset(&self) -> Vector3<f64> {
        self.programmed
            .orientation
            .inverse_transform_vector(&(self.actual.position - self.programmed.position))
    }
}

/// The reply to one cycle: the **absolute** correction from the programmed path, in the tool frame.
///
/// Drivers of robots that take increments (RSI `#RELATIVE`) convert; code written against the HAL always
/// speaks totals, so a lost reply can never be double-counted.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Correction {
    /// Translation offset, m, tool frame.
    pub translation: Vector3<f64>,
    /// Rotation offset as a small rotation vector, rad, tool frame.
    pub rotation: Vector3<f64>,
    /// Ask the robot to end the correction motion cleanly.
    pub stop: bool,
    /// The force process's state for the robot program (RSI: `FcState`); links without process
    /// channels ignore it.
    pub process: ProcessState,
}

impl Correction {
    /// A correction along the tool's z (normal) axis only.
    pub fn along_z(z: f64) -> Self {
        Self {
            translation: Vector3::new(0.0, 0.0, z),
            ..Self::default()
        }
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.translation.iter().all(|v| v.is_finite())
            && self.rotation.iter().all(|v| v.is_finite())
    }
}

/// A six-axis force/torque sensor.
///
/// # Contract
/// * `read` returns the **newest** measurement and never waits for the bus: drivers poll or receive in the
///   background (or, for sans-IO simulations, in the caller's time) and `read` only hands over what they hold.
/// * Units: N and N·m, in the sensor frame documented by the driver.
/// * Errors: [`ErrorKind::Stale`] or [`ErrorKind::Timeout`] when no measurement is newer than the driver's
///   staleness limit; [`ErrorKind::Saturated`] and [`ErrorKind::DeviceFault`] when the newest measurement is
///   unusable; [`ErrorKind::LinkLost`]/[`ErrorKind::BusOff`] when the sensor is gone. An error never carries
///   a sample: the caller holds its last safe command.
/// * A returned sample is finite. Callers still check: a misbehaving driver must not reach the command.
pub trait ForceSensor {
    /// The driver's error type.
    type Error: Error;

    /// The newest measurement.
    fn read(&mut self) -> Result<Sample, Self::Error>;
}

/// A robot's cyclic position-correction interface. The robot owns the clock.
///
/// # Contract
/// * [`next_cycle`](RobotLink::next_cycle) blocks until the robot's next cycle arrives (or, after a stall,
///   returns only the newest one) and returns it. When the robot stays silent past the driver's watchdog it
///   returns [`ErrorKind::LinkLost`]; the loop must end.
/// * Every cycle gets **exactly one** [`reply`](RobotLink::reply), as soon as possible within its period.
///   A second reply to the same cycle, or a reply before any cycle, is an error of kind [`ErrorKind::Other`].
/// * The reply is the absolute correction from the programmed path ([`Correction`]). Drivers enforce their
///   configured envelope and rate limits right before sending, never send a non-finite value, and report
///   what they clamped through their own diagnostics.
/// * A correction with `stop` set ends the robot's correction motion; the link is finished afterwards.
pub trait RobotLink {
    /// The driver's error type.
    type Error: Error;

    /// Wait for the robot's next cycle.
    fn next_cycle(&mut self) -> Result<Cycle, Self::Error>;

    /// Answer the cycle last returned by `next_cycle`.
    fn reply(&mut self, correction: &Correction) -> Result<(), Self::Error>;
}

impl<T: ForceSensor + ?Sized> ForceSensor for &mut T {
    type Error = T::Error;
    fn read(&mut self) -> Result<Sample, Self::Error> {
        (**self).read()
    }
}

impl<T: RobotLink + ?Sized> RobotLink for &mut T {
    type Error = T::Error;
    fn next_cycle(&mut self) -> Result<Cycle, Self::Error> {
        (**self).next_cycle()
    }
    fn reply(&mut self, correction: &Correction) -> Result<(), Self::Error> {
        (**self).reply(correction)
    }
}

/// mockall mocks of the HAL traits (feature `mock`), with [`ErrorKind`] as their error type.
#[cfg(feature = "mock")]
pub mod mock {
    use super::*;

    mockall::mock! {
        /// A mocked [`ForceSensor`].
        pub Sensor {}
        impl ForceSensor for Sensor {
            type Error = ErrorKind;
            fn read(&mut self) -> Result<Sample, ErrorKind>;
        }
    }

    mockall::mock! {
        /// A mocked [`RobotLink`].
        pub Robot {}
        impl RobotLink for Robot {
            type Error = ErrorKind;
            fn next_cycle(&mut self) -> Result<Cycle, ErrorKind>;
            fn reply(&mut self, correction: &Correction) -> Result<(), ErrorKind>;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tool_offset_is_expressed_in_the_programmed_tool_frame() {
        // Tool z points along base -z (tool flipped about x): moving down in base is +z in the tool.
        let flipped = UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0);
        let programmed = Pose {
            position: Vector3::new(0.4, 0.0, 0.9),
            orientation: flipped,
        };
        let actual = Pose {
            position: Vector3::new(0.4, 0.0, 0.899),
            orientation: flipped,
        };
        let c = Cycle {
            seq: 1,
            t: 0.0,
            period: 0.004,
            actual,
            programmed,
            late_replies: 0,
            missed: 0,
            replied_late: 0,
            new_session: false,
            process: None,
        };
        let off = c.tool_offset();
        assert!((off.z - 0.001).abs() < 1e-12, "{off:?}");
        assert!(off.x.abs() < 1e-12 && off.y.abs() < 1e-12);
    }

    #[test]
    fn wrench_array_round_trip_and_finiteness() {
        let w = Wrench::from_array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(w.to_array(), [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert!(w.is_finite());
        let bad = Wrench::from_array([1.0, f64::NAN, 3.0, 4.0, 5.0, 6.0]);
        assert!(!bad.is_finite());
    }

    #[test]
    fn process_codes_round_trip() {
        for c in -1..12 {
            assert_eq!(ProcessMode::from_code(c).code(), c);
            if let Some(p) = ProcessPhase::from_code(c) {
                assert_eq!(p.code(), c);
            }
            if let Some(f) = ProcessFault::from_code(c) {
                assert_eq!(f.code(), c);
            }
        }
        assert_eq!(ProcessMode::from_code(7), ProcessMode::Unknown(7));
        assert_eq!(ProcessPhase::from_code(5), None);
        assert_eq!(ProcessPhase::Fault.code(), 9);
        assert_eq!(ProcessFault::from_code(7), None);
    }

    #[test]
    fn transient_kinds() {
        assert!(ErrorKind::Timeout.is_transient());
        assert!(!ErrorKind::LinkLost.is_transient());
        assert!(!ErrorKind::BusOff.is_transient());
    }
}
