//! The ATI driver against the simulated node on a **real SocketCAN interface** (vcan), plus interop
//! with can-utils. Ignored in a plain `cargo test` (most kernels of build machines have no CAN);
//! `scripts/vcan-tests.sh` runs them on `vcan0` natively, inside User-Mode Linux or inside QEMU.
//!
//! Each test uses its own base identifier, so tests may share the interface. The interface name comes
//! from `FORCECELL_VCAN` (default `vcan0`). Deadlines are generous (system calls inside UML are slow)
//! and are multiplied by `FORCECELL_VCAN_TIME_SCALE` (default 1; `scripts/vcan-tests.sh` raises it
//! under User-Mode Linux and QEMU; the driver's turnaround by at most 5 of it): headroom, never a
//! weaker assertion. No test asserts on timing.

mod ati_common;

use core::time::Duration;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

use ati_can::{
    Answer, Base, BusError, BusEvent, CanTransport, Config, Driver, Frame, Gauges, Request,
    SocketCanTransport, TransportError,
};
use ati_common::*;
use hal::Wrench;
use sim::ati_node::{NodeConfig, SharedNode, serve};

const WHY: &str = "needs a vcan0 interface: run scripts/vcan-tests.sh";

fn iface() -> String {
    sim::vcan_env::interface()
}

/// The configured headroom for slow guests (`FORCECELL_VCAN_TIME_SCALE`, 1 to 100).
fn scale() -> u32 {
    sim::vcan_env::time_scale().unwrap_or_else(|e| panic!("{e}"))
}

/// A deadline with the configured headroom.
fn deadline(d: Duration) -> Duration {
    d * scale()
}

/// The most of the time scale the driver's turnaround takes. The scale is set for `run`'s chains of
/// wall-clock bounds (`tests/ati_cli_vcan.rs`: 20 under UML); a turnaround only needs to outlast a
/// stall of the guest (CI's UML guest stalled 150 ms, `FORCECELL_VCAN_STALL=60/300` stalls it up to
/// 240 ms): 200 ms × 5 = 1 s. Every answer these tests drop waits out a whole turnaround.
const TURNAROUND_SCALE_MAX: u32 = 5;

fn open() -> SocketCanTransport {
    SocketCanTransport::open(&iface()).unwrap_or_else(|e| panic!("{e}: {WHY}"))
}

/// The node's serving thread; stopped and joined on drop.
struct NodeThread {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<Result<(), TransportError>>>,
}

impl NodeThread {
    fn spawn(node: &SharedNode) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let transport = open();
        let (n, s) = (node.clone(), Arc::clone(&stop));
        let handle = std::thread::spawn(move || serve(&n, transport, &s));
        Self {
            stop,
            handle: Some(handle),
        }
    }
}

impl Drop for NodeThread {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(h) = self.handle.take() {
            let r = h.join();
            if !std::thread::panicking() {
                r.expect("node thread panicked").expect("node transport");
            }
        }
    }
}

struct Vcan {
    base: u8,
}

fn vcan_config(base: u8) -> Config {
    Config {
        base: Base::new(base).unwrap(),
        // vcan has no bit rate; inside UML a system call takes ~0.1–0.5 ms and threads are scheduled
        // on a slow clock: give every answer 200 ms, more under a guest that may stall.
        turnaround: Duration::from_millis(200) * scale().min(TURNAROUND_SCALE_MAX),
        stale_after: Duration::from_secs(60),
        ..Config::default()
    }
}

impl Bus for Vcan {
    fn config(&self) -> Config {
        vcan_config(self.base)
    }

    fn rig(&self, cfg: Config, mut node_cfg: NodeConfig) -> Rig {
        node_cfg.base = cfg.base;
        let source = Source::new();
        let node = make_node(node_cfg, &source);
        let thread = NodeThread::spawn(&node);
        let driver_port: Box<dyn CanTransport + Send> = Box::new(open());
        let injector: Box<dyn CanTransport + Send> = Box::new(open());
        let raiser = open();
        Rig {
            driver: Driver::new(driver_port, cfg).expect("driver"),
            node,
            source,
            injector,
            raise: Some(Box::new(move |e| {
                raiser.inject_error(e).expect("inject error frame")
            })),
            settle: || {
                std::thread::sleep(Duration::from_millis(100) * scale().min(TURNAROUND_SCALE_MAX))
            },
            keep: vec![Box::new(thread)],
        }
    }
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_startup_reads_identity_and_calibration() {
    ati_common::startup_reads_identity_and_calibration(&Vcan { base: 0x21 });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_samples_pair_with_their_requests() {
    ati_common::samples_pair_with_their_requests(&Vcan { base: 0x22 });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_answer_faults_are_counted_and_never_give_a_sample() {
    ati_common::answer_faults_are_counted_and_never_give_a_sample(&Vcan { base: 0x23 });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_extra_frames_never_disturb_pairing() {
    ati_common::extra_frames_never_disturb_pairing(&Vcan { base: 0x24 });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_timeouts_enter_and_leave_the_timeout_state_with_hysteresis() {
    ati_common::timeouts_enter_and_leave_the_timeout_state_with_hysteresis(&Vcan { base: 0x25 });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_critical_status_withholds_samples_until_it_clears() {
    ati_common::critical_status_withholds_samples_until_it_clears(&Vcan { base: 0x26 });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_saturation_is_detected_on_raw_counts() {
    ati_common::saturation_is_detected_on_raw_counts(&Vcan { base: 0x27 });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_watchdog_reset_runs_start_up_again() {
    ati_common::watchdog_reset_runs_start_up_again(&Vcan { base: 0x28 });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_old_firmware_falls_back_to_legacy_counts() {
    ati_common::old_firmware_falls_back_to_legacy_counts(&Vcan { base: 0x29 });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_start_up_refuses_a_wrong_slot_echo_and_a_silent_board() {
    ati_common::start_up_refuses_a_wrong_slot_echo_and_a_silent_board(&Vcan { base: 0x2A });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_corrupted_matrix_rows_are_asked_again() {
    ati_common::corrupted_matrix_rows_are_asked_again(&Vcan { base: 0x2B });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_bias_is_averaged_on_raw_gauges_and_refused_when_unsafe() {
    ati_common::bias_is_averaged_on_raw_gauges_and_refused_when_unsafe(&Vcan { base: 0x2C });
}

#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_bus_off_stops_polling_until_restart() {
    ati_common::bus_off_stops_polling_until_restart(&Vcan { base: 0x2D });
}

// ---- interop with can-utils -----------------------------------------------------------------------

fn tool(name: &str) -> Command {
    // The guest's PATH is minimal; can-utils lives in /usr/bin.
    let path = ["/usr/bin", "/bin", "/usr/local/bin"]
        .iter()
        .map(|d| format!("{d}/{name}"))
        .find(|p| std::path::Path::new(p).exists())
        .unwrap_or_else(|| panic!("{name} not found: install can-utils"));
    Command::new(path)
}

struct Kill(Child);

impl Drop for Kill {
    fn drop(&mut self) {
        // Ends only the child this test started, by its own handle.
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn parse_candump_line(line: &str) -> Option<Frame> {
    // `(1700000000.123456) vcan0 2E0#0000F401FF9C0000`
    let frame = line.split_whitespace().nth(2)?;
    let (id, data) = frame.split_once('#')?;
    let id = u16::from_str_radix(id, 16).ok()?;
    let bytes: Option<Vec<u8>> = (0..data.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(data.get(i..i + 2)?, 16).ok())
        .collect();
    Frame::standard(id, &bytes?)
}

/// An answer the simulated node sends is seen by `candump` with the spec's identifiers and layout.
#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_candump_sees_the_spec_identifiers_and_layout() {
    let base = Base::new(0x2E).unwrap();
    let wrench = Wrench::from_array([3.0, -1.5, 42.0, 0.2, -0.1, 0.05]);
    let source = Source::new();
    source.set(Mode::Fixed(wrench));
    let node_cfg = NodeConfig {
        base,
        ..NodeConfig::default()
    };
    let node = make_node(node_cfg, &source);
    let expected: Gauges = node.lock().gauges_for(&wrench, Duration::ZERO);
    let _serving = NodeThread::spawn(&node);

    let mut dump = Kill(
        tool("candump")
            .args([
                "-L",
                "-n",
                "3",
                &format!("{},{:03X}:7F0", iface(), base.id(0)),
            ])
            .stdout(Stdio::piped())
            .spawn()
            .expect("start candump"),
    );
    let out = dump.0.stdout.take().expect("candump stdout");
    let mut requester = open();
    let poll = Request::Poll.encode(base).unwrap();
    // candump needs a moment to bind; repeat the poll until it has seen three frames and exits.
    let mut done = false;
    for _ in 0..100 {
        requester.send(&poll).unwrap();
        std::thread::sleep(Duration::from_millis(100));
        if dump.0.try_wait().expect("candump status").is_some() {
            done = true;
            break;
        }
    }
    if !done {
        let _ = dump.0.kill();
    }
    let status = dump.0.wait().expect("candump");
    assert!(
        done && status.success(),
        "candump did not see three frames: {status}"
    );
    let mut frames: Vec<Frame> = BufReader::new(out)
        .lines()
        .map_while(Result::ok)
        .filter_map(|l| parse_candump_line(&l))
        .collect();
    frames.sort_by_key(|f| (f.id(), f.dlc()));
    let text: Vec<String> = frames.iter().map(|f| f.to_string()).collect();
    let (first, second) = ati_can::codec::split(&expected);
    let answer0 = Answer::PollFirst {
        status: ati_can::Status(0),
        gauges: first,
    }
    .encode(base)
    .unwrap();
    let answer1 = Answer::PollSecond { gauges: second }.encode(base).unwrap();
    assert_eq!(
        text,
        vec!["2E0#".to_string(), answer0.to_string(), answer1.to_string()],
        "request 2E0 DLC 0, answer 2E0 DLC 8 (status, sg0, sg2, sg4), 2E1 DLC 6 (sg1, sg3, sg5)"
    );
    // And the bytes are big-endian as the spec says: sg0 is bytes 2..4 of 2E0.
    let d = frames[1].data();
    assert_eq!(i16::from_be_bytes([d[2], d[3]]), expected.0[0]);
}

/// Frames injected with `cansend` are decoded by the driver: a node whose answers go out through
/// `cansend` (one process per frame) carries the driver through start-up and polls.
#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_cansend_frames_are_decoded_by_the_driver() {
    let base = Base::new(0x2F).unwrap();
    let wrench = Wrench::from_array([-4.0, 2.5, 17.0, -0.3, 0.15, 0.02]);
    let source = Source::new();
    source.set(Mode::Fixed(wrench));
    let node = make_node(
        NodeConfig {
            base,
            ..NodeConfig::default()
        },
        &source,
    );
    // The listening half of the node on a socket; the talking half is cansend.
    let stop = Arc::new(AtomicBool::new(false));
    let listener = {
        let (node, stop) = (node.clone(), Arc::clone(&stop));
        let mut rx = open();
        rx.accept_only(base).unwrap();
        std::thread::spawn(move || {
            let mut sent = 0u32;
            // This socket also sees what cansend sends; a slot echo looks exactly like a slot request.
            let mut own: std::collections::VecDeque<Frame> = std::collections::VecDeque::new();
            while !stop.load(Ordering::Acquire) {
                let Some(BusEvent::Frame(f)) = rx.recv(Duration::from_millis(20)).unwrap() else {
                    continue;
                };
                if own.front() == Some(&f) {
                    own.pop_front();
                    continue;
                }
                let mut answers = Vec::new();
                node.lock()
                    .handle(&f, Duration::ZERO, &mut |_, a| answers.push(a));
                for a in answers {
                    let status = tool("cansend")
                        .args([iface(), a.to_string()])
                        .status()
                        .expect("run cansend");
                    assert!(status.success(), "cansend {a} failed: {status}");
                    own.push_back(a);
                    sent += 1;
                }
            }
            sent
        })
    };
    let cfg = Config {
        // Each answer frame is a process start inside a slow guest.
        // Within the driver's own bound on a turnaround (10 s) whatever the headroom.
        turnaround: deadline(Duration::from_secs(3)).min(Duration::from_secs(10)),
        ..vcan_config(base.get())
    };
    let mut driver = Driver::new(open(), cfg).unwrap();
    let info = driver.start().expect("start-up through cansend");
    assert_eq!(info.calibration, NodeConfig::default().slots[0]);
    let mut samples = 0;
    while samples < 3 {
        if let ati_can::Outcome::Sample(_) = driver.step().unwrap() {
            samples += 1;
        }
        assert!(driver.counters().requests < 40, "{:?}", driver.counters());
    }
    let s = driver.read().unwrap();
    for (got, want) in s.wrench.to_array().iter().zip(wrench.to_array()) {
        assert!((got - want).abs() < 0.02, "{:?} vs {wrench:?}", s.wrench);
    }
    stop.store(true, Ordering::Release);
    let sent = listener.join().expect("listener");
    // 1 + 1 + 1 + 6×3 + 1 + 1 start-up frames, then two per poll.
    let polls = driver.counters().requests - 11;
    assert_eq!(u64::from(sent), 23 + 2 * polls);
}

/// Error frames reach the driver through the kernel's error filter.
#[test]
#[ignore = "needs a vcan0 interface: run scripts/vcan-tests.sh"]
fn vcan_error_frames_reach_the_transport() {
    let mut rx = open();
    rx.accept_only(Base::new(0x30).unwrap()).unwrap();
    let tx = open();
    tx.inject_error(BusError::from_raw(BusError::BUSOFF))
        .unwrap();
    let got = rx.recv(Duration::from_secs(5)).unwrap();
    assert!(
        matches!(got, Some(BusEvent::Error(BusError { bus_off: true, .. }))),
        "{got:?}"
    );
}
