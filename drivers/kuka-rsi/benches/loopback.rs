//! The driver over real loopback UDP (`cargo bench -p forcecell-kuka-rsi --bench loopback`).
//!
//! First a report, not a divan measurement: the receive→send turnaround distribution as the driver
//! itself records it, over `RSI_BENCH_CYCLES` (default 100 000) lockstep cycles with the robot in
//! another thread. Then divan times one whole round trip (robot send → `next_cycle` → `reply` →
//! robot receive) in one thread.

use std::net::UdpSocket;
use std::thread;
use std::time::Instant;

use divan::Bencher;
use hal::{Correction, RobotLink};
use kuka_rsi::{EthernetConfig, Frame, Ipoc, LinkConfig, RobotFilter, RsiLink, Schema};

const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];

fn setup() -> (RsiLink, UdpSocket, Schema, Schema) {
    let cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false);
    let robot = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut lc = LinkConfig::new(cfg.clone(), RobotFilter::Exact(robot.local_addr().unwrap()));
    lc.bind = Some("127.0.0.1:0".parse().unwrap());
    lc.watchdog_cycles = 2500; // 10 s: a benchmark machine may stall
    let link = RsiLink::bind(lc).unwrap();
    (
        link,
        robot,
        cfg.rob_schema(4).unwrap(),
        cfg.sen_schema(4).unwrap(),
    )
}

fn rob_bytes(rob: &Schema, ipoc: u64, buf: &mut [u8]) -> usize {
    let mut f = Frame::new();
    f.set6(
        rob.six("RIst", POSE).unwrap(),
        [445.0, 0.0, 890.0, 180.0, 0.0, 180.0],
    );
    f.set6(
        rob.six("RSol", POSE).unwrap(),
        [445.0, 0.0, 890.0, 180.0, 0.0, 180.0],
    );
    f.set_ipoc(Ipoc::new(ipoc));
    rob.write(&f, buf).unwrap()
}

fn turnaround_report() {
    let cycles: u64 = std::env::var("RSI_BENCH_CYCLES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(100_000);
    let (mut link, robot, rob, sen) = setup();
    let to = link.local_addr().unwrap();
    let robot_thread = thread::spawn(move || {
        let mut out = [0u8; 2048];
        let mut inp = [0u8; 2048];
        let mut f = Frame::new();
        let mut mismatched = 0u64;
        for k in 0..cycles {
            let ipoc = 1_000_000 + 4 * k;
            let n = rob_bytes(&rob, ipoc, &mut out);
            robot.send_to(&out[..n], to).unwrap();
            let (m, _) = robot.recv_from(&mut inp).unwrap();
            sen.parse(&inp[..m], &mut f).unwrap();
            mismatched += u64::from(f.ipoc().value() != ipoc);
        }
        mismatched
    });
    let started = Instant::now();
    for _ in 0..cycles {
        let c = link.next_cycle().unwrap();
        link.reply(&Correction::along_z(1e-5 * (c.t * 10.0).sin()))
            .unwrap();
    }
    let wall = started.elapsed();
    let mismatched = robot_thread.join().unwrap();
    let d = link.diagnostics();
    let l = &d.latency;
    println!(
        "receive→send turnaround over {cycles} lockstep cycles on loopback (driver's own histogram):"
    );
    println!(
        "  p50 {:?}  p90 {:?}  p99 {:?}  p99.9 {:?}  max {:?}  mean {:?}",
        l.quantile(0.5),
        l.quantile(0.9),
        l.quantile(0.99),
        l.quantile(0.999),
        l.max(),
        l.mean()
    );
    println!(
        "  late (> {:?}): {}   skipped: {}   IPOC mismatches at the robot: {}   round trips/s: {:.0}",
        link.config().late_after,
        d.counters.late,
        d.counters.skipped,
        mismatched,
        cycles as f64 / wall.as_secs_f64()
    );
}

fn main() {
    turnaround_report();
    divan::main();
}

/// One round trip in one thread: robot send → next_cycle → reply → robot receive.
#[divan::bench]
fn round_trip(b: Bencher) {
    let (mut link, robot, rob, _) = setup();
    let to = link.local_addr().unwrap();
    let mut out = [0u8; 2048];
    let mut inp = [0u8; 2048];
    let mut k = 0u64;
    b.bench_local(|| {
        k += 1;
        let n = rob_bytes(&rob, 1_000_000 + 4 * k, &mut out);
        robot.send_to(&out[..n], to).unwrap();
        link.next_cycle().unwrap();
        link.reply(&Correction::default()).unwrap();
        robot.recv_from(&mut inp).unwrap();
    });
}
