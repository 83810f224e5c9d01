//! The driver-against-node scenarios, written once and run on two transports: the in-memory bus on a
//! virtual clock (`ati_driver.rs`, plain `cargo test`) and a real SocketCAN vcan interface
//! (`ati_vcan.rs`, run by `scripts/vcan-tests.sh`).
//!
//! Every scenario drives the driver one exchange at a time (`Driver::step`) and checks the pairing of
//! every sample with its request: the node's true wrench for its k-th poll has `Fz = pair_force(k)`, and
//! the driver's sample of its k-th poll has `seq = k`, so a late or foreign answer paired with the wrong
//! request shows up as a wrong force.
#![allow(dead_code)]

use core::time::Duration;
use std::sync::{Arc, Mutex};

use ati_can::{
    AtiError, BiasConfig, BiasError, CanTransport, Config, Counters, Driver, Firmware, Health,
    Outcome, StartupProblem, Status,
};
use hal::{Error as _, ErrorKind, Wrench};
use sim::ati_node::{AtiNode, Fault, NodeConfig, SharedNode};

/// What the test source returns.
#[derive(Clone, Copy, Debug)]
pub enum Mode {
    /// `Fz = pair_force(k)` for the node's k-th poll.
    Pairing,
    /// A constant wrench.
    Fixed(Wrench),
    /// A wrench that alternates between two values every poll (a moving or vibrating tool).
    Alternating(Wrench, Wrench),
}

pub fn pair_force(k: u64) -> f64 {
    1.0 + (k % 200) as f64 * 0.5
}

/// The node's wrench source, steerable from the test.
#[derive(Clone)]
pub struct Source {
    mode: Arc<Mutex<Mode>>,
}

impl Source {
    pub fn new() -> Self {
        Self {
            mode: Arc::new(Mutex::new(Mode::Pairing)),
        }
    }

    pub fn mode(&self) -> Mode {
        *self.mode.lock().unwrap()
    }

    pub fn set(&self, m: Mode) {
        *self.mode.lock().unwrap() = m;
    }

    fn node_source(&self) -> impl FnMut(Duration) -> Wrench + Send + 'static {
        let mode = Arc::clone(&self.mode);
        let mut k = 0u64;
        move |_t| {
            k += 1;
            match *mode.lock().unwrap() {
                Mode::Pairing => Wrench::from_array([0.0, 0.0, pair_force(k), 0.0, 0.0, 0.0]),
                Mode::Fixed(w) => w,
                Mode::Alternating(a, b) => {
                    if k.is_multiple_of(2) {
                        a
                    } else {
                        b
                    }
                }
            }
        }
    }
}

/// A driver, the node it talks to, and a spare endpoint on the same bus to inject frames from.
pub struct Rig {
    pub driver: Driver<Box<dyn CanTransport + Send>>,
    pub node: SharedNode,
    pub source: Source,
    pub injector: Box<dyn CanTransport + Send>,
    /// Raise a controller error on the bus, where the transport can.
    pub raise: Option<Box<dyn Fn(ati_can::BusError)>>,
    /// Let frames already sent by other threads arrive (a no-op on the synchronous in-memory bus).
    pub settle: fn(),
    /// Whatever must live as long as the rig (a node thread).
    pub keep: Vec<Box<dyn std::any::Any>>,
}

/// How to build a rig on some transport.
pub trait Bus {
    /// Driver settings suited to this transport (deadlines).
    fn config(&self) -> Config;
    fn rig(&self, cfg: Config, node_cfg: NodeConfig) -> Rig;
}

pub fn make_node(node_cfg: NodeConfig, source: &Source) -> SharedNode {
    SharedNode::new(AtiNode::new(node_cfg, source.node_source()).expect("node calibration"))
}

impl Rig {
    pub fn counters(&self) -> Counters {
        self.driver.counters()
    }

    /// Step until a sample (skipping quiet waits and start-up steps); panics after `max` steps.
    pub fn next_sample(&mut self, max: usize) -> u64 {
        for _ in 0..max {
            match self.driver.step().expect("step") {
                Outcome::Sample(seq) => {
                    self.check_pairing(seq);
                    return seq;
                }
                Outcome::StartupFailed(p) => panic!("start-up failed: {p}"),
                _ => {}
            }
        }
        panic!(
            "no sample within {max} steps; health {:?}, counters {:?}",
            self.driver.health(),
            self.counters()
        );
    }

    /// Steps `n` times, checking every sample's pairing; returns the outcomes.
    pub fn steps(&mut self, n: usize) -> Vec<Outcome> {
        (0..n)
            .map(|_| {
                let o = self.driver.step().expect("step");
                if let Outcome::Sample(seq) = o {
                    self.check_pairing(seq);
                }
                o
            })
            .collect()
    }

    /// The newest sample must be the true wrench of the poll it answered (checked while the source
    /// is in pairing mode).
    pub fn check_pairing(&self, seq: u64) {
        if !matches!(self.source.mode(), Mode::Pairing) {
            return;
        }
        let s = self
            .driver
            .last_sample()
            .expect("a sample after Outcome::Sample");
        assert_eq!(s.seq, seq);
        let f = s.wrench.force;
        assert!(
            (f.z - pair_force(seq)).abs() < 0.05 && f.x.abs() < 0.05 && f.y.abs() < 0.05,
            "sample {seq} reads {f:?}, expected Fz = {} (paired with the wrong request?)",
            pair_force(seq)
        );
    }

    /// Run start-up to the end and reach Ok with a first sample.
    pub fn start(&mut self) {
        self.driver.start().expect("start-up");
        self.next_sample(10);
        assert_eq!(self.driver.health(), Health::Ok);
    }

    /// Step until health is Ok again, returning the steps it took; panics after `max`.
    pub fn recover(&mut self, max: usize) -> usize {
        for i in 0..max {
            if self.driver.health() == Health::Ok {
                return i;
            }
            let o = self.driver.step().expect("step");
            if let Outcome::Sample(seq) = o {
                self.check_pairing(seq);
            }
        }
        panic!(
            "no recovery within {max} steps: {:?} {:?}",
            self.driver.health(),
            self.counters()
        );
    }
}

fn delta(a: Counters, b: Counters) -> [(&'static str, u64); 12] {
    [
        ("timeouts", b.timeouts - a.timeouts),
        ("malformed", b.malformed - a.malformed),
        ("sequence_errors", b.sequence_errors - a.sequence_errors),
        ("stray", b.stray - a.stray),
        ("foreign", b.foreign - a.foreign),
        ("device_errors", b.device_errors - a.device_errors),
        ("saturated", b.saturated - a.saturated),
        ("implausible", b.implausible - a.implausible),
        ("watchdog_resets", b.watchdog_resets - a.watchdog_resets),
        ("startup_failures", b.startup_failures - a.startup_failures),
        ("echo_mismatches", b.echo_mismatches - a.echo_mismatches),
        ("bus_off", b.bus_off - a.bus_off),
    ]
}

/// The counters that changed between `a` and `b`, by name.
pub fn changed(a: Counters, b: Counters) -> Vec<(&'static str, u64)> {
    delta(a, b).into_iter().filter(|(_, d)| *d > 0).collect()
}

// ---- scenarios ------------------------------------------------------------------------------------

pub fn startup_reads_identity_and_calibration(bus: &dyn Bus) {
    let node_cfg = NodeConfig::default();
    let expected = node_cfg.slots[3];
    let mut rig = bus.rig(
        Config {
            slot: 3,
            ..bus.config()
        },
        node_cfg,
    );
    let info = rig.driver.start().expect("start-up");
    assert_eq!(
        info.firmware,
        Firmware {
            major: 3,
            minor: 8,
            build: 1
        }
    );
    assert_eq!(info.serial_text().as_deref(), Some("FT-SIM01"));
    assert_eq!(info.slot, 3);
    assert_eq!(info.calibration, expected);
    assert!(!info.counts_assumed && !info.units_assumed);
    assert_eq!(rig.node.lock().active_slot(), 3);
    // 1 firmware + 1 serial + 1 slot + 6 matrix rows + 1 counts + 1 units
    assert_eq!(rig.counters().requests, 11);
    assert_eq!(rig.counters().startups, 1);
    assert_eq!(rig.driver.health(), Health::Waiting);
    assert!(matches!(rig.driver.read(), Err(AtiError::NotReady { .. })));
}

pub fn samples_pair_with_their_requests(bus: &dyn Bus) {
    let mut rig = bus.rig(
        Config {
            slot: 2,
            ..bus.config()
        },
        NodeConfig::default(),
    );
    rig.start();
    for _ in 0..40 {
        rig.next_sample(1);
    }
    let c = rig.counters();
    assert_eq!(c.samples, 41);
    assert_eq!(changed(Counters::default(), c), vec![]);
}

/// Every answer fault: the named counter moves, the faulted poll gives no sample, the next polls pair
/// correctly and the health stays (or comes back to) Ok.
pub fn answer_faults_are_counted_and_never_give_a_sample(bus: &dyn Bus) {
    // Pairing moves Fz by 50 counts per poll; a byte-swapped answer jumps by far more.
    let cfg = Config {
        max_gauge_step: Some(500),
        ..bus.config()
    };
    let late = cfg.deadline(ati_can::Request::Poll) * 3 / 2;
    let cases: [(Fault, &[(&str, u64)]); 10] = [
        (Fault::Drop, &[("timeouts", 1)]),
        (Fault::DropFrame(1), &[("timeouts", 1)]),
        (Fault::DropFrame(0), &[("sequence_errors", 1)]),
        (Fault::Swap, &[("sequence_errors", 1), ("stray", 1)]),
        (
            Fault::DuplicateFrame(0),
            &[("sequence_errors", 1), ("stray", 1)],
        ),
        (Fault::WrongDlc, &[("malformed", 1), ("stray", 1)]),
        (Fault::WrongOpcode(0xA), &[("malformed", 1), ("stray", 1)]),
        (
            Fault::WrongOpcode(0x3),
            &[("sequence_errors", 1), ("stray", 1)],
        ),
        (Fault::Late(late), &[("timeouts", 1), ("stray", 2)]),
        (Fault::WrongByteOrder, &[("implausible", 2)]),
    ];
    let mut rig = bus.rig(cfg, NodeConfig::default());
    rig.start();
    for (fault, expected) in cases {
        rig.next_sample(1);
        let before = rig.counters();
        rig.node.lock().inject(fault);
        let first = rig.driver.step().expect("step");
        assert!(
            !matches!(first, Outcome::Sample(_)),
            "{fault:?} gave a sample: {:?} {:?}",
            rig.driver.raw_gauges(),
            rig.counters()
        );
        // Quiet waits, then clean polls again; every sample on the way is checked for pairing.
        rig.next_sample(10);
        rig.next_sample(10);
        assert_eq!(changed(before, rig.counters()), expected, "{fault:?}");
        assert_eq!(rig.driver.health(), Health::Ok, "{fault:?}");
    }
}

/// The board's own answer plus duplicates and foreign traffic: filtered below the driver or dropped as
/// stray, never paired.
pub fn extra_frames_never_disturb_pairing(bus: &dyn Bus) {
    let mut rig = bus.rig(bus.config(), NodeConfig::default());
    rig.start();
    for fault in [Fault::Foreign, Fault::Extended, Fault::Remote] {
        let before = rig.counters();
        rig.node.lock().inject(fault);
        rig.next_sample(1);
        // The kernel filter (or the bus's) keeps these away from the driver entirely.
        assert_eq!(changed(before, rig.counters()), vec![], "{fault:?}");
    }
    let before = rig.counters();
    rig.node.lock().inject(Fault::DuplicateAnswer);
    rig.next_sample(1);
    // A duplicate that arrives only after the next request is indistinguishable from its answer
    // (CAN answers carry no tag): let it arrive first, as it does on a real bus within microseconds.
    (rig.settle)();
    rig.next_sample(1);
    assert_eq!(changed(before, rig.counters()), vec![("stray", 2)]);
    // Frames injected by another endpoint between polls are drained before the next request.
    let base = rig.driver.config().base;
    let fake = ati_can::Answer::PollSecond { gauges: [1, 2, 3] }
        .encode(base)
        .unwrap();
    rig.injector.send(&fake).unwrap();
    rig.injector
        .send(&ati_can::Frame::standard(0x7FF, &[1]).unwrap())
        .unwrap();
    (rig.settle)();
    let before = rig.counters();
    rig.next_sample(1);
    assert_eq!(changed(before, rig.counters()), vec![("stray", 1)]);
}

pub fn timeouts_enter_and_leave_the_timeout_state_with_hysteresis(bus: &dyn Bus) {
    let cfg = Config {
        timeout_after: 2,
        recover_after: 3,
        ..bus.config()
    };
    let mut rig = bus.rig(cfg, NodeConfig::default());
    rig.start();
    rig.node.lock().inject(Fault::Drop);
    rig.next_sample(10);
    assert_eq!(
        rig.driver.health(),
        Health::Ok,
        "one lost answer is not a timeout"
    );
    rig.node.lock().inject_n(Fault::Drop, 2);
    while rig.counters().timeouts < 3 {
        rig.driver.step().unwrap();
    }
    assert_eq!(rig.driver.health(), Health::Timeout);
    let e = rig.driver.read().unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Timeout);
    // Hysteresis: two good samples are not enough to leave the state.
    rig.next_sample(10);
    rig.next_sample(1);
    assert_eq!(rig.driver.health(), Health::Timeout);
    assert!(rig.driver.read().is_err());
    rig.next_sample(1);
    assert_eq!(rig.driver.health(), Health::Ok);
    assert!(rig.driver.read().is_ok());
}

pub fn critical_status_withholds_samples_until_it_clears(bus: &dyn Bus) {
    let mut rig = bus.rig(bus.config(), NodeConfig::default());
    rig.start();
    // Non-critical bits (CAN bus error, any error) keep samples flowing.
    rig.node.lock().set_status(Status::CAN_BUS_ERROR);
    rig.next_sample(1);
    assert_eq!(rig.driver.status(), Status(Status::CAN_BUS_ERROR));
    let bad = Status::ANY_ERROR | (1 << 6);
    rig.node.lock().set_status(bad);
    assert_eq!(rig.driver.step().unwrap(), Outcome::Withheld);
    assert_eq!(rig.driver.health(), Health::DeviceError(Status(bad)));
    let e = rig.driver.read().unwrap_err();
    assert_eq!(e.kind(), ErrorKind::DeviceFault);
    assert_eq!(rig.counters().device_errors, 1);
    rig.node.lock().set_status(0);
    rig.next_sample(1);
    assert!(
        matches!(rig.driver.health(), Health::DeviceError(_)),
        "hysteresis"
    );
    assert_eq!(rig.recover(5), 2);
}

pub fn saturation_is_detected_on_raw_counts(bus: &dyn Bus) {
    let mut rig = bus.rig(bus.config(), NodeConfig::default());
    rig.start();
    rig.source.set(Mode::Fixed(Wrench::from_array([
        0.0, 0.0, 900.0, 0.0, 0.0, 0.0,
    ])));
    assert_eq!(rig.driver.step().unwrap(), Outcome::Withheld);
    assert_eq!(rig.driver.health(), Health::Saturated);
    assert_eq!(rig.driver.read().unwrap_err().kind(), ErrorKind::Saturated);
    assert_eq!(
        rig.driver.begin_bias(BiasConfig::default()),
        Err(BiasError::Saturated)
    );
    rig.source.set(Mode::Pairing);
    rig.recover(10);
    assert_eq!(rig.counters().saturated, 1);
}

pub fn watchdog_reset_runs_start_up_again(bus: &dyn Bus) {
    let mut rig = bus.rig(
        Config {
            slot: 4,
            ..bus.config()
        },
        NodeConfig::default(),
    );
    rig.start();
    rig.node.lock().reset();
    assert_eq!(rig.node.lock().active_slot(), 0);
    assert_eq!(rig.driver.step().unwrap(), Outcome::Restarting);
    assert_eq!(rig.driver.health(), Health::Waiting);
    assert!(rig.driver.read().is_err());
    // Start-up again (11 requests), then samples through slot 4's calibration again.
    rig.next_sample(20);
    assert_eq!(rig.node.lock().active_slot(), 4);
    let c = rig.counters();
    assert_eq!((c.watchdog_resets, c.startups), (1, 2));
    rig.next_sample(1);
}

pub fn old_firmware_falls_back_to_legacy_counts(bus: &dyn Bus) {
    let mut node_cfg = NodeConfig {
        firmware: Firmware {
            major: 3,
            minor: 6,
            build: 9,
        },
        ..NodeConfig::default()
    };
    for slot in node_cfg.slots.iter_mut() {
        // The legacy value is what the board would use too.
        slot.counts_per_force = 1_000_000;
        slot.counts_per_torque = 1_000_000;
    }
    let mut rig = bus.rig(bus.config(), node_cfg);
    let info = rig.driver.start().expect("start-up on old firmware");
    assert!(info.counts_assumed);
    assert_eq!(info.calibration.counts_per_force, 1_000_000);
    assert_eq!(rig.counters().timeouts, 1, "one unanswered counts request");
    rig.next_sample(10);
}

pub fn start_up_refuses_a_wrong_slot_echo_and_a_silent_board(bus: &dyn Bus) {
    let node_cfg = NodeConfig {
        missing_slots: 1 << 5,
        ..NodeConfig::default()
    };
    let mut rig = bus.rig(
        Config {
            slot: 5,
            ..bus.config()
        },
        node_cfg,
    );
    let e = rig.driver.start().unwrap_err();
    assert!(
        matches!(
            e,
            AtiError::Startup(StartupProblem::SlotEcho {
                requested: 5,
                echoed: 0
            })
        ),
        "{e}"
    );
    assert_eq!(e.kind(), ErrorKind::Config);
    assert_eq!(rig.counters().echo_mismatches, 3);
    drop(rig);

    let mut rig = bus.rig(bus.config(), NodeConfig::default());
    rig.node.lock().set_silent(true);
    let e = rig.driver.start().unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Timeout, "{e}");
    assert!(e.to_string().contains("firmware"), "{e}");
    assert!(matches!(
        rig.driver.read(),
        Err(AtiError::NotReady { problem: Some(_) })
    ));
    rig.node.lock().set_silent(false);
    rig.start();
}

pub fn corrupted_matrix_rows_are_asked_again(bus: &dyn Bus) {
    let mut rig = bus.rig(bus.config(), NodeConfig::default());
    // Firmware, serial, slot answered cleanly; the first matrix row byte-swapped.
    for _ in 0..3 {
        assert_eq!(rig.driver.step().unwrap(), Outcome::StartupProgress);
    }
    rig.node.lock().inject(Fault::WrongByteOrder);
    assert_eq!(rig.driver.step().unwrap(), Outcome::NoAnswer);
    assert_eq!(rig.counters().malformed, 1);
    let info = rig.driver.start().expect("start-up after a retried row");
    assert_eq!(info.calibration, NodeConfig::default().slots[0]);
    rig.next_sample(10);
}

pub fn bias_is_averaged_on_raw_gauges_and_refused_when_unsafe(bus: &dyn Bus) {
    let mut rig = bus.rig(bus.config(), NodeConfig::default());
    rig.start();
    let tool = Wrench::from_array([1.0, -2.0, 15.0, 0.05, 0.02, -0.01]);
    rig.source.set(Mode::Fixed(tool));
    let bias = rig
        .driver
        .tare(BiasConfig {
            window: 16,
            max_spread: 4,
        })
        .expect("bias while still");
    // The bias applies to the newest sample at once (the window's last): a read before the next
    // poll (a slow poll rate) never shows the unbiased wrench.
    let s = rig.driver.read().unwrap();
    assert!(s.wrench.force.norm() < 0.02, "right after the tare: {s:?}");
    rig.driver.step().unwrap();
    let s = rig.driver.read().unwrap();
    assert!(
        s.wrench.force.norm() < 0.02 && s.wrench.torque.norm() < 1e-3,
        "{s:?}"
    );
    assert!(bias.iter().any(|b| b.abs() > 100.0), "{bias:?}");

    // Moving: refused, bias unchanged.
    rig.source.set(Mode::Alternating(
        tool,
        Wrench::from_array([1.0, -2.0, 25.0, 0.05, 0.02, -0.01]),
    ));
    let e = rig
        .driver
        .tare(BiasConfig {
            window: 16,
            max_spread: 4,
        })
        .unwrap_err();
    assert!(matches!(e, AtiError::Bias(BiasError::Moving { .. })), "{e}");
    assert_eq!(rig.driver.bias(), bias);

    // In error: refused.
    rig.source.set(Mode::Fixed(tool));
    rig.node.lock().set_status(1 << 3);
    rig.driver.step().unwrap();
    assert!(matches!(
        rig.driver.begin_bias(BiasConfig::default()),
        Err(BiasError::DeviceFault(_))
    ));
    // An error during the window fails the bias.
    rig.node.lock().set_status(0);
    rig.recover(10);
    rig.driver.begin_bias(BiasConfig::default()).unwrap();
    rig.driver.step().unwrap();
    rig.node.lock().set_status(1 << 3);
    rig.driver.step().unwrap();
    assert!(matches!(
        rig.driver.take_bias_outcome(),
        Some(Err(BiasError::DeviceFault(_)))
    ));
    assert_eq!(rig.driver.bias(), bias);
}

pub fn bus_off_stops_polling_until_restart(bus: &dyn Bus) {
    let mut rig = bus.rig(bus.config(), NodeConfig::default());
    rig.start();
    let Some(raise) = rig.raise.take() else {
        panic!("this bus cannot raise controller errors");
    };
    raise(ati_can::BusError::from_raw(ati_can::BusError::BUSOFF));
    // On a real (virtual) interface the error frame arrives like any frame: the driver may poll once
    // more before it reads it. From the step that reports bus-off on, nothing is sent.
    let mut steps = 0;
    while rig.driver.step().unwrap() != Outcome::BusOff {
        steps += 1;
        assert!(steps < 50, "bus-off never reported");
    }
    let sent = rig.counters().requests;
    for _ in 0..3 {
        assert_eq!(rig.driver.step().unwrap(), Outcome::BusOff);
    }
    assert_eq!(
        rig.counters().requests,
        sent,
        "nothing is sent while bus-off"
    );
    assert_eq!(rig.driver.health(), Health::BusOff);
    assert_eq!(rig.driver.read().unwrap_err().kind(), ErrorKind::BusOff);
    raise(ati_can::BusError::from_raw(ati_can::BusError::RESTARTED));
    assert_eq!(rig.driver.step().unwrap(), Outcome::Restarting);
    rig.next_sample(20);
    assert_eq!(rig.counters().startups, 2);
}
