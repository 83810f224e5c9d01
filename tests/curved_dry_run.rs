//! The dry run on a curved part: `forcecell sim --external-robot` with a curved scenario (its tuning
//! follows the surface) answered to an RSI client that is not ours — a plain UDP socket that writes
//! `<Rob>` by hand and moves like a stiff arm: its measured pose is the programmed one with the last
//! correction (translation and `A B C` rotation, tool frame) applied. The virtual part is the
//! scenario's (a cylinder, misplaced by 5° about the path); its truth decides the targets.
//!
//! A robot that applies the rotations lets the tool come square to the surface: every target of the
//! pass is met. One that ignores them (as a robot without `RKorr.A..C` wired would) leaves the tool
//! 5° off: the tilt targets fail.

mod common;

use std::net::UdpSocket;
use std::process::{Command, Output, Stdio};
use std::time::Duration;

use common::attr;
use hal::{UnitQuaternion, Vector3};

/// The hand-written robot: the tool points down (A 180, C 180) over the programmed path.
struct Robot {
    sock: UdpSocket,
    ipoc: u64,
    /// The correction in effect (`RKorr`): X, Y, Z in mm, A, B, C in degrees.
    corr: [f64; 6],
    /// Apply the correction's rotation to the measured pose.
    turns: bool,
}

const SOL: [f64; 6] = [445.0, 0.0, 890.0, 180.0, 0.0, 180.0];

fn rot(a: f64, b: f64, c: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(c.to_radians(), b.to_radians(), a.to_radians())
}

impl Robot {
    fn connect(to: &str, turns: bool) -> Self {
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        sock.connect(to).unwrap();
        sock.set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        Self {
            sock,
            ipoc: 7_000_000,
            corr: [0.0; 6],
            turns,
        }
    }

    /// The measured pose: the programmed one with the correction applied in the tool frame.
    fn ist(&self) -> [f64; 6] {
        let r_sol = rot(SOL[3], SOL[4], SOL[5]);
        let r_corr = if self.turns {
            rot(self.corr[3], self.corr[4], self.corr[5])
        } else {
            UnitQuaternion::identity()
        };
        let p = Vector3::new(SOL[0], SOL[1], SOL[2])
            + r_sol * Vector3::new(self.corr[0], self.corr[1], self.corr[2]);
        let (c, b, a) = (r_sol * r_corr).euler_angles();
        [
            p.x,
            p.y,
            p.z,
            a.to_degrees(),
            b.to_degrees(),
            c.to_degrees(),
        ]
    }

    /// One cycle: send `<Rob>`, wait for the reply, take its correction. `None`: no answer.
    fn cycle(&mut self) -> Option<String> {
        let f = |v: [f64; 6]| {
            format!(
                "X=\"{:.4}\" Y=\"{:.4}\" Z=\"{:.4}\" A=\"{:.4}\" B=\"{:.4}\" C=\"{:.4}\"",
                v[0], v[1], v[2], v[3], v[4], v[5]
            )
        };
        let rob = format!(
            "<Rob Type=\"KUKA\"><RIst {}/><RSol {}/>\
             <AIPos A1=\"0.0000\" A2=\"-90.0000\" A3=\"90.0000\" A4=\"0.0000\" A5=\"90.0000\" A6=\"0.0000\"/>\
             <ASPos A1=\"0.0000\" A2=\"-90.0000\" A3=\"90.0000\" A4=\"0.0000\" A5=\"90.0000\" A6=\"0.0000\"/>\
             <Delay D=\"0\"/><IPOC>{}</IPOC></Rob>",
            f(self.ist()),
            f(SOL),
            self.ipoc
        );
        let sen = common::exchange(&self.sock, &rob)?;
        self.ipoc += 4;
        for (i, name) in ["X", "Y", "Z", "A", "B", "C"].iter().enumerate() {
            self.corr[i] = attr(&sen, "RKorr", name).expect("every reply corrects");
        }
        Some(sen)
    }
}

/// The dry run of `curved-cylinder` against the hand-written robot; its output, the largest rotation
/// the robot was sent (degrees) and the rotation in effect at the end.
fn dry_run(turns: bool) -> (Output, String, f64, [f64; 3]) {
    let dir = tempfile::tempdir().unwrap();
    let port = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let listen = format!("127.0.0.1:{port}");
    let child = Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .args([
            "sim",
            "--external-robot",
            &listen,
            "--scenario",
            "curved-cylinder",
            "--check",
            "--out",
            "dry",
        ])
        .current_dir(dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut robot = Robot::connect(&listen, turns);
    let mut most: f64 = 0.0;
    for _ in 0..20_000 {
        let Some(sen) = robot.cycle() else { break };
        let [.., a, b, c] = robot.corr;
        most = most.max(rot(a, b, c).angle().to_degrees());
        if sen.contains("<Stop>1</Stop>") {
            break;
        }
    }
    let [.., a, b, c] = robot.corr;
    drop(robot);
    let o = child.wait_with_output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    (o, out, most, [a, b, c])
}

/// The verdict line of `metric` in a `--check` summary.
fn verdict<'a>(out: &'a str, metric: &str) -> &'a str {
    out.lines()
        .find(|l| l.trim_start().starts_with(metric))
        .unwrap_or_else(|| panic!("no {metric} verdict in:\n{out}"))
}

#[test]
fn a_robot_that_applies_the_rotations_brings_the_tool_square_and_meets_every_target() {
    let (o, out, most, end) = dry_run(true);
    assert!(
        o.status.success(),
        "{out}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for metric in [
        "tilt_error_settled",
        "tilt_error_max",
        "pressing_in_band_pct",
        "final_rotation",
    ] {
        assert!(verdict(&out, metric).ends_with("pass"), "{out}");
    }
    assert!(!out.contains("FAIL"), "{out}");
    // The normal turns 5° about the path (the misplacement) and, 20 mm from the crown of R 150 mm,
    // asin(20/150) = 7.7° about the cross axis: √(5² + 7.7²) = 9.1° at the pass's ends. The tool
    // was turned that far …
    assert!((8.5..9.8).contains(&most), "largest rotation sent {most}°");
    // … and turned back after RELEASE.
    assert!(
        end.iter().all(|v| v.abs() < 0.01),
        "rotation in effect at the end {end:?}°"
    );
}

#[test]
fn a_robot_that_ignores_the_rotations_leaves_the_tool_off_and_fails_the_tilt_targets() {
    let (_o, out, most, _) = dry_run(false);
    assert!(
        verdict(&out, "tilt_error_settled").ends_with("FAIL"),
        "{out}"
    );
    assert!(most > 1.0, "the law asked for a rotation: {most}°");
}
