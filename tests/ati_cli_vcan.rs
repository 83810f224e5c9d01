//! The `forcecell` binary's ATI commands on a real vcan interface: `sim-sensor ati` serves a simulated
//! node, `sensor ati info|read|tare` talks to it from another process, and `sim --can` runs a scenario
//! through the driver over the interface. Ignored in a plain `cargo test`; `scripts/vcan-tests.sh`
//! runs them natively, inside User-Mode Linux or inside QEMU.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::sync::atomic::Ordering;

use common::{
    Kill, SignallingArm, arm, client, finish, forcecell, free_port, read_until, run, signal, spawn,
};
use sim::krc::KrcEnd;

fn iface() -> String {
    std::env::var("FORCECELL_VCAN").unwrap_or_else(|_| "vcan0".into())
}

/// Headroom for slow guests (`FORCECELL_VCAN_TIME_SCALE`, 1 to 100; `scripts/vcan-tests.sh` raises it
/// under QEMU's software emulation): the sensor's turnaround is multiplied by it and the read rate
/// divided by it, so the driver's own check (a poll must fit in one period) still holds.
fn time_scale() -> u32 {
    std::env::var("FORCECELL_VCAN_TIME_SCALE")
        .ok()
        .map(|s| {
            s.parse::<u32>()
                .ok()
                .filter(|k| (1..=100).contains(k))
                .unwrap_or_else(|| panic!("FORCECELL_VCAN_TIME_SCALE must be 1 to 100, not {s:?}"))
        })
        .unwrap_or(1)
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn sensor_commands_talk_to_the_simulated_node_in_another_process() {
    let can = iface();
    let _node = Kill(
        forcecell()
            .args([
                "sim-sensor",
                "ati",
                "--can",
                &can,
                "--base",
                "0x31",
                "--fz",
                "12.5",
            ])
            .args(["--noise", "0", "--seconds", "120"])
            .stdout(Stdio::null())
            .spawn()
            .expect("start sim-sensor"),
    );
    let turnaround = (20_000 * time_scale()).to_string();
    let rate = (20.0 / f64::from(time_scale())).to_string();
    let common = [
        "sensor",
        "ati",
        "--can",
        &can,
        "--base",
        "0x31",
        "--turnaround-us",
        &turnaround,
    ];

    // The node binds its socket right after starting: retry `info` until it answers.
    let mut info = String::new();
    for _ in 0..20 {
        let (out, text) = run(&[&common[..], &["info"]].concat());
        info = text;
        if out.status.success() {
            break;
        }
    }
    assert!(info.contains("firmware        3.8 build 1"), "{info}");
    assert!(info.contains("serial          FT-SIM01"), "{info}");
    assert!(info.contains("status          0x0000"), "{info}");

    let (out, text) = run(&[&common[..], &["read", "--count", "3", "--rate", &rate]].concat());
    assert!(out.status.success(), "{text}");
    let fz: Vec<f64> = text
        .lines()
        .filter(|l| l.trim_end().ends_with("Ok"))
        .filter_map(|l| l.split_whitespace().nth(3)?.parse().ok())
        .collect();
    assert_eq!(fz.len(), 3, "{text}");
    assert!(fz.iter().all(|f| (f - 12.5).abs() < 0.02), "{fz:?}\n{text}");

    let (out, text) = run(&[
        &common[..],
        &["read", "--count", "2", "--rate", &rate, "--tare"],
    ]
    .concat());
    assert!(out.status.success(), "{text}");
    let after: Vec<f64> = text
        .lines()
        .filter(|l| l.trim_end().ends_with("Ok"))
        .filter_map(|l| l.split_whitespace().nth(3)?.parse().ok())
        .collect();
    assert_eq!(after.len(), 2, "{text}");
    assert!(
        after.iter().all(|f| f.abs() < 0.02),
        "bias removed: {after:?}\n{text}"
    );

    let (out, text) = run(&[&common[..], &["tare"]].concat());
    assert!(
        out.status.success() && text.contains("bias (counts"),
        "{text}"
    );
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn sim_runs_a_scenario_through_the_driver_over_vcan() {
    let dir = std::env::temp_dir().join(format!("forcecell-ati-vcan-{}", std::process::id()));
    let can = iface();
    let (out, text) = run(&[
        "sim",
        "--scenario",
        "paper-fig9",
        "--can",
        &can,
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains(&format!("ATI driver ↔ simulated node on {can}")),
        "{text}"
    );
    assert!(text.contains("ran 2000 steps"), "{text}");
    assert!(dir.join("paper-fig9.csv").exists(), "{text}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The simulated node on `can` at the example's base (0x20), serving for up to two minutes.
fn node(can: &str) -> Kill {
    Kill(
        forcecell()
            .args([
                "sim-sensor",
                "ati",
                "--can",
                can,
                "--fz",
                "10",
                "--noise",
                "2",
            ])
            .args(["--seconds", "120"])
            .stdout(Stdio::null())
            .spawn()
            .expect("start sim-sensor"),
    )
}

/// `examples/cell.toml` as shipped (`tare = true`, the `[gravity]` model), pointed at loopback and `can`,
/// with `duration` in place of the example's 60 s (`None`: the example's own).
fn example_cell(dir: &Path, can: &str, port: u16, duration: Option<&str>) -> PathBuf {
    let shipped =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cell.toml"))
            .unwrap();
    assert!(
        shipped.contains("tare = true"),
        "the example tares at start"
    );
    let mut text = shipped
        .replace("192.168.1.100:49152", &format!("127.0.0.1:{port}"))
        .replace("\"192.168.1.10\"", "\"127.0.0.1\"")
        .replace("can = \"can0\"", &format!("can = \"{can}\""));
    // A virtual interface (under User-Mode Linux) answers in milliseconds, not microseconds, and
    // background polling must leave each exchange that long.
    text = text
        .replace("tare = true", "tare = true\nturnaround_us = 20000")
        .replace("poll_hz = 1000.0", "poll_hz = 40.0");
    if let Some(d) = duration {
        text = text.replace("duration = 60.0", &format!("duration = {d}"));
    }
    assert_ne!(text, shipped);
    let path = dir.join("cell.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn recordings(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir.join("recordings"))
        .map(|r| r.map(|e| e.unwrap().path()).collect())
        .unwrap_or_default()
}

/// What ran was recorded: the MCAP recording, the CSV and PNG exported from it, the CAN log.
fn assert_recorded(dir: &Path, text: &str) {
    let files = recordings(dir);
    for ext in ["mcap", "csv", "png", "log"] {
        assert!(
            files
                .iter()
                .any(|f| f.extension().is_some_and(|e| e == ext)),
            "no .{ext} among {files:?}: {text}"
        );
    }
}

/// Start `run` on the example cell; returns the child once it listens for the robot.
fn start_run(dir: &Path) -> (Child, String, std::io::BufReader<std::process::ChildStdout>) {
    let mut child = spawn(&["run", "--config", "cell.toml"], dir);
    let (seen, r) = read_until(&mut child, "listening on");
    (child, seen, r)
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn run_with_the_example_cell_file_tares_runs_and_records() {
    let can = iface();
    let _node = node(&can);
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    example_cell(dir.path(), &can, port, Some("1.0"));
    let (child, seen, r) = start_run(dir.path());
    let mut krc = client(port, 100_000, |_| {});
    let report = krc.run(&mut arm());
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("bias taken"),
        "tare = true works as shipped: {text}"
    );
    assert!(
        text.contains("s of robot time done") && text.contains("Stop sent"),
        "{text}"
    );
    assert_eq!(report.end, KrcEnd::Stopped, "{report:?}");
    // The link's counters are printed.
    assert!(
        text.contains("RSI link: ") && text.contains(" foreign, "),
        "{text}"
    );
    let files = recordings(dir.path());
    assert!(
        files
            .iter()
            .any(|f| f.extension().is_some_and(|e| e == "csv")),
        "{files:?}"
    );
    assert!(
        files
            .iter()
            .any(|f| f.extension().is_some_and(|e| e == "png")),
        "{files:?}"
    );
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn sigterm_ends_run_with_stop_to_the_robot_and_a_recording() {
    let can = iface();
    let _node = node(&can);
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    example_cell(dir.path(), &can, port, None);
    let (child, seen, r) = start_run(dir.path());
    let mut krc = client(port, 100_000, |_| {});
    let mut mech = SignallingArm {
        arm: arm(),
        cycles: 0,
        after: 200,
        target: Some((child.id(), "TERM")),
        killer: None,
    };
    let report = krc.run(&mut mech);
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 130, "{text}");
    assert_eq!(
        report.end,
        KrcEnd::Stopped,
        "the robot got Stop: {report:?}\n{text}"
    );
    assert!(
        text.contains("stopped by the operator") && text.contains("Stop sent"),
        "{text}"
    );
    assert_recorded(dir.path(), &text);
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn ctrl_c_ends_run_while_it_waits_for_the_robot() {
    let can = iface();
    let _node = node(&can);
    let dir = tempfile::tempdir().unwrap();
    example_cell(dir.path(), &can, free_port(), None);
    // No robot ever sends.
    let (child, seen, r) = start_run(dir.path());
    signal(child.id(), "INT");
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 130, "{text}");
    assert!(
        text.contains("not sent (no robot cycle to answer)"),
        "{text}"
    );
    assert!(text.contains("nothing to record"), "{text}");
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn a_robot_that_falls_silent_ends_run_with_status_3() {
    let can = iface();
    let _node = node(&can);
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    example_cell(dir.path(), &can, port, None);
    let (child, seen, r) = start_run(dir.path());
    let mut krc = client(port, 100_000, |k| k.faults.silent_from = Some(200));
    let abort = krc.abort_handle();
    let robot = std::thread::spawn(move || krc.run(&mut arm()));
    let (code, text) = finish(child, seen, r);
    abort.store(true, Ordering::Relaxed);
    robot.join().unwrap();
    assert_eq!(code, 3, "{text}");
    assert!(text.contains("link lost"), "{text}");
    assert_recorded(dir.path(), &text);
}
