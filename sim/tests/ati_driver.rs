//! The ATI driver against the simulated node on the in-memory bus (virtual clock: deterministic, no
//! wall time). The same scenarios run on a real vcan interface in `ati_vcan.rs`.

mod ati_common;

use ati_can::{CanTransport, Config, MemBus};
use ati_common::*;
use sim::ati_node::NodeConfig;

struct Mem;

impl Bus for Mem {
    fn config(&self) -> Config {
        Config::default()
    }

    fn rig(&self, cfg: Config, mut node_cfg: NodeConfig) -> Rig {
        node_cfg.base = cfg.base;
        let bus = MemBus::with_virtual_clock();
        let source = Source::new();
        let node = make_node(node_cfg, &source);
        bus.attach(node.clone());
        let port: Box<dyn CanTransport + Send> = Box::new(bus.port());
        let injector: Box<dyn CanTransport + Send> = Box::new(bus.port());
        let raiser = bus.clone();
        Rig {
            driver: ati_can::Driver::new(port, cfg).expect("driver"),
            node,
            source,
            injector,
            raise: Some(Box::new(move |e| raiser.raise_error(e))),
            settle: || {},
            keep: Vec::new(),
        }
    }
}

#[test]
fn startup_reads_identity_and_calibration() {
    ati_common::startup_reads_identity_and_calibration(&Mem);
}

#[test]
fn samples_pair_with_their_requests() {
    ati_common::samples_pair_with_their_requests(&Mem);
}

#[test]
fn answer_faults_are_counted_and_never_give_a_sample() {
    ati_common::answer_faults_are_counted_and_never_give_a_sample(&Mem);
}

#[test]
fn extra_frames_never_disturb_pairing() {
    ati_common::extra_frames_never_disturb_pairing(&Mem);
}

#[test]
fn timeouts_enter_and_leave_the_timeout_state_with_hysteresis() {
    ati_common::timeouts_enter_and_leave_the_timeout_state_with_hysteresis(&Mem);
}

#[test]
fn critical_status_withholds_samples_until_it_clears() {
    ati_common::critical_status_withholds_samples_until_it_clears(&Mem);
}

#[test]
fn saturation_is_detected_on_raw_counts() {
    ati_common::saturation_is_detected_on_raw_counts(&Mem);
}

#[test]
fn watchdog_reset_runs_start_up_again() {
    ati_common::watchdog_reset_runs_start_up_again(&Mem);
}

#[test]
fn old_firmware_falls_back_to_legacy_counts() {
    ati_common::old_firmware_falls_back_to_legacy_counts(&Mem);
}

#[test]
fn start_up_refuses_a_wrong_slot_echo_and_a_silent_board() {
    ati_common::start_up_refuses_a_wrong_slot_echo_and_a_silent_board(&Mem);
}

#[test]
fn corrupted_matrix_rows_are_asked_again() {
    ati_common::corrupted_matrix_rows_are_asked_again(&Mem);
}

#[test]
fn bias_is_averaged_on_raw_gauges_and_refused_when_unsafe() {
    ati_common::bias_is_averaged_on_raw_gauges_and_refused_when_unsafe(&Mem);
}

#[test]
fn a_bias_after_a_pause_takes_fresh_samples() {
    // A command's lock-step driver is stale when stepped late (a stalled host, a slow terminal); the
    // bias needs no recent sample, only a window of fresh ones.
    let bus = MemBus::with_virtual_clock();
    let tool = hal::Wrench::from_array([1.0, -2.0, 15.0, 0.05, 0.02, -0.01]);
    bus.attach(fixed_node(tool));
    let mut driver = ati_can::Driver::new(bus.port(), Config::default()).unwrap();
    driver.start().unwrap();
    while driver.health() != ati_can::Health::Ok {
        driver.step().unwrap();
    }
    let clock = bus.clock();
    clock.advance_to(clock.now() + Duration::from_secs(1));
    assert_eq!(driver.health(), ati_can::Health::Stale);
    let bias = driver
        .tare(BiasConfig {
            window: 16,
            max_spread: 4,
        })
        .expect("a bias after a pause");
    assert!(bias[2].abs() > 100.0, "{bias:?}");
    let s = driver.read().unwrap();
    assert!(s.wrench.force.norm() < 0.02, "{s:?}");
}

#[test]
fn bus_off_stops_polling_until_restart() {
    ati_common::bus_off_stops_polling_until_restart(&Mem);
}

// ---- the two ForceSensor faces of the driver ------------------------------------------------------

use std::time::{Duration, Instant};

use ati_can::{AtiError, AtiSensor, BiasConfig, Driver, Health, Lockstep};
use hal::{Error as _, ErrorKind, ForceSensor, Wrench};
use sim::ati_node::{AtiNode, SharedNode};

fn fixed_node(w: Wrench) -> SharedNode {
    SharedNode::new(AtiNode::new(NodeConfig::default(), move |_t: Duration| w).unwrap())
}

/// Wait (bounded, generously) until `f` holds; panics with `what` otherwise. Not a timing assertion:
/// the bound only keeps a broken build from hanging.
fn eventually(what: &str, mut f: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !f() {
        assert!(t0.elapsed() < Duration::from_secs(30), "never: {what}");
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn background_sensor_reads_the_newest_sample_and_tares_through_the_poller() {
    let w = Wrench::from_array([0.5, -1.0, 20.0, 0.01, 0.02, 0.03]);
    let bus = MemBus::new();
    let node = fixed_node(w);
    bus.attach(node.clone());
    let driver = Driver::new(bus.port(), Config::default()).unwrap();
    let mut sensor = AtiSensor::spawn(driver, 200.0).unwrap();
    eventually("health Ok", || sensor.health() == Health::Ok);
    let s = sensor.read().unwrap();
    assert!((s.wrench.force.z - 20.0).abs() < 0.02, "{s:?}");
    let info = sensor.info().unwrap();
    assert_eq!(info.slot, 0);
    let first = s.seq;
    eventually("a newer sample", || {
        sensor.read().is_ok_and(|s| s.seq > first)
    });

    let bias = sensor
        .tare(
            BiasConfig {
                window: 20,
                max_spread: 2,
            },
            Duration::from_secs(30),
        )
        .unwrap();
    assert_eq!(sensor.bias(), bias);
    eventually("a biased sample", || {
        sensor.read().is_ok_and(|s| s.wrench.force.norm() < 0.02)
    });

    // A critical status reaches `read` as a DeviceFault, never as a sample.
    node.lock().set_status(1 << 4);
    eventually("device error", || {
        matches!(sensor.health(), Health::DeviceError(_))
    });
    assert_eq!(sensor.read().unwrap_err().kind(), ErrorKind::DeviceFault);
    sensor.stop();
}

#[test]
fn background_sensor_refuses_impossible_rates_and_virtual_clocks() {
    let bus = MemBus::new();
    let slow = Config {
        bitrate: 250_000,
        ..Config::default()
    };
    let e = AtiSensor::spawn(Driver::new(bus.port(), slow).unwrap(), 1000.0).unwrap_err();
    assert_eq!(e.kind(), ErrorKind::Config);
    assert!(e.to_string().contains("raise the bit rate"), "{e}");
    assert!(AtiSensor::spawn(Driver::new(bus.port(), Config::default()).unwrap(), 0.0).is_err());
    let virt = MemBus::with_virtual_clock();
    let e =
        AtiSensor::spawn(Driver::new(virt.port(), Config::default()).unwrap(), 100.0).unwrap_err();
    assert!(e.to_string().contains("Lockstep"), "{e}");
}

#[test]
fn lockstep_read_is_one_exchange_with_the_world_as_it_is_now() {
    let bus = MemBus::with_virtual_clock();
    let fz = std::sync::Arc::new(std::sync::Mutex::new(1.0));
    let source = {
        let fz = fz.clone();
        move |_t: Duration| Wrench::from_array([0.0, 0.0, *fz.lock().unwrap(), 0.0, 0.0, 0.0])
    };
    let node = SharedNode::new(AtiNode::new(NodeConfig::default(), source).unwrap());
    bus.attach(node.clone());
    let mut driver = Driver::new(bus.port(), Config::default()).unwrap();
    driver.start().unwrap();
    let mut sensor = Lockstep(driver);
    for k in 1..=5u64 {
        *fz.lock().unwrap() = 3.0 * k as f64;
        let s = sensor.read().unwrap();
        assert_eq!(s.seq, k);
        assert!((s.wrench.force.z - 3.0 * k as f64).abs() < 0.02, "{s:?}");
        assert_eq!(
            s.age,
            Duration::ZERO,
            "answered in the caller's thread, no bus time passed"
        );
    }
    assert_eq!(sensor.driver().counters().requests, 11 + 5);
    // A board that stops answering: the old sample ages, then the driver reports a timeout.
    node.lock().set_silent(true);
    let mut errors = Vec::new();
    for _ in 0..12 {
        if let Err(e) = sensor.read() {
            errors.push(e.kind());
        }
    }
    assert!(errors.contains(&ErrorKind::Timeout), "{errors:?}");
    assert!(matches!(sensor.read(), Err(AtiError::Timeout)));
}

// ---- random fault sequences ----------------------------------------------------------------------

use proptest::prelude::*;
use sim::ati_node::Fault;

/// Every answer fault except the byte order, which no single-answer check can catch in general (see
/// the driver's README; `answer_faults_are_counted_and_never_give_a_sample` covers its detection).
fn answer_fault() -> impl Strategy<Value = Fault> {
    // The poll's deadline is the shortest of all requests: 2.8 of it is inside every late window.
    let d = Config::default().deadline(ati_can::Request::Poll);
    prop_oneof![
        Just(Fault::Drop),
        (0usize..3).prop_map(Fault::DropFrame),
        Just(Fault::Swap),
        (0usize..3).prop_map(Fault::DuplicateFrame),
        Just(Fault::DuplicateAnswer),
        Just(Fault::WrongDlc),
        (0u8..16).prop_map(Fault::WrongOpcode),
        // Up to 2.8 deadlines late: inside the late window the driver waits out. Later than 3 deadlines
        // an answer is indistinguishable from the next one's (CAN answers carry no tag): the driver's
        // stated assumption, which proptest finds at once when this range is widened.
        (1u32..29).prop_map(move |tenths| Fault::Late(d * tenths / 10)),
        Just(Fault::Foreign),
        Just(Fault::Extended),
        Just(Fault::Remote),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Whatever goes wrong with the answers, every sample is the true wrench of the poll it answered,
    /// and the driver is back to Ok once the faults stop.
    #[test]
    fn random_answer_faults_never_mispair_and_always_recover(
        faults in proptest::collection::vec((answer_fault(), 0usize..3), 1..25)
    ) {
        let mut rig = Mem.rig(Config::default(), NodeConfig::default());
        rig.start();
        for (fault, gap) in faults {
            rig.node.lock().inject(fault);
            rig.steps(gap);
        }
        // Let the node use up the faults still queued, then expect recovery.
        for _ in 0..200 {
            if rig.node.lock().pending_faults() == 0 {
                break;
            }
            rig.steps(1);
        }
        prop_assert_eq!(rig.node.lock().pending_faults(), 0);
        rig.recover(40);
        rig.next_sample(10);
    }

    /// Faults during start-up (byte order included) cost retries, never a wrong calibration.
    #[test]
    fn random_start_up_faults_never_give_a_wrong_calibration(
        faults in proptest::collection::vec(
            prop_oneof![answer_fault(), Just(Fault::WrongByteOrder)], 1..15)
    ) {
        let mut rig = Mem.rig(Config { slot: 6, ..Config::default() }, NodeConfig::default());
        for f in faults {
            rig.node.lock().inject(f);
        }
        let mut started = None;
        for _ in 0..20 {
            if let Ok(info) = rig.driver.start() {
                started = Some(info);
                break;
            }
        }
        let info = started.expect("start-up within 20 passes");
        prop_assert_eq!(info.calibration, NodeConfig::default().slots[6]);
        prop_assert_eq!(info.slot, 6);
        prop_assert!(!info.counts_assumed);
    }
}
