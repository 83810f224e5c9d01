//! The loop's unit tests, against mocked devices.
use super::*;
use crate::law::{ContactState, ImpedanceLaw};
use hal::mock::{MockRobot, MockSensor};
use hal::{Pose, ProcessFault, Sample, Vector3, Wrench};
use mockall::Sequence;
use std::time::Duration;

fn cycle_at(seq: u64, x: f64) -> Cycle {
    Cycle {
        seq,
        t: seq as f64 * 0.004,
        period: 0.004,
        actual: Pose::from_position(Vector3::new(0.0, 0.0, x)),
        programmed: Pose::identity(),
        late_replies: 0,
        missed: 0,
        replied_late: 0,
        new_session: false,
        process: None,
    }
}

fn sample(fz: f64) -> Sample {
    Sample {
        wrench: Wrench::from_array([0.0, 0.0, fz, 0.0, 0.0, 0.0]),
        seq: 1,
        age: Duration::ZERO,
    }
}

fn fixed_law(x_r: f64) -> ImpedanceLaw {
    ImpedanceLaw::new(
        crate::ImpedanceParams::PAPER,
        crate::Reference::Fixed { x_r },
    )
    .unwrap()
}

#[test]
fn calls_are_cycle_then_wrench_then_one_reply() {
    let mut seq = Sequence::new();
    let mut robot = MockRobot::new();
    let mut sensor = MockSensor::new();
    for k in 0..3 {
        robot
            .expect_next_cycle()
            .times(1)
            .in_sequence(&mut seq)
            .returning(move || Ok(cycle_at(k, 0.001)));
        sensor
            .expect_read()
            .times(1)
            .in_sequence(&mut seq)
            .returning(|| Ok(sample(0.0)));
        robot
            .expect_reply()
            .times(1)
            .in_sequence(&mut seq)
            .returning(|_| Ok(()));
    }
    let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.002), LoopConfig::default());
    for _ in 0..3 {
        lp.cycle().unwrap();
    }
    assert_eq!(lp.stats().cycles, 3);
}

#[test]
fn sensor_timeout_holds_without_a_step_and_counts() {
    let mut robot = MockRobot::new();
    let mut sensor = MockSensor::new();
    robot
        .expect_next_cycle()
        .returning(|| Ok(cycle_at(1, 0.001)));
    let mut n = 0;
    sensor.expect_read().returning(move || {
        n += 1;
        if n == 1 {
            Ok(sample(0.0))
        } else {
            Err(ErrorKind::Timeout)
        }
    });
    let replies = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let r2 = replies.clone();
    robot.expect_reply().returning(move |c| {
        r2.lock().unwrap().push(*c);
        Ok(())
    });
    let mut lp = ControlLoop::new(robot, sensor, ImpedanceLaw::paper(), LoopConfig::default());
    let first = lp.cycle().unwrap();
    assert_eq!(first.fault, None);
    let law_before = lp.law().inner().clone();
    let second = lp.cycle().unwrap();
    assert_eq!(second.fault, Some(Fault::Sensor(ErrorKind::Timeout)));
    assert_eq!(lp.stats().sensor_faults, 1);
    assert_eq!(
        lp.law().inner(),
        &law_before,
        "the law must not step on a held cycle"
    );
    let r = replies.lock().unwrap();
    assert_eq!(r.len(), 2);
    assert_eq!(r[0], r[1], "a held cycle repeats the last command");
}

#[test]
fn lost_robot_link_ends_the_loop_with_the_error() {
    let mut robot = MockRobot::new();
    let sensor = MockSensor::new();
    robot
        .expect_next_cycle()
        .returning(|| Err(ErrorKind::LinkLost));
    robot.expect_reply().never();
    let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.002), LoopConfig::default());
    match lp.cycle() {
        Err(LoopError::Robot(ErrorKind::LinkLost)) => {}
        other => panic!("expected the robot's LinkLost, got {other:?}"),
    }
    assert!(
        format!("{}", LoopError::<_, ErrorKind>::Robot(ErrorKind::LinkLost)).contains("link lost")
    );
}

#[test]
fn transient_robot_errors_are_counted_and_skipped() {
    let mut robot = MockRobot::new();
    let mut sensor = MockSensor::new();
    let mut n = 0;
    robot.expect_next_cycle().returning(move || {
        n += 1;
        if n == 1 {
            Err(ErrorKind::Malformed)
        } else {
            Ok(cycle_at(2, 0.0))
        }
    });
    sensor.expect_read().returning(|| Ok(sample(0.0)));
    robot.expect_reply().times(1).returning(|_| Ok(()));
    let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.0), LoopConfig::default());
    lp.cycle().unwrap();
    assert_eq!(lp.stats().robot_glitches, 1);
}

#[test]
fn nan_wrench_never_reaches_the_command() {
    let mut robot = MockRobot::new();
    let mut sensor = MockSensor::new();
    robot
        .expect_next_cycle()
        .returning(|| Ok(cycle_at(1, 0.001)));
    sensor.expect_read().returning(|| Ok(sample(f64::NAN)));
    robot
        .expect_reply()
        .withf(|c: &Correction| c.is_finite() && c.translation.z == 0.001)
        .times(2)
        .returning(|_| Ok(()));
    let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.002), LoopConfig::default());
    for _ in 0..2 {
        let r = lp.cycle().unwrap();
        assert_eq!(r.fault, Some(Fault::NonFiniteSample));
        assert!(r.command.is_finite());
    }
    assert_eq!(lp.stats().nonfinite_inputs, 2);
}

/// Runs cycles until the loop ends; returns the corrections sent and the error it ended with.
fn run_until_end(
    lp: &mut MockLoop,
    sent: &std::sync::Mutex<Vec<Correction>>,
) -> (Vec<Correction>, LoopError<ErrorKind, ErrorKind>) {
    for _ in 0..10_000 {
        if let Err(e) = lp.cycle() {
            return (sent.lock().unwrap().clone(), e);
        }
    }
    panic!("the loop never ended")
}

type MockLoop = ControlLoop<MockRobot, MockSensor, AlongNormal<ImpedanceLaw>>;
type SentLog = std::sync::Arc<std::sync::Mutex<Vec<Correction>>>;

/// A robot at a fixed pose whose replies are logged, and a sensor that answers `read` in turn.
fn logged(
    read: impl FnMut(u64) -> Result<Sample, ErrorKind> + Send + 'static,
) -> (MockLoop, SentLog) {
    let (robot, sensor, sent) = devices(0.001, read);
    let lp = ControlLoop::new(robot, sensor, fixed_law(0.001), LoopConfig::default());
    (lp, sent)
}

/// A robot at `x` whose replies are logged, and a sensor that answers `read` in turn.
fn devices(
    x: f64,
    mut read: impl FnMut(u64) -> Result<Sample, ErrorKind> + Send + 'static,
) -> (MockRobot, MockSensor, SentLog) {
    let mut robot = MockRobot::new();
    let mut sensor = MockSensor::new();
    let mut k = 0;
    robot.expect_next_cycle().returning(move || {
        k += 1;
        Ok(cycle_at(k, x))
    });
    let mut n = 0;
    sensor.expect_read().returning(move || {
        n += 1;
        read(n)
    });
    let sent = SentLog::default();
    let log = sent.clone();
    robot.expect_reply().returning(move |c| {
        log.lock().unwrap().push(*c);
        Ok(())
    });
    (robot, sensor, sent)
}

/// The commands after `from` only ever back off (−z), by no more than the retract speed allows per
/// cycle, and end `retract_distance` below the command at `from`.
fn assert_backed_off(sent: &[Correction], from: usize) {
    let cfg = LoopConfig::default();
    let per_cycle = cfg.retract_speed * 0.004 + 1e-12;
    let z: Vec<f64> = sent.iter().map(|c| c.translation.z).collect();
    for w in z[from..].windows(2) {
        assert!(w[1] <= w[0] && w[0] - w[1] <= per_cycle, "{w:?}");
    }
    let backed = z[from] - z[z.len() - 1];
    assert!(
        (backed - cfg.retract_distance).abs() < 1e-12,
        "backed off {backed} m"
    );
}

#[test]
fn fatal_sensor_error_backs_off_then_ends() {
    let (mut lp, sent) = logged(|n| {
        if n < 3 {
            Ok(sample(0.0))
        } else {
            Err(ErrorKind::BusOff)
        }
    });
    let (sent, end) = run_until_end(&mut lp, &sent);
    assert!(
        matches!(end, LoopError::Sensor(ErrorKind::BusOff)),
        "{end:?}"
    );
    assert!(end.to_string().contains("backed off"), "{end}");
    // The failing cycle (the third) is answered with the last command; then the back-off.
    assert_eq!(sent[2], sent[1]);
    assert_backed_off(&sent, 2);
    assert_eq!(lp.stats().retract_cycles as usize, sent.len() - 3);
}

#[test]
fn a_hold_is_bounded_in_time_then_the_tool_backs_off() {
    // Two good samples, then the sensor only times out: the loop may hold 0.1 s (25 cycles of 4 ms).
    let (mut lp, sent) = logged(|n| {
        if n <= 2 {
            Ok(sample(0.0))
        } else {
            Err(ErrorKind::Timeout)
        }
    });
    let (sent, end) = run_until_end(&mut lp, &sent);
    let LoopError::HoldTimeout { held, last } = end else {
        panic!("expected a hold timeout, got {end:?}")
    };
    assert_eq!(last, Fault::Sensor(ErrorKind::Timeout));
    let cfg = LoopConfig::default();
    assert!(
        held > cfg.max_hold && held <= cfg.max_hold + 0.004 + 1e-9,
        "{held}"
    );
    let held_cycles = (held / 0.004).round() as usize;
    // Every held cycle repeated the last good command.
    for c in &sent[2..2 + held_cycles] {
        assert_eq!(c, &sent[1]);
    }
    assert_backed_off(&sent, 1 + held_cycles);
    // After the fault was reported, the loop keeps answering at the backed-off position.
    let r = lp.cycle().expect("a halted loop still answers");
    assert_eq!(r.fault, Some(Fault::Retracting));
    assert_eq!(r.command, *sent.last().unwrap());
}

#[test]
fn a_hold_shorter_than_max_hold_resumes_control() {
    // A 20-cycle (80 ms) dropout, under the 100 ms bound: the law resumes, nothing backs off.
    let (mut lp, sent) = logged(|n| {
        if (3..23).contains(&n) {
            Err(ErrorKind::Timeout)
        } else {
            Ok(sample(0.0))
        }
    });
    for _ in 0..60 {
        lp.cycle().expect("a short hold does not end the loop");
    }
    assert_eq!(lp.stats().retract_cycles, 0);
    assert_eq!(lp.stats().sensor_faults, 20);
    assert_eq!(sent.lock().unwrap().len(), 60);
}

/// The replies from `from` on report FAULT with `code` (on links with process channels the robot
/// program sees it in `FcState`).
fn assert_reported(sent: &[Correction], from: usize, code: ProcessFault) {
    for c in &sent[from..] {
        assert_eq!(c.process.phase, hal::ProcessPhase::Fault, "{c:?}");
        assert_eq!(c.process.fault, code);
    }
    assert!(
        sent[..from]
            .iter()
            .all(|c| c.process.phase == hal::ProcessPhase::Off),
        "no fault reported before it happened"
    );
}

#[test]
fn without_process_channels_the_force_limit_retracts_and_ends_with_its_code() {
    // Contact at 5 N, then the force jumps to 70 N (above the 60 N limit) on the sixth sample
    // and stays there for the first 40 cycles of the back-off: the tool still touches, so it
    // backs off until free (the 46th sample reads 0 N), then `retract_distance` further.
    let (mut lp, sent) = logged(|n| {
        Ok(sample(match n {
            ..6 => 5.0,
            6..46 => 70.0,
            _ => 0.0,
        }))
    });
    let (sent, end) = run_until_end(&mut lp, &sent);
    let LoopError::Guard { code, reason } = &end else {
        panic!("expected the guard to end the loop, got {end:?}")
    };
    assert_eq!(*code, ProcessFault::ForceLimit);
    assert_eq!(end.code(), Some(ProcessFault::ForceLimit));
    assert!(
        reason.contains("70.0") && reason.contains("60.0"),
        "{reason}"
    );
    assert!(end.to_string().contains("fault 2 (force limit)"), "{end}");
    // The sixth cycle commands as the law asked; from then on the tool only backs off, the
    // last 2 mm after it came free.
    let z: Vec<f64> = sent.iter().map(|c| c.translation.z).collect();
    for w in z[5..].windows(2) {
        assert!(w[1] < w[0], "only backing off: {w:?}");
    }
    let free = z[44];
    let backed = free - z[z.len() - 1];
    assert!(
        backed <= LoopConfig::default().retract_distance + 1e-12 && backed > 0.0019,
        "{backed} m after the last touching sample"
    );
    assert!(
        z[5] - z[z.len() - 1] > 0.0035,
        "more than 2 mm in all: {z:?}"
    );
    assert_reported(&sent, 6, ProcessFault::ForceLimit);
    assert_eq!(lp.process_fault_reason(), Some(reason.as_str()));
    // The `Stop` that ends the session carries the fault too.
    lp.stop().unwrap();
    assert_eq!(lp.process_state().fault, ProcessFault::ForceLimit);
}

#[test]
fn without_process_channels_a_contact_lost_too_long_retracts_and_ends() {
    // Contact at 5 N for 20 cycles, then nothing: lost after 0.5 s of 4 ms cycles.
    let (mut lp, sent) = logged(|n| Ok(sample(if n <= 20 { 5.0 } else { 0.0 })));
    let (sent, end) = run_until_end(&mut lp, &sent);
    assert_eq!(end.code(), Some(ProcessFault::ContactLost), "{end}");
    let faulted = sent
        .iter()
        .position(|c| c.process.phase == hal::ProcessPhase::Fault)
        .expect("a fault reported");
    // The filtered force falls below the 2 N entry force a few cycles after the last contact;
    // more than 0.5 s (125 cycles) later the loop faults.
    assert!((20 + 125..20 + 125 + 10).contains(&faulted), "{faulted}");
    assert_backed_off(&sent, faulted - 1);
    assert_reported(&sent, faulted, ProcessFault::ContactLost);
}

#[test]
fn a_short_loss_of_contact_does_not_end_the_loop() {
    // 0.3 s without contact, under the 0.5 s bound, then contact again: control goes on.
    let (mut lp, sent) = logged(|n| Ok(sample(if (20..95).contains(&n) { 0.0 } else { 5.0 })));
    for _ in 0..400 {
        lp.cycle().expect("a short loss does not end the loop");
    }
    assert_eq!(lp.stats().retract_cycles, 0);
    assert!(
        sent.lock()
            .unwrap()
            .iter()
            .all(|c| c.process.phase == hal::ProcessPhase::Off)
    );
}

#[test]
fn without_process_channels_the_correction_envelope_ends_the_loop() {
    let (robot, sensor, sent) = devices(0.0, |_| Ok(sample(0.0)));
    // The law wants 8 mm; the envelope is 5 mm and a step 1 mm: five steps reach 5 mm, the sixth
    // is clipped to the envelope.
    let law = DtLaw {
        at: Some(0.008),
        ..DtLaw::default()
    };
    let mut lp = ControlLoop::new(robot, sensor, law, LoopConfig::default());
    let (sent, end) = loop {
        if let Err(e) = lp.cycle() {
            break (sent.lock().unwrap().clone(), e);
        }
    };
    assert_eq!(end.code(), Some(ProcessFault::CorrectionLimit), "{end}");
    let z: Vec<f64> = sent.iter().map(|c| c.translation.z).collect();
    assert!(z.iter().all(|z| *z <= 0.005 + 1e-15), "{z:?}");
    let at_limit = z.iter().position(|z| *z >= 0.005 - 1e-15).unwrap();
    assert_eq!(at_limit, 4);
    assert_eq!(z[5], z[4], "clipped");
    assert_backed_off(&sent, 5);
    assert_reported(&sent, 6, ProcessFault::CorrectionLimit);
}

#[test]
fn a_hold_timeout_and_a_failed_sensor_report_their_codes() {
    let (mut lp, sent) = logged(|n| {
        if n <= 2 {
            Ok(sample(0.0))
        } else {
            Err(ErrorKind::Timeout)
        }
    });
    let (sent, end) = run_until_end(&mut lp, &sent);
    assert_eq!(
        end.code(),
        Some(ProcessFault::SensorLost),
        "a silent sensor: {end}"
    );
    assert_eq!(sent.last().unwrap().process.fault, ProcessFault::SensorLost);
    // A saturated sensor (the ATI's status word says so) is held the same way, then fault 1.
    let (mut lp, sent) = logged(|n| {
        if n <= 2 {
            Ok(sample(0.0))
        } else {
            Err(ErrorKind::Saturated)
        }
    });
    let (sent, end) = run_until_end(&mut lp, &sent);
    assert_eq!(end.code(), Some(ProcessFault::SensorLost));
    let LoopError::HoldTimeout {
        held,
        last: Fault::Sensor(ErrorKind::Saturated),
    } = end
    else {
        panic!("{end:?}")
    };
    assert_backed_off(&sent, 1 + (held / 0.004).round() as usize);
    let bus_off: LoopError<ErrorKind, ErrorKind> = LoopError::Sensor(ErrorKind::BusOff);
    assert_eq!(bus_off.code(), Some(ProcessFault::SensorLost));
    let pose: LoopError<ErrorKind, ErrorKind> = LoopError::HoldTimeout {
        held: 0.2,
        last: Fault::NonFinitePose,
    };
    assert_eq!(pose.code(), Some(ProcessFault::HoldTimeout));
    assert_eq!(
        LoopError::<ErrorKind, ErrorKind>::Robot(ErrorKind::LinkLost).code(),
        None
    );
}

#[test]
fn hold_and_retract_limits_are_validated() {
    for bad in [
        LoopConfig {
            max_hold: 0.0,
            ..LoopConfig::default()
        },
        LoopConfig {
            max_hold: f64::NAN,
            ..LoopConfig::default()
        },
        LoopConfig {
            max_hold: 5.0,
            ..LoopConfig::default()
        },
        LoopConfig {
            retract_distance: -0.001,
            ..LoopConfig::default()
        },
        LoopConfig {
            retract_speed: f64::INFINITY,
            ..LoopConfig::default()
        },
    ] {
        assert!(bad.validate().is_err(), "{bad:?}");
    }
    assert!(LoopConfig::default().validate().is_ok());
}

#[test]
fn stop_answers_the_next_cycle_with_the_last_command_and_stop() {
    let mut robot = MockRobot::new();
    let mut sensor = MockSensor::new();
    robot
        .expect_next_cycle()
        .returning(|| Ok(cycle_at(1, 0.001)));
    sensor.expect_read().returning(|| Ok(sample(0.0)));
    let sent = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let log = sent.clone();
    robot.expect_reply().returning(move |c| {
        log.lock().unwrap().push(*c);
        Ok(())
    });
    let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.002), LoopConfig::default());
    lp.cycle().unwrap();
    lp.stop().unwrap();
    let sent = sent.lock().unwrap();
    assert_eq!(sent.len(), 2);
    assert!(!sent[0].stop && sent[1].stop);
    assert_eq!(
        sent[1].translation, sent[0].translation,
        "stop holds the last command"
    );
}

#[test]
fn large_steps_are_limited_and_reported() {
    let mut robot = MockRobot::new();
    let mut sensor = MockSensor::new();
    robot.expect_next_cycle().returning(|| Ok(cycle_at(1, 0.0)));
    // A huge force error drives the fixed law hard towards x_r far away.
    sensor.expect_read().returning(|| Ok(sample(-1.0e7)));
    robot
        .expect_reply()
        .withf(|c: &Correction| c.translation.z.abs() <= 1e-4 + 1e-15)
        .returning(|_| Ok(()));
    let cfg = LoopConfig {
        max_step: 1e-4,
        ..LoopConfig::default()
    };
    let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.0), cfg);
    let r = lp.cycle().unwrap();
    assert_eq!(r.fault, Some(Fault::StepLimited));
    assert_eq!(lp.stats().limited, 1);
}

/// A law that records the `dt` of every step and commands where the tool is, or a fixed position.
#[derive(Default)]
struct DtLaw {
    dts: Vec<f64>,
    at: Option<f64>,
}

impl ForceLaw for DtLaw {
    fn start(&mut self, _x: f64) {}
    fn step(&mut self, x: f64, _f: f64, dt: f64) -> Output {
        self.dts.push(dt);
        Output {
            x_cmd: self.at.unwrap_or(x),
            ..Output::default()
        }
    }
    fn set_point(&self) -> f64 {
        5.0
    }
    fn set_set_point(&mut self, _f_r: f64) -> Result<(), String> {
        Ok(())
    }
}

#[test]
fn the_laws_clock_is_the_robots_stamps_held_and_skipped_cycles_included() {
    let mut robot = MockRobot::new();
    // Cycles 0, 1, 2, then the robot skips 3 and 4 (a late PC), then 5, 6 (sensor timeout), 7.
    let seqs = std::sync::Mutex::new(vec![0u64, 1, 2, 5, 6, 7].into_iter());
    robot
        .expect_next_cycle()
        .returning(move || Ok(cycle_at(seqs.lock().unwrap().next().unwrap(), 0.001)));
    robot.expect_reply().returning(|_| Ok(()));
    let mut sensor = MockSensor::new();
    let mut n = 0;
    sensor.expect_read().returning(move || {
        n += 1;
        if n == 5 {
            Err(ErrorKind::Timeout)
        } else {
            Ok(sample(1.0))
        }
    });
    let mut lp = ControlLoop::new(robot, sensor, DtLaw::default(), LoopConfig::default());
    for _ in 0..6 {
        lp.cycle().unwrap();
    }
    let steps: Vec<u64> = lp
        .law()
        .inner()
        .dts
        .iter()
        .map(|dt| (dt / 0.004).round() as u64)
        .collect();
    assert_eq!(
        steps,
        [1, 1, 1, 3, 2],
        "periods per step: {:?}",
        lp.law().inner().dts
    );
    // Whole periods, exactly: the stamps' float error stays out of the law.
    let whole = lp
        .law()
        .inner()
        .dts
        .iter()
        .zip(&steps)
        .all(|(dt, n)| *dt == *n as f64 * 0.004);
    assert!(whole, "{:?}", lp.law().inner().dts);
}

/// A law in contact for its first `contact_steps` steps, then approaching again (it took the contact
/// back), that keeps the set-point it is given.
struct TakeBackLaw {
    contact_steps: usize,
    steps: usize,
    sp: f64,
}

impl ForceLaw for TakeBackLaw {
    fn start(&mut self, _x: f64) {}
    fn step(&mut self, x: f64, _f: f64, _dt: f64) -> Output {
        self.steps += 1;
        let state = if self.steps <= self.contact_steps {
            ContactState::Contact
        } else {
            ContactState::Approach
        };
        Output {
            x_cmd: x,
            state: Some(state),
            ..Output::default()
        }
    }
    fn set_point(&self) -> f64 {
        self.sp
    }
    fn set_set_point(&mut self, f_r: f64) -> Result<(), String> {
        self.sp = f_r;
        Ok(())
    }
}

#[test]
fn a_contact_the_law_takes_back_hands_it_the_entry_force_again() {
    // PRESS 20 N over a 0.5 s ramp; the law touches at 3 N, ramps for five steps, then approaches
    // again: the pass is back at its approach and the law at the entry force (2 N), not at the
    // ramp's 3.7 N, until the next contact.
    let press = hal::ProcessCommand {
        mode: hal::ProcessMode::Press,
        force: 20.0,
        ramp: 0.5,
        segment: 1,
    };
    let mut robot = MockRobot::new();
    let mut k = 0;
    robot.expect_next_cycle().returning(move || {
        k += 1;
        Ok(Cycle {
            process: Some(press),
            ..cycle_at(k, 0.001)
        })
    });
    robot.expect_reply().returning(|_| Ok(()));
    let mut sensor = MockSensor::new();
    sensor.expect_read().returning(|| Ok(sample(3.0)));
    let law = TakeBackLaw {
        contact_steps: 5,
        steps: 0,
        sp: 0.0,
    };
    let mut lp = ControlLoop::new(robot, sensor, law, LoopConfig::default());
    for _ in 0..5 {
        lp.cycle().unwrap();
    }
    assert!(
        lp.law().inner().sp > 3.0,
        "ramping: {}",
        lp.law().inner().sp
    );
    for _ in 0..3 {
        lp.cycle().unwrap();
    }
    assert_eq!(lp.process_state().phase, hal::ProcessPhase::Approach);
    assert_eq!(lp.law().inner().sp, 2.0);
}

/// A law that asks for a tangential offset and a rotation beside a fixed normal command.
struct SideLaw {
    want: Vector3<f64>,
    rotation: Vector3<f64>,
}

impl CellLaw for SideLaw {
    fn start(&mut self, _: &Cycle, _: &Correction) {}
    fn step(&mut self, _: &Cycle, _: &Wrench, _: f64) -> crate::law::LawStep {
        crate::law::LawStep {
            correction: Correction {
                translation: self.want,
                rotation: self.rotation,
                ..Correction::default()
            },
            out: Output::default(),
        }
    }
    fn set_point(&self) -> f64 {
        0.0
    }
    fn set_set_point(&mut self, _: f64) -> Result<(), String> {
        Ok(())
    }
    fn counters(&self) -> crate::law::EventCounts {
        crate::law::EventCounts::default()
    }
}

#[test]
fn a_cell_laws_tangential_correction_is_step_and_envelope_limited_and_its_rotation_sent() {
    let (robot, sensor, sent) = devices(0.0, |_| Ok(sample(0.0)));
    let cfg = LoopConfig::default();
    let law = SideLaw {
        want: Vector3::new(1.0, -1.0, 0.0),
        rotation: Vector3::new(0.0, 0.01, 0.0),
    };
    let mut lp = ControlLoop::with_law(robot, sensor, law, cfg);
    let r = lp.cycle().unwrap();
    assert_eq!(r.fault, Some(Fault::StepLimited));
    let c = sent.lock().unwrap()[0];
    assert!((c.translation.x - cfg.max_step).abs() < 1e-15, "{c:?}");
    assert!((c.translation.y + cfg.max_step).abs() < 1e-15, "{c:?}");
    assert_eq!(c.rotation, Vector3::new(0.0, 0.01, 0.0));
    for _ in 0..10_000 {
        lp.cycle().unwrap();
    }
    let last = *sent.lock().unwrap().last().unwrap();
    assert!(
        (last.translation.x - cfg.max_offset).abs() < 1e-12
            && (last.translation.y + cfg.max_offset).abs() < 1e-12,
        "within the envelope: {last:?}"
    );
}

#[test]
fn the_normal_adapter_steps_the_1dof_law_on_the_tool_offset_and_the_signed_force() {
    let cycle = cycle_at(3, 0.0012);
    let w = Wrench::from_array([0.3, 0.2, -4.0, 0.0, 0.0, 0.0]);
    let mut bare = fixed_law(0.001);
    let mut adapted = AlongNormal::new(fixed_law(0.001), -1.0);
    bare.start(0.0012);
    adapted.start(&cycle, &Correction::along_z(0.0012));
    let want = bare.step(0.0012, 4.0, 0.004);
    let got = adapted.step(&cycle, &w, 0.004);
    assert_eq!((got.out.x_cmd, got.out.x_r), (want.x_cmd, want.x_r));
    assert_eq!(got.correction, Correction::along_z(want.x_cmd));
}

/// A loop with process channels and `rezero`: `n_off` cycles at OFF, then PRESS; the sensor reads a
/// 1.2 N offset (a sensor error on every cycle `bad` picks) and the robot's pose moves along the
/// normal at `speed` (m/s). Every report.
fn rezero_run(n_off: u64, bad: fn(u64) -> bool, speed: f64) -> (Vec<CycleReport>, Wrench) {
    let off = hal::ProcessCommand {
        mode: hal::ProcessMode::Off,
        force: 0.0,
        ramp: 0.0,
        segment: 1,
    };
    let press = hal::ProcessCommand {
        mode: hal::ProcessMode::Press,
        force: 20.0,
        ramp: 0.0,
        segment: 2,
    };
    let mut robot = MockRobot::new();
    let mut k = 0;
    robot.expect_next_cycle().returning(move || {
        k += 1;
        let c = cycle_at(k, 0.0);
        Ok(Cycle {
            process: Some(if k <= n_off { off } else { press }),
            actual: Pose::from_position(Vector3::new(0.0, 0.0, speed * c.t)),
            ..c
        })
    });
    robot.expect_reply().returning(|_| Ok(()));
    let mut sensor = MockSensor::new();
    let mut n = 0;
    sensor.expect_read().returning(move || {
        n += 1;
        if bad(n) {
            Err(ErrorKind::Timeout)
        } else {
            Ok(sample(1.2))
        }
    });
    let mut cfg = LoopConfig::default();
    cfg.process.rezero = true;
    let mut lp = ControlLoop::new(robot, sensor, fixed_law(0.002), cfg);
    let reports = (0..n_off + 20).map(|_| lp.cycle().unwrap()).collect();
    (reports, lp.sensor_zero())
}

#[test]
fn the_loop_rezeroes_at_off_in_free_air_and_the_next_pass_sees_the_new_zero() {
    let (reports, zero) = rezero_run(500, |_| false, 0.0);
    let events: Vec<(usize, RezeroEvent)> = reports
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.rezero.map(|e| (i, e)))
        .collect();
    assert_eq!(events.len(), 1, "{events:?}");
    let (at, e) = events[0];
    assert_eq!(e.outcome, RezeroOutcome::Done);
    assert!(at < 500, "at OFF: cycle {at}");
    assert!((zero.force.z - 1.2).abs() < 1e-9, "{zero:?}");
    // Before it the loop used the offset; after it, nothing; the pass that follows starts on it.
    assert!((reports[at].f.unwrap() - 1.2).abs() < 1e-9);
    assert!(reports[at + 1].f.unwrap().abs() < 1e-9);
    assert!(reports[510].f.unwrap().abs() < 1e-9);
    assert_eq!(
        reports[510].command.process.phase,
        hal::ProcessPhase::Approach
    );
    assert!(
        reports[at + 1].compensated,
        "the recorded wrench is the zeroed one"
    );
}

#[test]
fn the_loop_refuses_a_rezero_while_moving_or_unhealthy_and_keeps_its_zero() {
    // 10 mm/s along the normal through the whole OFF stretch.
    let (reports, zero) = rezero_run(500, |_| false, 0.01);
    let outcomes: Vec<RezeroOutcome> = reports
        .iter()
        .filter_map(|r| r.rezero.map(|e| e.outcome))
        .collect();
    assert_eq!(outcomes, [RezeroOutcome::Moving]);
    assert_eq!(zero, Wrench::default());
    // A sensor timeout every 40th read.
    let (reports, zero) = rezero_run(500, |n| n.is_multiple_of(40), 0.0);
    let outcomes: Vec<RezeroOutcome> = reports
        .iter()
        .filter_map(|r| r.rezero.map(|e| e.outcome))
        .collect();
    assert_eq!(outcomes, [RezeroOutcome::Unhealthy]);
    assert_eq!(zero, Wrench::default());
    assert!((reports[499].f.unwrap_or(1.2) - 1.2).abs() < 1e-9);
}
