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
    sim::vcan_env::interface()
}

/// Headroom for slow guests (`FORCECELL_VCAN_TIME_SCALE`, 1 to 100; `scripts/vcan-tests.sh` raises it
/// under User-Mode Linux and QEMU): the sensor's turnaround is multiplied by it and the read rate
/// divided by it, so the driver's own check (a poll must fit in one period) still holds; `run`'s
/// watchdog, hold and orientation age are multiplied by it too (see [`example_cell`]).
fn time_scale() -> u32 {
    sim::vcan_env::time_scale().unwrap_or_else(|e| panic!("{e}"))
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn sensor_commands_talk_to_the_simulated_node_in_another_process() {
    let can = iface();
    let _node = ready_node(&[
        "--can", &can, "--base", "0x31", "--fz", "12.5", "--noise", "0",
    ]);
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
    ready_node(&["--can", can, "--fz", "10", "--noise", "2"])
}

/// `forcecell sim-sensor ati ARGS --seconds 120`, once it serves.
fn ready_node(args: &[&str]) -> Kill {
    let mut child = forcecell()
        .args(["sim-sensor", "ati"])
        .args(args)
        .args(["--seconds", "120"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start sim-sensor");
    // Its first line comes once its CAN socket is open: a driver started before that would ask
    // into the void (seen under a loaded User-Mode Linux). The rest of its output is drained.
    let (_, mut rest) = read_until(&mut child, "simulated ATI NETCANOEM node on");
    std::thread::spawn(move || std::io::copy(&mut rest, &mut std::io::sink()));
    Kill(child)
}

/// `examples/cell.toml` as shipped (`tare = true`, the `[gravity]` model), pointed at loopback and `can`,
/// with `duration` in place of the example's 60 s (`None`: the example's own), its wall-clock bounds
/// scaled by [`time_scale`], and the shipped robust tuning beside it as `robust.toml` with its hold
/// scaled the same way.
fn example_cell(dir: &Path, can: &str, port: u16, duration: Option<&str>) -> PathBuf {
    let shipped =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cell.toml"))
            .unwrap();
    assert!(
        shipped.contains("tare = true"),
        "the example tares at start"
    );
    let mut text = shipped.clone();
    // Each setting the test changes is in the shipped file, as written here.
    let mut set = |from: &str, to: &str| {
        assert!(text.contains(from), "examples/cell.toml has no {from:?}");
        text = text.replace(from, to);
    };
    set("192.168.1.100:49152", &format!("127.0.0.1:{port}"));
    set("\"192.168.1.10\"", "\"127.0.0.1\"");
    set("can = \"can0\"", &format!("can = \"{can}\""));
    // A virtual interface (under User-Mode Linux) answers in milliseconds, not microseconds, and
    // background polling must leave each exchange that long. An emulated guest also stalls (a CI host
    // showed 140-150 ms): every wall-clock bound of the run gets the same headroom
    // (`FORCECELL_VCAN_TIME_SCALE`), so a stall is not taken for a silent robot or sensor.
    let k = time_scale();
    set(
        "tare = true",
        &format!("tare = true\nturnaround_us = {}", 20_000 * k),
    );
    set(
        "poll_hz = 1000.0",
        &format!("poll_hz = {}", 40.0 / f64::from(k)),
    );
    set(
        "watchdog_cycles = 25",
        &format!("watchdog_cycles = {}", 25 * k),
    );
    set(
        "max_age = 0.012",
        &format!("max_age = {}", 0.012 * f64::from(k)),
    );
    set("tuning = \"robust\"", "tuning = \"robust.toml\"");
    if let Some(d) = duration {
        set("duration = 60.0", &format!("duration = {d}"));
    }
    // The shipped robust tuning with its hold (0.1 s) given the headroom too (the loop allows ≤ 1 s).
    let tuning =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("tunings/robust.toml"))
            .unwrap();
    assert!(tuning.contains("max_hold = 0.1 "), "tunings/robust.toml");
    let held = tuning.replace(
        "max_hold = 0.1 ",
        &format!("max_hold = {} ", (0.1 * f64::from(k)).min(1.0)),
    );
    std::fs::write(dir.join("robust.toml"), held).unwrap();
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
    // The board's identity, from its serial and firmware answers, in the run's summary.
    let json = files
        .iter()
        .find(|f| f.extension().is_some_and(|e| e == "json"))
        .unwrap_or_else(|| panic!("a summary: {files:?}"));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    assert_eq!(summary["sensor_serial"], "FT-SIM01", "{summary}");
    assert!(
        summary["sensor_firmware"]
            .as_str()
            .unwrap()
            .starts_with("3.8"),
        "{summary}"
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

/// The readings a `sensor ati read` printed: (Fx, Fy, Fz, Mx, My, Mz) as printed (3 or 4 decimals).
fn printed_readings(text: &str) -> Vec<[f64; 6]> {
    text.lines()
        .filter_map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .take(7)
                .map(str::parse)
                .collect::<Result<_, _>>()
                .ok()?;
            (v.len() == 7).then(|| [v[1], v[2], v[3], v[4], v[5], v[6]])
        })
        .collect()
}

/// Every reading the log holds, in order: the log replayed in this process to the driver over the
/// in-memory bus (tests/candump.rs shows that this gives exactly the recorded readings).
fn readings_in_log(log: &Path, base: ati_can::Base) -> (u64, Vec<[f64; 6]>) {
    let records = forcecell::candump::read_log(log).unwrap();
    let replay = forcecell::candump::Replay::from_log(&records, base).unwrap();
    let polls = replay.recorded_polls;
    let bus = ati_can::MemBus::with_virtual_clock();
    bus.attach(replay);
    let mut driver = ati_can::Driver::new(
        bus.port(),
        ati_can::Config {
            base,
            turnaround: std::time::Duration::from_millis(20 * u64::from(time_scale())),
            ..ati_can::Config::default()
        },
    )
    .unwrap();
    driver.start().unwrap();
    let mut out = Vec::new();
    for _ in 0..polls {
        if let ati_can::Outcome::Sample(_) = driver.step().unwrap() {
            out.push(driver.last_sample().unwrap().wrench.to_array());
        }
    }
    (polls, out)
}

/// Whether `printed` (rounded as printed) is `exact`.
fn same_as_printed(printed: &[f64; 6], exact: &[f64; 6]) -> bool {
    printed
        .iter()
        .zip(exact)
        .enumerate()
        .all(|(i, (p, e))| (p - e).abs() <= if i < 3 { 0.0005 } else { 0.00005 } + 1e-9)
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn a_field_trace_replays_into_the_simulated_node_and_through_can_utils() {
    let can = iface();
    let dir = tempfile::tempdir().unwrap();
    let field = dir.path().join("field.log");
    let field_s = field.to_str().unwrap();
    let base = "0x32";
    let turnaround = (20_000 * time_scale()).to_string();
    let rate = (20.0 / f64::from(time_scale())).to_string();
    let common = [
        "sensor",
        "ati",
        "--can",
        &can,
        "--base",
        base,
        "--turnaround-us",
        &turnaround,
    ];

    // The field: a noisy sensor (every reading differs), read with the CAN traffic logged.
    let (field_text, (polls, recorded)) = {
        let _node = Kill(
            forcecell()
                .args(["sim-sensor", "ati", "--can", &can, "--base", base])
                .args(["--fz", "12.5", "--noise", "400", "--seconds", "120"])
                .stdout(Stdio::null())
                .spawn()
                .expect("start sim-sensor"),
        );
        let mut ready = false;
        for _ in 0..20 {
            if run(&[&common[..], &["info"]].concat()).0.status.success() {
                ready = true;
                break;
            }
        }
        assert!(ready, "the simulated node never answered");
        let (out, text) = run(&[
            &common[..],
            &[
                "--can-log",
                field_s,
                "read",
                "--count",
                "8",
                "--rate",
                &rate,
            ],
        ]
        .concat());
        assert!(out.status.success(), "{text}");
        (
            text,
            readings_in_log(&field, ati_can::Base::new(0x32).unwrap()),
        )
    };
    let printed = printed_readings(&field_text);
    assert_eq!(printed.len(), 8, "{field_text}");
    let distinct: std::collections::BTreeSet<String> =
        recorded.iter().map(|w| format!("{:.3}", w[2])).collect();
    assert!(
        distinct.len() >= 5,
        "noise makes readings differ: {distinct:?}"
    );
    // What the field run printed is what its log holds.
    assert!(
        printed
            .iter()
            .all(|p| recorded.iter().any(|r| same_as_printed(p, r))),
        "{field_text}\n{recorded:?}"
    );

    // The replay: the same command against `sim-sensor ati --replay` prints readings from the log,
    // in the log's order.
    {
        let mut node = Kill(
            forcecell()
                .args(["sim-sensor", "ati", "--can", &can, "--base", base])
                .args(["--replay", field_s, "--seconds", "120"])
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("start sim-sensor --replay"),
        );
        let (banner, _rest) = read_until(&mut node.0, "recorded polls");
        assert!(
            banner.contains(&format!("{polls} recorded polls")),
            "{banner}"
        );
        let (out, text) = run(&[&common[..], &["read", "--count", "3", "--rate", &rate]].concat());
        assert!(out.status.success(), "{text}");
        let again = printed_readings(&text);
        assert_eq!(again.len(), 3, "{text}");
        let mut from = 0;
        for p in &again {
            let i = recorded[from..]
                .iter()
                .position(|r| same_as_printed(p, r))
                .unwrap_or_else(|| {
                    panic!("{p:?} is not a recorded reading after #{from}:\n{text}\n{recorded:?}")
                });
            from += i;
        }
    }

    // can-utils: canplayer puts the log back on the bus, candump -L records it: the same frames.
    let dumped = dir.path().join("dumped.log");
    let mut dump = Kill(
        std::process::Command::new("candump")
            .args(["-L", &can])
            .stdout(std::fs::File::create(&dumped).unwrap())
            .spawn()
            .expect("start candump (apt-get install can-utils)"),
    );
    // candump needs a moment to bind: probe with a frame outside the sensor's ids until it shows.
    let mut probe = ati_can::SocketCanTransport::open(&can).unwrap();
    let marker = ati_can::Frame::standard(0x7FF, &[0xAB]).unwrap();
    let mut bound = false;
    for _ in 0..100 {
        ati_can::CanTransport::send(&mut probe, &marker).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(100));
        if std::fs::read_to_string(&dumped).unwrap().contains("7FF#AB") {
            bound = true;
            break;
        }
    }
    assert!(bound, "candump never saw the probe frame");
    let played = std::process::Command::new("canplayer")
        .arg("-I")
        .arg(&field)
        .status()
        .expect("run canplayer");
    assert!(played.success());
    let want: Vec<ati_can::Frame> = forcecell::candump::read_log(&field)
        .unwrap()
        .into_iter()
        .map(|(_, _, f)| f)
        .collect();
    let mut got = Vec::new();
    for _ in 0..100 {
        std::thread::sleep(std::time::Duration::from_millis(100));
        // candump may be mid-line: read again on the next pass.
        let Ok(lines) = forcecell::candump::read_log(&dumped) else {
            continue;
        };
        got = lines
            .into_iter()
            .map(|(_, _, f)| f)
            .filter(|f| f.id() != 0x7FF)
            .collect();
        if got.len() >= want.len() {
            break;
        }
    }
    let _ = dump.0.kill();
    assert_eq!(got, want, "canplayer → candump -L gives the logged frames");
}
