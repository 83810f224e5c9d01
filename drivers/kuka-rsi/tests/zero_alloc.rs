//! Proof that the driver's per-message path allocates nothing: a counting global allocator around
//! the codec alone and around whole `next_cycle` → `reply` rounds over loopback UDP.
//! (`harness = false`: a plain `main` in one thread, so nothing else allocates while it measures.)

use std::alloc::System;
use std::net::UdpSocket;

use hal::{Correction, RobotLink};
use kuka_rsi::{EthernetConfig, Frame, Ipoc, LinkConfig, RobotFilter, RsiLink};
use stats_alloc::{INSTRUMENTED_SYSTEM, Region, StatsAlloc};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];

fn main() {
    parse_write_and_link_round_trips_do_not_allocate();
    println!("zero_alloc: codec and driver path allocate nothing: 1 passed, 0 failed");
}

fn parse_write_and_link_round_trips_do_not_allocate() {
    let cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false);
    let rob = cfg.rob_schema(4).unwrap();
    let sen = cfg.sen_schema(4).unwrap();

    // Robot-side message to feed in, written once.
    let mut out = Frame::new();
    let rist = rob.six("RIst", POSE).unwrap();
    let rsol = rob.six("RSol", POSE).unwrap();
    out.set6(rist, [500.0, 0.0, 300.0, 0.0, 0.0, 180.0]);
    out.set6(rsol, [500.0, 0.0, 300.0, 0.0, 0.0, 180.0]);
    let mut rob_buf = [0u8; 2048];

    // Codec alone.
    let mut frame = Frame::new();
    let mut sen_buf = [0u8; 1024];
    let n = rob.write(&out, &mut rob_buf).unwrap();
    rob.parse(&rob_buf[..n], &mut frame).unwrap();
    let region = Region::new(GLOBAL);
    for k in 0..1000u64 {
        out.set_ipoc(Ipoc::new(1000 + k));
        let n = rob.write(&out, &mut rob_buf).unwrap();
        rob.parse(&rob_buf[..n], &mut frame).unwrap();
        let m = sen.write(&frame, &mut sen_buf).unwrap();
        sen.parse(&sen_buf[..m], &mut frame).unwrap();
    }
    let s = region.change();
    assert_eq!(
        (s.allocations, s.reallocations),
        (0, 0),
        "codec allocated: {s:?}"
    );

    // The whole driver path over a real socket.
    let robot = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut lc = LinkConfig::new(cfg, RobotFilter::Exact(robot.local_addr().unwrap()));
    lc.bind = Some("127.0.0.1:0".parse().unwrap());
    let mut link = RsiLink::bind(lc).unwrap();
    let to = link.local_addr().unwrap();
    let mut k = 0u64;
    let mut round = |link: &mut RsiLink| {
        out.set_ipoc(Ipoc::new(5000 + 4 * k));
        k += 1;
        let n = rob.write(&out, &mut rob_buf).unwrap();
        robot.send_to(&rob_buf[..n], to).unwrap();
        let c = link.next_cycle().unwrap();
        link.reply(&Correction::along_z(c.t * 1e-3)).unwrap();
        let (m, _) = robot.recv_from(&mut sen_buf).unwrap();
        sen.parse(&sen_buf[..m], &mut frame).unwrap();
    };
    for _ in 0..10 {
        round(&mut link);
    }
    let region = Region::new(GLOBAL);
    for _ in 0..1000 {
        round(&mut link);
    }
    let s = region.change();
    assert_eq!(
        (s.allocations, s.reallocations),
        (0, 0),
        "driver path allocated: {s:?}"
    );
    assert_eq!(link.diagnostics().counters.answered, 1010);
}
