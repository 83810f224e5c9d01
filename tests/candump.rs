//! candump `-L` logs of the ATI driver's traffic: the driver talks to the simulated node over the
//! in-memory bus through a logging transport; the log reads back (with the `socketcan` crate's
//! candump reader) as exactly the frames that crossed the bus, and can-utils' `log2asc` accepts it.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use std::cell::Cell;
use std::rc::Rc;

use ati_can::{Base, BusEvent, CanTransport, Clock, Config, Driver, Frame, MemBus, TransportError};
use forcecell::candump::{CanLog, CandumpWriter, Replay, read_log};
use hal::Wrench;
use sim::ati_node::{AtiNode, NodeConfig, SharedNode};

/// Counts the frames that cross the bus below the log.
struct Counting<T>(T, Rc<Cell<u64>>);

impl<T: CanTransport> CanTransport for Counting<T> {
    fn send(&mut self, frame: &Frame) -> Result<(), TransportError> {
        self.0.send(frame)?;
        self.1.set(self.1.get() + 1);
        Ok(())
    }
    fn recv(&mut self, timeout: Duration) -> Result<Option<BusEvent>, TransportError> {
        let ev = self.0.recv(timeout)?;
        if matches!(ev, Some(BusEvent::Frame(_))) {
            self.1.set(self.1.get() + 1);
        }
        Ok(ev)
    }
    fn accept_only(&mut self, base: Base) -> Result<(), TransportError> {
        self.0.accept_only(base)
    }
    fn clock(&self) -> Clock {
        self.0.clock()
    }
}

/// Start the driver on a logged in-memory bus and step it `steps` times; returns the frames logged.
fn logged_session(path: &Path, steps: usize) -> u64 {
    let base = Base::DEFAULT;
    let wrench = Wrench::from_array([0.0, 0.0, 12.5, 0.0, 0.0, 0.0]);
    let node = SharedNode::new(
        AtiNode::new(
            NodeConfig {
                base,
                ..NodeConfig::default()
            },
            move |_t: Duration| wrench,
        )
        .unwrap(),
    );
    let bus = MemBus::with_virtual_clock();
    bus.attach(node);
    let log = CandumpWriter::create(path, "vcan0").unwrap();
    let count = Rc::new(Cell::new(0));
    let mut driver = Driver::new(
        CanLog::new(Counting(bus.port(), count.clone()), log),
        Config {
            base,
            ..Config::default()
        },
    )
    .unwrap();
    driver.start().unwrap();
    for _ in 0..steps {
        driver.step().unwrap();
    }
    drop(driver);
    count.get()
}

#[test]
fn the_log_holds_every_frame_of_a_session_in_candump_format() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ati.log");
    let frames = logged_session(&path, 50);
    let text = std::fs::read_to_string(&path).unwrap();
    let first = text.lines().next().unwrap();
    // `(1700000000.123456) vcan0 201#` — seconds.micros, the interface, ID#DATA.
    assert!(first.starts_with('('), "{first}");
    assert!(first.contains(") vcan0 "), "{first}");
    let logged = read_log(&path).unwrap();
    assert_eq!(
        logged.len() as u64,
        frames,
        "every frame sent or received is logged"
    );
    let base = Base::DEFAULT;
    assert!(
        logged
            .iter()
            .all(|(_, dev, f)| dev == "vcan0" && f.id() >> 4 == u32::from(base.id(0)) >> 4),
        "only the sensor's ids"
    );
    for w in logged.windows(2) {
        assert!(w[1].0 >= w[0].0, "times in order");
    }
    // Requests (remote or data) and answers with data both appear.
    assert!(logged.iter().any(|(_, _, f)| !f.data().is_empty()));
    let round: Vec<Frame> = logged.iter().map(|(_, _, f)| *f).collect();
    let again = forcecell::candump::to_socketcan(&round[0])
        .and_then(|f| forcecell::candump::from_socketcan(&f))
        .unwrap();
    assert_eq!(again, round[0]);
}

#[test]
#[ignore = "needs can-utils (log2asc): apt-get install can-utils"]
fn can_utils_log2asc_reads_the_log() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ati.log");
    let frames = logged_session(&path, 20);
    let out = Command::new("log2asc")
        .args(["-I"])
        .arg(&path)
        .arg("vcan0")
        .output()
        .expect("run log2asc (apt-get install can-utils)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let asc = String::from_utf8_lossy(&out.stdout);
    // One ASC line per frame, each naming channel 1 and the frame's id.
    let lines = asc
        .lines()
        .filter(|l| l.trim_start().starts_with(|c: char| c.is_ascii_digit()) && l.contains(" 1 "))
        .count() as u64;
    assert_eq!(lines, frames, "{asc}");
}

/// A session with a noisy node (every reading differs), logged to `path`; returns its readings.
fn noisy_session(path: &Path, samples: usize) -> Vec<[f64; 6]> {
    let base = Base::DEFAULT;
    let wrench = Wrench::from_array([1.5, -2.0, 12.5, 0.1, -0.2, 0.03]);
    let node = SharedNode::new(
        AtiNode::new(
            NodeConfig {
                base,
                noise_counts: 40.0,
                ..NodeConfig::default()
            },
            move |_t: Duration| wrench,
        )
        .unwrap(),
    );
    let bus = MemBus::with_virtual_clock();
    bus.attach(node);
    let log = CandumpWriter::create(path, "vcan0").unwrap();
    let driver = Driver::new(
        CanLog::new(bus.port(), log),
        Config {
            base,
            ..Config::default()
        },
    )
    .unwrap();
    readings(driver, samples)
}

fn readings<T: CanTransport>(mut driver: Driver<T>, samples: usize) -> Vec<[f64; 6]> {
    readings_from(&mut driver, samples)
}

#[test]
fn a_replayed_log_gives_the_driver_the_recorded_readings() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("field.log");
    let recorded = noisy_session(&path, 40);
    assert_eq!(recorded.len(), 40);
    assert!(
        recorded.windows(2).all(|w| w[0] != w[1]),
        "noise makes every reading differ"
    );

    let records = read_log(&path).unwrap();
    let replay = Replay::from_log(&records, Base::DEFAULT).unwrap();
    assert_eq!(replay.recorded_polls, 40);
    // A fresh driver against the replay (it re-reads identity and calibration from the log).
    let bus = MemBus::with_virtual_clock();
    bus.attach(replay);
    let mut driver = Driver::new(
        bus.port(),
        Config {
            base: Base::DEFAULT,
            ..Config::default()
        },
    )
    .unwrap();
    let replayed = readings_from(&mut driver, 40);
    assert_eq!(replayed, recorded, "the recorded readings, in order");
    // Past the log's last poll the replay is silent: the trace has ended.
    assert!(matches!(driver.step().unwrap(), ati_can::Outcome::NoAnswer));

    // A log with no request on the base asked for is refused.
    let other = Base::new(0x31).unwrap();
    assert!(Replay::from_log(&records, other).is_err());
}

fn readings_from<T: CanTransport>(driver: &mut Driver<T>, samples: usize) -> Vec<[f64; 6]> {
    driver.start().unwrap();
    let mut out = Vec::new();
    for _ in 0..samples * 3 {
        if let ati_can::Outcome::Sample(_) = driver.step().unwrap() {
            out.push(driver.last_sample().unwrap().wrench.to_array());
            if out.len() == samples {
                break;
            }
        }
    }
    out
}

/// The node, with the answer to one poll (the `late`-th) held back `extra` beyond its turnaround.
struct LateOnce {
    node: SharedNode,
    polls: u32,
    late: u32,
    extra: Duration,
}

impl ati_can::Responder for LateOnce {
    fn on_frame(&mut self, frame: &Frame, now: Duration, out: &mut dyn FnMut(Duration, Frame)) {
        let poll = matches!(
            ati_can::Request::decode(frame, Base::DEFAULT),
            Ok(ati_can::Request::Poll)
        );
        let extra = if poll {
            self.polls += 1;
            if self.polls == self.late {
                self.extra
            } else {
                Duration::ZERO
            }
        } else {
            Duration::ZERO
        };
        self.node
            .on_frame(frame, now, &mut |d, f| out(d + extra, f));
    }
}

/// Step a driver 30 times; its readings and counters.
fn stepped<T: CanTransport>(mut driver: Driver<T>) -> (Vec<[f64; 6]>, ati_can::Counters) {
    driver.start().unwrap();
    let mut out = Vec::new();
    for _ in 0..30 {
        if let ati_can::Outcome::Sample(_) = driver.step().unwrap() {
            out.push(driver.last_sample().unwrap().wrench.to_array());
        }
    }
    (out, driver.counters())
}

#[test]
fn a_field_trace_with_a_late_answer_replays_the_same_readings() {
    // What a field trace is replayed for: the sensor answered one poll late (within the next poll's
    // window, or after it). The replay gives the driver the same timeout and the same readings.
    for extra_ms in [15, 45] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("field.log");
        let wrench = Wrench::from_array([1.5, -2.0, 12.5, 0.1, -0.2, 0.03]);
        let node = SharedNode::new(
            AtiNode::new(
                NodeConfig {
                    noise_counts: 40.0,
                    ..NodeConfig::default()
                },
                move |_t: Duration| wrench,
            )
            .unwrap(),
        );
        let bus = MemBus::with_virtual_clock();
        bus.attach(LateOnce {
            node,
            polls: 0,
            late: 10,
            extra: Duration::from_millis(extra_ms),
        });
        let log = CandumpWriter::create(&path, "vcan0").unwrap();
        let (live, c) =
            stepped(Driver::new(CanLog::new(bus.port(), log), Config::default()).unwrap());
        assert_eq!(c.timeouts, 1, "{extra_ms} ms late: {c:?}");
        assert!(live.len() > 20, "{c:?}");

        let replay = Replay::from_log(&read_log(&path).unwrap(), Base::DEFAULT).unwrap();
        let bus = MemBus::with_virtual_clock();
        bus.attach(replay);
        let (again, c2) = stepped(Driver::new(bus.port(), Config::default()).unwrap());
        assert_eq!(
            again, live,
            "{extra_ms} ms late: the recorded readings, in order"
        );
        assert_eq!((c2.timeouts, c2.samples), (c.timeouts, c.samples), "{c2:?}");
    }
}
