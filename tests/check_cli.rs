//! `forcecell check --config cell.toml` against a simulated FT 300 in another process: the shipped
//! example cell file (its addresses moved to loopback, its sensor to the simulated one) is ready,
//! and each broken cell file is not, with the problem and its fix named.

mod common;

use std::path::Path;

use common::{Kill, run};

/// A simulated FT 300 reporting `fz` N (the tool's weight, hanging still) at `dir/ft300`.
fn ft300(dir: &Path, fz: &str) -> Kill {
    common::ft300(&dir.join("ft300"), fz)
}

/// `examples/cell.toml` with its addresses on loopback (port `port`) and the simulated FT 300 at
/// `dir/ft300` as its sensor; `edit` changes it further.
fn cell(dir: &Path, port: u16, edit: impl Fn(String) -> String) -> std::path::PathBuf {
    let example =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cell.toml"))
            .unwrap();
    let mut out = String::new();
    for line in example.lines() {
        let key = line.split('=').next().unwrap_or("").trim();
        let line = match key {
            "listen" => format!("listen = \"127.0.0.1:{port}\""),
            "robot_ip" => "robot_ip = \"127.0.0.1\"".into(),
            "kind" if line.contains("\"ati\"") => format!(
                "kind = \"robotiq\"\nport = \"{}\"",
                dir.join("ft300").display()
            ),
            "can" | "base" | "bitrate" | "slot" | "poll_hz" | "tare" => continue,
            _ => line.to_string(),
        };
        out.push_str(&line);
        out.push('\n');
    }
    let path = dir.join("cell.toml");
    std::fs::write(&path, edit(out)).unwrap();
    path
}

/// A broken cell file: what is wrong, how the example is edited into it, what `check` must say.
type Case = (&'static str, Box<dyn Fn(String) -> String>, &'static str);

fn check(path: &Path) -> (Option<i32>, String) {
    let (out, text) = run(&["check", "--config", path.to_str().unwrap()]);
    (out.status.code(), text)
}

#[test]
fn the_example_cell_is_ready_against_the_simulated_peers() {
    let dir = tempfile::tempdir().unwrap();
    let _sensor = ft300(dir.path(), "19.613"); // 2.0 kg, the example's tool
    let path = cell(dir.path(), 49311, |s| s);
    let (code, text) = check(&path);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.trim_end().ends_with("ready"), "{text}");
    assert!(!text.contains("FAIL"), "{text}");
    for line in [
        "ok    listen 127.0.0.1:49311 is this PC's address",
        "ok    robot 127.0.0.1 is on loopback",
        "ok    the Ethernet config",
        "answers: ",
        "the tool weighs 19.6",
    ] {
        assert!(text.contains(line), "{line:?} in\n{text}");
    }
    assert!(
        text.contains("real-time settings granted") || text.contains("warn  SCHED_FIFO"),
        "{text}"
    );
}

#[test]
fn each_broken_cell_file_is_not_ready_and_names_its_problem() {
    let dir = tempfile::tempdir().unwrap();
    let _sensor = ft300(dir.path(), "19.613");
    let robot = dir.path().join("robot");
    let (out, text) = run(&[
        "rsi-config",
        "--ip",
        "127.0.0.1",
        "--port",
        "49312",
        "--robot-ip",
        "127.0.0.2",
        "--poscorr-mm",
        "5",
        "--poscorrmon-mm",
        "6",
        "--out",
        robot.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{text}");
    let xml = robot.join("forcecell_rsi.xml");
    let cases: Vec<Case> = vec![
        (
            "a listen address that is not this PC's",
            Box::new(|s| s.replace("127.0.0.1:49312", "192.0.2.1:49312")),
            "FAIL  listen 192.0.2.1:49312",
        ),
        (
            "no sensor on the port",
            Box::new(|s| s.replace("/ft300\"", "/no-such-ft300\"")),
            "FAIL  Robotiq FT 300 on",
        ),
        (
            "a tool model for another tool",
            Box::new(|s| s.replace("signed_mass = 2.0", "signed_mass = 3.0")),
            "the [gravity] model says 29.42 N",
        ),
        (
            "POSCORRMON inside POSCORR",
            Box::new(|s| s.replace("poscorrmon_mm = 6.0", "poscorrmon_mm = 4.0")),
            "FAIL  POSCORRMON 4.0 mm is below POSCORR 5.0 mm",
        ),
        (
            "an unknown tuning",
            Box::new(|s| s.replace("tuning = \"robust\"", "tuning = \"no-such-tuning\"")),
            "FAIL  tuning no-such-tuning",
        ),
        (
            "a robot whose POSCORR is not the cell file's",
            Box::new({
                let xml = xml.clone();
                move |s| {
                    s.replace("poscorr_mm = 5.0", "poscorr_mm = 4.0").replace(
                        "[robot]\n",
                        &format!("[robot]\nethernet_config = \"{}\"\n", xml.display()),
                    )
                }
            }),
            "POSCORR is 5.0 mm, robot.poscorr_mm says 4.0 mm",
        ),
    ];
    for (what, edit, want) in cases {
        let path = cell(dir.path(), 49312, edit);
        let (code, text) = check(&path);
        assert_eq!(code, Some(1), "{what}: {text}");
        assert!(text.contains(want), "{what}: {want:?} in\n{text}");
        assert!(text.contains("fix: "), "{what}: {text}");
        assert!(text.contains("not ready: "), "{what}: {text}");
    }
    // A file that is not a cell file at all is an error (2), as for `run`.
    std::fs::write(dir.path().join("bad.toml"), "tuning = 3\n").unwrap();
    let (code, text) = check(&dir.path().join("bad.toml"));
    assert_eq!(code, Some(2), "{text}");
    assert!(text.starts_with("error: "), "{text}");
}

/// `examples/egm-cell.toml` on loopback (port `port`), the simulated FT 300 at `dir/ft300` as its
/// sensor and, when given, `settings` (what `forcecell egm-config` wrote) as its `egm_settings`.
fn egm_cell(
    dir: &Path,
    port: u16,
    settings: Option<&Path>,
    edit: impl Fn(String) -> String,
) -> std::path::PathBuf {
    let example = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/egm-cell.toml"),
    )
    .unwrap();
    let mut out = String::new();
    for line in example.lines() {
        let key = line.split('=').next().unwrap_or("").trim();
        let line = match key {
            "listen" => format!("listen = \"127.0.0.1:{port}\""),
            "robot_ip" => "robot_ip = \"127.0.0.1\"".into(),
            "port" => format!("port = \"{}\"", dir.join("ft300").display()),
            "# egm_settings" => match settings {
                Some(p) => format!("egm_settings = \"{}\"", p.display()),
                None => continue,
            },
            _ => line.to_string(),
        };
        out.push_str(&line);
        out.push('\n');
    }
    let path = dir.join("egm-cell.toml");
    std::fs::write(&path, edit(out)).unwrap();
    path
}

/// `forcecell egm-config` for loopback port `port` into `dir/robot`, with `extra` options; the
/// settings file it wrote.
fn egm_config(dir: &Path, port: u16, extra: &[&str]) -> std::path::PathBuf {
    let robot = dir.join("robot");
    let port = port.to_string();
    let mut args = vec![
        "egm-config",
        "--host",
        "127.0.0.1",
        "--port",
        &port,
        "--force",
        "--out",
        robot.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let (out, text) = run(&args);
    assert!(out.status.success(), "{text}");
    robot.join("FcEgm-settings.txt")
}

#[test]
fn the_example_egm_cell_is_ready_with_the_settings_egm_config_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let _sensor = ft300(dir.path(), "0.0");
    let settings = egm_config(dir.path(), 49321, &[]);
    let path = egm_cell(dir.path(), 49321, Some(&settings), |s| s);
    let (code, text) = check(&path);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.trim_end().ends_with("ready"), "{text}");
    assert!(!text.contains("FAIL"), "{text}");
    for line in [
        "ok    listen 127.0.0.1:49321 is this PC's address",
        "ok    robot 127.0.0.1 is on loopback",
        "warn  the tuning's envelope ±50.0 mm is cut to ±4.5 mm by the path-correction range 5.0 mm",
        "the UDPUC entry sends to port 49321 and the path-correction range is 5.0 mm",
        "Robotiq FT 300 on",
        "zeroed at start",
    ] {
        assert!(text.contains(line), "{line:?} in\n{text}");
    }
    // Without the settings the cell still runs, but what the robot was given is not checked.
    let path = egm_cell(dir.path(), 49321, None, |s| s);
    let (code, text) = check(&path);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("warn  no robot.egm_settings"), "{text}");
}

#[test]
fn each_broken_egm_cell_is_not_ready_and_names_its_problem() {
    let dir = tempfile::tempdir().unwrap();
    let _sensor = ft300(dir.path(), "0.0");
    let other_port = egm_config(dir.path(), 49323, &[]);
    let moved = dir.path().join("other-port-settings.txt");
    std::fs::rename(&other_port, &moved).unwrap();
    let settings = egm_config(dir.path(), 49322, &["--correction-mm", "4.0"]);
    type EgmCase = (
        &'static str,
        Option<std::path::PathBuf>,
        Box<dyn Fn(String) -> String>,
        &'static str,
    );
    let cases: Vec<EgmCase> = vec![
        (
            "a UDPUC entry that sends to another port",
            Some(moved.clone()),
            Box::new(|s| s.replace("correction_mm = 5.0", "correction_mm = 4.0")),
            "the UDPUC entry sends to port 49323, robot.listen is 127.0.0.1:49322",
        ),
        (
            "a correction range that is not the robot's",
            Some(settings.clone()),
            Box::new(|s| s),
            "the path-correction range is 4 mm, robot.correction_mm says 5 mm",
        ),
        (
            "a listen address that is not this PC's",
            Some(settings.clone()),
            Box::new(|s| {
                s.replace("127.0.0.1:49322", "192.0.2.1:49322")
                    .replace("correction_mm = 5.0", "correction_mm = 4.0")
            }),
            "FAIL  listen 192.0.2.1:49322",
        ),
    ];
    for (what, settings, edit, want) in cases {
        let path = egm_cell(dir.path(), 49322, settings.as_deref(), edit);
        let (code, text) = check(&path);
        assert!(text.contains(want), "{what}: {want:?} in\n{text}");
        assert!(text.contains("fix: "), "{what}: {text}");
        assert_eq!(code, Some(1), "{what}: {text}");
        assert!(text.contains("not ready: "), "{what}: {text}");
    }
    // An option of the other robot kind is refused as a file error, in one line.
    let path = egm_cell(dir.path(), 49322, None, |s| {
        s.replace("[robot]\n", "[robot]\nposcorr_mm = 5.0\n")
    });
    let (code, text) = check(&path);
    assert_eq!(code, Some(2), "{text}");
    assert!(
        text.contains(
            "robot.poscorr_mm is a kuka-rsi option, and this [robot] is kind = \"abb-egm\""
        ),
        "{text}"
    );
    assert_eq!(text.trim_end().lines().count(), 1, "{text}");
    // The process command over EGM with nowhere to send the state back: refused before anything.
    let path = egm_cell(dir.path(), 49322, None, |s| {
        s.replace("process = false", "process = true")
    });
    let (code, text) = check(&path);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("needs robot.rws"), "{text}");
}

/// With the process contract over EGM, `check` reads `fc_phase` from the controller's Robot Web
/// Services (the simulated one here, HTTPS on loopback) and writes nothing: ready with the pinned
/// certificate, a warning naming the certificate without a pin, not ready with a wrong pin or password.
#[test]
fn check_reads_the_controllers_robot_web_services_with_the_pinned_certificate() {
    let dir = tempfile::tempdir().unwrap();
    let _sensor = ft300(dir.path(), "0.0");
    let vars = sim::irc5::RapidVariables::default();
    let server =
        sim::rws::RwsServer::start(sim::rws::RwsServerConfig::default(), vars.clone()).unwrap();
    let url = server.url();
    let pin = abb_egm::rws::fingerprint_text(&server.fingerprint());
    let with = |extra: String| {
        let url = url.clone();
        move |s: String| {
            s.replace(
                "process = false",
                &format!("process = true\nrws = \"{url}\"\n{extra}"),
            )
        }
    };
    let path = egm_cell(
        dir.path(),
        49331,
        None,
        with(format!("rws_fingerprint = \"{pin}\"")),
    );
    let (code, text) = check(&path);
    assert_eq!(code, Some(0), "{text}");
    assert!(
        text.contains(&format!(
            "ok    Robot Web Services at {url}: FcEgm/fc_phase readable, the pinned certificate presented"
        )),
        "{text}"
    );
    let path = egm_cell(dir.path(), 49331, None, with(String::new()));
    let (code, text) = check(&path);
    assert_eq!(code, Some(0), "{text}");
    assert!(
        text.contains(&format!("its certificate is not pinned (SHA-256 {pin})")),
        "{text}"
    );
    for (extra, want) in [
        (
            format!("rws_fingerprint = \"{}\"", "00:".repeat(31) + "00"),
            "is not the pinned one",
        ),
        (
            format!("rws_fingerprint = \"{pin}\"\nrws_password = \"nope\""),
            "401",
        ),
        (
            format!("rws_fingerprint = \"{pin}\"\nrws_module = \"Other\""),
            "404",
        ),
    ] {
        let path = egm_cell(dir.path(), 49331, None, with(extra.clone()));
        let (code, text) = check(&path);
        assert_eq!(code, Some(1), "{extra}: {text}");
        assert!(text.contains(want), "{extra}: {want} in\n{text}");
    }
    assert_eq!(vars.read(), None, "check writes nothing");
}
