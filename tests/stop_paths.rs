//! Every stop path of `forcecell sim` ends cleanly: SIGINT and SIGTERM (sent to the child process with
//! `/bin/kill`) end the run with the trace, the plot and the summary written and `Stop` sent to the
//! robot; a wait for the robot's first datagram ends on a signal; a lost link ends with its own exit
//! status. The robot is the simulated KUKA controller on loopback, in this process, and its mechanism
//! sends the signal at a chosen cycle, so no test depends on timing.

mod common;

use std::path::Path;
use std::process::Child;
use std::sync::atomic::Ordering;

use common::{SignallingArm, arm, client, finish, free_port, read_until, signal, spawn};
use sim::krc::{KrcEnd, KrcReport};

/// A 60 s scenario: long enough that only a signal or a lost link ends it in a test.
const LONG: &str = r#"
name = "long"
duration = 60.0
plant = "p2"
tuning = "robust"
[environment]
k_c = 70000.0
x_c = 0.01
"#;

/// `sim -s long.toml --external-robot 127.0.0.1:PORT --out o` in a new directory, once it listens.
fn start_external() -> (
    tempfile::TempDir,
    u16,
    Child,
    String,
    std::io::BufReader<std::process::ChildStdout>,
) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("long.toml"), LONG).unwrap();
    let port = free_port();
    let listen = format!("127.0.0.1:{port}");
    let mut child = spawn(
        &[
            "sim",
            "-s",
            "long.toml",
            "--external-robot",
            &listen,
            "--out",
            "o",
        ],
        dir.path(),
    );
    let (seen, r) = read_until(&mut child, "listening for an RSI client");
    (dir, port, child, seen, r)
}

/// Run `sim --external-robot` with a client that signals the process after `after` cycles.
fn external_signalled(
    sig: &'static str,
    after: u64,
) -> (i32, String, KrcReport, tempfile::TempDir) {
    let (dir, port, child, seen, r) = start_external();
    let mut krc = client(port, 100_000, |_| {});
    let mut mech = SignallingArm {
        arm: arm(),
        cycles: 0,
        after,
        target: Some((child.id(), sig)),
        killer: None,
    };
    let report = krc.run(&mut mech);
    let (code, text) = finish(child, seen, r);
    (code, text, report, dir)
}

/// Wait (at most 60 s) until the recording at `path` has grown past its header and attachments: the
/// recorder flushes those at once and messages at least every second (to `path.partial` until the run
/// finishes it).
fn wait_for_messages(path: &Path) {
    let path = forcecell::recorder::partial_path(path);
    let len = || path.metadata().map_or(0, |m| m.len());
    let start = std::time::Instant::now();
    let mut header = 0;
    loop {
        let now = len();
        if header == 0 {
            header = now;
        } else if now > header {
            return;
        }
        assert!(
            start.elapsed() < std::time::Duration::from_secs(60),
            "{}: no messages flushed",
            path.display()
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// The MCAP recording a signalled run left was finished (summary and index written), not cut off as
/// after a kill, and holds every cycle of its CSV.
fn assert_mcap_finished(path: &Path, text: &str) {
    assert!(
        text.contains("finished with summary and index"),
        "the recording was finished: {text}"
    );
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let back = forcecell::recorder::read_mcap(&bytes).unwrap();
    assert_eq!(back.truncated, None, "{}", path.display());
    assert_eq!(back.rows.len(), rows(&path.with_extension("csv")), "{text}");
    // The summary section with its chunk index (what indexed readers and Foxglove seek by).
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .unwrap_or_else(|| panic!("{}: no summary section", path.display()));
    assert!(!summary.chunk_indexes.is_empty(), "{}", path.display());
    assert!(
        summary
            .chunk_indexes
            .iter()
            .all(|c| c.message_index_length > 0),
        "{}: a chunk without message index",
        path.display()
    );
}

fn rows(path: &Path) -> usize {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .count()
        - 1
}

#[test]
fn sigterm_ends_sim_with_an_external_robot_with_stop_and_a_recording() {
    let (code, text, report, dir) = external_signalled("TERM", 200);
    assert_eq!(code, 130, "{text}");
    assert_eq!(
        report.end,
        KrcEnd::Stopped,
        "the robot got Stop: {report:?}\n{text}"
    );
    assert!(text.contains("stopped by SIGINT/SIGTERM"), "{text}");
    assert!(text.contains("Stop sent to the robot"), "{text}");
    assert!(text.contains("peak force"), "the summary: {text}");
    assert!(rows(&dir.path().join("o/long.csv")) >= 199, "{text}");
    assert!(dir.path().join("o/long.png").exists(), "{text}");
    assert_mcap_finished(&dir.path().join("o/long.mcap"), &text);
}

#[test]
fn sigint_ends_sim_with_an_external_robot_with_stop_and_a_recording() {
    let (code, text, report, dir) = external_signalled("INT", 150);
    assert_eq!(code, 130, "{text}");
    assert_eq!(report.end, KrcEnd::Stopped, "{report:?}\n{text}");
    assert!(rows(&dir.path().join("o/long.csv")) >= 149, "{text}");
}

#[test]
fn sigint_ends_sim_with_the_simulated_controller_in_real_time_with_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("long.toml"), LONG).unwrap();
    let mut child = spawn(
        &["sim", "-s", "long.toml", "--realtime", "--out", "o"],
        dir.path(),
    );
    let (seen, r) = read_until(&mut child, "robot: ");
    // Signal once the recording holds messages (a signal before the first cycle leaves a finished
    // recording without any, tested in `recording.rs`).
    wait_for_messages(&dir.path().join("o/long.mcap"));
    signal(child.id(), "INT");
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 130, "{text}");
    assert!(text.contains("stopped by SIGINT/SIGTERM"), "{text}");
    assert!(text.contains("wrote o/long.csv and o/long.png"), "{text}");
    assert!(dir.path().join("o/long.png").exists());
    std::fs::read_to_string(dir.path().join("o/long.csv")).unwrap();
    assert_mcap_finished(&dir.path().join("o/long.mcap"), &text);
}

#[test]
fn sigterm_ends_a_lockstep_sim_with_a_recording() {
    let dir = tempfile::tempdir().unwrap();
    // 3600 s of lockstep: far more than the test waits for.
    std::fs::write(
        dir.path().join("long.toml"),
        LONG.replace("duration = 60.0", "duration = 3600.0"),
    )
    .unwrap();
    let mut child = spawn(&["sim", "-s", "long.toml", "--out", "o"], dir.path());
    let (seen, r) = read_until(&mut child, "robot: ");
    wait_for_messages(&dir.path().join("o/long.mcap"));
    signal(child.id(), "TERM");
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 130, "{text}");
    assert!(dir.path().join("o/long.csv").exists(), "{text}");
    assert_mcap_finished(&dir.path().join("o/long.mcap"), &text);
}

#[test]
fn a_signal_ends_the_wait_for_the_first_datagram() {
    // No robot ever sends.
    let (_dir, _, child, seen, r) = start_external();
    signal(child.id(), "INT");
    let (code, text) = finish(child, seen, r);
    assert_eq!(code, 130, "{text}");
    assert!(
        text.contains("Stop not sent (no robot cycle to answer)"),
        "{text}"
    );
}

#[test]
fn a_lost_link_ends_with_its_own_exit_status() {
    let (dir, port, child, seen, r) = start_external();
    // The robot ends RSI without a goodbye after 300 cycles.
    let mut krc = client(port, 100_000, |k| k.faults.silent_from = Some(300));
    let abort = krc.abort_handle();
    let robot = std::thread::spawn(move || krc.run(&mut arm()));
    let (code, text) = finish(child, seen, r);
    abort.store(true, Ordering::Relaxed);
    let report = robot.join().unwrap();
    assert_eq!(code, 3, "{text}\n{report:?}");
    assert!(text.contains("the loop ended early"), "{text}");
    assert_eq!(rows(&dir.path().join("o/long.csv")), 300, "{text}");
    assert_mcap_finished(&dir.path().join("o/long.mcap"), &text);
}
