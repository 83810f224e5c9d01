//! A scenario run in process, lockstep, in simulated time: the simulated world, the in-process robot
//! and sensor, the controller's loop — recorded and measured as `forcecell sim` records and measures a
//! run (the application's runner adds wires, recording and progress around the same pieces). The
//! controller's closed-loop tests use this, so a scenario file and a metric mean the same thing in both.

use anyhow::{Result, anyhow};
use controller::{CellParams, ControlLoop, EventCounts, ForceLaw, LoopStats, Tuning};
use sim::{InProcRobot, InProcSensor, InnerLoopModel, SensorParams, World};

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

/// [`run`], keeping the steps of a run that a fault ended (what led to it, its peak force); an error
/// only when the law cannot be built.
pub fn run_to_end(scenario: &Scenario, plant: &InnerLoopModel, tuning: &Tuning) -> Result<Ended> {
    let mut tuning = tuning.clone();
    tuning.law.apply(&scenario.controller);
    tuning.law.set_cell(cell_model(plant, &scenario.sensor));
    let law = tuning.law.build().map_err(|e| anyhow!(e))?;
    let world = World::new(
        scenario.environment.plant(),
        *plant,
        scenario.sensor.clone(),
        scenario.start_position(),
    )
    .with_form(scenario.environment.form.clone());
    let world = match &scenario.program {
        Some(p) => world.with_program(p.clone()),
        None => world,
    }
    .shared();
    let mut lp = ControlLoop::new(
        InProcRobot::new(world.clone()),
        InProcSensor::new(world.clone()),
        law,
        tuning.loop_config(),
    );
    let steps = (scenario.duration / plant.period).round().max(1.0) as usize;
    let mut rows = Vec::with_capacity(steps);
    let (mut fault, mut fault_code) = (None, None);
    for _ in 0..steps {
        // A robot program ends the run when it ends (as `forcecell sim` does).
        if sim::world::lock(&world).program().is_some_and(|p| p.done()) {
            break;
        }
        match lp.cycle() {
            Ok(r) => rows.push(Row::from_report(&r, r.set_point)),
            Err(e) => {
                fault_code = e.code().map(|c| c.code());
                fault = Some(anyhow!("the loop ended after {} steps: {e}", rows.len()));
                break;
            }
        }
    }
    let counters = lp.law().counters();
    let stats = lp.stats();
    drop(lp);
    let truth = sim::world::lock(&world).truth_log();
    fill_truth(&mut rows, &truth, plant.period);
    Ok(Ended {
        run: Run {
            rows,
            counters,
            stats,
        },
        fault,
        fault_code,
    })
}
