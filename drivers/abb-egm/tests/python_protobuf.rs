//! Google's protobuf runtime (Python) against forcecell's codec: Python classes generated at test time
//! from the project's own `proto/egm.proto` (`grpc_tools.protoc`) decode forcecell's path correction
//! and robot message, and encode an `EgmRobot` that forcecell's session turns into a cycle. Installs
//! `protobuf` and `grpcio-tools` from PyPI into `target/egm-venv` (`scripts/egm-venv.sh`), hence
//! ignored: `cargo test --release -p forcecell-abb-egm --test python_protobuf -- --ignored`.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use abb_egm::msg::{
    EgmClock, EgmFeedBack, EgmHeader, EgmJoints, EgmMeasuredForce, EgmPlanned, EgmPose,
    EgmRapiddata, EgmRobot, MessageType,
};
use abb_egm::{CommandSlots, EgmSession, LinkConfig, RobotFilter, wire};
use hal::{Correction, Pose, ProcessMode, UnitQuaternion, Vector3};
use prost::Message;

const SCRIPT: &str = r#"
import sys
sys.path.insert(0, sys.argv[1])
import egm_pb2 as egm
pc = egm.EgmSensorPathCorr()
pc.ParseFromString(bytes.fromhex(sys.argv[2]))
print("pc.seqno", pc.header.seqno)
print("pc.mtype", egm.EgmHeader.MessageType.Name(pc.header.mtype))
print("pc.pos", pc.pathCorr.pos.x, pc.pathCorr.pos.y, pc.pathCorr.pos.z)
print("pc.age", pc.pathCorr.age)
print("pc.initialized", pc.IsInitialized())
r = egm.EgmRobot()
r.ParseFromString(bytes.fromhex(sys.argv[3]))
print("r.seqno", r.header.seqno, r.header.tm)
print("r.feedback", r.feedBack.cartesian.pos.x, r.feedBack.cartesian.pos.z, r.feedBack.cartesian.orient.u1)
print("r.joints", *r.feedBack.joints.joints)
print("r.dnum", *r.RAPIDfromRobot.dnum)
print("r.clock", r.feedBack.time.sec, r.feedBack.time.usec)
print("r.force", r.measuredForce.fcActive, *r.measuredForce.force)
m = egm.EgmRobot()
m.header.seqno = 42
m.header.tm = 1234
m.header.mtype = egm.EgmHeader.MSGTYPE_DATA
for p in (m.feedBack.cartesian, m.planned.cartesian):
    p.pos.x, p.pos.y, p.pos.z = 400.0, -25.0, 250.0
    p.orient.u0, p.orient.u1, p.orient.u2, p.orient.u3 = 0.0, 1.0, 0.0, 0.0
m.feedBack.cartesian.pos.z = 249.5
m.feedBack.joints.joints.extend([0.0, 10.0, 20.0, 0.0, 60.0, 0.0])
m.motorState.state = egm.EgmMotorState.MOTORS_ON
m.rapidExecState.state = egm.EgmRapidCtrlExecState.RAPID_RUNNING
m.mciState.state = egm.EgmMCIState.MCI_RUNNING
m.moveIndex = 3
m.RAPIDfromRobot.dnum.extend([2.0, 15.0, 0.25, 9.0])
m.utilizationRate = 12.5
print("python.robot", m.SerializeToString().hex())
"#;

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("forcecell-egm-py-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn robot_from_rust() -> EgmRobot {
    let (pos, orient) = wire::pose_to_wire(&Pose {
        position: Vector3::new(0.5, 0.0, 0.3),
        orientation: UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0),
    });
    let pose = EgmPose {
        pos: Some(pos),
        orient: Some(orient),
        euler: None,
    };
    EgmRobot {
        header: Some(EgmHeader {
            seqno: Some(7),
            tm: Some(1000),
            mtype: Some(MessageType::Data as i32),
        }),
        feed_back: Some(EgmFeedBack {
            joints: Some(EgmJoints {
                joints: vec![1.0, 2.0, 3.0],
            }),
            cartesian: Some(pose),
            external_joints: None,
            time: Some(EgmClock {
                sec: Some(1_700_000_000),
                usec: Some(250),
            }),
        }),
        planned: Some(EgmPlanned {
            cartesian: Some(pose),
            ..EgmPlanned::default()
        }),
        measured_force: Some(EgmMeasuredForce {
            fc_active: Some(true),
            force: vec![0.5, -1.0],
        }),
        rapid_from_robot: Some(EgmRapiddata {
            dig_val: None,
            dnum: vec![1.0, 20.0, 0.5, 3.0],
        }),
        ..EgmRobot::default()
    }
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

const SCRIPT_PATH: &str = "../../scripts/egm-venv.sh";

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
#[ignore = "installs protobuf and grpcio-tools from PyPI into target/egm-venv (python3 with venv, network)"]
fn googles_protobuf_runtime_reads_and_writes_what_forcecell_does() {
    let python = venv_python(&["protobuf", "grpcio-tools"]);
    let out = dir();
    let proto = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("proto");
    let st = Command::new(&python)
        .args(["-m", "grpc_tools.protoc", "-I"])
        .arg(&proto)
        .arg(format!("--python_out={}", out.display()))
        .arg("egm.proto")
        .status()
        .expect("the venv's python");
    assert!(st.success(), "grpc_tools.protoc failed on proto/egm.proto");

    // forcecell's bytes: a path correction from the session, and a robot message from the codec.
    let robot = SocketAddr::from(([127, 0, 0, 1], 40_000));
    let mut cfg = LinkConfig::new(
        SocketAddr::from(([127, 0, 0, 1], 0)),
        RobotFilter::Exact(robot),
    );
    cfg.process = Some(CommandSlots::default());
    let mut s = EgmSession::new(cfg).unwrap();
    let t0 = Instant::now();
    let ours = robot_from_rust().encode_to_vec();
    s.receive(&ours, robot, t0).unwrap();
    let mut buf = [0u8; 128];
    let o = s
        .reply(&Correction::along_z(0.0002), t0, &mut buf)
        .unwrap()
        .unwrap();

    let py = Command::new(&python)
        .args(["-c", SCRIPT])
        .arg(&out)
        .arg(hex(&buf[..o.len]))
        .arg(hex(&ours))
        .output()
        .expect("the venv's python");
    let text = String::from_utf8_lossy(&py.stdout);
    assert!(
        py.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&py.stderr)
    );
    let line = |key: &str| -> Vec<String> {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{key} ")))
            .unwrap_or_else(|| panic!("no {key} in {text}"))
            .split_whitespace()
            .map(str::to_owned)
            .collect()
    };
    let num = |key: &str| -> Vec<f64> { line(key).iter().map(|v| v.parse().unwrap()).collect() };
    assert_eq!(num("pc.seqno"), [1.0]);
    assert_eq!(line("pc.mtype"), ["MSGTYPE_PATH_CORRECTION"]);
    let pos = num("pc.pos");
    assert!(
        pos[0] == 0.0 && pos[1] == 0.0 && (pos[2] - 0.2).abs() < 1e-12,
        "{pos:?}"
    );
    assert_eq!(num("pc.age"), [0.0]);
    assert_eq!(
        line("pc.initialized"),
        ["True"],
        "every required field is there"
    );
    assert_eq!(num("r.seqno"), [7.0, 1000.0]);
    let fb = num("r.feedback");
    assert!(
        (fb[0] - 500.0).abs() < 1e-9 && (fb[1] - 300.0).abs() < 1e-9 && (fb[2] - 1.0).abs() < 1e-12
    );
    assert_eq!(num("r.joints"), [1.0, 2.0, 3.0]);
    assert_eq!(num("r.dnum"), [1.0, 20.0, 0.5, 3.0]);
    assert_eq!(num("r.clock"), [1_700_000_000.0, 250.0]);
    assert_eq!(line("r.force"), ["True", "0.5", "-1.0"]);

    // Python's bytes through forcecell's session.
    let theirs: Vec<u8> = {
        let h = &line("python.robot")[0];
        (0..h.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&h[i..i + 2], 16).unwrap())
            .collect()
    };
    let m = EgmRobot::decode(&theirs[..]).unwrap();
    assert_eq!(m.move_index, Some(3));
    assert_eq!(m.utilization_rate, Some(12.5));
    assert_eq!(
        m.feed_back
            .as_ref()
            .unwrap()
            .joints
            .as_ref()
            .unwrap()
            .joints
            .len(),
        6
    );
    let c = s.receive(&theirs, robot, t0).unwrap();
    assert!(!c.new_session, "seqno 42 after 7 is the same session");
    assert_eq!(c.seq, 42);
    assert!(
        (c.t - 0.234).abs() < 1e-12,
        "tm 1234 ms after the session's 1000"
    );
    assert!((c.actual.position - Vector3::new(0.4, -0.025, 0.2495)).norm() < 1e-12);
    assert!(
        (c.tool_offset().z - 0.0005).abs() < 1e-12,
        "tool z down: 0.5 mm below the plan"
    );
    let p = c.process.unwrap();
    assert_eq!(
        (p.mode, p.force, p.ramp, p.segment),
        (ProcessMode::Release, 15.0, 0.25, 9)
    );
    let st = s.diagnostics().robot;
    assert_eq!(
        (st.motors, st.rapid, st.mci, st.move_index),
        (Some(1), Some(2), Some(3), Some(3))
    );
    std::fs::remove_dir_all(out).ok();
}
