//! Golden byte vectors for both directions, written out by hand from the protobuf wire format
//! (tag = field number << 3 | wire type; varints; doubles as 8 little-endian bytes; nested messages
//! length-delimited; `repeated double` unpacked, proto2's default), then checked against the codec.

use std::net::SocketAddr;
use std::time::Instant;

use abb_egm::msg::{
    EgmCartesian, EgmHeader, EgmPathCorr, EgmRobot, EgmSensorPathCorr, MessageType,
};
use abb_egm::{CommandSlots, EgmSession, LinkConfig, RobotFilter};
use hal::{Correction, ProcessMode, UnitQuaternion, Vector3};
use prost::Message;

const D0: [u8; 8] = [0; 8]; // 0.0
const D1: [u8; 8] = [0, 0, 0, 0, 0, 0, 0xf0, 0x3f]; // 1.0 = 0x3FF0_0000_0000_0000
const D1_5: [u8; 8] = [0, 0, 0, 0, 0, 0, 0xf8, 0x3f]; // 1.5
const D500: [u8; 8] = [0, 0, 0, 0, 0, 0x40, 0x7f, 0x40]; // 500.0 = 0x407F_4000_0000_0000
const D300: [u8; 8] = [0, 0, 0, 0, 0, 0xc0, 0x72, 0x40]; // 300.0 = 0x4072_C000_0000_0000
const D20: [u8; 8] = [0, 0, 0, 0, 0, 0, 0x34, 0x40]; // 20.0
const D0_5: [u8; 8] = [0, 0, 0, 0, 0, 0, 0xe0, 0x3f]; // 0.5
const D3: [u8; 8] = [0, 0, 0, 0, 0, 0, 0x08, 0x40]; // 3.0

fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

/// EgmSensorPathCorr { header { seqno 1, mtype PATH_CORRECTION }, pathCorr { pos { 0, 0, 1.5 }, age 4 } }
fn path_corr_bytes() -> Vec<u8> {
    cat(&[
        &[0x0a, 0x04, 0x08, 0x01, 0x18, 0x04], // header (1, LEN 4): seqno (1) 1, mtype (3) 4
        &[0x12, 0x1f],                         // pathCorr (2, LEN 31)
        &[0x0a, 0x1b],                         //   pos (1, LEN 27)
        &[0x09],
        &D0, //     x (1, I64)
        &[0x11],
        &D0, //     y (2, I64)
        &[0x19],
        &D1_5,         //     z (3, I64)
        &[0x10, 0x04], //   age (2, VARINT) 4
    ])
}

/// The pose both feedback and planned carry: 500, 0, 300 mm, quaternion (0, 1, 0, 0): 180° about x.
fn pose_bytes() -> Vec<u8> {
    cat(&[
        &[0x12, 0x43], // cartesian (2, LEN 67)
        &[0x0a, 0x1b], //   pos (1, LEN 27)
        &[0x09],
        &D500,
        &[0x11],
        &D0,
        &[0x19],
        &D300,
        &[0x12, 0x24], //   orient (2, LEN 36)
        &[0x09],
        &D0,
        &[0x11],
        &D1,
        &[0x19],
        &D0,
        &[0x21],
        &D0,
    ])
}

/// EgmRobot { header { seqno 7, tm 1000, mtype DATA }, feedBack, planned, motorState ON,
/// rapidExecState RUNNING, RAPIDfromRobot { dnum [1, 20, 0.5, 3] } }
fn robot_bytes() -> Vec<u8> {
    let pose = pose_bytes();
    cat(&[
        &[0x0a, 0x07, 0x08, 0x07, 0x10, 0xe8, 0x07, 0x18, 0x02], // header: tm 1000 = e8 07
        &[0x12, 0x45],                                           // feedBack (2, LEN 69)
        &pose,
        &[0x1a, 0x45], // planned (3, LEN 69)
        &pose,
        &[0x22, 0x02, 0x08, 0x01], // motorState (4): state MOTORS_ON
        &[0x42, 0x02, 0x08, 0x02], // rapidExecState (8): state RAPID_RUNNING
        &[0x6a, 0x24],             // RAPIDfromRobot (13 << 3 | 2 = 0x6a, LEN 36)
        &[0x11],
        &D1, //   dnum (2, I64), one tag per number
        &[0x11],
        &D20,
        &[0x11],
        &D0_5,
        &[0x11],
        &D3,
    ])
}

#[test]
fn path_correction_golden_both_ways() {
    let m = EgmSensorPathCorr {
        header: Some(EgmHeader {
            seqno: Some(1),
            tm: None,
            mtype: Some(MessageType::PathCorrection as i32),
        }),
        path_corr: Some(EgmPathCorr {
            pos: Some(EgmCartesian {
                x: Some(0.0),
                y: Some(0.0),
                z: Some(1.5),
            }),
            age: Some(4),
        }),
    };
    assert_eq!(m.encode_to_vec(), path_corr_bytes());
    assert_eq!(
        EgmSensorPathCorr::decode(&path_corr_bytes()[..]).unwrap(),
        m
    );
}

#[test]
fn robot_golden_decodes_and_re_encodes_identically() {
    let bytes = robot_bytes();
    let m = EgmRobot::decode(&bytes[..]).unwrap();
    assert_eq!(
        m.encode_to_vec(),
        bytes,
        "field order and unpacked dnum as written"
    );
    assert_eq!(
        m.rapid_from_robot.as_ref().unwrap().dnum,
        [1.0, 20.0, 0.5, 3.0]
    );
}

#[test]
fn robot_golden_through_the_session_is_a_cycle_in_si() {
    let robot = SocketAddr::from(([127, 0, 0, 1], 40_000));
    let mut cfg = LinkConfig::new(
        SocketAddr::from(([127, 0, 0, 1], 0)),
        RobotFilter::Exact(robot),
    );
    cfg.process = Some(CommandSlots::default());
    let mut s = EgmSession::new(cfg).unwrap();
    let t0 = Instant::now();
    let c = s.receive(&robot_bytes(), robot, t0).unwrap();
    assert_eq!((c.seq, c.t, c.new_session), (7, 0.0, true));
    assert!((c.actual.position - Vector3::new(0.5, 0.0, 0.3)).norm() < 1e-15);
    let flipped = UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0);
    assert!(c.actual.orientation.angle_to(&flipped) < 1e-12);
    let p = c.process.unwrap();
    assert_eq!(
        (p.mode, p.force, p.ramp, p.segment),
        (ProcessMode::Press, 20.0, 0.5, 3)
    );
    let st = s.diagnostics().robot;
    assert_eq!((st.motors, st.rapid), (Some(1), Some(2)));
    // The reply: 0.25 mm along the tool's z (the rate limit's first step), age 0.
    let mut out = [0u8; 128];
    let o = s
        .reply(&Correction::along_z(1.0), t0, &mut out)
        .unwrap()
        .unwrap();
    let sent = &out[..o.len];
    // Header and framing byte for byte; the one double checked by value.
    assert_eq!(sent[..6], [0x0a, 0x04, 0x08, 0x01, 0x18, 0x04]);
    assert_eq!(sent[6..10], [0x12, 0x1f, 0x0a, 0x1b]);
    assert_eq!(sent[10], 0x09);
    assert_eq!(sent[11..19], D0);
    assert_eq!(sent[19], 0x11);
    assert_eq!(sent[28], 0x19);
    let z = f64::from_le_bytes(sent[29..37].try_into().unwrap());
    assert!((z - 0.25).abs() < 1e-12, "{z}");
    assert_eq!(sent[37..], [0x10, 0x00]);
}
