//! The force process the robot program commands, closed loop on the simulated cell: each way a pass
//! can end — the program's own RELEASE and every fault of the contract — with the state and fault code
//! the program sees, the back-off, and re-arming by OFF. Simulated time only.

use controller::run::{Each, End, RunLimits};
use controller::{ControlLoop, CycleReport, ForceLaw, Tuning};
use hal::{ErrorKind, ProcessFault, ProcessPhase};
use sim::program::{FormStep, SegmentMode};
use sim::{
    ContactPlant, Event, InProcRobot, InProcSensor, InnerLoopModel, Program, Schedule, Segment,
    SensorParams, SurfaceForm, Window, World,
};

fn robust() -> Tuning {
    toml::from_str(include_str!("../../tunings/robust.toml")).expect("robust.toml parses")
}

fn press(force: f64, length: f64, n: i64) -> Segment {
    Segment {
        mode: SegmentMode::Press,
        force,
        ramp: 0.3,
        segment: n,
        feed: 0.05,
        length,
        dwell: 0.0,
    }
}

fn release(n: i64) -> Segment {
    Segment {
        mode: SegmentMode::Release,
        force: 0.0,
        ramp: 0.3,
        segment: n,
        feed: 0.0,
        length: 0.0,
        dwell: 0.0,
    }
}

/// What the program saw, cycle by cycle.
struct Seen {
    phases: Vec<ProcessPhase>,
    faults: Vec<ProcessFault>,
    commands: Vec<f64>,
    forces: Vec<f64>,
    done: bool,
}

impl Seen {
    fn first_fault(&self) -> Option<(usize, ProcessFault)> {
        self.faults
            .iter()
            .position(|f| *f != ProcessFault::None)
            .map(|i| (i, self.faults[i]))
    }
}

fn run(
    plant: ContactPlant,
    form: SurfaceForm,
    sensor: SensorParams,
    program: Program,
    t: f64,
) -> Seen {
    let world = World::new(plant, InnerLoopModel::P1, sensor, 0.0)
        .with_form(form)
        .with_program(program)
        .shared();
    let tuning = robust();
    let law: Box<dyn ForceLaw + Send> = tuning.law.build().unwrap();
    let mut lp = ControlLoop::new(
        InProcRobot::new(world.clone()),
        InProcSensor::new(world.clone()),
        law,
        tuning.loop_config(),
    );
    let mut seen = Seen {
        phases: vec![],
        faults: vec![],
        commands: vec![],
        forces: vec![],
        done: false,
    };
    let mut after = 0;
    let limits = RunLimits {
        cycles: Some((t / 0.001) as u64),
        ..RunLimits::default()
    };
    let outcome = controller::run::run(
        &mut lp,
        limits,
        &mut Each(|r: &CycleReport| {
            seen.phases.push(r.command.process.phase);
            seen.faults.push(r.command.process.fault);
            seen.commands.push(r.command.translation.z);
            seen.forces.push(sim::world::lock(&world).true_force());
            // Half a second past the program's end: the correction's way home after its last OFF.
            if sim::world::lock(&world).program().unwrap().done() {
                seen.done = true;
                after += 1;
            }
            after <= 500
        }),
    );
    assert!(
        matches!(outcome.end, End::Done),
        "a process fault never ends the loop: {}",
        outcome.end
    );
    seen
}

fn flat() -> ContactPlant {
    ContactPlant::spring(70_000.0, 0.001)
}

#[test]
fn a_pass_presses_holds_releases_and_ends_off_at_zero() {
    let p = Program {
        segments: vec![press(20.0, 0.05, 1), release(2)],
        wait_timeout: 5.0,
        passes: 1,
        step_over: 0.0,
        transfer_feed: 0.1,
    };
    let s = run(
        flat(),
        SurfaceForm::default(),
        SensorParams::default(),
        p,
        10.0,
    );
    assert!(s.done, "the program ran to its end");
    assert_eq!(s.first_fault(), None);
    // The order the program sees: OFF → APPROACH → RAMP → PRESSING → RELEASE → OFF.
    let mut order = s.phases.clone();
    order.dedup();
    assert_eq!(
        order,
        [
            ProcessPhase::Approach,
            ProcessPhase::Ramp,
            ProcessPhase::Pressing,
            ProcessPhase::Release,
            ProcessPhase::Off
        ]
    );
    assert_eq!(
        *s.commands.last().unwrap(),
        0.0,
        "the correction is back at zero"
    );
    let pressing: Vec<f64> = s
        .phases
        .iter()
        .zip(&s.forces)
        .filter(|(p, _)| **p == ProcessPhase::Pressing)
        .map(|(_, f)| *f)
        .collect();
    assert!(pressing.len() > 900, "pressed for the 50 mm at 50 mm/s");
    assert!(
        pressing.iter().all(|f| (f - 20.0).abs() <= 1.0),
        "held within 5 %"
    );
}

#[test]
fn a_force_above_the_limit_faults_retracts_and_off_rearms() {
    // The part rises 1.5 mm into the tool after 20 mm of path: 105 N more than the 60 N limit allows.
    let form = SurfaceForm {
        steps: vec![FormStep {
            at: 0.02,
            height: -0.0015,
            along: Default::default(),
        }],
        ..SurfaceForm::default()
    };
    let p = Program {
        segments: vec![press(20.0, 0.05, 1), release(2)],
        wait_timeout: 5.0,
        passes: 1,
        step_over: 0.0,
        transfer_feed: 0.1,
    };
    let s = run(flat(), form, SensorParams::default(), p, 10.0);
    let (at, fault) = s.first_fault().expect("faulted");
    assert_eq!(fault, ProcessFault::ForceLimit);
    assert_eq!(s.phases[at], ProcessPhase::Fault);
    // It backs off: 50 ms later the command is well behind where it faulted.
    assert!(s.commands[at + 50] < s.commands[at] - 0.0009, "retracting");
    // The program aborts on FAULT with OFF: that re-arms the process and brings the correction home.
    assert!(s.done);
    assert_eq!(*s.phases.last().unwrap(), ProcessPhase::Off);
    assert_eq!(
        *s.faults.last().unwrap(),
        ProcessFault::None,
        "OFF re-armed"
    );
    assert_eq!(*s.commands.last().unwrap(), 0.0);
}

#[test]
fn no_surface_within_the_envelope_is_a_correction_limit_fault() {
    // The part lies 60 mm away: beyond the 50 mm envelope the tuning allows.
    let p = Program {
        segments: vec![press(20.0, 0.05, 1)],
        wait_timeout: 40.0,
        passes: 1,
        step_over: 0.0,
        transfer_feed: 0.1,
    };
    let s = run(
        ContactPlant::spring(70_000.0, 0.06),
        SurfaceForm::default(),
        SensorParams::default(),
        p,
        40.0,
    );
    assert_eq!(
        s.first_fault().map(|f| f.1),
        Some(ProcessFault::CorrectionLimit)
    );
    assert!(s.forces.iter().all(|f| *f == 0.0), "never touched anything");
}

#[test]
fn an_edge_loses_contact_for_too_long() {
    let form = SurfaceForm {
        edge: Some(0.02),
        ..SurfaceForm::default()
    };
    let p = Program {
        segments: vec![press(20.0, 0.05, 1), release(2)],
        wait_timeout: 5.0,
        passes: 1,
        step_over: 0.0,
        transfer_feed: 0.1,
    };
    let s = run(flat(), form, SensorParams::default(), p, 10.0);
    let (at, fault) = s.first_fault().expect("faulted");
    assert_eq!(fault, ProcessFault::ContactLost);
    assert!(
        s.commands[at + 100] < s.commands[at],
        "backs off after the fault"
    );
}

#[test]
fn a_silent_sensor_faults_after_the_hold_limit_not_later() {
    let sensor = SensorParams {
        dropouts: vec![Window {
            at: 1.5,
            duration: 100.0,
        }],
        ..SensorParams::default()
    };
    let p = Program {
        segments: vec![press(20.0, 0.1, 1), release(2)],
        wait_timeout: 5.0,
        passes: 1,
        step_over: 0.0,
        transfer_feed: 0.1,
    };
    let s = run(flat(), SurfaceForm::default(), sensor, p, 10.0);
    let (at, fault) = s.first_fault().expect("faulted");
    assert_eq!(fault, ProcessFault::SensorLost);
    let t = at as f64 * 0.001;
    let max_hold = robust().loop_cfg.max_hold;
    assert!(
        t > 1.5 + max_hold - 0.002 && t < 1.5 + max_hold + 0.01,
        "faulted at {t} s: the hold is bounded by max_hold"
    );
}

#[test]
fn bad_commands_fault_with_code_4() {
    // The program's own validation refuses these forces; the wire may still carry them, so the robot
    // here rewrites the force of a valid program's PRESS on every cycle.
    for force in [f64::NAN, -5.0, 60.0, 500.0] {
        let world = World::new(flat(), InnerLoopModel::P1, SensorParams::default(), 0.0)
            .with_program(Program {
                segments: vec![press(20.0, 0.01, 1)],
                wait_timeout: 1.0,
                passes: 1,
                step_over: 0.0,
                transfer_feed: 0.1,
            })
            .shared();
        let tuning = robust();
        let mut lp = ControlLoop::new(
            BadForce(InProcRobot::new(world.clone()), force),
            InProcSensor::new(world.clone()),
            tuning.law.build().unwrap(),
            tuning.loop_config(),
        );
        let r = lp.cycle().unwrap();
        assert_eq!(r.command.process.phase, ProcessPhase::Fault, "F = {force}");
        assert_eq!(r.command.process.fault, ProcessFault::BadCommand);
        assert!(lp.process_fault_reason().unwrap().contains("PRESS"));
        // The program sees FAULT and aborts with OFF, which re-arms the process.
        let r = lp.cycle().unwrap();
        assert_eq!(r.cycle.process.unwrap().mode, hal::ProcessMode::Off);
        assert_eq!(r.command.process.phase, ProcessPhase::Off);
        assert_eq!(r.command.process.fault, ProcessFault::None);
    }
}

#[test]
fn a_pass_on_a_rising_plant_keeps_its_stiffness_changes_out_of_faults() {
    // A stiffer patch (×2) mid-pass is no fault: the force is held.
    let plant = ContactPlant {
        k_c: Schedule::constant(70_000.0).with(Event::Scale {
            at: 1.5,
            factor: 2.0,
        }),
        ..flat()
    };
    let p = Program {
        segments: vec![press(20.0, 0.1, 1), release(2)],
        wait_timeout: 5.0,
        passes: 1,
        step_over: 0.0,
        transfer_feed: 0.1,
    };
    let s = run(
        plant,
        SurfaceForm::default(),
        SensorParams::default(),
        p,
        10.0,
    );
    assert_eq!(s.first_fault(), None);
    assert!(s.done);
}

/// A robot whose program sends force `F` on every cycle.
struct BadForce(InProcRobot, f64);

impl hal::RobotLink for BadForce {
    type Error = ErrorKind;
    fn next_cycle(&mut self) -> Result<hal::Cycle, ErrorKind> {
        let mut c = self.0.next_cycle()?;
        if let Some(p) = &mut c.process {
            p.force = self.1;
        }
        Ok(c)
    }
    fn reply(&mut self, c: &hal::Correction) -> Result<(), ErrorKind> {
        self.0.reply(c)
    }
}
