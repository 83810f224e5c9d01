//! The EGM driver against the simulated IRC5 over real loopback UDP (127.0.0.1, ephemeral ports).
//! No timing is asserted: lateness is injected by not answering, and wall-clock deadlines are generous.

use std::net::{SocketAddr, UdpSocket};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use abb_egm::msg::EgmRobot;
use abb_egm::{CommandSlots, EgmLink, LinkConfig, LinkError, RobotFilter};
use hal::{
    Correction, Cycle, Error as _, ErrorKind, Pose, ProcessCommand, ProcessMode, ProcessPhase,
    ProcessState, RobotLink, Vector3,
};
use prost::Message;
use sim::irc5::{Irc5, Irc5Config, Irc5End, Irc5Report};
use sim::krc::{Mechanism, RigidArm, Timing};

const LOCAL: [u8; 4] = [127, 0, 0, 1];

fn link_config() -> LinkConfig {
    let mut c = LinkConfig::new(SocketAddr::from((LOCAL, 0)), RobotFilter::Any);
    c.watchdog_cycles = 250; // 1 s: generous on a shared machine
    c.first_contact_timeout = Some(Duration::from_secs(20));
    c
}

/// Bind a link, then a controller aimed at it; the link accepts only the controller's address.
fn pair(
    link_tweak: impl FnOnce(&mut LinkConfig),
    irc5_tweak: impl FnOnce(&mut Irc5Config),
) -> (EgmLink, Irc5) {
    let mut lc = link_config();
    link_tweak(&mut lc);
    let mut link = EgmLink::bind(lc).unwrap();
    let mut kc = Irc5Config::new(link.local_addr().unwrap());
    kc.log = true;
    irc5_tweak(&mut kc);
    let irc5 = Irc5::new(kc).unwrap();
    link.set_robot_filter(RobotFilter::Exact(irc5.local_addr().unwrap()));
    (link, irc5)
}

fn rigid() -> RigidArm {
    RigidArm::new(Pose {
        position: Vector3::new(0.5, 0.0, 0.3),
        orientation: hal::UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0),
    })
}

fn spawn(mut irc5: Irc5, mut mech: impl Mechanism + Send + 'static) -> JoinHandle<Irc5Report> {
    thread::spawn(move || irc5.run(&mut mech))
}

/// Answer every cycle with `f` until the link ends; returns the cycles and the ending error.
fn serve(
    link: &mut EgmLink,
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
fn corrections_move_the_simulated_robot_and_every_cycle_is_answered() {
    let (mut link, irc5) = pair(|_| {}, |k| k.cycles = Some(50));
    let h = spawn(irc5, rigid());
    let (cycles, end) = serve(&mut link, |_, _| Some(Correction::along_z(0.0001)));
    let r = h.join().unwrap();
    assert_eq!(r.end, Irc5End::Completed);
    assert_eq!((r.good, r.late, r.bad, r.wrong_type), (50, 0, 0, 0));
    assert_eq!(end.kind(), ErrorKind::LinkLost, "{end}");
    assert_eq!(cycles.len(), 50);
    assert!(cycles[0].new_session && cycles[1..].iter().all(|c| !c.new_session));
    assert!(cycles.windows(2).all(|w| w[1].seq == w[0].seq + 1));
    assert!((cycles[1].t - 0.004).abs() < 1e-12);
    // The rigid arm reports the correction back: 0.1 mm along the tool's z, as sent in mm.
    let last = cycles.last().unwrap();
    assert!((last.tool_offset().z - 0.0001).abs() < 1e-9, "{last:?}");
    assert!(r.log.iter().all(|c| (c.correction[2] - 0.1).abs() < 1e-9));
    let d = link.diagnostics();
    assert_eq!((d.counters.answered, d.counters.received), (50, 50));
    assert_eq!(d.latency.count(), 50);
    assert_eq!((d.robot.motors, d.robot.rapid), (Some(1), Some(2)));
}

#[test]
fn the_process_command_arrives_and_the_state_goes_back_through_the_rapid_variables() {
    /// A robot program that presses until it reads PRESSING, then releases.
    struct Program {
        arm: RigidArm,
        seen: Option<ProcessState>,
    }
    impl Mechanism for Program {
        fn poses(&mut self) -> (Pose, Pose) {
            self.arm.poses()
        }
        fn advance(&mut self, c: &Correction) {
            self.arm.advance(c);
        }
        fn process_command(&mut self) -> Option<ProcessCommand> {
            let pressing = self.seen.is_some_and(|s| s.phase == ProcessPhase::Pressing);
            Some(ProcessCommand {
                mode: if pressing {
                    ProcessMode::Release
                } else {
                    ProcessMode::Press
                },
                force: 20.0,
                ramp: 0.5,
                segment: 7,
            })
        }
        fn process_state(&mut self, s: ProcessState) {
            self.seen = Some(s);
        }
    }
    let (mut link, irc5) = pair(
        |l| l.process = Some(CommandSlots::default()),
        |k| {
            k.cycles = Some(20);
            k.process = Some(CommandSlots::default());
        },
    );
    link.set_state_channel(Box::new(irc5.rapid_variables()));
    let h = spawn(
        irc5,
        Program {
            arm: rigid(),
            seen: None,
        },
    );
    let (cycles, _) = serve(&mut link, |i, _| {
        let mut c = Correction::default();
        c.process.phase = if i >= 5 {
            ProcessPhase::Pressing
        } else {
            ProcessPhase::Approach
        };
        c.process.force = 19.5;
        Some(c)
    });
    let r = h.join().unwrap();
    assert_eq!(r.end, Irc5End::Completed);
    assert_eq!(cycles[0].process.unwrap().mode, ProcessMode::Press);
    assert_eq!(cycles[0].process.unwrap().segment, 7);
    // The state the PC sent with cycle 5's reply is what the program read at the end of cycle 5, and
    // its command changed on the next cycle.
    assert_eq!(r.log[5].state.unwrap().phase, ProcessPhase::Pressing);
    assert_eq!(cycles[5].process.unwrap().mode, ProcessMode::Press);
    assert_eq!(cycles[6].process.unwrap().mode, ProcessMode::Release);
    assert_eq!(
        link.diagnostics().counters.states_published,
        2,
        "on change only"
    );
}

#[test]
fn bad_datagrams_and_foreign_senders_never_become_cycles() {
    let (mut link, irc5) = pair(
        |_| {},
        |k| {
            k.cycles = Some(10);
            k.garbage = vec![2, 5];
        },
    );
    let to = link.local_addr().unwrap();
    let h = spawn(irc5, rigid());
    // A valid-looking EgmRobot from another socket, sent before the controller starts.
    let stranger = UdpSocket::bind(SocketAddr::from((LOCAL, 0))).unwrap();
    let mut fake = EgmRobot::default();
    fake.header.get_or_insert_default().seqno = Some(1);
    stranger.send_to(&fake.encode_to_vec(), to).unwrap();
    let (cycles, _) = serve(&mut link, |_, _| Some(Correction::default()));
    let r = h.join().unwrap();
    assert_eq!((r.good, r.late), (10, 0));
    assert_eq!(cycles.len(), 10);
    let c = link.diagnostics().counters;
    assert_eq!((c.malformed, c.foreign, c.answered), (2, 1, 10), "{c:?}");
    assert!(link.diagnostics().last_malformed.is_some());
}

#[test]
fn unanswered_cycles_reach_the_controllers_comm_timeout_and_silence_the_watchdog() {
    let (mut link, irc5) = pair(
        |l| l.watchdog_cycles = 50,
        |k| {
            k.comm_timeout = 5;
            k.timing = Timing::Lockstep {
                deadline: Duration::from_millis(20),
            };
        },
    );
    let h = spawn(irc5, rigid());
    let (cycles, end) = serve(&mut link, |i, _| {
        (i < 10).then(|| Correction::along_z(0.0002))
    });
    let r = h.join().unwrap();
    assert_eq!(r.end, Irc5End::CommTimeout);
    assert_eq!((r.good, r.late), (10, 5));
    assert_eq!(cycles.len(), 15);
    assert!(
        r.log[10..]
            .iter()
            .all(|c| c.correction == r.log[9].correction),
        "the controller holds the last correction"
    );
    assert!(matches!(end, LinkError::LinkLost { .. }), "{end}");
    assert!(link.diagnostics().counters.unanswered >= 4);
}

#[test]
fn a_restarted_egm_session_is_a_new_session_and_stop_finishes_the_link() {
    let (mut link, irc5) = pair(|_| {}, |k| k.new_session = Some((10, 50_000)));
    let abort = irc5.abort_handle();
    let h = spawn(irc5, rigid());
    let mut seen = Vec::new();
    for i in 0..20 {
        let c = link.next_cycle().unwrap();
        seen.push(c);
        link.reply(&Correction {
            stop: i == 19,
            ..Correction::default()
        })
        .unwrap();
    }
    abort.store(true, std::sync::atomic::Ordering::Relaxed);
    let r = h.join().unwrap();
    assert!(matches!(r.end, Irc5End::Aborted | Irc5End::Completed));
    assert!(seen[10].new_session && seen[10].t == 0.0);
    assert_eq!(link.diagnostics().counters.sessions, 2);
    assert!(link.is_stopped());
    assert!(matches!(link.next_cycle(), Err(LinkError::Stopped)));
}

#[test]
fn a_port_in_use_is_refused_with_a_clear_error() {
    let holder = UdpSocket::bind(SocketAddr::from((LOCAL, 0))).unwrap();
    let mut lc = link_config();
    lc.bind = holder.local_addr().unwrap();
    let err = EgmLink::bind(lc).unwrap_err();
    assert!(err.to_string().contains("already in use"), "{err}");
}
