//! Proof that the driver's per-cycle path allocates nothing: a counting global allocator around the
//! codec alone and around whole `next_cycle` → `reply` rounds over loopback UDP.
//! (`harness = false`: a plain `main` in one thread, so nothing else allocates while it measures.)

use std::alloc::System;
use std::net::UdpSocket;

use abb_egm::msg::{
    EgmFeedBack, EgmHeader, EgmJoints, EgmPlanned, EgmPose, EgmRapiddata, EgmRobot,
    EgmSensorPathCorr, MessageType,
};
use abb_egm::{CommandSlots, EgmLink, LinkConfig, RobotFilter, wire};
use hal::{Correction, Pose, RobotLink, Vector3};
use prost::Message;
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

fn main() {
    decode_encode_and_link_round_trips_do_not_allocate();
    println!("zero_alloc: EGM codec and driver path allocate nothing: 1 passed, 0 failed");
}

fn robot_message(seqno: u32) -> EgmRobot {
    let (pos, orient) = wire::pose_to_wire(&Pose::from_position(Vector3::new(0.5, 0.0, 0.3)));
    let pose = EgmPose {
        pos: Some(pos),
        orient: Some(orient),
        euler: None,
    };
    let joints = EgmJoints {
        joints: vec![0.0, 10.0, 20.0, 0.0, 60.0, 0.0],
    };
    EgmRobot {
        header: Some(EgmHeader {
            seqno: Some(seqno),
            tm: Some(seqno * 4),
            mtype: Some(MessageType::Data as i32),
        }),
        feed_back: Some(EgmFeedBack {
            joints: Some(joints.clone()),
            cartesian: Some(pose),
            ..EgmFeedBack::default()
        }),
        planned: Some(EgmPlanned {
            joints: Some(joints),
            cartesian: Some(pose),
            ..EgmPlanned::default()
        }),
        rapid_from_robot: Some(EgmRapiddata {
            dig_val: None,
            dnum: vec![1.0, 20.0, 0.5, 3.0],
        }),
        ..EgmRobot::default()
    }
}

fn decode_encode_and_link_round_trips_do_not_allocate() {
    // Codec alone: decode into one message, encode a path correction into a fixed buffer.
    let bytes: Vec<Vec<u8>> = (0..1000)
        .map(|k| robot_message(k).encode_to_vec())
        .collect();
    let mut rx = EgmRobot::default();
    rx.decode_into(&bytes[0]).unwrap();
    let mut out = [0u8; 256];
    let reply = EgmSensorPathCorr::default();
    let region = Region::new(GLOBAL);
    for b in &bytes {
        rx.decode_into(b).unwrap();
        let mut buf = &mut out[..];
        reply.encode(&mut buf).unwrap();
    }
    let s = region.change();
    assert_eq!(
        (s.allocations, s.reallocations),
        (0, 0),
        "codec allocated: {s:?}"
    );
    assert_eq!(rx.rapid_from_robot.unwrap().dnum.len(), 4);

    // The whole driver path over a real socket.
    let robot = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut lc = LinkConfig::new(
        "127.0.0.1:0".parse().unwrap(),
        RobotFilter::Exact(robot.local_addr().unwrap()),
    );
    lc.process = Some(CommandSlots::default());
    let mut link = EgmLink::bind(lc).unwrap();
    let to = link.local_addr().unwrap();
    let bytes: Vec<Vec<u8>> = (0..1010)
        .map(|k| robot_message(100 + k).encode_to_vec())
        .collect();
    let mut back = [0u8; 256];
    let mut round = |link: &mut EgmLink, k: usize| {
        robot.send_to(&bytes[k], to).unwrap();
        let c = link.next_cycle().unwrap();
        link.reply(&Correction::along_z(c.t * 1e-3)).unwrap();
        robot.recv_from(&mut back).unwrap();
    };
    for k in 0..10 {
        round(&mut link, k);
    }
    let region = Region::new(GLOBAL);
    for k in 10..1010 {
        round(&mut link, k);
    }
    let s = region.change();
    assert_eq!(
        (s.allocations, s.reallocations),
        (0, 0),
        "driver path allocated: {s:?}"
    );
    assert_eq!(link.diagnostics().counters.answered, 1010);
}
