//! Late replies are measured from the datagram's arrival (the kernel's receive stamp), over a real
//! loopback socket: a plain UDP peer sends while the loop is held before it reads, and every reply to
//! such a datagram counts late, though the loop answered it as soon as it read it.

use std::net::UdpSocket;
use std::thread;
use std::time::Duration;

use hal::{Correction, RobotLink};
use kuka_rsi::{EthernetConfig, Frame, Ipoc, LinkConfig, RobotFilter, RsiLink};

const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];

/// How long the loop is held after the robot's datagram was sent: far beyond `late_after` (2 ms).
const STALL: Duration = Duration::from_millis(30);

/// The first socket in the system to ask for receive stamps switches the kernel's stamping on through
/// a deferred work item; until it has run, datagrams are stamped when read (no earlier than the read:
/// lateness is then under-counted, never over-counted). Wait, bounded, until a stamp comes before the
/// read on a socket of our own.
fn wait_for_stamping_on_arrival() {
    use nix::sys::socket::{
        ControlMessageOwned, MsgFlags, SockaddrIn, recvmsg, setsockopt, sockopt,
    };
    use nix::sys::time::TimeSpec;
    use std::io::IoSliceMut;
    use std::time::SystemTime;
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    setsockopt(&sock, sockopt::ReceiveTimestampns, &true).unwrap();
    let peer = UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut cmsg = nix::cmsg_space!(TimeSpec);
    for _ in 0..500 {
        peer.send_to(&[0; 8], sock.local_addr().unwrap()).unwrap();
        let sent = SystemTime::now();
        let mut data = [0u8; 16];
        let mut iov = [IoSliceMut::new(&mut data)];
        let msg = recvmsg::<SockaddrIn>(
            std::os::fd::AsRawFd::as_raw_fd(&sock),
            &mut iov,
            Some(&mut cmsg),
            MsgFlags::empty(),
        )
        .unwrap();
        let on_arrival = msg.cmsgs().unwrap().any(|m| match m {
            ControlMessageOwned::ScmTimestampns(ts) => {
                let d = Duration::new(ts.tv_sec() as u64, ts.tv_nsec() as u32);
                SystemTime::UNIX_EPOCH + d <= sent
            }
            _ => false,
        });
        if on_arrival {
            return;
        }
        thread::sleep(Duration::from_millis(1));
    }
    panic!("the kernel never stamped a datagram on arrival");
}

#[test]
fn replies_to_datagrams_that_waited_in_the_socket_count_late() {
    let cfg = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false);
    let rob = cfg.rob_schema(4).unwrap();
    let robot = UdpSocket::bind("127.0.0.1:0").unwrap();
    robot
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let mut lc = LinkConfig::new(cfg, RobotFilter::Exact(robot.local_addr().unwrap()));
    lc.bind = Some("127.0.0.1:0".parse().unwrap());
    let mut link = RsiLink::bind(lc).unwrap();
    assert!(link.kernel_stamps(), "the kernel refused SO_TIMESTAMPNS");
    let to = link.local_addr().unwrap();
    wait_for_stamping_on_arrival();
    let mut f = Frame::new();
    f.set6(
        rob.six("RIst", POSE).unwrap(),
        [500.0, 0.0, 300.0, 0.0, 0.0, 180.0],
    );
    f.set6(
        rob.six("RSol", POSE).unwrap(),
        [500.0, 0.0, 300.0, 0.0, 0.0, 180.0],
    );
    let mut buf = [0u8; 2048];
    let mut reply = [0u8; 2048];
    const ROUNDS: u64 = 3;
    // The kernel stamps on the wall clock, which NTP may slew by up to 500 ppm against the monotonic
    // one the stall is slept on: a slack of 1 % of the stall keeps these orderings, not timings.
    let slack = STALL / 100;
    // One reply's time out of a distribution: the growth of its sum (mean × count, exact to a few ns).
    let sum = |l: &hal::Latency| l.mean() * l.count() as u32;
    for k in 0..ROUNDS {
        f.set_ipoc(Ipoc::new(1000 + 4 * k));
        let n = rob.write(&f, &mut buf).unwrap();
        robot.send_to(&buf[..n], to).unwrap();
        // The loop is busy elsewhere: the datagram waits in the socket.
        thread::sleep(STALL);
        let (arrival0, read0) = {
            let d = link.diagnostics();
            (sum(&d.from_arrival), sum(&d.latency))
        };
        let c = link.next_cycle().unwrap();
        assert_eq!(c.seq, 1000 + 4 * k);
        assert_eq!(c.replied_late, k, "the cycle carries the count so far");
        link.reply(&Correction::default()).unwrap();
        robot.recv_from(&mut reply).unwrap();
        let d = link.diagnostics();
        assert_eq!(
            d.counters.late,
            k + 1,
            "every held datagram's reply is late"
        );
        // This reply's arrival→send time holds the whole stall (the datagram arrived before the hold
        // began, the reply left after it ended) ...
        let from_arrival = sum(&d.from_arrival).saturating_sub(arrival0);
        let from_read = sum(&d.latency).saturating_sub(read0);
        assert!(from_arrival + slack >= STALL, "{from_arrival:?}");
        // ... which the old measure, from the receive call's return, never saw.
        assert!(
            from_read + STALL <= from_arrival + slack,
            "read→send {from_read:?}, arrival→send {from_arrival:?}"
        );
    }
    let c = link.diagnostics().counters;
    assert_eq!((c.answered, c.late, c.unstamped), (ROUNDS, ROUNDS, 0));
}
