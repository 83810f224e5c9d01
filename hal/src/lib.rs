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

/// What the robot program asks of the force process (RSI: `<FcCmd Mode=…>`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProcessMode {
    /// No force control: the correction returns to zero and stays there.
    Off,
    /// Approach until contact, ramp to the commanded force, hold it.
    Press,
    /// Ramp the force down, lift off, bring the correction back to zero, then report [`ProcessPhase::Off`].
    Release,
    /// A mode number the contract does not define; the process faults with [`ProcessFault::BadCommand`].
    Unknown(i64),
}

impl ProcessMode {
    /// The mode for a wire number (0 OFF, 1 PRESS, 2 RELEASE, anything else [`ProcessMode::Unknown`]).
    pub fn from_code(code: i64) -> Self {
        match code {
            0 => Self::Off,
            1 => Self::Press,
            2 => Self::Release,
            other => Self::Unknown(other),
        }
    }

    /// The wire number.
    pub fn code(self) -> i64 {
        match self {
            Self::Off => 0,
            Self::Press => 1,
            Self::Release => 2,
            Self::Unknown(c) => c,
        }
    }

    /// A short name, for the operator and recordings (`unknown` for a number the contract does not
    /// define).
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Press => "press",
            Self::Release => "release",
            Self::Unknown(_) => "unknown",
        }
    }

    /// Every defined wire number with its name, for a legend: `0 off, 1 press, 2 release`.
    pub fn legend() -> String {
        (0..)
            .map(Self::from_code)
            .take_while(|m| !matches!(m, Self::Unknown(_)))
            .map(|m| format!("{} {}", m.code(), m.name()))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The robot program's process command, carried by one cycle. SI units: the driver converts at the wire.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProcessCommand {
    /// What to do.
    pub mode: ProcessMode,
    /// Force set-point while pressing, N (compressive, along the tool's +z).
    pub force: f64,
    /// How long a change of set-point takes, s; 0 means the tuning's own rate.
    pub ramp: f64,
    /// The program's path segment number (recorded with every row).
    pub segment: i64,
}

/// Where the force process is, as reported to the robot program (RSI: `<FcState State=…>`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum ProcessPhase {
    /// No force control; the correction is (back) at zero.
    #[default]
    Off,
    /// Pressing was asked; moving towards the surface.
    Approach,
    /// In contact, the set-point ramps towards the commanded force.
    Ramp,
    /// Holding the commanded force within the tuning's tolerance.
    Pressing,
    /// Releasing: force ramps down, the tool lifts off, the correction returns to zero.
    Release,
    /// A latched fault; re-armed only by [`ProcessMode::Off`].
    Fault,
}

impl ProcessPhase {
    /// The wire number (0 OFF · 1 APPROACH · 2 RAMP · 3 PRESSING · 4 RELEASE · 9 FAULT).
    pub fn code(self) -> i64 {
        match self {
            Self::Off => 0,
            Self::Approach => 1,
            Self::Ramp => 2,
            Self::Pressing => 3,
            Self::Release => 4,
            Self::Fault => 9,
        }
    }

    /// The phase for a wire number, if the contract defines it.
    pub fn from_code(code: i64) -> Option<Self> {
        Some(match code {
            0 => Self::Off,
            1 => Self::Approach,
            2 => Self::Ramp,
            3 => Self::Pressing,
            4 => Self::Release,
            9 => Self::Fault,
            _ => return None,
        })
    }

    /// A short name, for the operator and recordings.
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Approach => "approach",
            Self::Ramp => "ramp",
            Self::Pressing => "pressing",
            Self::Release => "release",
            Self::Fault => "fault",
        }
    }

    /// Every wire number with its name, for a legend: `0 off, 1 approach, …, 9 fault`.
    pub fn legend() -> String {
        (0..=u8::MAX)
            .filter_map(|c| Self::from_code(i64::from(c)))
            .map(|p| format!("{} {}", p.code(), p.name()))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Why the force process faulted (RSI: `FcState.Fault`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum ProcessFault {
    /// No fault.
    #[default]
    None,
    /// The sensor was lost, or gave nothing usable for too long.
    SensorLost,
    /// The measured force exceeded the tuning's limit.
    ForceLimit,
    /// The correction reached its envelope.
    CorrectionLimit,
    /// The program sent a command the contract does not allow.
    BadCommand,
    /// Contact was lost for too long while pressing.
    ContactLost,
    /// The last command was held too long without a usable input.
    HoldTimeout,
}

impl ProcessFault {
    /// The wire number (0 none · 1 sensor · 2 force limit · 3 correction limit · 4 bad command ·
    /// 5 contact lost · 6 hold timeout).
    pub fn code(self) -> i64 {
        match self {
            Self::None => 0,
            Self::SensorLost => 1,
            Self::ForceLimit => 2,
            Self::CorrectionLimit => 3,
            Self::BadCommand => 4,
            Self::ContactLost => 5,
            Self::HoldTimeout => 6,
        }
    }

    /// A short name, for the operator and recordings.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::SensorLost => "sensor lost",
            Self::ForceLimit => "force limit",
            Self::CorrectionLimit => "correction limit",
            Self::BadCommand => "bad command",
            Self::ContactLost => "contact lost",
            Self::HoldTimeout => "hold timeout",
        }
    }

    /// Every wire number with its name, for a legend: `0 none, 1 sensor lost, …, 6 hold timeout`.
    pub fn legend() -> String {
        (0..)
            .map_while(Self::from_code)
            .map(|f| format!("{} {}", f.code(), f.name()))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The fault for a wire number, if the contract defines it.
    pub fn from_code(code: i64) -> Option<Self> {
        Some(match code {
            0 => Self::None,
            1 => Self::SensorLost,
            2 => Self::ForceLimit,
            3 => Self::CorrectionLimit,
            4 => Self::BadCommand,
            5 => Self::ContactLost,
            6 => Self::HoldTimeout,
            _ => return None,
        })
    }
}

/// The force process's state, sent with a reply.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct ProcessState {
    /// Where the process is.
    pub phase: ProcessPhase,
    /// Measured compensated normal force, N (0 when none is known).
    pub force: f64,
    /// The latched fault, [`ProcessFault::None`] unless `phase` is [`ProcessPhase::Fault`].
    pub fault: ProcessFault,
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
