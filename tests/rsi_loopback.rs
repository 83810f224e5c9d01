//! The RSI driver against the simulated KUKA controller over real loopback UDP (127.0.0.1, ephemeral
//! ports). No timing is asserted: lateness is injected by not answering, and wall-clock deadlines are
//! generous wherever a test expects replies to be on time.

use std::net::{SocketAddr, UdpSocket};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use controller::run::{End, RunLimits};
use controller::{ControlLoop, ImpedanceLaw, ImpedanceParams, LoopConfig, LoopError, Reference};
use hal::{Correction, Cycle, Error as _, ErrorKind, Pose, RobotLink, Vector3};
use kuka_rsi::{
    CorrectionMode, EthernetConfig, Frame, Ipoc, LinkConfig, LinkError, RobotFilter, RsiLink,
};
use sim::krc::{Counting, Garbage, Krc, KrcConfig, KrcEnd, KrcReport, RigidArm, Timing};
use sim::{ContactPlant, InProcSensor, InnerLoopModel, SensorParams, World};

const LOCAL: [u8; 4] = [127, 0, 0, 1];

fn ethernet(relative: bool) -> EthernetConfig {
    EthernetConfig::forcecell(LOCAL.into(), 0, relative)
}

fn link_config(eth: &EthernetConfig) -> LinkConfig {
    let mut c = LinkConfig::new(eth.clone(), RobotFilter::Any);
    c.bind = Some(SocketAddr::from((LOCAL, 0)));
    c.watchdog_cycles = 250; // 1 s: generous on a shared machine
    c.first_contact_timeout = Some(Duration::from_secs(20));
    c
}

fn krc_config(eth: &EthernetConfig, target: SocketAddr) -> KrcConfig {
    let mut k = KrcConfig::new(eth.clone(), target);
    k.log = true;
    k
}

/// Bind a link, then a controller aimed at it; the link accepts only the controller's address.
fn pair(
    eth: &EthernetConfig,
    link_tweak: impl FnOnce(&mut LinkConfig),
    krc_tweak: impl FnOnce(&mut KrcConfig),
) -> (RsiLink, Krc) {
    let mut lc = link_config(eth);
    link_tweak(&mut lc);
    let mut link = RsiLink::bind(lc).unwrap();
    let mut kc = krc_config(eth, link.local_addr().unwrap());
    krc_tweak(&mut kc);
    let krc = Krc::new(kc).unwrap();
    link.set_robot_filter(RobotFilter::Exact(krc.local_addr().unwrap()));
    (link, krc)
}

fn rigid() -> RigidArm {
    RigidArm::new(Pose {
        position: Vector3::new(0.5, 0.0, 0.3),
        orientation: hal::UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0),
    })
}

fn spawn(mut krc: Krc) -> JoinHandle<KrcReport> {
    thread::spawn(move || krc.run(&mut rigid()))
}

/// Answer every cycle with `f` until the link ends; returns the cycles and the ending error.
fn serve(
    link: &mut RsiLink,
    mut f: impl FnMut(usize, &Cycle) -> Option<Correction>,
) -> (Vec<Cycle>, LinkError) {
    let mut cycles = Vec::new();
    loop {
        match link.next_cycle() {
            Ok(c) => {
                if let Some(corr) = f(cycles.len(), &c) {
                    link.reply(&corr).unwrap();
                }
                cycles.push(c);
            }
            Err(e) => return (cycles, e),
        }
    }
}

#[test]
fn first_contact_link_first() {
    let eth = ethernet(false);
    let (mut link, krc) = pair(&eth, |_| {}, |k| k.cycles = Some(50));
    let robot = krc.local_addr().unwrap();
    let h = spawn(krc);
    let (cycles, end) = serve(&mut link, |_, _| Some(Correction::along_z(0.0001)));
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::Completed);
    assert_eq!((r.good, r.late, r.bad, r.ipoc_mismatch), (50, 0, 0, 0));
    assert_eq!(end.kind(), ErrorKind::LinkLost, "{end}");
    assert_eq!(cycles.len(), 50);
    assert!(cycles[0].new_session && cycles[1..].iter().all(|c| !c.new_session));
    assert!(cycles.windows(2).all(|w| w[1].seq == w[0].seq + 4));
    assert!((cycles[1].t - 0.004).abs() < 1e-12);
    let d = link.diagnostics();
    assert_eq!(d.counters.answered, 50);
    assert_eq!(d.counters.received, 50);
    assert_eq!(d.latency.count(), 50);
    assert_eq!(link.config().robot, RobotFilter::Exact(robot));
    // The rigid arm reports the correction back: measured offset along the tool normal.
    let last = cycles.last().unwrap();
    assert!((last.tool_offset().z - 0.0001).abs() < 1e-7, "{last:?}");
}

#[test]
fn first_contact_robot_first() {
    let eth = ethernet(false);
    // Find a free port, release it, and aim the controller at it before anyone listens there.
    let port = UdpSocket::bind(SocketAddr::from((LOCAL, 0)))
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let target = SocketAddr::from((LOCAL, port));
    let mut kc = krc_config(&eth, target);
    kc.timing = Timing::Lockstep {
        deadline: Duration::from_millis(20),
    };
    kc.timeout = 1_000_000;
    kc.cycles = Some(60);
    let krc = Krc::new(kc).unwrap();
    let robot = krc.local_addr().unwrap();
    let h = spawn(krc);
    thread::sleep(Duration::from_millis(100)); // the robot is already sending into the void
    let mut lc = link_config(&eth);
    lc.bind = Some(target);
    lc.robot = RobotFilter::Exact(robot);
    let mut link = RsiLink::bind(lc).unwrap();
    let (cycles, end) = serve(&mut link, |_, _| Some(Correction::default()));
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::Completed);
    assert!(r.late >= 1, "the first cycles went unanswered: {r:?}");
    assert_eq!(r.good + r.late, 60);
    assert_eq!(
        cycles.len() as u64,
        r.good,
        "every cycle the link saw was answered in time"
    );
    assert!(
        cycles[0].late_replies >= 1,
        "the robot reported its late replies"
    );
    assert!(cycles[0].new_session);
    assert_eq!(cycles.last().unwrap().late_replies, 0, "Delay resets");
    assert_eq!(end.kind(), ErrorKind::LinkLost);
}

#[test]
fn unanswered_cycles_grow_delay_and_break_off_exactly_at_timeout() {
    for counting in [Counting::Consecutive, Counting::Cumulative] {
        let eth = ethernet(false);
        let (mut link, krc) = pair(
            &eth,
            |_| {},
            |k| {
                k.timeout = 5;
                k.counting = counting;
                k.timing = Timing::Lockstep {
                    deadline: Duration::from_millis(20),
                };
            },
        );
        let h = spawn(krc);
        // Consecutive: answer 10, then nothing. Cumulative: answer 3, skip 2, answer 3, then nothing.
        let answer = |i: usize| match counting {
            Counting::Consecutive => i < 10,
            Counting::Cumulative => i < 3 || (5..8).contains(&i),
        };
        let (cycles, end) = serve(&mut link, |i, _| answer(i).then(Correction::default));
        let r = h.join().unwrap();
        assert_eq!(r.end, KrcEnd::Timeout, "{counting:?}");
        assert_eq!(r.late, 5, "{counting:?}: breaks off exactly at Timeout");
        let delays: Vec<u32> = cycles.iter().map(|c| c.late_replies).collect();
        match counting {
            Counting::Consecutive => {
                assert_eq!(r.cycles, 15);
                assert_eq!(delays[9..], [0, 0, 1, 2, 3, 4]);
            }
            Counting::Cumulative => {
                assert_eq!(r.cycles, 11);
                assert_eq!(delays, [0, 0, 0, 0, 1, 2, 2, 2, 2, 3, 4]);
            }
        }
        assert_eq!(r.max_delay, 4);
        assert_eq!(
            link.diagnostics().counters.delay_alarms,
            delays.iter().filter(|&&d| d > 0).count() as u64
        );
        assert!(link.diagnostics().counters.unanswered >= 4);
        assert_eq!(end.kind(), ErrorKind::LinkLost);
    }
}

/// The test plays the PC with a bare socket and the codec to send what the driver never would.
#[test]
fn wrong_ipoc_and_wrong_sentype_are_rejected_by_the_controller() {
    let eth = ethernet(false);
    let pc = UdpSocket::bind(SocketAddr::from((LOCAL, 0))).unwrap();
    let mut kc = krc_config(&eth, pc.local_addr().unwrap());
    kc.cycles = Some(4);
    kc.timing = Timing::Lockstep {
        deadline: Duration::from_millis(100),
    };
    let h = spawn(Krc::new(kc).unwrap());
    let rob = eth.rob_schema(4).unwrap();
    let sen = eth.sen_schema(4).unwrap();
    let mut wrong_type = eth.clone();
    wrong_type.sentype = "Other".into();
    let other = wrong_type.sen_schema(4).unwrap();
    let mut buf = vec![0u8; 65536];
    let mut frame = Frame::new();
    for k in 0..4 {
        let (n, from) = pc.recv_from(&mut buf).unwrap();
        rob.parse(&buf[..n], &mut frame).unwrap();
        let mut reply = Frame::new();
        let ipoc = frame.ipoc().value();
        let (schema, ipoc) = match k {
            0 => (&sen, ipoc + 1),
            1 => (&other, ipoc),
            2 => (&sen, ipoc.saturating_sub(4)),
            _ => (&sen, ipoc),
        };
        reply.set_ipoc(Ipoc::new(ipoc));
        let m = schema.write(&reply, &mut buf).unwrap();
        pc.send_to(&buf[..m], from).unwrap();
        if k == 3 {
            // A garbage reply after the good one is never mistaken for it.
            pc.send_to(b"<Sen Type=\"ImFree\"><IPOC>1", from).unwrap();
        }
    }
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::Completed);
    assert_eq!(r.ipoc_mismatch, 2);
    assert_eq!(r.wrong_sentype, 1);
    assert_eq!((r.good, r.late), (1, 3));
    assert_eq!(
        r.log.iter().map(|c| c.delay).collect::<Vec<_>>(),
        [0, 1, 2, 3]
    );
}

#[test]
fn bad_robot_datagrams_are_dropped_counted_and_never_answered() {
    let eth = ethernet(false);
    let (mut link, krc) = pair(
        &eth,
        |l| l.max_datagram = 4096,
        |k| {
            k.cycles = Some(10);
            k.faults.garbage = vec![
                (2, Garbage::Malformed),
                (3, Garbage::Oversized(5000)),
                (4, Garbage::Truncated),
                (5, Garbage::NonAscii),
                (6, Garbage::Oversized(60_000)),
            ];
        },
    );
    let h = spawn(krc);
    let (cycles, end) = serve(&mut link, |_, _| Some(Correction::default()));
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::Completed);
    assert_eq!((r.good, r.late, r.ipoc_mismatch, r.bad), (10, 0, 0, 0));
    assert_eq!(cycles.len(), 10);
    let c = link.diagnostics().counters;
    assert_eq!(c.malformed, 3, "{c:?}");
    assert_eq!(c.oversized, 2, "{c:?}");
    assert_eq!(c.received, 15);
    assert_eq!(c.answered, 10);
    assert!(link.diagnostics().last_malformed.is_some());
    assert_eq!(end.kind(), ErrorKind::LinkLost);
}

#[test]
fn foreign_sources_are_ignored() {
    let eth = ethernet(false);
    let (mut link, krc) = pair(
        &eth,
        |_| {},
        |k| {
            k.cycles = Some(12);
            k.faults.foreign = vec![3, 4, 9];
        },
    );
    assert!(krc.foreign_addr().is_some());
    let h = spawn(krc);
    let (cycles, _) = serve(&mut link, |_, _| Some(Correction::default()));
    let r = h.join().unwrap();
    assert_eq!((r.good, r.late), (12, 0));
    let c = link.diagnostics().counters;
    assert_eq!(c.foreign, 3);
    assert_eq!(c.answered, 12);
    assert_eq!(c.sessions, 1, "a foreign datagram never changes state");
    assert!(
        cycles.windows(2).all(|w| w[1].seq == w[0].seq + 4),
        "no foreign IPOC became a cycle"
    );
}

#[test]
fn a_backlog_is_drained_and_only_the_newest_answered() {
    let eth = ethernet(false);
    let robot = UdpSocket::bind(SocketAddr::from((LOCAL, 0))).unwrap();
    let mut lc = link_config(&eth);
    lc.robot = RobotFilter::Exact(robot.local_addr().unwrap());
    let mut link = RsiLink::bind(lc).unwrap();
    let to = link.local_addr().unwrap();
    let rob = eth.rob_schema(4).unwrap();
    let sen = eth.sen_schema(4).unwrap();
    let mut buf = vec![0u8; 4096];
    let mut send = |ipoc: u64| {
        let mut f = Frame::new();
        f.set6(
            rob.six("RIst", ["X", "Y", "Z", "A", "B", "C"]).unwrap(),
            [500.0, 0.0, 300.0, 0.0, 0.0, 180.0],
        );
        f.set_ipoc(Ipoc::new(ipoc));
        let n = rob.write(&f, &mut buf).unwrap();
        robot.send_to(&buf[..n], to).unwrap();
    };
    // A stall: four cycles queue up before the driver reads.
    for ipoc in [100, 104, 108, 112] {
        send(ipoc);
    }
    let c = link.next_cycle().unwrap();
    assert_eq!(c.seq, 112);
    link.reply(&Correction::default()).unwrap();
    assert_eq!(link.diagnostics().counters.skipped, 3);
    // Duplicates and a reordered old one, then the next cycle.
    for ipoc in [112, 108, 116, 116] {
        send(ipoc);
    }
    let c = link.next_cycle().unwrap();
    assert_eq!(c.seq, 116);
    assert!(!c.new_session);
    link.reply(&Correction::default()).unwrap();
    let counters = link.diagnostics().counters;
    assert_eq!(counters.stale, 3);
    assert_eq!(counters.answered, 2);
    // Exactly two replies came back, to the robot's source port, echoing 112 and 116.
    let mut got = Vec::new();
    robot
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let mut frame = Frame::new();
    while let Ok((n, from)) = robot.recv_from(&mut buf) {
        assert_eq!(from, to);
        sen.parse(&buf[..n], &mut frame).unwrap();
        got.push(frame.ipoc().value());
    }
    assert_eq!(got, [112, 116]);
}

#[test]
fn a_burst_after_a_stall_is_survived() {
    let eth = ethernet(false);
    let (mut link, krc) = pair(
        &eth,
        |l| l.watchdog_cycles = 1000, // the 1.5 s stall must not look like a lost link
        |k| {
            k.cycles = Some(20);
            k.timing = Timing::Lockstep {
                deadline: Duration::from_millis(500),
            };
            k.faults.stall = Some((5, 3));
        },
    );
    let h = spawn(krc);
    let (cycles, _) = serve(&mut link, |_, _| Some(Correction::default()));
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::Completed);
    assert_eq!(r.late, 3, "the stalled cycles could not be answered");
    assert_eq!(r.good, 17);
    let c = link.diagnostics().counters;
    assert_eq!(c.skipped + c.stale + c.answered, 20, "{c:?}");
    assert!(cycles.windows(2).all(|w| w[1].seq > w[0].seq));
}

/// The whole cell: controller loop ↔ driver ↔ UDP ↔ simulated KRC ↔ shared world ↔ simulated sensor.
#[test]
fn closed_loop_new_session_and_silence() {
    let eth = ethernet(false);
    let world = World::new(
        ContactPlant::spring(70_000.0, 0.01),
        InnerLoopModel::P2,
        SensorParams::default(),
        0.0,
    )
    .shared();
    let (link, krc) = pair(
        &eth,
        |l| l.watchdog_cycles = 50,
        |k| {
            k.faults.new_session = Some((40, 9_000_000_000));
            k.faults.silent_from = Some(80);
        },
    );
    let mut w = world.clone();
    let mut krc = krc;
    let h = thread::spawn(move || krc.run(&mut w));
    let law = ImpedanceLaw::new(ImpedanceParams::PAPER, Reference::Fixed { x_r: 0.002 }).unwrap();
    let mut lp = ControlLoop::new(
        link,
        InProcSensor::new(world.clone()),
        law,
        LoopConfig::default(),
    );
    let mut reports = Vec::new();
    let outcome = controller::run::run(&mut lp, RunLimits::default(), &mut reports);
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::Silent);
    assert_eq!(r.late, 0);
    assert_eq!(reports.len(), 80);
    match outcome.end {
        End::LinkLost(LoopError::Robot(e)) => assert_eq!(e.kind(), ErrorKind::LinkLost),
        other => panic!("expected link lost, got {other}"),
    }
    assert!(outcome.stop.is_none(), "no Stop to a link that is gone");
    assert_eq!(lp.stats().sessions, 1, "references captured again once");
    assert!(reports[40].cycle.new_session);
    assert_eq!(reports[40].cycle.seq, 9_000_000_000);
    assert_eq!(reports[40].cycle.t, 0.0);
    assert_eq!(lp.robot().diagnostics().counters.sessions, 2);
    // The world moved towards the commanded reference, and held when the robot fell silent.
    let x = sim::world::lock(&world).position();
    assert!(x > 0.0005 && x <= 0.005, "x = {x}");
    assert!(reports.iter().all(|r| r.command.is_finite()));
}

/// Max change of the applied Z correction from one cycle to the next, mm.
fn max_step(r: &KrcReport) -> f64 {
    r.log
        .windows(2)
        .map(|w| (w[1].correction[2] - w[0].correction[2]).abs())
        .fold(0.0, f64::max)
}

fn lossy(relative: bool, holdon_abs: bool) -> (KrcReport, RsiLink) {
    let mut eth = ethernet(relative);
    if !relative && !holdon_abs {
        for e in &mut eth.receive {
            e.holdon = Some(false);
        }
    }
    let (mut link, krc) = pair(
        &eth,
        |l| {
            l.mode = if relative {
                CorrectionMode::Relative
            } else {
                CorrectionMode::Absolute
            }
        },
        |k| {
            k.mode = if relative {
                CorrectionMode::Relative
            } else {
                CorrectionMode::Absolute
            };
            k.cycles = Some(300);
            k.timeout = 1000;
            k.seed = 7;
            k.timing = Timing::Lockstep {
                deadline: Duration::from_millis(15),
            };
            k.faults.drop_rob = 0.1;
            k.faults.drop_sen = 0.1;
        },
    );
    let h = spawn(krc);
    // A ramp to 3 mm over 100 cycles, then hold.
    serve(&mut link, |i, _| {
        Some(Correction::along_z(0.003 * (i as f64 / 100.0).min(1.0)))
    });
    (h.join().unwrap(), link)
}

#[test]
fn absolute_and_relative_modes_never_jump_under_packet_loss() {
    for relative in [false, true] {
        let (r, link) = lossy(relative, true);
        assert!(r.late > 10, "loss was injected: {r:?}");
        let step = max_step(&r);
        // The driver's rate limit is 0.25 mm per cycle; the ramp asks for 0.03 mm per cycle.
        assert!(
            step <= 0.25 + 1e-3,
            "relative={relative}: jump of {step} mm"
        );
        let last = r.log.last().unwrap().correction[2];
        // Relative mode never re-sends a lost increment, so the total may fall short (the force loop
        // closes that gap in a cell); it must never overshoot.
        assert!(
            last > 1.5 && last <= 3.0 + 1e-3,
            "relative={relative}: ended at {last} mm"
        );
        if !relative {
            assert!(
                (last - 3.0).abs() < 1e-3,
                "absolute totals converge exactly"
            );
        }
        assert_eq!(link.diagnostics().counters.rate_limited, 0);
    }
    // The spec's warning, reproduced: absolute mode with HOLDON = 0 jumps back to 0 on a late reply.
    let (r, _) = lossy(false, false);
    assert!(max_step(&r) > 1.0, "HOLDON=0 jumps: {}", max_step(&r));
}

#[test]
fn the_envelope_is_enforced_before_sending() {
    let eth = ethernet(false);
    let (mut link, krc) = pair(&eth, |_| {}, |k| k.cycles = Some(60));
    let h = spawn(krc);
    serve(&mut link, |i, _| {
        Some(if i == 30 {
            Correction::along_z(f64::NAN)
        } else {
            let mut c = Correction::along_z(0.02);
            c.translation.x = -0.02;
            c.rotation.z = 0.5;
            c
        })
    });
    let r = h.join().unwrap();
    assert_eq!(
        r.end,
        KrcEnd::Completed,
        "POSCORRMON (6 mm overall) never tripped"
    );
    assert_eq!(r.clamped, 0, "POSCORR (5 mm per axis) never had to act");
    let last = r.log.last().unwrap().correction;
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    assert!((norm(&last[..3]) - 4.5).abs() < 1e-3, "{last:?}");
    assert!(
        (last[2] + last[0]).abs() < 1e-3,
        "scaled along the asked direction: {last:?}"
    );
    assert!(
        (last[3] - 4.5).abs() < 1e-3,
        "A (about z) limited: {last:?}"
    );
    assert!(
        r.log
            .iter()
            .all(|c| norm(&c.correction[..3]) <= 4.5 + 1e-3
                && norm(&c.correction[3..]) <= 4.5 + 1e-3)
    );
    let c = link.diagnostics().counters;
    assert!(c.envelope_limited >= 59 && c.rate_limited >= 10, "{c:?}");
    assert_eq!(c.nonfinite_held, 1);
    assert_eq!(
        r.log[30].correction, r.log[29].correction,
        "a NaN command holds the last total"
    );
}

#[test]
fn stop_ends_the_motion_cleanly() {
    let eth = ethernet(false);
    let (mut link, krc) = pair(&eth, |_| {}, |_| {});
    let h = spawn(krc);
    for i in 0..10 {
        link.next_cycle().unwrap();
        let mut c = Correction::along_z(0.0001);
        c.stop = i == 9;
        link.reply(&c).unwrap();
    }
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::Stopped);
    assert_eq!(r.cycles, 10);
    assert!(link.is_stopped());
    assert!(matches!(link.next_cycle(), Err(LinkError::Stopped)));
    assert!(matches!(
        link.reply(&Correction::default()),
        Err(LinkError::Stopped)
    ));
}

#[test]
fn a_port_in_use_is_refused_with_a_clear_error() {
    let eth = ethernet(false);
    let holder = UdpSocket::bind(SocketAddr::from((LOCAL, 0))).unwrap();
    let mut lc = link_config(&eth);
    lc.bind = Some(holder.local_addr().unwrap());
    let err = RsiLink::bind(lc.clone()).unwrap_err();
    match &err {
        LinkError::Bind { source, .. } => {
            assert_eq!(source.kind(), std::io::ErrorKind::AddrInUse)
        }
        other => panic!("{other}"),
    }
    assert!(err.to_string().contains("already in use"), "{err}");
    // A second driver on the same port fails the same way.
    let first = RsiLink::bind(link_config(&eth)).unwrap();
    lc.bind = Some(first.local_addr().unwrap());
    assert!(matches!(RsiLink::bind(lc), Err(LinkError::Bind { .. })));
}

#[test]
fn onlysend_robot_gets_no_replies() {
    let mut eth = ethernet(false);
    eth.onlysend = true;
    let (mut link, krc) = pair(&eth, |_| {}, |k| k.cycles = Some(15));
    let h = spawn(krc);
    let (cycles, _) = serve(&mut link, |_, _| Some(Correction::along_z(0.001)));
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::Completed);
    assert_eq!(r.cycles, 15);
    assert_eq!(r.unexpected_replies, 0);
    assert_eq!((r.late, r.good), (0, 0));
    assert_eq!(cycles.len(), 15);
    let c = link.diagnostics().counters;
    assert_eq!((c.answered, c.suppressed), (0, 15));
}

#[test]
fn reply_before_any_cycle_and_twice_is_an_error() {
    let eth = ethernet(false);
    let (mut link, krc) = pair(&eth, |_| {}, |k| k.cycles = Some(1));
    assert!(matches!(
        link.reply(&Correction::default()),
        Err(LinkError::NoCycle)
    ));
    let h = spawn(krc);
    link.next_cycle().unwrap();
    link.reply(&Correction::default()).unwrap();
    let e = link.reply(&Correction::default()).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Other);
    assert_eq!(h.join().unwrap().good, 1);
}

#[test]
fn duplicates_reordering_and_loss_never_get_an_older_ipoc_answered() {
    let eth = ethernet(false);
    let (mut link, krc) = pair(
        &eth,
        |_| {},
        |k| {
            k.cycles = Some(200);
            k.timeout = 1000;
            k.seed = 11;
            k.timing = Timing::Lockstep {
                deadline: Duration::from_millis(20),
            };
            k.faults.duplicate = 0.2;
            k.faults.reorder = 0.1;
            k.faults.drop_rob = 0.05;
            k.faults.drop_sen = 0.05;
        },
    );
    let h = spawn(krc);
    let (cycles, _) = serve(&mut link, |_, _| Some(Correction::along_z(0.0002)));
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::Completed);
    assert_eq!(r.good + r.late, 200);
    assert!(r.late > 0, "faults were injected");
    // A datagram delayed past its own cycle but still the newest the driver has seen is answered
    // (the driver cannot know better) and the controller counts that reply as late; older ones never are.
    assert!(r.ipoc_mismatch <= r.late);
    let c = link.diagnostics().counters;
    assert!(c.stale > 10, "{c:?}");
    assert_eq!(c.answered, cycles.len() as u64);
    assert!(cycles.windows(2).all(|w| w[1].seq > w[0].seq));
    assert_eq!(c.sessions, 1);
}

#[test]
fn realtime_at_12_ms_with_send_jitter() {
    let eth = ethernet(false);
    let (mut link, krc) = pair(
        &eth,
        |l| l.period = Duration::from_millis(12),
        |k| {
            k.cycles = Some(40);
            k.timing = Timing::Realtime;
            k.period = Duration::from_millis(12);
            k.ipoc_step = 12;
            k.timeout = 1000;
            k.faults.jitter = Duration::from_millis(3);
        },
    );
    let h = spawn(krc);
    let (cycles, _) = serve(&mut link, |_, _| Some(Correction::default()));
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::Completed);
    assert_eq!(r.cycles, 40);
    assert_eq!(r.good + r.late, 40);
    assert!(cycles.windows(2).all(|w| (w[1].seq - w[0].seq) % 12 == 0));
    assert!(cycles.iter().all(|c| c.period == 0.012));
    let last = cycles.last().unwrap();
    assert!((last.t - (last.seq - cycles[0].seq) as f64 * 0.001).abs() < 1e-12);
}

#[test]
fn poscorr_clamps_and_poscorrmon_stops() {
    let eth = ethernet(false);
    let pc = UdpSocket::bind(SocketAddr::from((LOCAL, 0))).unwrap();
    let mut kc = krc_config(&eth, pc.local_addr().unwrap());
    kc.timing = Timing::Lockstep {
        deadline: Duration::from_millis(500),
    };
    let h = spawn(Krc::new(kc).unwrap());
    let rob = eth.rob_schema(4).unwrap();
    let sen = eth.sen_schema(4).unwrap();
    let rkorr = sen.six("RKorr", ["X", "Y", "Z", "A", "B", "C"]).unwrap();
    let mut buf = vec![0u8; 65536];
    let mut frame = Frame::new();
    // 7 mm along Z alone is clamped to 5 mm; then 5.9 mm on X and Z (overall 7.1 mm > 6 mm) trips POSCORRMON.
    for k in 0..2 {
        let (n, from) = pc.recv_from(&mut buf).unwrap();
        rob.parse(&buf[..n], &mut frame).unwrap();
        let mut reply = Frame::new();
        reply.set6(
            rkorr,
            if k == 0 {
                [0.0, 0.0, 7.0, 0.0, 0.0, 0.0]
            } else {
                [5.9, 0.0, 5.9, 0.0, 0.0, 0.0]
            },
        );
        reply.set_ipoc(*frame.ipoc());
        let m = sen.write(&reply, &mut buf).unwrap();
        pc.send_to(&buf[..m], from).unwrap();
    }
    let r = h.join().unwrap();
    assert_eq!(r.end, KrcEnd::PoscorrMon);
    assert_eq!(r.clamped, 2);
    assert_eq!(r.log[0].correction[2], 5.0);
    assert_eq!(r.log[1].correction[..3], [5.0, 0.0, 5.0]);
}

#[test]
fn any_source_locks_onto_the_first_robot_until_the_link_is_lost() {
    let eth = ethernet(false);
    let mut lc = link_config(&eth);
    lc.watchdog_cycles = 5; // 20 ms
    let mut link = RsiLink::bind(lc).unwrap();
    let to = link.local_addr().unwrap();
    let rob = eth.rob_schema(4).unwrap();
    let a = UdpSocket::bind(SocketAddr::from((LOCAL, 0))).unwrap();
    let b = UdpSocket::bind(SocketAddr::from((LOCAL, 0))).unwrap();
    let send = |s: &UdpSocket, ipoc: u64| {
        let mut f = Frame::new();
        f.set_ipoc(Ipoc::new(ipoc));
        let mut buf = [0u8; 2048];
        let n = rob.write(&f, &mut buf).unwrap();
        s.send_to(&buf[..n], to).unwrap();
    };
    send(&a, 100);
    let c = link.next_cycle().unwrap();
    assert!(c.new_session && c.seq == 100);
    link.reply(&Correction::default()).unwrap();
    send(&b, 104);
    send(&a, 104);
    let c = link.next_cycle().unwrap();
    assert_eq!(c.seq, 104);
    assert_eq!(link.diagnostics().counters.foreign, 1);
    link.reply(&Correction::default()).unwrap();
    // A falls silent: the link is lost, and B may start the next session.
    assert_eq!(link.next_cycle().unwrap_err().kind(), ErrorKind::LinkLost);
    send(&b, 5000);
    let c = link.next_cycle().unwrap();
    assert!(c.new_session && c.seq == 5000);
    link.reply(&Correction::default()).unwrap();
    let mut buf = [0u8; 2048];
    b.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let (_, from) = b.recv_from(&mut buf).unwrap();
    assert_eq!(from, to, "B gets its reply");
    assert_eq!(link.diagnostics().counters.sessions, 2);
}

/// The rigid arm, with its reported `RIst` moved `jump` m along x in the cycles `from..until`.
struct JumpingArm {
    arm: RigidArm,
    cycle: u64,
    from: u64,
    until: u64,
    jump: f64,
}

impl sim::krc::Mechanism for JumpingArm {
    fn poses(&mut self) -> (Pose, Pose) {
        let (mut actual, programmed) = self.arm.poses();
        if (self.from..self.until).contains(&self.cycle) {
            actual.position.x += self.jump;
        }
        (actual, programmed)
    }
    fn advance(&mut self, c: &Correction) {
        self.arm.advance(c);
        self.cycle += 1;
    }
}

/// Run 120 cycles with `RIst` jumped by 400 mm in cycles `from..until`; every cycle answered.
fn jumped(from: u64, until: u64) -> (Vec<Cycle>, RsiLink) {
    let eth = ethernet(false);
    let (mut link, mut krc) = pair(&eth, |_| {}, |k| k.cycles = Some(120));
    let h = thread::spawn(move || {
        krc.run(&mut JumpingArm {
            arm: rigid(),
            cycle: 0,
            from,
            until,
            jump: 0.4,
        })
    });
    let (cycles, _) = serve(&mut link, |_, _| Some(Correction::along_z(0.0)));
    let r = h.join().unwrap();
    assert!(r.end == KrcEnd::Completed && r.good == 120, "{r:?}");
    (cycles, link)
}

#[test]
fn a_pose_jump_no_robot_can_make_is_a_counted_fault_not_an_input() {
    // One cycle 400 mm away (100 m/s at 4 ms): a fault; the next, back on the path, is plausible.
    let (cycles, link) = jumped(50, 51);
    assert_eq!(cycles.len(), 120);
    assert_eq!(link.diagnostics().counters.implausible, 1);
    assert_eq!(link.diagnostics().counters.answered, 120);
    for (i, c) in cycles.iter().enumerate() {
        assert_eq!(c.actual.is_finite(), i != 50, "cycle {i}: {:?}", c.actual);
        assert_eq!(c.programmed.is_finite(), i != 50, "cycle {i}");
    }
    // A jump that stays: a fault until the time since the last plausible pose allows the distance at
    // the default 3 m/s (0.4 m in 134 ms = 34 cycles of 4 ms), then accepted as where the robot is.
    let (cycles, link) = jumped(50, 1000);
    assert_eq!(link.diagnostics().counters.implausible, 33);
    assert!(cycles[50..83].iter().all(|c| !c.actual.is_finite()));
    assert!(cycles[83..].iter().all(|c| c.actual.is_finite()));
}
