//! `forcecell calibrate` with a `kind = "abb-egm"` cell file, as an integrator starts it: the sensor is a
//! simulated FT 300 on a pseudo-terminal (another process), the robot the simulated IRC5 in this process,
//! sending `EgmRobot` over loopback UDP while its arm holds the tool still in three orientations. The EGM
//! link is what the cell file's kind makes of it (`RobotSpec::open`): calibrate collects the three poses
//! and prints the `[gravity]` section.

mod common;

use std::net::SocketAddr;

use common::{finish, free_port, read_until, spawn};
use hal::{Correction, Pose, UnitQuaternion, Vector3};
use sim::irc5::{Irc5, Irc5Config, Irc5End};
use sim::krc::{Mechanism, Timing};

/// An arm that holds its tool still, pointing down, and turns it 20° about x, then 20° about y, each
/// after `hold` cycles.
struct TurningArm {
    cycle: u64,
    hold: u64,
}

impl Mechanism for TurningArm {
    fn poses(&mut self) -> (Pose, Pose) {
        let down = UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0);
        let turn = match self.cycle / self.hold {
            0 => UnitQuaternion::identity(),
            1 => UnitQuaternion::from_euler_angles(20f64.to_radians(), 0.0, 0.0),
            _ => UnitQuaternion::from_euler_angles(0.0, 20f64.to_radians(), 0.0),
        };
        let p = Pose {
            position: Vector3::new(0.5, 0.0, 0.3),
            orientation: turn * down,
        };
        (p, p)
    }
    fn advance(&mut self, _c: &Correction) {
        self.cycle += 1;
    }
}

#[test]
fn calibrate_collects_its_poses_over_egm() {
    let dir = tempfile::tempdir().unwrap();
    let _sensor = common::ft300(&dir.path().join("ft300"), "19.613");
    let port = free_port();
    let cell = format!(
        r#"tuning = "robust-100hz"
record = "rec"

[robot]
kind = "abb-egm"
listen = "127.0.0.1:{port}"
robot_ip = "127.0.0.1"

[sensor]
kind = "robotiq"
port = "ft300"
"#
    );
    std::fs::write(dir.path().join("cell.toml"), cell).unwrap();
    let mut child = spawn(
        &["calibrate", "--config", "cell.toml", "--poses", "3"],
        dir.path(),
    );
    let (seen, r) = read_until(&mut child, "listening on");
    assert!(
        seen.contains(&format!("listening on 127.0.0.1:{port}")),
        "{seen}"
    );
    let mut cfg = Irc5Config::new(SocketAddr::from(([127, 0, 0, 1], port)));
    cfg.timing = Timing::Realtime;
    // Three holds of 1.2 s, then a little more; calibrate ends once it has its poses.
    cfg.cycles = Some(1000);
    let mut irc5 = Irc5::new(cfg).unwrap();
    let mut arm = TurningArm {
        cycle: 0,
        hold: 300,
    };
    let report = irc5.run(&mut arm);
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 0, "{text}\n{report:?}");
    assert!(
        matches!(report.end, Irc5End::Completed | Irc5End::CommTimeout),
        "{report:?}"
    );
    assert!(
        report.good >= 600,
        "calibrate answered the robot: {report:?}"
    );
    for n in 1..=3 {
        assert!(text.contains(&format!("pose {n} of 3")), "{text}");
    }
    assert!(text.contains("fitted over 3 poses"), "{text}");
    assert!(text.contains("[gravity]"), "{text}");
    // A constant 19.6 N in the sensor's frame whatever the orientation is no weight: a bias.
    let bias: Vec<f64> = text
        .lines()
        .find_map(|l| l.strip_prefix("force_bias = ["))
        .unwrap_or_else(|| panic!("a force_bias line in {text}"))
        .trim_end_matches(']')
        .split(", ")
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        bias[0].abs() < 0.1 && bias[1].abs() < 0.1 && (bias[2] - 19.61).abs() < 0.1,
        "{bias:?}"
    );
    let names: Vec<String> = std::fs::read_dir(dir.path().join("rec"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        names
            .iter()
            .any(|n| n.starts_with("calibrate-") && n.ends_with(".mcap")),
        "{names:?}"
    );
}
