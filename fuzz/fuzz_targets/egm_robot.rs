//! Fuzz the EGM session's receive side (the bytes a network peer controls): any datagram is either
//! refused with a typed reason or becomes a cycle whose poses and time are finite, whose process
//! command (with process channels configured) is finite, and whose reply encodes and decodes back as
//! the path correction it is. And the message decoder alone: whatever it accepts re-encodes and
//! decodes to the same bytes.
#![no_main]

use std::net::SocketAddr;
use std::time::Instant;

use abb_egm::msg::{EgmRobot, EgmSensorPathCorr};
use abb_egm::{CommandSlots, EgmSession, LinkConfig, RobotFilter};
use hal::{Correction, Vector3};
use libfuzzer_sys::fuzz_target;
use prost::Message;

fn session(process: bool) -> EgmSession {
    let robot: SocketAddr = "127.0.0.1:6510".parse().unwrap();
    let mut cfg = LinkConfig::new("127.0.0.1:6511".parse().unwrap(), RobotFilter::Exact(robot));
    if process {
        cfg.process = Some(CommandSlots { first: 0 });
    }
    EgmSession::new(cfg).expect("a valid config")
}

fuzz_target!(|data: &[u8]| {
    let robot: SocketAddr = "127.0.0.1:6510".parse().unwrap();
    for process in [false, true] {
        let mut s = session(process);
        let now = Instant::now();
        if let Ok(cycle) = s.receive(data, robot, now) {
            assert!(cycle.t.is_finite() && cycle.period > 0.0);
            // A pose is usable or, where no arm moves that fast, NaN as a whole (held by the loop).
            for pose in [cycle.actual, cycle.programmed] {
                let v = pose.position;
                assert!(v.iter().all(|x| x.is_finite()) || v.iter().all(|x| x.is_nan()));
            }
            if let Some(p) = cycle.process {
                assert!(p.force.is_finite() && p.ramp.is_finite());
            }
            let mut out = [0u8; 1024];
            let c = Correction {
                translation: Vector3::new(0.0, 0.0, 0.001),
                ..Correction::default()
            };
            let sent = s.reply(&c, now, &mut out).expect("a taken cycle is answered");
            let sent = sent.expect("every cycle is answered");
            let back = EgmSensorPathCorr::decode(&out[..sent.len]).expect("our reply decodes");
            assert!(back.path_corr.is_some());
        }
    }
    if let Ok(m) = EgmRobot::decode(data) {
        // Compared as bytes: a NaN field is the same message though `NaN != NaN`.
        let bytes = m.encode_to_vec();
        let again = EgmRobot::decode(bytes.as_slice()).expect("re-encoded bytes decode");
        assert_eq!(again.encode_to_vec(), bytes);
    }
});
