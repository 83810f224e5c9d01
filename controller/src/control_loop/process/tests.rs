//! The process's unit tests.

use super::*;
use crate::law::ContactState;

/// A process at OFF whose faults back off 2 mm, within −5 mm.
fn new() -> Process {
    Process::new(ProcessConfig::default(), 0.002, -0.005)
}

/// A process pressing at `f` (N) that has had its contact.
fn pressing(f: f64) -> Process {
    let mut p = new();
    p.command(&press(f, 0.0)).unwrap();
    p.guard.had_contact = true;
    p.phase = ProcessPhase::Pressing;
    p
}

fn press(f: f64, ramp: f64) -> ProcessCommand {
    ProcessCommand {
        mode: ProcessMode::Press,
        force: f,
        ramp,
        segment: 1,
    }
}

#[test]
fn commands_the_contract_forbids_are_refused() {
    let c = ProcessConfig::default();
    assert!(c.check(&press(20.0, 0.5)).is_ok());
    assert!(c.check(&press(0.0, 0.5)).is_err());
    assert!(c.check(&press(-1.0, 0.5)).is_err());
    assert!(c.check(&press(f64::NAN, 0.5)).is_err());
    assert!(c.check(&press(60.0, 0.5)).is_err(), "at the limit");
    assert!(c.check(&press(20.0, -1.0)).is_err());
    assert!(c.check(&press(20.0, f64::INFINITY)).is_err());
    let bad = ProcessCommand {
        mode: ProcessMode::Unknown(7),
        ..press(20.0, 0.5)
    };
    assert_eq!(c.check(&bad), Err(Refusal::UndefinedMode(7)));
    assert!(c.check(&bad).unwrap_err().to_string().contains('7'));
}

#[test]
fn entry_ramp_runs_from_the_contact_force_to_f_over_ramp() {
    let mut p = new();
    assert_eq!(p.command(&press(20.0, 0.5)), Ok(true));
    assert_eq!(p.phase, ProcessPhase::Approach);
    assert_eq!(p.sp, 2.0);
    p.ramp_step(0.004);
    assert_eq!(p.sp, 2.0, "no ramp before contact");
    let contact = Output {
        state: Some(ContactState::Contact),
        ..Output::default()
    };
    p.after_step(&contact, 3.0, 0.004).unwrap();
    assert_eq!(p.phase, ProcessPhase::Ramp);
    assert_eq!(p.sp, 3.0);
    // 17 N over 0.5 s: 34 N/s.
    let mut t = 0.0_f64;
    while p.sp < 20.0 {
        p.ramp_step(0.004);
        t += 0.004;
    }
    assert!((t - 0.5).abs() < 0.005, "{t}");
    p.guard.f_filt = 19.5;
    p.after_step(&contact, 19.5, 0.004).unwrap();
    assert_eq!(p.phase, ProcessPhase::Pressing);
}

/// A contact the law takes back (it approaches again) puts the pass back to its approach, and
/// the program's ramp starts over from the next contact instead of going on in free air.
#[test]
fn a_contact_the_law_takes_back_restarts_the_approach_and_the_ramp() {
    let mut p = new();
    p.command(&press(20.0, 0.5)).unwrap();
    let contact = Output {
        state: Some(ContactState::Contact),
        ..Output::default()
    };
    p.after_step(&contact, 3.0, 0.004).unwrap();
    for _ in 0..10 {
        p.ramp_step(0.004);
    }
    assert!(p.sp > 4.0, "{}", p.sp);
    let approach = Output {
        state: Some(ContactState::Approach),
        ..Output::default()
    };
    p.after_step(&approach, 0.0, 0.004).unwrap();
    assert_eq!(p.phase, ProcessPhase::Approach);
    assert_eq!(p.sp, 2.0, "back to the entry force");
    p.ramp_step(0.004);
    assert_eq!(p.sp, 2.0, "no ramp before the next contact");
    p.after_step(&contact, 2.5, 0.004).unwrap();
    assert_eq!((p.phase, p.sp), (ProcessPhase::Ramp, 2.5));
}

#[test]
fn a_new_force_ramps_again_and_leaves_pressing() {
    let mut p = new();
    p.command(&press(10.0, 0.0)).unwrap();
    p.phase = ProcessPhase::Pressing;
    p.sp = 10.0;
    assert_eq!(p.command(&press(30.0, 0.5)), Ok(false));
    assert_eq!(p.phase, ProcessPhase::Ramp);
    assert!((p.rate - 40.0).abs() < 1e-9, "20 N over 0.5 s");
    p.sp = 30.0;
    p.command(&press(10.0, 0.1)).unwrap();
    assert_eq!(p.rate, 50.0, "never faster than the law's own rate");
}

#[test]
fn release_ramps_down_lifts_returns_then_off() {
    let mut p = pressing(20.0);
    p.sp = 20.0;
    let rel = ProcessCommand {
        mode: ProcessMode::Release,
        ..press(20.0, 0.3)
    };
    p.command(&rel).unwrap();
    assert_eq!(p.phase, ProcessPhase::Release);
    assert_eq!(p.release, Release::RampDown);
    assert_eq!(p.act(), Act::Control);
    let mut n = 0;
    while !p.release_ramp_done() {
        p.ramp_step(0.004);
        n += 1;
    }
    // 18 N over 0.3 s asks for 60 N/s: the law's 50 N/s make it 0.36 s.
    assert!((90..=91).contains(&n), "{n} steps");
    p.lift_off(0.001);
    assert_eq!(p.release, Release::Lift { target: -0.001 });
    assert_eq!(p.act(), Act::MoveTo { target: -0.001 });
    p.arrived();
    assert_eq!(p.act(), Act::MoveTo { target: 0.0 });
    p.arrived();
    assert_eq!(p.phase, ProcessPhase::Off);
}

#[test]
fn a_fault_latches_until_off() {
    let mut p = new();
    p.command(&press(20.0, 0.0)).unwrap();
    p.latch(ProcessFault::ForceLimit, || "x".into(), 0.002);
    p.latch(ProcessFault::ContactLost, || "y".into(), 0.0);
    assert_eq!(p.fault, ProcessFault::ForceLimit, "the first fault stands");
    assert_eq!(p.act(), Act::MoveTo { target: 0.0 });
    assert_eq!(
        p.command(&press(20.0, 0.0)),
        Ok(false),
        "PRESS does not re-arm"
    );
    assert_eq!(p.phase, ProcessPhase::Fault);
    let off = ProcessCommand {
        mode: ProcessMode::Off,
        ..press(20.0, 0.0)
    };
    p.command(&off).unwrap();
    assert_eq!(p.state().phase, ProcessPhase::Off);
    assert_eq!(p.state().fault, ProcessFault::None);
    assert_eq!(p.command(&press(20.0, 0.0)), Ok(true));
}

#[test]
fn a_fault_backs_off_until_the_tool_is_free() {
    let mut p = new();
    p.command(&press(20.0, 0.0)).unwrap();
    p.latch(ProcessFault::ForceLimit, || "x".into(), 0.004);
    assert_eq!(p.act(), Act::MoveTo { target: 0.002 });
    p.back_off_further(70.0, 0.003);
    assert_eq!(p.act(), Act::MoveTo { target: 0.001 }, "still touching");
    p.back_off_further(1.0, 0.0015);
    assert_eq!(p.act(), Act::MoveTo { target: 0.001 }, "free: no further");
    p.back_off_further(70.0, -0.004);
    assert_eq!(
        p.act(),
        Act::MoveTo { target: -0.005 },
        "never beyond the floor"
    );
    let mut q = new();
    q.back_off_further(70.0, 0.0);
    assert_eq!(q.retract_target, 0.0, "only while a fault backs off");
}

#[test]
fn contact_lost_too_long_is_a_fault() {
    let mut p = pressing(20.0);
    let lost = Output {
        state: Some(ContactState::Reacquire),
        ..Output::default()
    };
    let mut r = Ok(());
    for _ in 0..200 {
        r = p.after_step(&lost, 0.0, 0.004);
        if r.is_err() {
            break;
        }
    }
    assert_eq!(r.unwrap_err().0, ProcessFault::ContactLost);
}
