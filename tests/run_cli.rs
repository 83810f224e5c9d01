//! `forcecell run` as an integrator starts it, without CAN: the cell file names a simulated FT 300 on
//! a pseudo-terminal (another process) and the robot is the simulated KUKA controller on loopback in
//! this process. The run says what it does: the real-time settings it got (read back by the kernel:
//! `SCHED_FIFO` and locked memory, or the refusal with its fix), a status line while it runs, the
//! robot's late replies against its budget at the end, and a recording traceable to its cell file.

mod common;

use common::{arm, attr, client, finish, free_port, read_until, spawn};

#[test]
fn run_says_what_it_got_and_what_it_does() {
    let dir = tempfile::tempdir().unwrap();
    let _sensor = common::ft300(&dir.path().join("ft300"), "0.0");
    let port = free_port();
    let cell = format!(
        r#"tuning = "robust-100hz"
duration = 1.0
record = "rec"

[robot]
listen = "127.0.0.1:{port}"
robot_ip = "127.0.0.1"
poscorr_mm = 55.0
poscorrmon_mm = 60.0
timeout = 80

[sensor]
kind = "robotiq"
port = "ft300"

[realtime]
priority = 20
sensor_priority = 10
"#
    );
    std::fs::write(dir.path().join("cell.toml"), cell).unwrap();
    let mut child = spawn(&["run", "--config", "cell.toml"], dir.path());
    let (seen, r) = read_until(&mut child, "listening on");
    let mut krc = client(port, 400, |_| {});
    let report = krc.run(&mut arm());
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 0, "{text}");
    assert!(report.cycles >= 250, "{report:?}");

    // The real-time settings: granted and said (as root, or with an rtprio limit), or refused with
    // the fix and the run going on.
    let granted =
        text.contains("real-time: cycle thread SCHED_FIFO 20, sensor reader SCHED_FIFO 10");
    let refused = text.contains("warning: SCHED_FIFO 20 refused") && text.contains("rtprio");
    assert!(granted || refused, "{text}");
    assert!(
        text.contains("memory locked (") || text.contains("warning: locking memory refused"),
        "{text}"
    );
    // A status line (plain, not on a terminal) with the state, the force, the late budget.
    assert!(text.contains("t    0.00 s"), "{text}");
    assert!(text.contains("late 0 of 80"), "{text}");
    // The end: the robot's late replies against its budget.
    assert!(text.contains("robot late replies 0 of 80"), "{text}");

    // Traceable: an ISO-dated name, the provenance in a JSON summary beside the recording (and as
    // the recording's metadata).
    let names: Vec<String> = std::fs::read_dir(dir.path().join("rec"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let json = names
        .iter()
        .find(|n| n.ends_with(".json"))
        .unwrap_or_else(|| panic!("a summary: {names:?}"));
    let stem = json.trim_end_matches(".json");
    assert!(
        stem.len() == "run-2026-12-04T20-25-00Z".len()
            && stem.starts_with("run-20")
            && stem.ends_with('Z'),
        "{stem}"
    );
    for ext in ["mcap", "csv", "png"] {
        assert!(names.contains(&format!("{stem}.{ext}")), "{names:?}");
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("rec").join(json)).unwrap())
            .unwrap();
    let cell_bytes = std::fs::read(dir.path().join("cell.toml")).unwrap();
    assert_eq!(
        summary["source_sha256"],
        forcecell::provenance::sha256_hex(&cell_bytes).as_str()
    );
    assert_eq!(summary["end_reason"], "1 s of robot time done");
    assert_eq!(summary["stop_sent"], true);
    assert_eq!(summary["tuning"], "robust-100hz");
    assert!(
        summary["sensor"]
            .as_str()
            .unwrap()
            .contains("Robotiq FT 300")
    );
    // The sensor's identity as it answered its start-up queries (the simulated FT 300's registers).
    assert_eq!(summary["sensor_serial"], "FTS-875704368", "{summary}");
    assert!(
        summary["sensor_firmware"]
            .as_str()
            .unwrap()
            .starts_with("FTS-3.1"),
        "{summary}"
    );
    assert!(summary["started"].as_str().unwrap().ends_with('Z'));
    assert!(summary["ended"].as_str().unwrap() >= summary["started"].as_str().unwrap());
}

/// Issue 35, item 12: a robot whose every 25th datagram never arrives (an IPOC gap of one cycle, as the
/// network would lose it). `run` counts each as missed, in its end summary and in the recording, and
/// prints the late replies measured from each datagram's arrival beside it.
#[test]
fn run_counts_the_robot_cycles_that_never_arrived_in_the_summary_and_the_recording() {
    use std::net::UdpSocket;
    use std::time::Duration;
    let dir = tempfile::tempdir().unwrap();
    let _sensor = common::ft300(&dir.path().join("ft300"), "0.0");
    let port = free_port();
    let cell = format!(
        r#"tuning = "robust-100hz"
duration = 1.0
record = "rec"

[robot]
listen = "127.0.0.1:{port}"
robot_ip = "127.0.0.1"
poscorr_mm = 55.0
poscorrmon_mm = 60.0

[sensor]
kind = "robotiq"
port = "ft300"
"#
    );
    std::fs::write(dir.path().join("cell.toml"), cell).unwrap();
    let mut child = spawn(&["run", "--config", "cell.toml"], dir.path());
    let (seen, r) = read_until(&mut child, "listening on");
    // The robot stand-in: a plain UDP socket sending <Rob> in the forcecell layout on a 4 ms real-time
    // cycle as a robot does (a faster one outruns the FT 300's 10 ms frames: the loop would see its
    // sensor stale and fault), the tool pointing down (A 180, C 180) and following the correction
    // along its z.
    let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
    sock.connect(("127.0.0.1", port)).unwrap();
    sock.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut ipoc = 7_000_000u64;
    let mut z_corr = 0.0;
    let mut skipped = Vec::new();
    let mut stop_ipoc = None;
    let mut buf = [0u8; 2048];
    let start = std::time::Instant::now();
    for i in 0..2_000u32 {
        // Pacing only (the robot's clock); nothing here asserts a time.
        let tick = start + Duration::from_millis(4 * u64::from(i));
        std::thread::sleep(tick.saturating_duration_since(std::time::Instant::now()));
        if i % 25 == 24 {
            skipped.push(ipoc); // sent by the robot, lost on the way
            ipoc += 4;
        }
        let z_sol = 890.0;
        let z_ist = z_sol - z_corr;
        let rob = format!(
            "<Rob Type=\"KUKA\"><RIst X=\"445.0000\" Y=\"0.0000\" Z=\"{z_ist:.4}\" A=\"180.0000\" B=\"0.0000\" C=\"180.0000\"/>\
             <RSol X=\"445.0000\" Y=\"0.0000\" Z=\"{z_sol:.4}\" A=\"180.0000\" B=\"0.0000\" C=\"180.0000\"/>\
             <AIPos A1=\"0.0000\" A2=\"-90.0000\" A3=\"90.0000\" A4=\"0.0000\" A5=\"90.0000\" A6=\"0.0000\"/>\
             <ASPos A1=\"0.0000\" A2=\"-90.0000\" A3=\"90.0000\" A4=\"0.0000\" A5=\"90.0000\" A6=\"0.0000\"/>\
             <Delay D=\"0\"/><IPOC>{ipoc}</IPOC></Rob>"
        );
        sock.send(rob.as_bytes()).unwrap();
        let n = sock.recv(&mut buf).expect("every datagram is answered");
        let sen = String::from_utf8_lossy(&buf[..n]).into_owned();
        z_corr = attr(&sen, "RKorr", "Z").expect("every reply corrects");
        if sen.contains("<Stop>1</Stop>") {
            stop_ipoc = Some(ipoc);
            break;
        }
        ipoc += 4;
    }
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 0, "{text}");
    let stop_ipoc = stop_ipoc.expect("the run ends with Stop");
    // Every gap before the Stop cycle is a missed cycle, said in the summary beside the late replies
    // measured from the datagrams' arrival.
    let expected = skipped.iter().filter(|&&s| s < stop_ipoc).count() as u64;
    assert!(expected >= 9, "{expected} of {skipped:?}");
    let link = text
        .lines()
        .find(|l| l.starts_with("RSI link: "))
        .unwrap_or_else(|| panic!("no link summary: {text}"));
    assert!(link.contains(&format!(", {expected} missed,")), "{link}");
    assert!(link.contains(" late after arrival,"), "{link}");
    assert!(text.contains("  arrival→send: p50 "), "{text}");
    // The status line names the three counts.
    assert!(text.contains("  missed 0  replied late "), "{text}");
    // The recording: each cycle carries the count so far, the last one all of them but a gap just
    // before the Stop cycle (not recorded).
    let mcap = std::fs::read_dir(dir.path().join("rec"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("a recording");
    let bytes = std::fs::read(&mcap).unwrap();
    let mut recs = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == scenario::telemetry::CYCLE_TOPIC {
            let mut rec = forcecell::recorder::Record::unknown();
            scenario::telemetry::decode(&scenario::telemetry::CYCLE, &m.data, &mut rec).unwrap();
            recs.push(rec);
        }
    }
    let last = recs.last().expect("records");
    let before_last = skipped.iter().filter(|&&s| s < last.robot_seq).count() as u64;
    assert_eq!(
        last.missed, before_last,
        "{skipped:?} last seq {}",
        last.robot_seq
    );
    assert!(before_last + 1 >= expected, "{before_last} vs {expected}");
    // The count rises at each gap, never elsewhere.
    for w in recs.windows(2) {
        let gaps = skipped
            .iter()
            .filter(|&&s| s > w[0].robot_seq && s < w[1].robot_seq)
            .count() as u64;
        assert_eq!(
            w[1].missed - w[0].missed,
            gaps,
            "{} → {}",
            w[0].robot_seq,
            w[1].robot_seq
        );
        assert!(w[1].replied_late >= w[0].replied_late);
    }
}

/// While `run` waits for the robot, what arrives and is not the robot's cycle is said on stderr: a
/// line per class of rejected datagram, naming the sender and the reason, at most one a second per
/// class however many arrive (here about 150 of each in 1.5 s).
#[test]
fn run_says_why_it_drops_datagrams_while_it_waits() {
    let dir = tempfile::tempdir().unwrap();
    let _sensor = common::ft300(&dir.path().join("ft300"), "0.0");
    let port = free_port();
    let cell = format!(
        r#"tuning = "robust-100hz"
duration = 1.0
record = "rec"

[robot]
listen = "127.0.0.1:{port}"
robot_ip = "127.0.0.2"
poscorr_mm = 55.0
poscorrmon_mm = 60.0

[sensor]
kind = "robotiq"
port = "ft300"
"#
    );
    std::fs::write(dir.path().join("cell.toml"), cell).unwrap();
    let mut child = spawn(&["run", "--config", "cell.toml"], dir.path());
    let (seen, r) = read_until(&mut child, "listening on");
    // A stranger on 127.0.0.1 sends a good datagram; the robot's address sends one without <RSol>.
    let good = r#"<Rob Type="KUKA"><RIst X="445.0000" Y="0.0000" Z="890.0000" A="180.0000" B="0.0000" C="180.0000"/><RSol X="445.0000" Y="0.0000" Z="890.0000" A="180.0000" B="0.0000" C="180.0000"/><AIPos A1="0.0000" A2="-90.0000" A3="90.0000" A4="0.0000" A5="90.0000" A6="0.0000"/><ASPos A1="0.0000" A2="-90.0000" A3="90.0000" A4="0.0000" A5="90.0000" A6="0.0000"/><Delay D="0"/><IPOC>1000</IPOC></Rob>"#;
    let no_rsol = good.replace(
        r#"<RSol X="445.0000" Y="0.0000" Z="890.0000" A="180.0000" B="0.0000" C="180.0000"/>"#,
        "",
    );
    let stranger = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let robot = std::net::UdpSocket::bind("127.0.0.2:0").unwrap();
    let to = format!("127.0.0.1:{port}");
    for _ in 0..150 {
        stranger.send_to(good.as_bytes(), &to).unwrap();
        robot.send_to(no_rsol.as_bytes(), &to).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    common::signal(child.id(), "INT");
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 130, "{text}");
    let foreign: Vec<&str> = text
        .lines()
        .filter(|l| l.contains("from 127.0.0.1, expected 127.0.0.2"))
        .collect();
    let malformed: Vec<&str> = text
        .lines()
        .filter(|l| l.contains("malformed: no complete <RSol>, which the Ethernet config lists"))
        .collect();
    assert!(!foreign.is_empty(), "{text}");
    assert!(!malformed.is_empty(), "{text}");
    for l in foreign.iter().chain(&malformed) {
        assert!(l.starts_with("waiting for the robot: "), "{l}");
    }
    assert!(
        malformed.iter().all(|l| l.contains("from 127.0.0.2:")),
        "{malformed:?}"
    );
    // Rate-limited: 150 of each class in about 1.5 s give a handful of lines, not 150.
    assert!(foreign.len() <= 5 && malformed.len() <= 5, "{text}");
    // The lines together account for what was dropped (the rest counted at the end).
    assert!(
        text.contains(" foreign, ") && text.contains(" malformed, "),
        "{text}"
    );
}
