//! The simulated controller speaks the process channels (`FcCmd` out, `FcState` in) over real loopback
//! UDP against the driver's `RsiLink`; no timing is asserted.

use std::net::{SocketAddr, UdpSocket};
use std::thread;
use std::time::Duration;

use hal::{
    Correction, Pose, ProcessCommand, ProcessFault, ProcessMode, ProcessPhase, ProcessState,
    RobotLink, Vector3,
};
use kuka_rsi::{EthernetConfig, LinkConfig, ProcessChannels, RobotFilter, RsiLink};
use sim::krc::{Krc, KrcConfig, KrcEnd, Mechanism, RigidArm};

const LOCAL: [u8; 4] = [127, 0, 0, 1];

fn ethernet() -> EthernetConfig {
    EthernetConfig::forcecell(LOCAL.into(), 0, false).with_process(ProcessChannels::default())
}

/// A rigid arm running a tiny program: PRESS with the segment number = cycle, and a record of the
/// states the PC reported.
struct Program {
    arm: RigidArm,
    n: i64,
    seen: Vec<ProcessState>,
}

impl Mechanism for Program {
    fn poses(&mut self) -> (Pose, Pose) {
        self.arm.poses()
    }
    fn advance(&mut self, c: &Correction) {
        self.arm.advance(c);
    }
    fn process_command(&mut self) -> Option<ProcessCommand> {
        self.n += 1;
        Some(ProcessCommand {
            mode: ProcessMode::Press,
            force: 10.0 * self.n as f64,
            ramp: 0.25,
            segment: self.n,
        })
    }
    fn process_state(&mut self, s: ProcessState) {
        self.seen.push(s);
    }
}

fn program() -> Program {
    Program {
        arm: RigidArm::new(Pose::from_position(Vector3::new(0.5, 0.0, 0.3))),
        n: 0,
        seen: Vec::new(),
    }
}

#[test]
fn fc_cmd_goes_out_and_fc_state_comes_back_every_cycle() {
    let eth = ethernet();
    let mut lc = LinkConfig::new(eth.clone(), RobotFilter::Any);
    lc.bind = Some(SocketAddr::from((LOCAL, 0)));
    lc.watchdog_cycles = 250;
    let mut link = RsiLink::bind(lc).unwrap();
    let mut kc = KrcConfig::new(eth, link.local_addr().unwrap());
    kc.log = true;
    kc.cycles = Some(20);
    let mut krc = Krc::new(kc).unwrap();
    link.set_robot_filter(RobotFilter::Exact(krc.local_addr().unwrap()));
    let robot = thread::spawn(move || {
        let mut p = program();
        let r = krc.run(&mut p);
        (r, p)
    });
    let mut commands = Vec::new();
    for _ in 0..20 {
        let c = link.next_cycle().unwrap();
        let cmd = c.process.expect("the config declares FcCmd");
        commands.push(cmd);
        link.reply(&Correction {
            process: ProcessState {
                phase: ProcessPhase::Pressing,
                force: cmd.force - 0.004,
                fault: ProcessFault::None,
            },
            ..Correction::default()
        })
        .unwrap();
    }
    let (report, p) = robot.join().unwrap();
    assert_eq!(report.end, KrcEnd::Completed);
    assert_eq!((report.good, report.bad_process), (20, 0));
    for (k, cmd) in commands.iter().enumerate() {
        let n = k as i64 + 1;
        assert_eq!(cmd.segment, n);
        assert_eq!(cmd.mode, ProcessMode::Press);
        assert!((cmd.force - 10.0 * n as f64).abs() < 1e-9);
        assert!((cmd.ramp - 0.25).abs() < 1e-12);
    }
    assert_eq!(p.seen.len(), 20);
    for (k, s) in p.seen.iter().enumerate() {
        assert_eq!(s.phase, ProcessPhase::Pressing);
        // Two decimals on the wire.
        assert!(
            (s.force - (10.0 * (k + 1) as f64 - 0.0)).abs() < 0.006,
            "{s:?}"
        );
    }
    let log = &report.log;
    assert_eq!(log.len(), 20);
    assert_eq!(log[4].command.unwrap().segment, 5);
    assert_eq!(log[4].state.unwrap().phase, ProcessPhase::Pressing);
}

#[test]
fn an_fc_state_outside_the_contract_is_a_bad_reply() {
    let eth = ethernet();
    let pc = UdpSocket::bind(SocketAddr::from((LOCAL, 0))).unwrap();
    pc.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    let mut kc = KrcConfig::new(eth, pc.local_addr().unwrap());
    kc.log = true;
    kc.timeout = 3;
    let mut krc = Krc::new(kc).unwrap();
    let robot = thread::spawn(move || krc.run(&mut program()));
    let mut buf = [0u8; 4096];
    let mut answered = 0;
    while answered < 3 {
        let (n, from) = pc.recv_from(&mut buf).unwrap();
        let text = core::str::from_utf8(&buf[..n]).unwrap();
        assert!(text.contains("<FcCmd Mode=\"1\""), "{text}");
        let ipoc = &text[text.find("<IPOC>").unwrap() + 6..text.find("</IPOC>").unwrap()];
        let reply = format!(
            "<Sen Type=\"ImFree\"><RKorr X=\"0\" Y=\"0\" Z=\"0\" A=\"0\" B=\"0\" C=\"0\"/><Stop>0</Stop><FcState State=\"5\" F=\"1.00\" Fault=\"0\"/><IPOC>{ipoc}</IPOC></Sen>"
        );
        pc.send_to(reply.as_bytes(), from).unwrap();
        answered += 1;
    }
    let report = robot.join().unwrap();
    assert_eq!(report.end, KrcEnd::Timeout, "{report:?}");
    assert_eq!(report.bad_process, 3);
    assert_eq!(
        report.last_bad_process,
        Some(kuka_rsi::ProcessError::BadState(5))
    );
    assert!(report.log.iter().all(|c| c.state
        == Some(ProcessState {
            phase: ProcessPhase::Off,
            force: 0.0,
            fault: ProcessFault::None
        })));
}
