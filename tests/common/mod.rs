//! Helpers shared by the tests that run `forcecell` as a child process and stop it with signals, with
//! the simulated KUKA controller in this process as the robot.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, UdpSocket};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use hal::{Correction, Pose, UnitQuaternion, Vector3};
use kuka_rsi::{EthernetConfig, PoscorrLimits};
use sim::krc::{Krc, KrcConfig, Mechanism, RigidArm, Timing};

/// The `forcecell` binary under test.
pub fn forcecell() -> Command {
    Command::new(env!("CARGO_BIN_EXE_forcecell"))
}

/// A child process (a simulated device) that is killed and reaped when the test lets go of it.
pub struct Kill(pub Child);

impl Drop for Kill {
    fn drop(&mut self) {
        // Ends only the process this test started, by its own handle.
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A simulated FT 300 (`forcecell sim-sensor robotiq`) on a pseudo-terminal linked at `link`,
/// reporting `fz` N and nothing else, served until dropped.
pub fn ft300(link: &Path, fz: &str) -> Kill {
    let mut child = forcecell()
        .args(["sim-sensor", "robotiq", "--link"])
        .arg(link)
        .args(["--fz", fz, "--noise", "0", "--seconds", "300"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("start sim-sensor");
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    let sensor = Kill(child);
    assert_eq!(first.trim(), link.display().to_string(), "prints the path");
    sensor
}

/// Run `forcecell ARGS` to its end; returns its output and stdout + stderr as text.
pub fn run(args: &[&str]) -> (Output, String) {
    let out = forcecell().args(args).output().expect("run forcecell");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out, text)
}

pub fn signal(pid: u32, sig: &str) {
    // Signals only the forcecell process this test started, by its id.
    let st = Command::new("/bin/kill")
        .args([&format!("-{sig}"), &pid.to_string()])
        .status()
        .expect("run /bin/kill");
    assert!(st.success(), "kill -{sig} {pid}");
}

pub fn spawn(args: &[&str], dir: &Path) -> Child {
    forcecell()
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start forcecell")
}

/// Read the child's stdout until a line containing `needle`; returns everything read.
pub fn read_until(
    child: &mut Child,
    needle: &str,
) -> (String, BufReader<std::process::ChildStdout>) {
    let mut r = BufReader::new(child.stdout.take().unwrap());
    let mut seen = String::new();
    loop {
        let mut line = String::new();
        let n = r.read_line(&mut line).unwrap();
        if n == 0 {
            use std::io::Read;
            let mut err = String::new();
            let _ = child.stderr.take().unwrap().read_to_string(&mut err);
            panic!("the child ended before printing {needle:?}:\n{seen}{err}");
        }
        seen.push_str(&line);
        if line.contains(needle) {
            return (seen, r);
        }
    }
}

/// Wait for the child and collect the rest of its output.
pub fn finish(
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
pub struct SignallingArm {
    pub arm: RigidArm,
    pub cycles: u64,
    pub after: u64,
    pub target: Option<(u32, &'static str)>,
    pub killer: Option<Child>,
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
            // Without waiting for /bin/kill: the robot keeps its cycle meanwhile (a slow process start
            // must not look like a robot that fell silent).
            let child = Command::new("/bin/kill")
                .args([&format!("-{sig}"), &pid.to_string()])
                .spawn()
                .expect("run /bin/kill");
            self.killer = Some(child);
        }
    }
}

impl Drop for SignallingArm {
    fn drop(&mut self) {
        if let Some(mut k) = self.killer.take() {
            let st = k.wait().expect("wait for /bin/kill");
            assert!(st.success(), "/bin/kill failed");
        }
    }
}

pub fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// An RSI client (the simulated controller on a stiff arm) aimed at `port`, for `cycles` cycles.
pub fn client(port: u16, cycles: u64, tweak: impl FnOnce(&mut KrcConfig)) -> Krc {
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

pub fn arm() -> RigidArm {
    RigidArm::new(Pose {
        position: Vector3::new(0.5, 0.0, 0.3),
        orientation: UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0),
    })
}

/// The value of `name="…"` in the first `<tag …>` of an RSI datagram: a hand-written robot reads
/// forcecell's replies by string matching, without forcecell's codec.
pub fn attr(xml: &str, tag: &str, name: &str) -> Option<f64> {
    let start = xml.find(&format!("<{tag} "))?;
    let el = &xml[start..start + xml[start..].find('>')?];
    let at = el.find(&format!(" {name}=\""))? + name.len() + 3;
    el[at..at + el[at..].find('"')?].parse().ok()
}

/// Send `datagram` on the connected `sock` and wait for the answer; a server still starting (the port
/// refuses, or nothing answers yet) is retried for at most about 20 s. `None`: no answer.
pub fn exchange(sock: &UdpSocket, datagram: &str) -> Option<String> {
    let mut buf = [0u8; 2048];
    for _ in 0..100 {
        if sock.send(datagram.as_bytes()).is_err() {
            std::thread::sleep(Duration::from_millis(200));
            continue;
        }
        match sock.recv(&mut buf) {
            Ok(n) => return Some(String::from_utf8_lossy(&buf[..n]).into_owned()),
            // Refused (ICMP port unreachable) returns at once: wait before the next try.
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {
                std::thread::sleep(Duration::from_millis(200));
            }
            Err(_) => {}
        }
    }
    None
}
