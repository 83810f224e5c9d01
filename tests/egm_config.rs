//! `forcecell egm-config` as a user runs it: the files it writes for the ABB controller, their
//! structure, the port the robot is told to send to (the one forcecell's EGM link binds), and a
//! user's existing files left untouched.

use std::net::{Ipv4Addr, SocketAddr, UdpSocket};
use std::path::Path;
use std::process::{Command, Output};

fn forcecell(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .arg("egm-config")
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run forcecell")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The number after `-RemotePortNumber` in the settings' UDPUC entry.
fn remote_port(settings: &str) -> u16 {
    let mut words = settings.split_whitespace();
    words
        .find(|w| *w == "-RemotePortNumber")
        .expect("UDPUC port");
    words.next().unwrap().parse().unwrap()
}

#[test]
fn writes_the_module_and_settings_with_the_port_the_link_binds() {
    let dir = tempfile::tempdir().unwrap();
    // A port free right now on loopback, given to egm-config as forcecell's EGM port.
    let port = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let o = forcecell(
        &[
            "--host",
            "192.168.125.7",
            "--port",
            &port.to_string(),
            "--tool",
            "tPad",
            "--correction-mm",
            "7.5",
            "--out",
            "egm",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let module = std::fs::read_to_string(dir.path().join("egm/FcEgm.mod")).unwrap();
    let settings = std::fs::read_to_string(dir.path().join("egm/FcEgm-settings.txt")).unwrap();
    assert!(settings.contains("-Type \"UDPUC\" -RemoteAddress \"192.168.125.7\""));
    assert!(
        module
            .contains("EGMActMove fc_egm_id, tPad.tframe \\SampleRate:=4 \\DataToSensor:=fc_cmd;")
    );
    // The correction range given is the one a cell file's robot.correction_mm is checked against.
    assert_eq!(
        abb_egm::rapid::SettingsFacts::parse(&settings).correction_mm,
        Some(7.5)
    );
    assert!(module.contains(&format!("192.168.125.7:{port}")));
    // The robot is told to send where forcecell's EGM link listens: the link binds that port.
    let told = remote_port(&settings);
    assert_eq!(told, port);
    let cfg = abb_egm::LinkConfig::new(
        SocketAddr::from((Ipv4Addr::LOCALHOST, told)),
        abb_egm::RobotFilter::Any,
    );
    let link = abb_egm::EgmLink::bind(cfg).expect("bind the told port");
    assert_eq!(link.local_addr().unwrap().port(), port);
    // Nothing else is left in the directory (no temporary files).
    let names: Vec<_> = std::fs::read_dir(dir.path().join("egm"))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
}

#[test]
fn the_default_port_is_the_links_default() {
    let dir = tempfile::tempdir().unwrap();
    let o = forcecell(&["--host", "10.0.0.2", "--out", "."], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let settings = std::fs::read_to_string(dir.path().join("FcEgm-settings.txt")).unwrap();
    assert_eq!(remote_port(&settings), abb_egm::rapid::DEFAULT_PORT);
}

#[test]
fn existing_files_are_refused_untouched_unless_force() {
    let dir = tempfile::tempdir().unwrap();
    let mine = dir.path().join("FcEgm.mod");
    std::fs::write(&mine, "MODULE Mine\nENDMODULE\n").unwrap();
    let o = forcecell(&["--host", "10.0.0.2", "--out", "."], dir.path());
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("already exist") && err.contains("--force"),
        "{err}"
    );
    assert!(!err.contains("panicked"));
    assert_eq!(
        std::fs::read_to_string(&mine).unwrap(),
        "MODULE Mine\nENDMODULE\n"
    );
    // Neither file was written: the settings file that did not exist is not there either.
    assert!(!dir.path().join("FcEgm-settings.txt").exists());
    let o = forcecell(&["--host", "10.0.0.2", "--out", ".", "--force"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::read_to_string(&mine)
            .unwrap()
            .starts_with("MODULE FcEgm")
    );
}

#[test]
fn bad_names_are_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    for (args, needle) in [
        (vec!["--host", "10.0.0.2", "--tool", "my tool"], "tool name"),
        (
            vec!["--host", "10.0.0.2", "--module", "9lives"],
            "module name",
        ),
        (vec!["--host", "0.0.0.0"], "host"),
        (vec!["--host", "10.0.0.2", "--port", "0"], "port 0"),
        (vec!["--host", "10.0.0.2", "--max-wait", "inf"], "max wait"),
    ] {
        let mut a = args.clone();
        a.extend(["--out", "out"]);
        let o = forcecell(&a, dir.path());
        assert!(!o.status.success(), "{args:?}");
        let err = stderr(&o);
        assert!(
            err.contains(needle) && !err.contains("panicked"),
            "{args:?}: {err}"
        );
        assert!(!dir.path().join("out").exists(), "{args:?} wrote something");
    }
}
