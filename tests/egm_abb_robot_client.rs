//! The `abb-robot-client` Python package (PyPI, its `EGM` class: the external-device side, written by
//! others) against the simulated IRC5 over loopback UDP: it reads valid feedback and its path
//! corrections move the simulated robot. Installs `abb-robot-client` from PyPI into `target/egm-venv`
//! (`scripts/egm-venv.sh`), hence ignored:
//! `cargo test --release --test egm_abb_robot_client -- --ignored`.

use std::net::{SocketAddr, UdpSocket};
use std::process::{Command, Stdio};
use std::thread;
use std::time::Duration;

use hal::{Pose, Vector3};
use sim::irc5::{Irc5, Irc5Config, Irc5End};
use sim::krc::{RigidArm, Timing};

const SCRIPT: &str = r#"
import sys
from abb_robot_client.egm import EGM
egm = EGM(port=int(sys.argv[1]))
n = 0
seen = []
while n < 40:
    ok, state = egm.receive_from_robot(timeout=5)
    if not ok:
        print("timeout"); break
    p, q = state.cartesian
    seen.append(p[2])
    # 0.5 mm along the sensor frame's z, measurement age 4 ms
    egm.send_to_robot_path_corr([0.0, 0.0, 0.5], age=4)
    n += 1
print("cycles", n)
print("first", seen[0], state.cartesian[1][1], state.motors_on, state.rapid_running)
print("last", seen[-1])
print("planned", state.cartesian_planned[0][2])
"#;

const SCRIPT_PATH: &str = "scripts/egm-venv.sh";

/// The python of `target/egm-venv` with `packages` installed from PyPI (`scripts/egm-venv.sh`).
fn venv_python(packages: &[&str]) -> String {
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(SCRIPT_PATH);
    let out = Command::new("bash")
        .arg(&script)
        .args(packages)
        .output()
        .expect("run scripts/egm-venv.sh");
    assert!(
        out.status.success(),
        "{} failed (python3 with venv and pip, and PyPI, are needed):\n{}",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .last()
        .expect("the venv's python")
        .to_string()
}

#[test]
#[ignore = "installs abb-robot-client from PyPI into target/egm-venv (python3 with venv, network)"]
fn abb_robot_client_runs_a_path_correction_session_against_the_simulated_irc5() {
    let port = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let python = venv_python(&["abb-robot-client"]);
    let client = Command::new(&python)
        .args(["-c", SCRIPT, &port.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the venv's python");
    thread::sleep(Duration::from_millis(500)); // the client binds its port
    let mut cfg = Irc5Config::new(SocketAddr::from(([127, 0, 0, 1], port)));
    cfg.cycles = Some(40);
    cfg.log = true;
    cfg.timing = Timing::Lockstep {
        deadline: Duration::from_secs(2),
    };
    let mut irc5 = Irc5::new(cfg).unwrap();
    // Tool pointing down (180° about x): +z of the tool is −z of the base.
    let mut arm = RigidArm::new(Pose {
        position: Vector3::new(0.5, 0.0, 0.3),
        orientation: hal::UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0),
    });
    let report = irc5.run(&mut arm);
    let out = client.wait_with_output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line = |k: &str| -> Vec<String> {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{k} ")))
            .unwrap_or_else(|| panic!("no {k} in {text}"))
            .split_whitespace()
            .map(str::to_owned)
            .collect()
    };
    assert_eq!(report.end, Irc5End::Completed);
    assert_eq!(
        (report.good, report.late, report.bad),
        (40, 0, 0),
        "{report:?}"
    );
    assert_eq!(report.max_age, 4);
    assert_eq!(line("cycles"), ["40"]);
    let first = line("first");
    assert_eq!(first[0].parse::<f64>().unwrap(), 300.0, "feedback z in mm");
    assert!(
        (first[1].parse::<f64>().unwrap() - 1.0).abs() < 1e-12,
        "quaternion [w,x,y,z]: x = 1"
    );
    assert_eq!(first[2..], ["True", "True"], "motors on, RAPID running");
    // Its corrections moved the robot: 0.5 mm along the tool's z, i.e. down in the base.
    let last: f64 = line("last")[0].parse().unwrap();
    assert!((last - 299.5).abs() < 1e-9, "{last}");
    assert_eq!(line("planned")[0].parse::<f64>().unwrap(), 300.0);
    assert!((arm.correction.translation.z - 0.0005).abs() < 1e-12);
}
