//! The dry run against an RSI client that is not ours: a plain UDP socket that writes `<Rob>` by hand,
//! moves like a stiff arm (the measured pose is the programmed one plus the last correction), and reads
//! the replies with string matching — no forcecell codec on this side.

mod common;

use std::net::UdpSocket;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use common::attr;

/// Start `forcecell sim --external-robot` on a free loopback port.
fn start(dir: &Path, extra: &[&str]) -> (Child, String) {
    let port = UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let listen = format!("127.0.0.1:{port}");
    let mut args = vec!["sim", "--external-robot", &listen, "--out", "dry"];
    args.extend_from_slice(extra);
    let child = Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .args(&args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    (child, listen)
}

/// The hand-written robot.
struct Robot {
    sock: UdpSocket,
    ipoc: u64,
    /// The correction along the tool's z in effect, mm.
    z_corr: f64,
    /// Decimals of the positions sent (a KUKA ETHERNET object's `Precision`), and the IPOC step.
    decimals: usize,
    step: u64,
    /// X along the pass, mm, and its change per cycle.
    x: f64,
    dx: f64,
}

impl Robot {
    fn connect(to: &str) -> Self {
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        sock.connect(to).unwrap();
        sock.set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        Self {
            sock,
            ipoc: 5_000_000,
            z_corr: 0.0,
            decimals: 4,
            step: 4,
            x: 445.0,
            dx: 0.0,
        }
    }

    /// One cycle: send `<Rob>` (with `fc` inside if given), wait for the reply. The tool points down
    /// (A 180, C 180): its +z is the base's −Z, so a correction of +z mm lowers the measured Z.
    fn cycle(&mut self, fc: Option<&str>) -> Option<String> {
        let z_sol = 890.0;
        let z_ist = z_sol - self.z_corr;
        let (p, x) = (self.decimals, self.x);
        let rob = format!(
            "<Rob Type=\"KUKA\"><RIst X=\"{x:.p$}\" Y=\"0.0000\" Z=\"{z_ist:.p$}\" A=\"180.0000\" B=\"0.0000\" C=\"180.0000\"/>\
             <RSol X=\"{x:.p$}\" Y=\"0.0000\" Z=\"{z_sol:.p$}\" A=\"180.0000\" B=\"0.0000\" C=\"180.0000\"/>\
             <AIPos A1=\"0.0000\" A2=\"-90.0000\" A3=\"90.0000\" A4=\"0.0000\" A5=\"90.0000\" A6=\"0.0000\"/>\
             <ASPos A1=\"0.0000\" A2=\"-90.0000\" A3=\"90.0000\" A4=\"0.0000\" A5=\"90.0000\" A6=\"0.0000\"/>\
             <Delay D=\"0\"/>{}<IPOC>{}</IPOC></Rob>",
            fc.unwrap_or(""),
            self.ipoc
        );
        let sen = common::exchange(&self.sock, &rob)?;
        self.ipoc += self.step;
        self.x += self.dx;
        self.z_corr = attr(&sen, "RKorr", "Z").expect("every reply corrects");
        Some(sen)
    }
}

fn finish(child: Child) -> Output {
    child.wait_with_output().unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn a_client_with_its_own_program_presses_holds_releases_and_ends_its_session() {
    let dir = tempfile::tempdir().unwrap();
    let (child, listen) = start(
        dir.path(),
        &["--scenario", "pass-flat-20n", "--process-channels"],
    );
    let mut robot = Robot::connect(&listen);
    let fc =
        |mode: u8, f: f64| format!("<FcCmd Mode=\"{mode}\" F=\"{f:.2}\" Ramp=\"0.30\" Seg=\"7\"/>");
    let mut states = Vec::new();
    let mut pressing_forces = Vec::new();
    let mut step = |robot: &mut Robot, mode: u8| {
        let sen = robot
            .cycle(Some(&fc(mode, 20.0)))
            .expect("forcecell answers");
        let state = attr(&sen, "FcState", "State").expect("every reply carries FcState") as u8;
        let f = attr(&sen, "FcState", "F").unwrap();
        if states.last() != Some(&state) {
            states.push(state);
        }
        (state, f)
    };
    for _ in 0..10 {
        assert_eq!(step(&mut robot, 0).0, 0, "OFF");
    }
    // PRESS, then wait for PRESSING (the KRL template's WAIT FOR, bounded).
    let mut n = 0;
    while step(&mut robot, 1).0 != 3 {
        n += 1;
        assert!(
            n < 5000,
            "no PRESSING within 20 s of robot time: {states:?}"
        );
    }
    for _ in 0..250 {
        let (state, f) = step(&mut robot, 1);
        assert_eq!(state, 3);
        pressing_forces.push(f);
    }
    // RELEASE, then wait for OFF.
    let mut n = 0;
    while step(&mut robot, 2).0 != 0 {
        n += 1;
        assert!(n < 5000, "no OFF after RELEASE: {states:?}");
    }
    for _ in 0..10 {
        step(&mut robot, 0);
    }
    let final_corr = robot.z_corr;
    drop(robot); // RSI_OFF: the robot falls silent.
    let o = finish(child);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains("the robot ended its session"),
        "{}",
        text(&o.stdout)
    );
    assert_eq!(states, [0, 1, 2, 3, 4, 0], "the states the program saw");
    assert!(
        pressing_forces.iter().all(|f| (f - 20.0).abs() <= 1.0),
        "FcState.F while pressing: {pressing_forces:?}"
    );
    assert_eq!(final_corr, 0.0, "the correction is back at zero");
}

#[test]
fn a_client_without_fc_cmd_gets_the_scenarios_program_and_then_stop() {
    let dir = tempfile::tempdir().unwrap();
    let (child, listen) = start(dir.path(), &["--scenario", "pass-flat-20n", "--check"]);
    let mut robot = Robot::connect(&listen);
    let mut last = String::new();
    let mut deepest: f64 = 0.0;
    for _ in 0..10_000 {
        let Some(sen) = robot.cycle(None) else { break };
        assert!(!sen.contains("FcState"), "no process channels configured");
        deepest = deepest.max(robot.z_corr);
        let stop = sen.contains("<Stop>1</Stop>");
        last = sen;
        if stop {
            break;
        }
    }
    assert!(
        last.contains("<Stop>1</Stop>"),
        "the session ends with Stop: {last}"
    );
    let o = finish(child);
    let out = text(&o.stdout);
    assert!(o.status.success(), "{out}\n{}", text(&o.stderr));
    // The virtual part sits 1 mm beyond where the session started: the tool reached it and pressed
    // (20 N on 10 N/mm is 2 mm more), within POSCORR's 5 mm.
    assert!(
        deepest > 2.5 && deepest < 5.0,
        "deepest correction {deepest} mm"
    );
    assert!(out.contains("pressing_in_band_pct"), "{out}");
    assert!(!out.contains("FAIL"), "{out}");
    assert_eq!(robot.z_corr, 0.0, "the correction is back at zero");
}

/// A scenario whose surface drops 10 mm away in a steady contact: the re-acquire search reaches its
/// `search_depth` (5 mm beyond the last contact) before the loop's `contact_loss_time` (2 mm fast,
/// then at what stops within 2·f_r on 70 kN/m: about 6 mm in 0.5 s).
const SURFACE_DROPS: &str = r#"name = "surface-drops"
description = "the surface drops 10 mm away at 1.5 s"
duration = 4.0
plant = "p2"
tuning = "robust"
x0 = 0.009

[environment]
k_c = 70000.0
x_c = 0.010
x_c_events = [{ kind = "step", at = 1.5, delta = 0.010 }]
"#;

#[test]
fn a_client_without_fc_cmd_sees_a_lost_contact_end_in_a_retract_and_stop() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("drops.toml"), SURFACE_DROPS).unwrap();
    let (child, listen) = start(dir.path(), &["--scenario", "drops.toml"]);
    let mut robot = Robot::connect(&listen);
    let mut z = Vec::new();
    let mut stopped = false;
    for _ in 0..10_000 {
        let Some(sen) = robot.cycle(None) else { break };
        z.push(robot.z_corr);
        if sen.contains("<Stop>1</Stop>") {
            stopped = true;
            break;
        }
    }
    let o = finish(child);
    let out = text(&o.stdout);
    assert!(stopped, "the session ends with Stop: {out}");
    assert_eq!(o.status.code(), Some(4), "a fault ended it: {out}");
    assert!(
        out.contains("fault 5 (contact lost): contact lost: the search reached 5.0 mm beyond"),
        "{out}"
    );
    // The part is 1 mm beyond the start and drops 10 mm away at 1.5 s (375 cycles): before that the
    // tool presses (5 N on 70 kN/m is 0.07 mm more); then it searches towards where the part went,
    // no deeper than 5 mm beyond its last command in contact, backs off, and returns to the path
    // (zero) before the Stop.
    assert!((1.0..1.2).contains(&z[370]), "pressing at {} mm", z[370]);
    let deepest = z.iter().copied().fold(f64::MIN, f64::max);
    assert!(
        deepest > 1.5 && deepest <= z[370] + 5.0 + 0.1,
        "searched after the part, within the bound: {deepest} mm"
    );
    let at = z.iter().position(|v| *v == deepest).unwrap();
    for w in z[at..].windows(2) {
        assert!(w[1] <= w[0], "only backing off after the search: {w:?}");
    }
    assert_eq!(z[z.len() - 1], 0.0, "back on the path before the Stop");
    // About 0.5 s of search at most: the run ended long before the scenario's 4 s.
    assert!(z.len() < 700, "{} cycles", z.len());
}

/// `--ethernet-config FILE`: the dry run reads what the robot's own configuration says it sends and
/// answers in its layout — here a configuration with axis corrections only (`<AK A1..A6/>`, `Stop`),
/// which `run` would refuse (said at start), answered with zeros in that layout.
#[test]
fn the_dry_run_answers_in_the_robots_own_layout() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/rsi-corpus/configs/axis-only.xml");
    let (mut child, listen) = start(
        dir.path(),
        &[
            "--scenario",
            "pass-flat-20n",
            "--ethernet-config",
            cfg.to_str().unwrap(),
        ],
    );
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.connect(&listen).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let mut replies = Vec::new();
    let mut ipoc = 77_000u64;
    let mut buf = [0u8; 2048];
    for _ in 0..200 {
        if replies.len() == 20 {
            break;
        }
        // What axis-only.xml's SEND says: RIst, RSol, AIPos.
        let rob = format!(
            "<Rob Type=\"KUKA\"><RIst X=\"445.0\" Y=\"0.0\" Z=\"890.0\" A=\"180.0\" B=\"0.0\" C=\"180.0\"/>\
             <RSol X=\"445.0\" Y=\"0.0\" Z=\"890.0\" A=\"180.0\" B=\"0.0\" C=\"180.0\"/>\
             <AIPos A1=\"0.0\" A2=\"-90.0\" A3=\"90.0\" A4=\"0.0\" A5=\"90.0\" A6=\"0.0\"/><IPOC>{ipoc}</IPOC></Rob>"
        );
        if sock.send(rob.as_bytes()).is_err() {
            std::thread::sleep(Duration::from_millis(100));
            continue;
        }
        match sock.recv(&mut buf) {
            Ok(n) => {
                replies.push(String::from_utf8_lossy(&buf[..n]).into_owned());
                ipoc += 4;
            }
            Err(_) => std::thread::sleep(Duration::from_millis(50)),
        }
    }
    child.kill().unwrap();
    let o = finish(child);
    let out = text(&o.stdout);
    assert_eq!(replies.len(), 20, "{out}\n{}", text(&o.stderr));
    for (k, sen) in replies.iter().enumerate() {
        assert!(sen.starts_with("<Sen Type=\"ImFree\">"), "{sen}");
        assert!(sen.contains("<AK A1=\"0.0000\" A2=\"0.0000\""), "{sen}");
        assert!(sen.contains("<Stop>0</Stop>"), "{sen}");
        assert!(!sen.contains("RKorr"), "{sen}");
        assert!(
            sen.contains(&format!("<IPOC>{}</IPOC>", 77_000 + 4 * k as u64)),
            "{sen}"
        );
    }
    assert!(
        out.contains("`forcecell run` would refuse") && out.contains("no Cartesian correction"),
        "{out}"
    );
}

/// A client that sends positions at 0.1 mm (`Precision 1`) and steps its IPOC by 1 per cycle, as
/// several robot-side simulators do: the dry run says both, with the steady force error the
/// resolution implies at the workpiece's stiffness, and the fix.
#[test]
fn coarse_positions_and_an_ipoc_step_of_one_are_warned() {
    let dir = tempfile::tempdir().unwrap();
    let (child, listen) = start(dir.path(), &["--scenario", "pass-flat-20n"]);
    let mut robot = Robot::connect(&listen);
    robot.decimals = 1;
    robot.step = 1;
    robot.dx = 0.1;
    let mut last = String::new();
    for _ in 0..10_000 {
        let Some(sen) = robot.cycle(None) else { break };
        let stop = sen.contains("<Stop>1</Stop>");
        last = sen;
        if stop {
            break;
        }
    }
    assert!(last.contains("<Stop>1</Stop>"), "{last}");
    let o = finish(child);
    let out = text(&o.stdout);
    assert!(
        out.contains("warning: the robot sends positions at 0.1000 mm resolution")
            && out.contains("k*q/2"),
        "{out}"
    );
    assert!(out.contains("IPOC steps by 1 per cycle, not 4"), "{out}");
}

/// Issue 35, defect 9: a client whose every tenth datagram never arrives (an IPOC gap of one cycle).
/// The run lasts the scenario's robot time, not a count of answered cycles: it ends by t = 2 s, every
/// row has its truth (the world followed the robot's time through the gaps), and the summary has no NaN.
#[test]
fn lost_cycles_are_robot_time_the_run_ends_on_time_with_every_row_s_truth() {
    let dir = tempfile::tempdir().unwrap();
    let (child, listen) = start(dir.path(), &["--scenario", "paper-fig9"]);
    let mut robot = Robot::connect(&listen);
    let mut answered = 0u32;
    for i in 0..10_000 {
        if i % 10 == 9 {
            robot.ipoc += 4; // a datagram the robot sent that never arrived
        }
        let Some(sen) = robot.cycle(None) else { break };
        answered += 1;
        if sen.contains("<Stop>1</Stop>") {
            break;
        }
    }
    let o = finish(child);
    let out = text(&o.stdout);
    assert!(o.status.success(), "{out}\n{}", text(&o.stderr));
    assert!(!out.contains("NaN"), "{out}");
    // 2 s of 4 ms cycles is 500 robot cycles, a tenth of them lost (and the Stop cycle answered).
    assert!((440..=460).contains(&answered), "{answered} answered");
    // Each lost datagram is a robot cycle missed, counted from the IPOC gaps.
    let missed: u32 = out
        .split(" missed")
        .next()
        .and_then(|s| s.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no missed counter: {out}"));
    assert!((45..=55).contains(&missed), "{missed} missed: {out}");
    let csv = std::fs::read_dir(dir.path().join("dry"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "csv"))
        .expect("the trace");
    let csv = std::fs::read_to_string(csv).unwrap();
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |n: &str| head.iter().position(|h| *h == n).unwrap();
    let (t, f_true, k_c, x_c) = (col("t"), col("f_true"), col("k_c"), col("x_c"));
    let mut last_t = 0.0;
    let mut rows = 0;
    for l in lines {
        let v: Vec<&str> = l.split(',').collect();
        for c in [f_true, k_c, x_c] {
            assert!(!v[c].is_empty(), "row without truth: {l}");
        }
        last_t = v[t].parse::<f64>().unwrap();
        rows += 1;
    }
    assert!(rows > 400, "{rows} rows");
    assert!(
        last_t <= 2.0 + 1e-9 && last_t > 1.98,
        "the run ends on robot time (the first cycle at or past 2 s less a cycle): last row at t = {last_t} s"
    );
}
