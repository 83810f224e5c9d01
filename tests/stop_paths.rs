//! Every stop path of `forcecell sim` ends cleanly: SIGINT and SIGTERM (sent to the child process with
//! `/bin/kill`) end the run with the trace, the plot and the summary written and `Stop` sent to the
//! robot; a wait for the robot's first datagram ends on a signal; a lost link ends with its own exit
//! status. The robot is the simulated KUKA controller on loopback, in this process, and its mechanism
//! sends the signal at a chosen cycle, so no test depends on timing.

use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, UdpSocket};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::Ordering;
use std::time::Duration;

use hal::{Correction, Pose, UnitQuaternion, Vector3};
use kuka_rsi::{EthernetConfig, PoscorrLimits};
use sim::krc::{Krc, KrcConfig, KrcEnd, KrcReport, Mechanism, RigidArm, Timing};

/// A 60 s scenario: long enough that only a signal or a lost link ends it in a test.
const LONG: &str = r#"
name = "long"
duration = 60.0
plant = "p2"
tuning = "robust"
[environment]
k_c = 70000.0
x_c = 0.01
"#;

fn signal(pid: u32, sig: &str) {
    // Signals only the forcecell process this test started, by its id.
    let st = Command::new("/bin/kill")
        .args([&format!("-{sig}"), &pid.to_string()])
        .status()
        .expect("run /bin/kill");
    assert!(st.success(), "kill -{sig} {pid}");
}

fn spawn(args: &[&str], dir: &Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start forcecell")
}

/// Read the child's stdout until a line containing `needle`; returns everything read.
fn read_until(child: &mut Child, needle: &str) -> (String, BufReader<std::process::ChildStdout>) {
    let mut r = BufReader::new(child.stdout.take().unwrap());
    let mut seen = String::new();
    loop {
        let mut line = String::new();
        let n = r.read_line(&mut line).unwrap();
        assert!(n > 0, "the child ended before printing {needle:?}:\n{seen}");
        seen.push_str(&line);
        if line.contains(needle) {
            return (seen, r);
        }
    }
}

/// Wait for the child and collect the rest of its output.
fn finish(
    mut child: Child,
    mut out: String,
    mut r: BufReader<std::process::ChildStdout>,
) -> (i32, String) {
    use std::io::Read;
    r.read_to_string(&mut out).unwrap();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let st = child.wait().unwrap();
    assert!(
        st.code().is_some(),
        "killed by a signal ({st:?}) instead of ending cleanly:\n{out}{err}"
    );
    (st.code().unwrap(), format!("{out}{err}"))
}

/// The rigid arm of an external RSI client, which sends `sig` to `pid` after `after` cycles.
struct SignallingArm {
    arm: RigidArm,
    cycles: u64,
    after: u64,
    target: Option<(u32, &'static str)>,
}

impl Mechanism for SignallingArm {
    fn poses(&mut self) -> (Pose, Pose) {
        self.arm.poses()
    }
    fn advance(&mut self, c: &Correction) {
        self.arm.advance(c);
        self.cycles += 1;
        if self.cycles == self.after
            && let Some((pid, sig)) = self.target.take()
        {
            signal(pid, sig);
        }
    }
}

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// An RSI client (the simulated controller on a stiff arm) aimed at `port`, for `cycles` cycles.
fn client(port: u16, cycles: u64, tweak: impl FnOnce(&mut KrcConfig)) -> Krc {
    let target: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let mut kc = KrcConfig::new(
        EthernetConfig::forcecell([127, 0, 0, 1].into(), port, false),
        target,
    );
    kc.timing = Timing::Lockstep {
        deadline: Duration::from_millis(500),
    };
    // A forcecell that died without answering ends the client after 20 late replies, not never.
    kc.timeout = 20;
    kc.cycles = Some(cycles);
    kc.poscorr = PoscorrLimits {
        translation: 0.055,
        ..PoscorrLimits::default()
    };
    kc.poscorrmon = PoscorrLimits {
        translation: 0.06,
        ..PoscorrLimits::MONITOR_DEFAULT
    };
    tweak(&mut kc);
    Krc::new(kc).unwrap()
}

fn arm() -> RigidArm {
    RigidArm::new(Pose {
        position: Vector3::new(0.5, 0.0, 0.3),
        orientation: UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0),
    })
}

/// Run `sim --external-robot` with a client that signals the process after `after` cycles.
fn external_signalled(
    sig: &'static str,
    after: u64,
) -> (i32, String, KrcReport, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("long.toml"), LONG).unwrap();
    let port = free_port();
    let listen = format!("127.0.0.1:{port}");
    let mut child = spawn(
        &[
            "sim",
            "-s",
            "long.toml",
            "--external-robot",
            &listen,
            "--out",
            "o",
        ],
        dir.path(),
    );
    let (seen, r) = read_until(&mut child, "listening for an RSI client");
    let mut krc = client(port, 100_000, |_| {});
    let mut mech = SignallingArm {
        arm: arm(),
        cycles: 0,
        after,
        target: Some((child.id(), sig)),
    };
    let report = krc.run(&mut mech);
    let (code, text) = finish(child, seen, r);
    (code, text, report, dir)
}

fn rows(path: &Path) -> usize {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .count()
        - 1
}

#[test]
fn sigterm_ends_sim_with_an_external_robot_with_stop_and_a_recording() {
    let (code, text, report, dir) = external_signalled("TERM", 200);
    assert_eq!(code, 130, "{text}");
    assert_eq!(
        report.end,
        KrcEnd::Stopped,
        "the robot got Stop: {report:?}\n{text}"
    );
    assert!(text.contains("stopped by SIGINT/SIGTERM"), "{text}");
    assert!(text.contains("Stop sent to the robot"), "{text}");
    assert!(text.contains("peak force"), "the summary: {text}");
    assert!(rows(&dir.path().join("o/long.csv")) >= 199, "{text}");
    assert!(dir.path().join("o/long.png").exists(), "{text}");
}

#[test]
fn sigint_ends_sim_with_an_external_robot_with_stop_and_a_recording() {
    let (code, text, report, dir) = external_signalled("INT", 150);
    assert_eq!(code, 130, "{text}");
    assert_eq!(report.end, KrcEnd::Stopped, "{report:?}\n{text}");
    assert!(rows(&dir.path().join("o/long.csv")) >= 149, "{text}");
}

#[test]
fn sigint_ends_sim_with_the_simulated_controller_in_real_time_with_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("long.toml"), LONG).unwrap();
    let mut child = spawn(
        &["sim", "-s", "long.toml", "--realtime", "--out", "o"],
        dir.path(),
    );
    let (seen, r) = read_until(&mut child, "robot: ");
    signal(child.id(), "INT");
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 130, "{text}");
    assert!(text.contains("stopped by SIGINT/SIGTERM"), "{text}");
    assert!(text.contains("wrote o/long.csv and o/long.png"), "{text}");
    assert!(dir.path().join("o/long.png").exists());
    std::fs::read_to_string(dir.path().join("o/long.csv")).unwrap();
}

#[test]
fn sigterm_ends_a_lockstep_sim_with_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    // 3600 s of lockstep: far more than the test waits for.
    std::fs::write(
        dir.path().join("long.toml"),
        LONG.replace("duration = 60.0", "duration = 3600.0"),
    )
    .unwrap();
    let mut child = spawn(&["sim", "-s", "long.toml", "--out", "o"], dir.path());
    let (seen, r) = read_until(&mut child, "robot: ");
    signal(child.id(), "TERM");
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 130, "{text}");
    assert!(dir.path().join("o/long.csv").exists(), "{text}");
}

#[test]
fn a_signal_ends_the_wait_for_the_first_datagram() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("long.toml"), LONG).unwrap();
    let listen = format!("127.0.0.1:{}", free_port());
    let mut child = spawn(
        &[
            "sim",
            "-s",
            "long.toml",
            "--external-robot",
            &listen,
            "--out",
            "o",
        ],
        dir.path(),
    );
    // No robot ever sends.
    let (seen, r) = read_until(&mut child, "listening for an RSI client");
    signal(child.id(), "INT");
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 130, "{text}");
    assert!(
        text.contains("Stop not sent (no robot cycle to answer)"),
        "{text}"
    );
}

#[test]
fn a_lost_link_ends_with_its_own_exit_status() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("long.toml"), LONG).unwrap();
    let port = free_port();
    let listen = format!("127.0.0.1:{port}");
    let mut child = spawn(
        &[
            "sim",
            "-s",
            "long.toml",
            "--external-robot",
            &listen,
            "--out",
            "o",
        ],
        dir.path(),
    );
    let (seen, r) = read_until(&mut child, "listening for an RSI client");
    // The robot ends RSI without a goodbye after 300 cycles.
    let mut krc = client(port, 100_000, |k| k.faults.silent_from = Some(300));
    let abort = krc.abort_handle();
    let robot = std::thread::spawn(move || krc.run(&mut arm()));
    let (code, text) = finish(child, seen, r);
    abort.store(true, Ordering::Relaxed);
    let report = robot.join().unwrap();
    assert_eq!(code, 3, "{text}\n{report:?}");
    assert!(text.contains("the loop ended early"), "{text}");
    assert_eq!(rows(&dir.path().join("o/long.csv")), 300, "{text}");
}
