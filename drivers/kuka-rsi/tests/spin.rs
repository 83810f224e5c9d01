//! `LinkConfig::spin` over a real loopback socket: the link polls for the robot's datagram around
//! when it is due instead of sleeping in the receive call. Whatever the datagrams' timing — on time,
//! early (before the polling starts), late (after it ends) or in a burst — every cycle is delivered
//! once, in order, and answered; nothing is lost or answered twice. (No timing is asserted: what the
//! polling buys is measured in `examples/cell_latency.rs`, docs/performance.md.)

use std::net::UdpSocket;
use std::thread;
use std::time::Duration;

use hal::{Correction, RobotLink};
use kuka_rsi::{EthernetConfig, Frame, Ipoc, LinkConfig, RobotFilter, RsiLink, Schema};

const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];

fn rob_datagram(rob: &Schema, ipoc: u64) -> Vec<u8> {
    let mut f = Frame::new();
    let pose = [500.0, 0.0, 300.0, 0.0, 0.0, 180.0];
    f.set6(rob.six("RIst", POSE).unwrap(), pose);
    f.set6(rob.six("RSol", POSE).unwrap(), pose);
    f.set_ipoc(Ipoc::new(ipoc));
    let mut buf = vec![0u8; 2048];
    let n = rob.write(&f, &mut buf).unwrap();
    buf.truncate(n);
    buf
}

#[test]
fn a_spinning_link_answers_every_cycle_once_whatever_the_timing() {
    let cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false);
    let rob = cfg.rob_schema(4).unwrap();
    let robot = UdpSocket::bind("127.0.0.1:0").unwrap();
    robot
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let mut lc = LinkConfig::new(cfg, RobotFilter::Exact(robot.local_addr().unwrap()));
    lc.bind = Some("127.0.0.1:0".parse().unwrap());
    lc.spin = Duration::from_millis(1);
    // A slow machine must not lose the link between the robot's sends.
    lc.watchdog_cycles = 250;
    let mut link = RsiLink::bind(lc).unwrap();
    let to = link.local_addr().unwrap();
    // The robot's waits before each send, ms: on time (4), early (0: before the link polls), late
    // (9: past its polling), and a burst of two sent at once while the loop is busy elsewhere (the
    // older is skipped, the newer answered).
    let waits = [0u64, 4, 4, 0, 9, 0, 1, 4];
    let robot_side = thread::spawn(move || {
        let mut reply = [0u8; 2048];
        let mut answered = Vec::new();
        for (k, &w) in waits.iter().enumerate() {
            thread::sleep(Duration::from_millis(w));
            let ipoc = 1000 + 4 * k as u64;
            robot.send_to(&rob_datagram(&rob, ipoc), to).unwrap();
            if k == 5 {
                // The burst: a second datagram right behind the first, one reply for both.
                let ipoc = ipoc + 2;
                robot.send_to(&rob_datagram(&rob, ipoc), to).unwrap();
            }
            let (n, _) = robot.recv_from(&mut reply).unwrap();
            let text = String::from_utf8(reply[..n].to_vec()).unwrap();
            answered.push(text);
        }
        answered
    });
    let mut seqs = Vec::new();
    for k in 0..waits.len() {
        if k == 5 {
            // Busy: the burst is queued whole before the link reads again.
            thread::sleep(Duration::from_millis(30));
        }
        let c = link.next_cycle().unwrap();
        seqs.push(c.seq);
        link.reply(&Correction::default()).unwrap();
    }
    let answered = robot_side.join().unwrap();
    let want: Vec<u64> = (0..waits.len() as u64)
        .map(|k| 1000 + 4 * k + if k == 5 { 2 } else { 0 })
        .collect();
    assert_eq!(seqs, want);
    for (text, ipoc) in answered.iter().zip(&want) {
        assert!(
            text.contains(&format!("<IPOC>{ipoc}</IPOC>")),
            "{text} answers {ipoc}"
        );
    }
    let c = link.diagnostics().counters;
    assert_eq!(c.answered, waits.len() as u64);
    assert_eq!(c.skipped, 1, "the older datagram of the burst");
    assert_eq!(c.unanswered, 0);
}

#[test]
fn spin_longer_than_a_quarter_period_is_refused() {
    let cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false);
    let mut lc = LinkConfig::new(cfg, RobotFilter::Any);
    lc.bind = Some("127.0.0.1:0".parse().unwrap());
    lc.spin = Duration::from_micros(1001);
    let e = RsiLink::bind(lc).unwrap_err().to_string();
    assert!(
        e.contains("spin must be at most a quarter of the period"),
        "{e}"
    );
}
