//! A scenario run in process, lockstep, in simulated time: the simulated world, the in-process robot
//! and sensor, the controller's loop — recorded and measured as `forcecell sim` records and measures a
//! run (the application's runner adds wires, recording and progress around the same pieces). The
//! controller's closed-loop tests use this, so a scenario file and a metric mean the same thing in both.

use std::time::{Duration, Instant};

use anyhow::{Result, anyhow};
use controller::run::{End, Program, RunLimits, Sink};
use controller::{CellLaw, CellParams, ControlLoop, CycleReport, EventCounts, LoopStats, Tuning};
use sim::{InProcRobot, InProcSensor, InnerLoopModel, SensorParams, SharedWorld, World};

use crate::metrics::Metrics;
use crate::record::Row;
use crate::scenario::{Scenario, Target};

/// The law's model of the cell, from the simulated plant (the cycle, the lag, the delay) and sensor
/// (how much older its force is than the position it comes with).
pub fn cell_model(m: &InnerLoopModel, sensor: &SensorParams) -> CellParams {
    CellParams {
        cycle: m.period,
        lag: m.tau,
        delay: m.delay(),
        sensor_delay: sensor.delay(),
    }
}

/// Fill the truth columns of `rows` (one per control step of `period`) from the world's log.
pub fn fill_truth(rows: &mut [Row], truth: &[sim::world::Truth], period: f64) {
    for r in rows {
        let k = (r.t / period).round();
        if k >= 0.0
            && let Some(tr) = truth.get(k as usize)
        {
            r.f_true = tr.f;
            r.k_c = tr.k_c;
            r.x_c = tr.x_c;
            r.s = tr.s;
            r.tilt_error = tr.tilt_error;
        }
    }
}

/// A target checked against a run.
#[derive(Clone, Debug)]
pub struct Check {
    /// The target.
    pub target: Target,
    /// The metric's value over the target's window.
    pub value: f64,
    /// Whether it is met.
    pub pass: bool,
}

impl Check {
    /// Check `target` against `rows`.
    pub fn of(target: &Target, rows: &[Row]) -> Self {
        let m = Metrics::compute(
            rows,
            target.after.unwrap_or(0.0),
            target.until.unwrap_or(f64::INFINITY),
        );
        let value = m.get(&target.metric).unwrap_or(f64::NAN);
        let pass = !value.is_nan()
            && target.max.is_none_or(|mx| value <= mx)
            && target.min.is_none_or(|mn| value >= mn);
        Self {
            target: target.clone(),
            value,
            pass,
        }
    }
}

/// What an in-process run produced.
#[derive(Clone, Debug)]
pub struct Run {
    /// One row per step, with the truth.
    pub rows: Vec<Row>,
    /// The law's event counters.
    pub counters: EventCounts,
    /// The loop's counters.
    pub stats: LoopStats,
}

impl Run {
    /// Metrics over `[from, until]`.
    pub fn metrics(&self, from: f64, until: f64) -> Metrics {
        Metrics::compute(&self.rows, from, until)
    }

    /// Every target of `targets` checked.
    pub fn check(&self, targets: &[Target]) -> Vec<Check> {
        targets.iter().map(|t| Check::of(t, &self.rows)).collect()
    }
}

/// An in-process run up to its end, with what ended it early, if anything.
#[derive(Debug)]
pub struct Ended {
    /// Every step up to the end (the last one before a fault), with the truth.
    pub run: Run,
    /// The loop's error that ended the run early (a fault, backed off), or `None`.
    pub fault: Option<anyhow::Error>,
    /// That fault's code in the process contract (`FcState.Fault`: 2 force limit, 5 contact lost, …),
    /// `None` without one.
    pub fault_code: Option<i64>,
    /// Why the robot program ended early, when it did (a simulated program's abort).
    pub aborted: Option<String>,
    /// The robot got its `Stop` at the end.
    pub stopped: bool,
}

/// Run `scenario` on `plant` with `tuning` (the scenario's overrides and the plant's cell model
/// applied), in process; a fault that ends the loop is an error.
pub fn run(scenario: &Scenario, plant: &InnerLoopModel, tuning: &Tuning) -> Result<Run> {
    let ended = run_to_end(scenario, plant, tuning)?;
    match ended.fault {
        Some(e) => Err(e),
        None => Ok(ended.run),
    }
}

/// The simulated world for `scenario` on `plant`: its environment, sensor, start and program.
pub fn world(scenario: &Scenario, plant: &InnerLoopModel) -> SharedWorld {
    let world = World::new(
        scenario.environment.plant(),
        *plant,
        scenario.sensor.clone(),
        scenario.start_position(),
    )
    .with_form(scenario.environment.form.clone());
    let world = match scenario.environment.geometry {
        Some(g) => world.with_geometry(g),
        None => world,
    };
    match &scenario.program {
        Some(p) => world.with_program(p.clone()),
        None => world,
    }
    .shared()
}

/// `tuning` as it runs `scenario` on `plant`: the scenario's overrides applied and the law's model of
/// the cell taken from the simulated plant and sensor.
pub fn resolve_tuning(scenario: &Scenario, plant: &InnerLoopModel, tuning: &Tuning) -> Tuning {
    let mut tuning = tuning.clone();
    tuning.law.apply(&scenario.controller);
    scenario.process.apply(&mut tuning.loop_cfg.process);
    tuning.law.set_cell(cell_model(plant, &scenario.sensor));
    tuning
}

/// The longest a [`WorldSink`] waits for the robot to take the world's step after a reply: longer
/// than any lockstep deadline of the simulated KRC, short beside a run.
const PROGRAM_WAIT: Duration = Duration::from_millis(100);
/// How often it looks meanwhile.
const PROGRAM_POLL: Duration = Duration::from_micros(20);

/// The sink of a simulated run: one [`Row`] per answered cycle, the simulated robot program's end,
/// and whatever else the caller hands each cycle to (a recorder, a progress bar).
pub struct WorldSink<'a> {
    /// One row per answered cycle of the run's control (truth columns filled by
    /// [`WorldSink::finish`]).
    pub rows: Vec<Row>,
    /// One row per cycle of the return to the programmed path after an early end
    /// ([`Sink::unwound`]): recorded, but not the run's control, so no metric sees it.
    pub after: Vec<Row>,
    world: &'a SharedWorld,
    has_program: bool,
    /// Robot time of the last cycle answered, s.
    last_t: f64,
    also: &'a mut dyn FnMut(&CycleReport, &Row),
}

impl<'a> WorldSink<'a> {
    /// A sink watching `world`'s program, room for `steps` rows; `also` sees every cycle and its row.
    pub fn new(
        world: &'a SharedWorld,
        steps: usize,
        also: &'a mut dyn FnMut(&CycleReport, &Row),
    ) -> Self {
        // Whether the world runs a program is fixed for the run: only then is its end looked up.
        let has_program = sim::world::lock(world).program().is_some();
        Self {
            rows: Vec::with_capacity(steps),
            after: Vec::new(),
            world,
            has_program,
            last_t: f64::NEG_INFINITY,
            also,
        }
    }

    /// Every row (the control's, then the return's), with the truth of the world's log filled in,
    /// and how many of them are the control's.
    pub fn finish(mut self, period: f64) -> (Vec<Row>, usize) {
        let control = self.rows.len();
        self.rows.append(&mut self.after);
        let truth = sim::world::lock(self.world).truth_log();
        fill_truth(&mut self.rows, &truth, period);
        (self.rows, control)
    }
}

impl Sink for WorldSink<'_> {
    fn record(&mut self, report: &CycleReport) -> bool {
        self.last_t = report.cycle.t;
        let row = Row::from_report(report, report.set_point);
        (self.also)(report, &row);
        self.rows.push(row);
        true
    }

    fn unwound(&mut self, report: &CycleReport) {
        let row = Row::from_report(report, report.set_point);
        (self.also)(report, &row);
        self.after.push(row);
    }

    fn program(&mut self) -> Program {
        if !self.has_program {
            return Program::Running;
        }
        // The program's end as of the world's step after the cycle answered last: a robot on another
        // thread (the simulated KRC) takes that step once it has the reply, so wait for it (bounded:
        // a robot that never takes it, silent or ended, is answered with the world as it is).
        // Whether the robot had taken the step when the loop looks was a race that ended the run
        // one cycle sooner or later from run to run; the program's end time makes it none.
        let deadline = Instant::now() + PROGRAM_WAIT;
        let mut w = sim::world::lock(self.world);
        while self.last_t.is_finite()
            && w.time() < self.last_t + w.period() / 2.0
            && Instant::now() < deadline
        {
            drop(w);
            std::thread::sleep(PROGRAM_POLL);
            w = sim::world::lock(self.world);
        }
        let seen = w
            .program_done_at()
            .is_some_and(|t| t <= self.last_t + 1.5 * w.period());
        match w.program() {
            Some(p) if seen => match p.aborted() {
                Some(why) => Program::Aborted(why.to_string()),
                None => Program::Done,
            },
            _ => Program::Running,
        }
    }
}

/// [`run`], keeping the steps of a run that a fault ended (what led to it, its peak force); an error
/// only when the law cannot be built.
pub fn run_to_end(scenario: &Scenario, plant: &InnerLoopModel, tuning: &Tuning) -> Result<Ended> {
    run_watched(scenario, plant, tuning, &mut |_, _| {})
}

/// [`run_to_end`], handing every answered cycle's report and row to `watch` — the return to the
/// programmed path after an early end included, which [`Ended::run`]'s rows leave out.
pub fn run_watched(
    scenario: &Scenario,
    plant: &InnerLoopModel,
    tuning: &Tuning,
    watch: &mut dyn FnMut(&CycleReport, &Row),
) -> Result<Ended> {
    let tuning = resolve_tuning(scenario, plant, tuning);
    let law = tuning.cell_law().map_err(|e| anyhow!(e))?;
    let world = world(scenario, plant);
    let mut lp = ControlLoop::with_law(
        InProcRobot::new(world.clone()),
        InProcSensor::new(world.clone()),
        law,
        tuning.loop_config(),
    );
    let steps = (scenario.duration / plant.period).round().max(1.0) as u64;
    let mut sink = WorldSink::new(&world, steps as usize, watch);
    let limits = RunLimits {
        cycles: Some(steps),
        ..RunLimits::default()
    };
    let outcome = controller::run::run(&mut lp, limits, &mut sink);
    let (fault, fault_code) = match &outcome.end {
        End::Fault(e) | End::LinkLost(e) => (
            Some(anyhow!(
                "the loop ended after {} steps: {e}",
                sink.rows.len()
            )),
            e.code().map(|c| c.code()),
        ),
        _ => (None, None),
    };
    let aborted = match &outcome.end {
        End::Program(why) => why.clone(),
        _ => None,
    };
    let stopped = outcome.stopped();
    let counters = lp.law().counters();
    let stats = lp.stats();
    drop(lp);
    Ok(Ended {
        run: Run {
            rows: {
                // The return to the path after a fault is not the scenario's course.
                let (mut rows, control) = sink.finish(plant.period);
                rows.truncate(control);
                rows
            },
            counters,
            stats,
        },
        fault,
        fault_code,
        aborted,
        stopped,
    })
}
