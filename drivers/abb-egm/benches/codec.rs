//! Codec speed per message with allocations counted (`cargo bench -p forcecell-abb-egm --bench codec`):
//! the decode of `EgmRobot` into one kept message, on what the simulated IRC5 sends with process channels
//! (`false`: header, poses, states, process numbers) and on one that also carries what a controller adds
//! (`true`: joints, clocks, Euler angles); and the path correction's encode into a fixed buffer.

use abb_egm::msg::{
    EgmCartesian, EgmClock, EgmEuler, EgmFeedBack, EgmHeader, EgmJoints, EgmMciState,
    EgmMotorState, EgmPathCorr, EgmPlanned, EgmPose, EgmRapidCtrlExecState, EgmRapiddata, EgmRobot,
    EgmSensorPathCorr, MessageType,
};
use abb_egm::wire;
use divan::{AllocProfiler, Bencher, black_box};
use hal::{Pose, UnitQuaternion, Vector3};
use prost::Message;

#[global_allocator]
static ALLOC: AllocProfiler = AllocProfiler::system();

fn main() {
    divan::main();
}

/// A pose as the simulated IRC5 writes it (`wire::pose_to_wire`), with Euler angles where a controller
/// adds them.
fn pose(z_m: f64, euler: bool) -> EgmPose {
    let p = Pose {
        position: Vector3::new(0.445_123_4, -0.0125, z_m),
        orientation: UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.5),
    };
    let (pos, orient) = wire::pose_to_wire(&p);
    EgmPose {
        pos: Some(pos),
        orient: Some(orient),
        euler: euler.then_some(EgmEuler {
            x: Some(180.0),
            y: Some(0.0),
            z: Some(28.6),
        }),
    }
}

/// The simulated IRC5's message (`full = false`) or one with joints, clocks and Euler angles as well.
fn robot(full: bool) -> Vec<u8> {
    let joints = full.then(|| EgmJoints {
        joints: vec![0.5, 12.25, 20.0, -0.75, 60.5, 90.0],
    });
    let time = full.then_some(EgmClock {
        sec: Some(1_764_930_000),
        usec: Some(123_456),
    });
    EgmRobot {
        header: Some(EgmHeader {
            seqno: Some(123_456),
            tm: Some(987_654),
            mtype: Some(MessageType::Data as i32),
        }),
        feed_back: Some(EgmFeedBack {
            joints: joints.clone(),
            cartesian: Some(pose(0.890_000_1, full)),
            external_joints: None,
            time,
        }),
        planned: Some(EgmPlanned {
            joints,
            cartesian: Some(pose(0.890, full)),
            external_joints: None,
            time,
        }),
        motor_state: Some(EgmMotorState { state: Some(1) }),
        mci_state: Some(EgmMciState { state: Some(3) }),
        rapid_exec_state: Some(EgmRapidCtrlExecState { state: Some(2) }),
        rapid_from_robot: Some(EgmRapiddata {
            dig_val: None,
            dnum: vec![1.0, 20.0, 0.5, 3.0],
        }),
        ..EgmRobot::default()
    }
    .encode_to_vec()
}

/// `EgmRobot::decode_into`, what the session calls.
#[divan::bench(args = [false, true])]
fn decode_robot(b: Bencher, full: bool) {
    let bytes = robot(full);
    let mut m = EgmRobot::default();
    m.decode_into(&bytes).unwrap();
    b.bench_local(|| m.decode_into(black_box(&bytes)).unwrap());
}

/// The reply: an `EgmSensorPathCorr` into a fixed buffer.
#[divan::bench]
fn encode_path_correction(b: Bencher) {
    let m = EgmSensorPathCorr {
        header: Some(EgmHeader {
            seqno: Some(123_456),
            tm: Some(987_654),
            mtype: Some(MessageType::PathCorrection as i32),
        }),
        path_corr: Some(EgmPathCorr {
            pos: Some(EgmCartesian {
                x: Some(0.0),
                y: Some(0.0),
                z: Some(1.234_5),
            }),
            age: Some(4),
        }),
    };
    let mut out = [0u8; 128];
    b.bench_local(|| {
        let mut buf = &mut out[..];
        black_box(&m).encode(&mut buf).unwrap();
        black_box(&out);
    });
}
