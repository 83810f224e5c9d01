//! The EGM dry run end to end over real UDP on loopback, in two processes: `forcecell sim
//! --external-robot ADDR --robot egm` plays the simulated IRC5 (its RAPID program the programmed pass
//! `pass-flat-20n` on the 4 ms plant P2), the virtual workpiece and a simulated FT 300 that measures it; `forcecell run`
//! with a `kind = "abb-egm"` cell file is the EGM client that presses. The force is held at the
//! program's 20 N, the process goes APPROACH → RAMP → PRESSING → RELEASE → OFF, and the run ends cleanly when the robot ends
//! its session, with its recording.

mod common;

use common::{finish, free_port, read_until, spawn};

/// Column `name` of a CSV header line.
fn column(header: &str, name: &str) -> usize {
    header
        .split(',')
        .position(|c| c == name)
        .unwrap_or_else(|| panic!("no column {name:?} in {header}"))
}

#[test]
fn run_with_an_egm_cell_holds_the_programmed_force_against_the_dry_run() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_port();
    let listen = format!("127.0.0.1:{port}");
    let mut robot = spawn(
        &[
            "sim",
            "--external-robot",
            &listen,
            "--robot",
            "egm",
            "--scenario",
            "pass-flat-20n",
            "--plant",
            "p2",
            "--sensor-link",
            "ft300",
        ],
        dir.path(),
    );
    let (robot_seen, robot_out) = read_until(&mut robot, "rws_fingerprint = \"");
    let quoted = |key: &str| {
        robot_seen
            .split(&format!("{key} = \""))
            .nth(1)
            .and_then(|r| r.split('"').next())
            .unwrap_or_else(|| panic!("no {key} in {robot_seen}"))
            .to_string()
    };
    let (rws, fingerprint) = (quoted("robot.rws"), quoted("rws_fingerprint"));
    assert!(rws.starts_with("https://127.0.0.1:"), "{rws}");
    let cell = format!(
        r#"tuning = "robust-100hz"
record = "rec"

[robot]
kind = "abb-egm"
listen = "{listen}"
robot_ip = "127.0.0.1"
correction_mm = 10.0
process = true
rws = "{rws}"
rws_fingerprint = "{fingerprint}"

[sensor]
kind = "robotiq"
port = "ft300"

[removal]
preston = 1e-12
pad = "uniform"
pad_radius = 0.01
tool = "disc"
rpm = 3000.0
effective_radius = 0.02
"#
    );
    std::fs::write(dir.path().join("egm-cell.toml"), cell).unwrap();
    let mut client = spawn(&["run", "--config", "egm-cell.toml"], dir.path());
    let (seen, r) = read_until(&mut client, "listening on");
    assert!(seen.contains("abb-egm"), "{seen}");
    let (code, text) = finish(client, seen, r);
    let (robot_code, robot_text) = finish(robot, robot_seen, robot_out);
    assert_eq!(robot_code, 0, "{robot_text}\n--- run:\n{text}");
    assert_eq!(code, 0, "{text}\n--- sim:\n{robot_text}");
    // The robot ran its course, its program to the end, and the client said how the session ended.
    assert!(robot_text.contains("ended Completed"), "{robot_text}");
    assert!(!robot_text.contains("aborted"), "{robot_text}");
    assert!(
        text.contains("the robot ended EGM: the process was off"),
        "{text}"
    );
    assert!(text.contains("Stop "), "{text}");
    assert!(text.contains("EGM link: "), "{text}");
    // The process state went back over Robot Web Services (HTTPS, the pinned certificate): every
    // state written, none failed; the controller counted the variables.
    let rws_line = text
        .lines()
        .find(|l| l.contains("RWS: "))
        .unwrap_or_else(|| panic!("an RWS line in {text}"));
    assert!(rws_line.contains(" 0 failures"), "{rws_line}");
    let states: u64 = rws_line
        .split("RWS: ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap();
    // APPROACH, RAMP, PRESSING, RELEASE, OFF at least (force changes are written too).
    assert!(states >= 5, "{rws_line}");
    assert!(
        robot_text.contains(&format!(
            "process variables written over RWS: {}",
            3 * states
        )),
        "{robot_text}\n{rws_line}"
    );

    // The recording: MCAP, CSV, PNG and the summary beside it.
    let names: Vec<String> = std::fs::read_dir(dir.path().join("rec"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let csv = names
        .iter()
        .find(|n| n.ends_with(".csv"))
        .unwrap_or_else(|| panic!("a CSV: {names:?}"));
    let stem = csv.trim_end_matches(".csv");
    for ext in ["mcap", "png", "json"] {
        assert!(names.contains(&format!("{stem}.{ext}")), "{names:?}");
    }
    // The cell file describes the pad: `run` maps what the pass removed, beside the recording.
    for name in [
        format!("{stem}-removal.png"),
        format!("{stem}-removal.mcap"),
    ] {
        assert!(names.contains(&name), "{name} in {names:?}\n{text}");
    }
    assert!(text.contains("mean removal"), "{text}");
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("rec").join(format!("{stem}.json"))).unwrap(),
    )
    .unwrap();
    assert!(
        summary["robot"]
            .as_str()
            .unwrap()
            .contains("ABB EGM path correction"),
        "{summary}"
    );

    // The force while the program's pass is PRESSING (phase 3): held at 20 N.
    let trace = std::fs::read_to_string(dir.path().join("rec").join(csv)).unwrap();
    let mut lines = trace.lines();
    let header = lines.next().unwrap();
    let (t_col, f_col, phase_col) = (
        column(header, "t"),
        column(header, "f"),
        column(header, "phase"),
    );
    let mut pressing: Vec<(f64, f64)> = Vec::new();
    let mut phases: Vec<u8> = Vec::new();
    for l in lines {
        let v: Vec<&str> = l.split(',').collect();
        let phase: u8 = match v[phase_col].parse::<f64>() {
            Ok(p) => p as u8,
            Err(_) => continue,
        };
        if phases.last() != Some(&phase) {
            phases.push(phase);
        }
        if phase == 3 {
            let t: f64 = v[t_col].parse().unwrap();
            let f: f64 = v[f_col].parse().unwrap_or(f64::NAN);
            pressing.push((t, f));
        }
    }
    // APPROACH, RAMP, PRESSING, RELEASE, OFF: the program's PRESS from its first cycle, then RELEASE.
    assert_eq!(phases, [1, 2, 3, 4, 0], "phases");
    let span = pressing.last().unwrap().0 - pressing.first().unwrap().0;
    // 100 mm at 50 mm/s: two seconds of pressing.
    assert!(span >= 1.5, "pressing for {span} s");
    let forces: Vec<f64> = pressing
        .iter()
        .map(|p| p.1)
        .filter(|f| f.is_finite())
        .collect();
    let mean = forces.iter().sum::<f64>() / forces.len() as f64;
    let within = forces.iter().filter(|f| (**f - 20.0).abs() <= 2.0).count();
    assert!((mean - 20.0).abs() <= 1.0, "mean pressing force {mean} N");
    assert!(
        within as f64 >= 0.9 * forces.len() as f64,
        "{within} of {} pressing cycles within 20 ± 2 N",
        forces.len()
    );
}
