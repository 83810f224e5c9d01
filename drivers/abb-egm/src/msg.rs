//! The EGM messages as prost structs: exactly the fields of `proto/egm.proto`, written by hand
//! (no `protoc`, no build script). The proto file's `required` fields are `Option`s here, so a message
//! that lacks one is seen as such by the session and refused, never read as a zero.
//!
//! Repeated numbers are unpacked on the wire (`proto2`'s default, what the controller sends and
//! expects); decoding accepts packed ones too, as every protobuf decoder must.
//!
//! [`EgmRobot::scrub`] empties a message for the next decode while keeping the capacity of its
//! repeated fields, so decoding cycle after cycle into one message allocates nothing.
#![allow(missing_docs)] // one struct per message of the .proto; the .proto documents them

use prost::{Enumeration, Message};

/// `EgmHeader.MessageType`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Enumeration)]
#[repr(i32)]
pub enum MessageType {
    Undefined = 0,
    Command = 1,
    Data = 2,
    Correction = 3,
    PathCorrection = 4,
}

/// `EgmMotorState.MotorStateType`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Enumeration)]
#[repr(i32)]
pub enum MotorStateType {
    MotorsUndefined = 0,
    MotorsOn = 1,
    MotorsOff = 2,
}

/// `EgmMCIState.MCIStateType`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Enumeration)]
#[repr(i32)]
pub enum MciStateType {
    MciUndefined = 0,
    MciError = 1,
    MciStopped = 2,
    MciRunning = 3,
}

/// `EgmRapidCtrlExecState.RapidCtrlExecStateType`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Enumeration)]
#[repr(i32)]
pub enum RapidCtrlExecStateType {
    RapidUndefined = 0,
    RapidStopped = 1,
    RapidRunning = 2,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmHeader {
    #[prost(uint32, optional, tag = "1")]
    pub seqno: Option<u32>,
    #[prost(uint32, optional, tag = "2")]
    pub tm: Option<u32>,
    #[prost(enumeration = "MessageType", optional, tag = "3")]
    pub mtype: Option<i32>,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmCartesian {
    #[prost(double, optional, tag = "1")]
    pub x: Option<f64>,
    #[prost(double, optional, tag = "2")]
    pub y: Option<f64>,
    #[prost(double, optional, tag = "3")]
    pub z: Option<f64>,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmQuaternion {
    #[prost(double, optional, tag = "1")]
    pub u0: Option<f64>,
    #[prost(double, optional, tag = "2")]
    pub u1: Option<f64>,
    #[prost(double, optional, tag = "3")]
    pub u2: Option<f64>,
    #[prost(double, optional, tag = "4")]
    pub u3: Option<f64>,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmEuler {
    #[prost(double, optional, tag = "1")]
    pub x: Option<f64>,
    #[prost(double, optional, tag = "2")]
    pub y: Option<f64>,
    #[prost(double, optional, tag = "3")]
    pub z: Option<f64>,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmClock {
    #[prost(uint64, optional, tag = "1")]
    pub sec: Option<u64>,
    #[prost(uint64, optional, tag = "2")]
    pub usec: Option<u64>,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmPose {
    #[prost(message, optional, tag = "1")]
    pub pos: Option<EgmCartesian>,
    #[prost(message, optional, tag = "2")]
    pub orient: Option<EgmQuaternion>,
    #[prost(message, optional, tag = "3")]
    pub euler: Option<EgmEuler>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmCartesianSpeed {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub value: Vec<f64>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmJoints {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub joints: Vec<f64>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmExternalJoints {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub joints: Vec<f64>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmPlanned {
    #[prost(message, optional, tag = "1")]
    pub joints: Option<EgmJoints>,
    #[prost(message, optional, tag = "2")]
    pub cartesian: Option<EgmPose>,
    #[prost(message, optional, tag = "3")]
    pub external_joints: Option<EgmJoints>,
    #[prost(message, optional, tag = "4")]
    pub time: Option<EgmClock>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmSpeedRef {
    #[prost(message, optional, tag = "1")]
    pub joints: Option<EgmJoints>,
    #[prost(message, optional, tag = "2")]
    pub cartesians: Option<EgmCartesianSpeed>,
    #[prost(message, optional, tag = "3")]
    pub external_joints: Option<EgmJoints>,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmPathCorr {
    #[prost(message, optional, tag = "1")]
    pub pos: Option<EgmCartesian>,
    #[prost(uint32, optional, tag = "2")]
    pub age: Option<u32>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmFeedBack {
    #[prost(message, optional, tag = "1")]
    pub joints: Option<EgmJoints>,
    #[prost(message, optional, tag = "2")]
    pub cartesian: Option<EgmPose>,
    #[prost(message, optional, tag = "3")]
    pub external_joints: Option<EgmJoints>,
    #[prost(message, optional, tag = "4")]
    pub time: Option<EgmClock>,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmMotorState {
    #[prost(enumeration = "MotorStateType", optional, tag = "1")]
    pub state: Option<i32>,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmMciState {
    #[prost(enumeration = "MciStateType", optional, tag = "1")]
    pub state: Option<i32>,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmRapidCtrlExecState {
    #[prost(enumeration = "RapidCtrlExecStateType", optional, tag = "1")]
    pub state: Option<i32>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmTestSignals {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub signals: Vec<f64>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmMeasuredForce {
    #[prost(bool, optional, tag = "1")]
    pub fc_active: Option<bool>,
    #[prost(double, repeated, packed = "false", tag = "2")]
    pub force: Vec<f64>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmCollisionInfo {
    #[prost(bool, optional, tag = "1")]
    pub collsion_triggered: Option<bool>,
    #[prost(double, repeated, packed = "false", tag = "2")]
    pub coll_det_quota: Vec<f64>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmRapiddata {
    #[prost(bool, optional, tag = "1")]
    pub dig_val: Option<bool>,
    #[prost(double, repeated, packed = "false", tag = "2")]
    pub dnum: Vec<f64>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmRobot {
    #[prost(message, optional, tag = "1")]
    pub header: Option<EgmHeader>,
    #[prost(message, optional, tag = "2")]
    pub feed_back: Option<EgmFeedBack>,
    #[prost(message, optional, tag = "3")]
    pub planned: Option<EgmPlanned>,
    #[prost(message, optional, tag = "4")]
    pub motor_state: Option<EgmMotorState>,
    #[prost(message, optional, tag = "5")]
    pub mci_state: Option<EgmMciState>,
    #[prost(bool, optional, tag = "6")]
    pub mci_convergence_met: Option<bool>,
    #[prost(message, optional, tag = "7")]
    pub test_signals: Option<EgmTestSignals>,
    #[prost(message, optional, tag = "8")]
    pub rapid_exec_state: Option<EgmRapidCtrlExecState>,
    #[prost(message, optional, tag = "9")]
    pub measured_force: Option<EgmMeasuredForce>,
    #[prost(double, optional, tag = "10")]
    pub utilization_rate: Option<f64>,
    #[prost(uint32, optional, tag = "11")]
    pub move_index: Option<u32>,
    #[prost(message, optional, tag = "12")]
    pub collision_info: Option<EgmCollisionInfo>,
    #[prost(message, optional, tag = "13")]
    pub rapid_from_robot: Option<EgmRapiddata>,
}

#[derive(Clone, PartialEq, Message)]
pub struct EgmSensor {
    #[prost(message, optional, tag = "1")]
    pub header: Option<EgmHeader>,
    #[prost(message, optional, tag = "2")]
    pub planned: Option<EgmPlanned>,
    #[prost(message, optional, tag = "3")]
    pub speed_ref: Option<EgmSpeedRef>,
    #[prost(message, optional, tag = "4")]
    pub rapid_to_robot: Option<EgmRapiddata>,
}

#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmSensorPathCorr {
    #[prost(message, optional, tag = "1")]
    pub header: Option<EgmHeader>,
    #[prost(message, optional, tag = "2")]
    pub path_corr: Option<EgmPathCorr>,
}

/// Clear the repeated values of an optional message in place (keeping their allocation); the caller
/// decides, by presence of leaves, what the next datagram carried.
fn keep<T>(slot: &mut Option<T>, clear: impl FnOnce(&mut T)) {
    if let Some(v) = slot {
        clear(v);
    }
}

impl EgmPose {
    fn scrub(&mut self) {
        *self = Self::default();
    }
}

impl EgmFeedBack {
    fn scrub(&mut self) {
        keep(&mut self.joints, |j| j.joints.clear());
        keep(&mut self.external_joints, |j| j.joints.clear());
        keep(&mut self.cartesian, EgmPose::scrub);
        self.time = None;
    }
}

impl EgmPlanned {
    fn scrub(&mut self) {
        keep(&mut self.joints, |j| j.joints.clear());
        keep(&mut self.external_joints, |j| j.joints.clear());
        keep(&mut self.cartesian, EgmPose::scrub);
        self.time = None;
    }
}

impl EgmRobot {
    /// Empty the message for the next [`Message::merge`], keeping the allocation of every repeated
    /// field. Scalars and messages without repeated fields become absent; a message holding a repeated
    /// field stays present but empty, so **presence is judged by its leaves** (a pose's `pos.x`, the
    /// length of `dnum`), never by the message's own `Option`.
    pub fn scrub(&mut self) {
        self.header = None;
        keep(&mut self.feed_back, EgmFeedBack::scrub);
        keep(&mut self.planned, EgmPlanned::scrub);
        self.motor_state = None;
        self.mci_state = None;
        self.mci_convergence_met = None;
        keep(&mut self.test_signals, |t| t.signals.clear());
        self.rapid_exec_state = None;
        keep(&mut self.measured_force, |m| {
            m.fc_active = None;
            m.force.clear();
        });
        self.utilization_rate = None;
        self.move_index = None;
        keep(&mut self.collision_info, |c| {
            c.collsion_triggered = None;
            c.coll_det_quota.clear();
        });
        keep(&mut self.rapid_from_robot, |r| {
            r.dig_val = None;
            r.dnum.clear();
        });
    }

    /// Decode `bytes` into `self` (scrubbed first). No allocation once the repeated fields have grown
    /// to the robot's sizes.
    pub fn decode_into(&mut self, bytes: &[u8]) -> Result<(), prost::DecodeError> {
        self.scrub();
        self.merge(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scrub_keeps_capacity_and_forgets_values() {
        let mut m = EgmRobot {
            header: Some(EgmHeader {
                seqno: Some(3),
                tm: Some(12),
                mtype: Some(MessageType::Data as i32),
            }),
            rapid_from_robot: Some(EgmRapiddata {
                dig_val: None,
                dnum: vec![1.0, 2.0, 3.0, 4.0],
            }),
            ..EgmRobot::default()
        };
        m.scrub();
        assert_eq!(m.header, None);
        let r = m.rapid_from_robot.as_ref().unwrap();
        assert!(r.dnum.is_empty() && r.dnum.capacity() >= 4);
    }
}
