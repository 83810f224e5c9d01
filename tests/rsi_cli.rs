//! `forcecell sim` over RSI and `forcecell rsi-config`, as a user runs them (loopback only).

use std::net::{SocketAddr, UdpSocket};
use std::path::Path;
use std::process::{Command, Output};
use std::sync::atomic::Ordering;
use std::time::Duration;

use hal::{Pose, UnitQuaternion, Vector3};
use kuka_rsi::{EthernetConfig, PoscorrLimits};
use sim::krc::{Krc, KrcConfig, RigidArm, Timing};

fn forcecell(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run forcecell")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn rsi_config_writes_matching_robot_files() {
    let dir = tempfile::tempdir().unwrap();
    let o = forcecell(
        &[
            "rsi-config",
            "--ip",
            "10.0.0.5",
            "--robot-ip",
            "10.0.0.6",
            "--poscorr-mm",
            "5",
            "--poscorrmon-mm",
            "6",
            "--port",
            "6008",
            "--out",
            "robot",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let xml = std::fs::read_to_string(dir.path().join("robot/forcecell_rsi.xml")).unwrap();
    let cfg = EthernetConfig::parse(&xml).unwrap();
    assert_eq!(
        cfg,
        EthernetConfig::forcecell([10, 0, 0, 5].into(), 6008, false)
            .with_process(kuka_rsi::ProcessChannels::default()),
        "the process channels are on by default"
    );
    let krl = std::fs::read_to_string(dir.path().join("robot/forcecell_rsi.src")).unwrap();
    assert!(krl.contains("RSI_ON(#ABSOLUTE, #IPO_FAST)"), "{krl}");
    assert!(krl.contains("ConfigFile=forcecell_rsi.xml"), "{krl}");
    assert!(krl.contains("+-5.000 mm"), "{krl}");

    let o = forcecell(
        &[
            "rsi-config",
            "--ip",
            "10.0.0.5",
            "--robot-ip",
            "10.0.0.6",
            "--mode",
            "relative",
            "--ipo12",
            "--tuning",
            "paper",
            "--name",
            "cell3",
            "--out",
            "r2",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let cfg =
        EthernetConfig::parse(&std::fs::read_to_string(dir.path().join("r2/cell3.xml")).unwrap())
            .unwrap();
    assert!(
        cfg.receive
            .iter()
            .filter(|e| e.tag.starts_with("RKorr"))
            .all(|e| e.holdon == Some(false)),
        "relative mode never re-applies an increment"
    );
    let krl = std::fs::read_to_string(dir.path().join("r2/cell3.src")).unwrap();
    assert!(krl.contains("RSI_ON(#RELATIVE, #IPO)"), "{krl}");
    assert!(
        krl.contains("+-55.000 mm"),
        "POSCORR from the tuning: {krl}"
    );

    let o = forcecell(&["rsi-config", "--name", "bad name"], dir.path());
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("KRL names"), "{}", text(&o.stderr));
}

/// The element with `TAG="tag"` of a plain-XML-parsed config: its INDX.
fn indx_of(doc: &roxmltree::Document<'_>, tag: &str) -> String {
    doc.descendants()
        .find(|n| n.has_tag_name("ELEMENT") && n.attribute("TAG") == Some(tag))
        .and_then(|n| n.attribute("INDX"))
        .unwrap_or_else(|| panic!("no ELEMENT {tag}"))
        .to_owned()
}

#[test]
fn rsi_config_writes_the_process_channels_and_a_polishing_template() {
    let dir = tempfile::tempdir().unwrap();
    let o = forcecell(
        &[
            "rsi-config",
            "--ip",
            "192.168.1.100",
            "--robot-ip",
            "192.168.1.10",
            "--poscorr-mm",
            "5",
            "--poscorrmon-mm",
            "6",
            "--out",
            "robot",
            "--pint-mode",
            "11",
            "--pint-seg",
            "12",
            "--pint-state",
            "13",
            "--pint-fault",
            "14",
            "--prea-force",
            "5",
            "--prea-ramp",
            "6",
            "--prea-measured",
            "7",
            "--segments",
            "15:40,25:80",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    assert!(out.contains("$SEN_PINT[11]  -> FcCmd.Mode"), "{out}");
    assert!(out.contains("$SEN_PREA[7]   <- FcState.F"), "{out}");
    assert!(out.contains("UNVERIFIED"), "{out}");

    let xml = std::fs::read_to_string(dir.path().join("robot/forcecell_rsi.xml")).unwrap();
    // The project's own parser...
    let cfg = EthernetConfig::parse(&xml).unwrap();
    assert!(cfg.has_process_command());
    // ... and a plain XML parser that knows nothing of RSI.
    let doc = roxmltree::Document::parse(&xml).expect("well-formed XML");
    assert_eq!(doc.root_element().tag_name().name(), "ROOT");
    for (tag, indx) in [
        ("FcCmd.Mode", "1"),
        ("FcCmd.F", "2"),
        ("FcCmd.Ramp", "3"),
        ("FcCmd.Seg", "4"),
        ("FcState.State", "8"),
        ("FcState.F", "9"),
        ("FcState.Fault", "10"),
    ] {
        assert_eq!(indx_of(&doc, tag), indx, "{tag}");
    }
    let comment: String = doc
        .root()
        .children()
        .filter(|n| n.is_comment())
        .filter_map(|n| n.text())
        .collect();
    assert!(comment.contains("UNVERIFIED"), "{comment}");

    let krl = std::fs::read_to_string(dir.path().join("robot/forcecell_rsi.src")).unwrap();
    for (var, tag) in [
        ("$SEN_PINT[11]", "FcCmd.Mode"),
        ("$SEN_PINT[12]", "FcCmd.Seg"),
        ("$SEN_PINT[13]", "FcState.State"),
        ("$SEN_PINT[14]", "FcState.Fault"),
        ("$SEN_PREA[5]", "FcCmd.F"),
        ("$SEN_PREA[6]", "FcCmd.Ramp"),
        ("$SEN_PREA[7]", "FcState.F"),
    ] {
        // Listed in both headers with the same element...
        let line = |t: &str| t.lines().any(|l| l.contains(var) && l.contains(tag));
        assert!(line(&xml), "XML header lacks {var} {tag}");
        assert!(line(&krl), "KRL header lacks {var} {tag}");
    }
    // ... and used by the program.
    assert!(krl.contains("RSI_ON(#ABSOLUTE, #IPO_FAST)"), "{krl}");
    assert!(
        krl.contains("$SEN_PREA[5] = 15.000\n  $SEN_PINT[12] = 1\n  $SEN_PINT[11] = 1"),
        "{krl}"
    );
    assert!(krl.contains("WAIT FOR ($SEN_PINT[13] == 3)"), "{krl}");
    assert!(krl.contains("DO $SEN_PREA[5] = 25.000"), "{krl}");
    assert!(krl.contains("DO $SEN_PINT[12] = 2"), "{krl}");
    assert!(krl.contains("LIN_REL {X 80.0}"), "{krl}");
    assert!(krl.contains("WAIT FOR ($SEN_PINT[13] == 0)"), "{krl}");
    assert!(
        krl.contains("RETURN"),
        "the PRESSING timeout ends the program: {krl}"
    );
    let off = krl.rfind("RSI_OFF()").unwrap();
    let release = krl.rfind("$SEN_PINT[11] = 2").unwrap();
    assert!(release < off, "RELEASE before RSI_OFF");

    // A FAULT mid-path: an interrupt on State 9 around the path, which runs in its own level so that
    // the fault routine's RESUME returns to the main program; there the tool is lifted clear before
    // OFF brings the correction back to zero, then RSI is switched off and the program ends.
    let at = |needle: &str| {
        krl.find(needle)
            .unwrap_or_else(|| panic!("no {needle:?} in {krl}"))
    };
    let decl = at("INTERRUPT DECL 21 WHEN $SEN_PINT[13] == 9 DO FC_FAULT()");
    let on = at("INTERRUPT ON 21");
    let call = at("  FC_PATH()\n");
    let off_irq = at("  INTERRUPT OFF 21\n  IF $FLAG[1] THEN");
    assert!(decl < on && on < call && call < off_irq, "{krl}");
    let branch = &krl[off_irq..];
    let branch = &branch[..branch.find("ENDIF").unwrap()];
    let lift = branch
        .find("LIN_REL {Z 50.0}")
        .expect("lift clear on a fault");
    let re_arm = branch.find("$SEN_PINT[11] = 0").expect("OFF re-arms");
    let rsi_off = branch.find("RSI_OFF()").expect("RSI off on a fault");
    assert!(
        lift < re_arm && re_arm < rsi_off && branch.contains("RETURN"),
        "{branch}"
    );
    let body = |name: &str| {
        let from = at(&format!("DEF {name}()"));
        let len = krl[from..].find("\nEND").unwrap();
        krl[from..from + len].to_string()
    };
    let path = body("FC_PATH");
    assert_eq!(path.matches("LIN_REL {X").count(), 2, "{path}");
    assert!(
        !krl[..at("DEF FC_PATH()")].contains("LIN_REL {X"),
        "the path only in FC_PATH"
    );
    assert!(
        path.trim_end().ends_with(
            "WAIT SEC 0 ; advance-run stop: a RESUME must find the advance run in this level"
        ),
        "{path}"
    );
    let fault = body("FC_FAULT");
    let (brake, flag, resume) = (
        fault.find("BRAKE").unwrap(),
        fault.find("$FLAG[1] = TRUE").unwrap(),
        fault.find("RESUME").unwrap(),
    );
    assert!(brake < flag && flag < resume, "{fault}");
    // Three programs, each closed; every IF closed.
    let lines: Vec<&str> = krl.lines().map(str::trim).collect();
    let count = |p: &dyn Fn(&str) -> bool| lines.iter().filter(|l| p(l)).count();
    assert_eq!(count(&|l| l.starts_with("DEF ")), 3);
    assert_eq!(count(&|l| l == "END"), 3);
    assert_eq!(
        count(&|l| l.starts_with("IF ")),
        count(&|l| l.starts_with("ENDIF"))
    );

    // Indices used twice, and bad segments, are refused with a reason.
    let o = forcecell(
        &[
            "rsi-config",
            "--pint-state",
            "1",
            "--ip",
            "192.168.1.100",
            "--robot-ip",
            "192.168.1.10",
            "--poscorr-mm",
            "5",
            "--poscorrmon-mm",
            "6",
        ],
        dir.path(),
    );
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("$SEN_PINT[1] is used for both"),
        "{}",
        text(&o.stderr)
    );
    let o = forcecell(
        &[
            "rsi-config",
            "--segments",
            "10:50,x",
            "--ip",
            "192.168.1.100",
            "--robot-ip",
            "192.168.1.10",
            "--poscorr-mm",
            "5",
            "--poscorrmon-mm",
            "6",
        ],
        dir.path(),
    );
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("--segments"),
        "{}",
        text(&o.stderr)
    );

    // Without the process channels: the config of before.
    let o = forcecell(
        &[
            "rsi-config",
            "--no-process",
            "--out",
            "plain",
            "--ip",
            "192.168.1.100",
            "--robot-ip",
            "192.168.1.10",
            "--poscorr-mm",
            "5",
            "--poscorrmon-mm",
            "6",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let xml = std::fs::read_to_string(dir.path().join("plain/forcecell_rsi.xml")).unwrap();
    assert_eq!(
        EthernetConfig::parse(&xml).unwrap(),
        EthernetConfig::forcecell([192, 168, 1, 100].into(), 49152, false)
    );
    roxmltree::Document::parse(&xml).unwrap();
    let krl = std::fs::read_to_string(dir.path().join("plain/forcecell_rsi.src")).unwrap();
    assert!(
        krl.contains("RSI_MOVECORR()") && !krl.contains("SEN_PINT"),
        "{krl}"
    );
}

fn rows(dir: &Path, file: &str) -> Vec<String> {
    std::fs::read_to_string(dir.join(file))
        .unwrap()
        .lines()
        .map(str::to_owned)
        .collect()
}

#[test]
fn sim_over_rsi_matches_the_in_process_robot() {
    let dir = tempfile::tempdir().unwrap();
    let o = forcecell(&["sim", "--out", "udp"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    assert!(
        out.contains("RSI link: 2001 received, 2001 answered"),
        "2000 steps and the Stop that ends the session: {out}"
    );
    assert!(out.contains("2001 good, 0 late"), "{out}");
    assert!(out.contains("ended Stopped"), "{out}");
    let o = forcecell(&["sim", "--robot", "inproc", "--out", "mem"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(!text(&o.stdout).contains("RSI link"));
    let udp = rows(dir.path(), "udp/paper-fig9.csv");
    let mem = rows(dir.path(), "mem/paper-fig9.csv");
    assert_eq!(udp.len(), mem.len());
    assert_eq!(udp[0], mem[0]);
    // The wire carries 0.1 µm; the force trajectories agree to within that times the stiffness.
    let col = |r: &str, i: usize| r.split(',').nth(i).unwrap().parse::<f64>().unwrap();
    let f = udp[0].split(',').position(|h| h == "f").unwrap();
    let worst = udp[1..]
        .iter()
        .zip(&mem[1..])
        .map(|(a, b)| (col(a, f) - col(b, f)).abs())
        .fold(0.0, f64::max);
    assert!(worst < 0.05, "force differs by up to {worst} N");

    let o = forcecell(&["sim", "--robot", "inproc", "--realtime"], dir.path());
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("--realtime needs"));
}

#[test]
fn sim_with_an_external_robot_client() {
    let dir = tempfile::tempdir().unwrap();
    let port = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let listen = format!("127.0.0.1:{port}");
    let child = Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .args(["sim", "--external-robot", &listen, "--out", "ext"])
        .current_dir(dir.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Any RSI client will do: here the simulated controller on a stiff arm.
    let target: SocketAddr = listen.parse().unwrap();
    let mut kc = KrcConfig::new(
        EthernetConfig::forcecell([127, 0, 0, 1].into(), port, false),
        target,
    );
    kc.timing = Timing::Lockstep {
        deadline: Duration::from_millis(200),
    };
    kc.timeout = 1_000_000;
    kc.poscorr = PoscorrLimits {
        translation: 0.055,
        ..PoscorrLimits::default()
    };
    kc.poscorrmon = PoscorrLimits {
        translation: 0.06,
        ..PoscorrLimits::MONITOR_DEFAULT
    };
    let mut krc = Krc::new(kc).unwrap();
    let abort = krc.abort_handle();
    let client = std::thread::spawn(move || {
        krc.run(&mut RigidArm::new(Pose {
            position: Vector3::new(0.5, 0.0, 0.3),
            orientation: UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0),
        }))
    });
    let o = child.wait_with_output().unwrap();
    abort.store(true, Ordering::Relaxed);
    let report = client.join().unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    assert!(out.contains("listening for an RSI client"), "{out}");
    assert!(out.contains("501 answered"), "500 steps, then Stop: {out}");
    assert!(report.good >= 500, "{report:?}");
    assert_eq!(
        report.end,
        sim::KrcEnd::Stopped,
        "the session ends with <Stop>1</Stop>, not silence: {report:?}"
    );
    // The client's reported pose drove the simulated sensor: contact was made and force controlled.
    // Without --tuning, an external robot runs the robust tuning.
    assert!(out.contains("tuning robust"), "{out}");
    let csv = rows(dir.path(), "ext/paper-fig9-p0-robust.csv");
    let f = csv[0].split(',').position(|h| h == "f").unwrap();
    let last: f64 = csv
        .last()
        .unwrap()
        .split(',')
        .nth(f)
        .unwrap()
        .parse()
        .unwrap();
    assert!((last - 5.0).abs() < 0.5, "final force {last} N");
    // The virtual workpiece sits where the scenario puts it relative to the pose the client reported
    // at the start of its session (correction zero, as a real robot after RSI_ON): the scenario starts
    // 0.9 mm short of the surface, so the whole run's corrections stay within a few millimetres —
    // inside RSI's default POSCORR of 5 mm — not the 10 mm of the scenario's absolute coordinates.
    let xc = csv[0].split(',').position(|h| h == "x_cmd").unwrap();
    let widest = csv[1..]
        .iter()
        .map(|r| r.split(',').nth(xc).unwrap().parse::<f64>().unwrap().abs())
        .fold(0.0, f64::max);
    assert!(widest < 0.003, "correction reached {widest} m");
}

/// A simulated cell starts with its tool away from the programmed path (the correction in effect). With a
/// tight per-cycle rate limit the first replies must neither drag the tool back towards the path nor
/// differ from the in-process robot.
#[test]
fn a_tight_rate_limit_does_not_drag_the_tool_back_at_start() {
    let dir = tempfile::tempdir().unwrap();
    let robust =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("tunings/robust.toml"))
            .unwrap();
    let tight: String = robust
        .lines()
        .map(|l| {
            if l.trim_start().starts_with("max_step") {
                "max_step = 0.0002".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert_ne!(tight, robust, "the tuning must set max_step");
    std::fs::write(dir.path().join("tight.toml"), tight).unwrap();
    let common = [
        "-s",
        "b01-approach",
        "--plant",
        "p2",
        "--tuning",
        "tight.toml",
    ];
    let rsi = forcecell(
        &[&["sim", "--out", "rsi"][..], &common[..]].concat(),
        dir.path(),
    );
    assert!(rsi.status.success(), "{}", text(&rsi.stderr));
    let inproc = forcecell(
        &[
            &["sim", "--out", "in", "--robot", "inproc"][..],
            &common[..],
        ]
        .concat(),
        dir.path(),
    );
    assert!(inproc.status.success(), "{}", text(&inproc.stderr));
    let x = |dir_name: &str| -> Vec<f64> {
        rows(&dir.path().join(dir_name), "b01-approach-p2-robust.csv")
            .iter()
            .skip(1)
            .map(|r| r.split(',').nth(4).unwrap().parse::<f64>().unwrap())
            .collect()
    };
    let (xr, xi) = (x("rsi"), x("in"));
    assert_eq!(xr.len(), xi.len());
    let x0 = xr[0];
    let lowest = xr.iter().take(50).copied().fold(f64::INFINITY, f64::min);
    assert!(lowest >= x0 - 1e-6, "dragged from {x0} m to {lowest} m");
    let worst = xr
        .iter()
        .zip(&xi)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-5,
        "RSI and in-process robots differ by {worst} m"
    );
}

/// `rsi-config` writes for the cell `run` will use: the addresses and the robot's correction limits
/// come from the cell file (flags override), and without either it refuses, naming what is missing,
/// instead of guessing an address. It never replaces a file without `--force`, and a failure on one
/// file leaves every other as it was.
#[test]
fn rsi_config_takes_the_cell_file_or_refuses_and_overwrites_nothing_unasked() {
    let dir = tempfile::tempdir().unwrap();
    let cell = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/cell.toml");

    // Neither the cell file nor the flags: one line naming each missing value, nothing written.
    let o = forcecell(&["rsi-config", "--out", "none"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    for needle in [
        "--ip",
        "--robot-ip",
        "--poscorr-mm",
        "--poscorrmon-mm",
        "--config",
    ] {
        assert!(err.contains(needle), "{needle} in {err}");
    }
    assert!(!dir.path().join("none").exists());
    // Some flags but not all: only the missing ones are named.
    let o = forcecell(
        &[
            "rsi-config",
            "--ip",
            "10.0.0.5",
            "--poscorr-mm",
            "5",
            "--out",
            "none",
        ],
        dir.path(),
    );
    let err = text(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("--robot-ip") && err.contains("--poscorrmon-mm"),
        "{err}"
    );
    assert!(
        !err.contains("(--ip)") && !err.contains("(--poscorr-mm)"),
        "{err}"
    );

    // From the cell file: the PC's address and port of `robot.listen`, its POSCORR (5 mm),
    // POSCORRMON (6 mm), and its `process = false` (the plain layout `run` then expects).
    let o = forcecell(
        &["rsi-config", "--config", cell, "--out", "robot"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let xml = std::fs::read_to_string(dir.path().join("robot/forcecell_rsi.xml")).unwrap();
    assert_eq!(
        EthernetConfig::parse(&xml).unwrap(),
        EthernetConfig::forcecell([192, 168, 1, 100].into(), 49152, false)
    );
    let krl = std::fs::read_to_string(dir.path().join("robot/forcecell_rsi.src")).unwrap();
    assert!(krl.contains("+-5.000 mm"), "{krl}");
    let rsix = std::fs::read_to_string(dir.path().join("robot/forcecell_rsi.rsix")).unwrap();
    assert!(
        rsix.contains(r#"Name="UpperLimX" ParamId="3" ParamValue="5.000""#)
            && rsix.contains(r#"Name="MaxTrans" ParamId="0" ParamValue="6.000""#),
        "{rsix}"
    );

    // Flags override the file.
    let o = forcecell(
        &[
            "rsi-config",
            "--config",
            cell,
            "--ip",
            "192.168.1.50",
            "--poscorr-mm",
            "3",
            "--out",
            "over",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let xml = std::fs::read_to_string(dir.path().join("over/forcecell_rsi.xml")).unwrap();
    assert_eq!(
        EthernetConfig::parse(&xml).unwrap(),
        EthernetConfig::forcecell([192, 168, 1, 50].into(), 49152, false)
    );
    let krl = std::fs::read_to_string(dir.path().join("over/forcecell_rsi.src")).unwrap();
    assert!(krl.contains("+-3.000 mm"), "{krl}");

    // The robot's own address as the PC's: refused.
    let o = forcecell(
        &[
            "rsi-config",
            "--config",
            cell,
            "--ip",
            "192.168.1.10",
            "--out",
            "same",
        ],
        dir.path(),
    );
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("robot's own"),
        "{}",
        text(&o.stderr)
    );
    assert!(!dir.path().join("same").exists());

    // Existing files are not replaced without --force; every one is named.
    let robot = dir.path().join("robot");
    let xml_path = robot.join("forcecell_rsi.xml");
    std::fs::write(&xml_path, "the integrator's edited file").unwrap();
    let o = forcecell(
        &["rsi-config", "--config", cell, "--out", "robot"],
        dir.path(),
    );
    assert!(!o.status.success());
    let err = text(&o.stderr);
    assert!(
        err.contains("--force") && err.contains("forcecell_rsi.src"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_to_string(&xml_path).unwrap(),
        "the integrator's edited file"
    );
    // With --force, a failure on the second file leaves the first as it was.
    let src_path = robot.join("forcecell_rsi.src");
    std::fs::remove_file(&src_path).unwrap();
    std::fs::create_dir(&src_path).unwrap();
    std::fs::write(src_path.join("keep"), "x").unwrap();
    let o = forcecell(
        &["rsi-config", "--config", cell, "--out", "robot", "--force"],
        dir.path(),
    );
    assert!(!o.status.success());
    assert_eq!(
        std::fs::read_to_string(&xml_path).unwrap(),
        "the integrator's edited file",
        "{}",
        text(&o.stderr)
    );
    // No temporary file is left behind.
    let mut names: Vec<String> = std::fs::read_dir(&robot)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "forcecell_rsi.rsix",
            "forcecell_rsi.src",
            "forcecell_rsi.xml"
        ]
    );
    // And with --force and nothing in the way, they are replaced.
    std::fs::remove_dir_all(&src_path).unwrap();
    let o = forcecell(
        &["rsi-config", "--config", cell, "--out", "robot", "--force"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        std::fs::read_to_string(&xml_path)
            .unwrap()
            .contains("192.168.1.100")
    );
}

#[test]
fn rsi_config_with_orientation_following_writes_the_rotation_limits_of_the_tuning() {
    let dir = tempfile::tempdir().unwrap();
    let o = forcecell(
        &[
            "rsi-config",
            "--tuning",
            "robust-curved",
            "--ip",
            "192.168.1.100",
            "--robot-ip",
            "192.168.1.10",
            "--out",
            "curved",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let krl = std::fs::read_to_string(dir.path().join("curved/forcecell_rsi.src")).unwrap();
    // POSCORR's rotation limit is the tuning's `poscorr` (0.26 rad), POSCORRMON's 20 % beyond it.
    let poscorr = 0.26f64.to_degrees();
    assert!(
        krl.contains(&format!("MaxRotAngle {poscorr:.3} deg  <- RKorr.X..C")),
        "{krl}"
    );
    assert!(
        krl.contains("POSCORRMON MaxTrans")
            && krl.contains(&format!("MaxRotAngle {:.3} deg", poscorr * 1.2)),
        "{krl}"
    );
    // The rotational channels are in the config the robot reads.
    let xml = std::fs::read_to_string(dir.path().join("curved/forcecell_rsi.xml")).unwrap();
    for a in ["A", "B", "C"] {
        assert!(xml.contains(&format!("RKorr.{a}")), "{a}: {xml}");
    }
    // Without orientation following: RSI's default 5°.
    let o = forcecell(
        &[
            "rsi-config",
            "--tuning",
            "robust",
            "--ip",
            "192.168.1.100",
            "--robot-ip",
            "192.168.1.10",
            "--out",
            "flat",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let krl = std::fs::read_to_string(dir.path().join("flat/forcecell_rsi.src")).unwrap();
    assert!(
        krl.contains("MaxRotAngle 5.000 deg  <- RKorr.X..C"),
        "{krl}"
    );
    // A cell file's own rotation limits (what `run` holds the robot to) come before the tuning's.
    std::fs::write(
        dir.path().join("cell.toml"),
        "tuning = \"robust-curved\"\n[robot]\nlisten = \"192.168.1.100:49152\"\n\
         robot_ip = \"192.168.1.10\"\nposcorr_deg = 16.0\nposcorrmon_deg = 19.5\n\
         [sensor]\nkind = \"ati\"\ncan = \"can0\"\n",
    )
    .unwrap();
    let o = forcecell(
        &["rsi-config", "--config", "cell.toml", "--out", "cell"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    let krl = std::fs::read_to_string(dir.path().join("cell/forcecell_rsi.src")).unwrap();
    assert!(
        krl.contains("MaxRotAngle 16.000 deg  <- RKorr.X..C")
            && krl.contains("MaxRotAngle 19.500 deg"),
        "{krl}"
    );
}
