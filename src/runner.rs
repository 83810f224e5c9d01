//! Runs a scenario: builds the simulated world, wires a robot link and a force sensor to the control loop,
//! records every step and computes the metrics.

use std::time::{Duration, Instant};

use ::scenario::run::WorldSink;
use anyhow::{Result, anyhow};
use controller::run::{End, Outcome, RobotSession, RunLimits};
use controller::{CellLaw, ControlLoop, EventCounts, LoopStats, Tuning};
use hal::{ForceSensor, RobotLink};
use sim::{InProcRobot, InProcSensor, InnerLoopModel, SharedWorld};

use crate::metrics::Metrics;
use crate::record::Row;
use crate::recorder::{Record, Recorder};
use crate::scenario::{PlantSpec, Scenario, Target, load_tuning};

/// A scenario with its plant and tuning resolved.
#[derive(Clone, Debug)]
pub struct RunSpec {
    /// The scenario.
    pub scenario: Scenario,
    /// Label of the plant (for file names and tables).
    pub plant_label: String,
    /// The inner loop.
    pub plant: InnerLoopModel,
    /// The tuning, with the scenario's overrides applied.
    pub tuning: Tuning,
    /// The robot is an outside RSI client (`--external-robot`): when it commands the process itself
    /// (`FcCmd`), the run lasts until it ends its session, not the scenario's duration.
    pub external: bool,
}

impl RunSpec {
    /// Resolve a scenario with optional plant and tuning overrides (CLI `--plant`, `--tuning`).
    pub fn new(scenario: Scenario, plant: Option<&str>, tuning: Option<&str>) -> Result<Self> {
        let spec = match plant {
            Some(p) => PlantSpec::Name(p.to_string()),
            None => scenario.plant.clone(),
        };
        let model = spec.model()?;
        // The law's model of the cell is the cell's: here, the simulated plant's and sensor's.
        let tuning = ::scenario::run::resolve_tuning(
            &scenario,
            &model,
            &load_tuning(tuning.unwrap_or(&scenario.tuning))?,
        );
        tuning
            .validate()
            .map_err(|e| anyhow!("tuning {} with the scenario's overrides: {e}", tuning.name))?;
        let steps = scenario.duration / model.period;
        if steps > crate::scenario::MAX_STEPS as f64 {
            return Err(anyhow!(
                "{} s at plant {}'s {} s period is {steps:.0} steps; at most {} are recorded",
                scenario.duration,
                spec.label(),
                model.period,
                crate::scenario::MAX_STEPS
            ));
        }
        Ok(Self {
            plant_label: spec.label(),
            plant: model,
            tuning,
            scenario,
            external: false,
        })
    }

    /// Number of control steps.
    pub fn steps(&self) -> u64 {
        (self.scenario.duration / self.plant.period)
            .round()
            .max(1.0) as u64
    }

    /// A fresh simulated world for this run.
    pub fn world(&self) -> SharedWorld {
        ::scenario::run::world(&self.scenario, &self.plant)
    }

    /// `NAME` or `NAME-PLANT-TUNING` when either differs from the scenario's defaults.
    pub fn file_stem(&self) -> String {
        let s = &self.scenario;
        if self.plant_label == s.plant.label() && self.tuning.name == s.tuning {
            s.name.clone()
        } else {
            format!("{}-{}-{}", s.name, self.plant_label, self.tuning.name)
        }
    }
}

/// What a run produced.
#[derive(Clone, Debug)]
pub struct RunResult {
    /// One row per answered cycle: the run's control, then the return to the programmed path after
    /// an early end (see [`control`](Self::control)).
    pub rows: Vec<Row>,
    /// How many of `rows` are the run's control: the metrics and verdicts see only these.
    pub control: usize,
    /// Loop counters.
    pub stats: LoopStats,
    /// The law's own event counters (contacts, lift-offs, limits that acted; zero for laws without).
    pub law_events: EventCounts,
    /// Metrics over the whole run.
    pub metrics: Metrics,
    /// Wall-clock time the run took.
    pub wall: Duration,
    /// Why the loop ended early, if it did (not counting an operator's stop).
    pub ended_early: Option<String>,
    /// The early end was a fault of the loop's guard (exit status 4), not the robot's doing (3).
    pub fault: bool,
    /// Stopped by SIGINT/SIGTERM ([`crate::stop::requested`]) before the end; `Some(true)` when the
    /// robot then got `Stop`, `Some(false)` when it could not (no cycle came).
    pub interrupted: Option<bool>,
    /// `sent`, or `not sent` and the real reason ([`controller::run::Outcome::stop_note`]).
    pub stop_note: String,
    /// Every re-zero of the sensor between passes, and every refusal (`[process] rezero`).
    pub rezeros: Vec<controller::RezeroEvent>,
}

/// A scenario target checked against a run (the same check as the controller's scenario tests).
pub type Verdict = ::scenario::run::Check;

impl RunResult {
    /// The rows of the run's control (without the return to the path after an early end).
    pub fn control_rows(&self) -> &[Row] {
        &self.rows[..self.control]
    }

    /// Check every target of the scenario. A run the loop ended early (a fault backed the tool off)
    /// meets none: what it measured before the fault is not the scenario's course.
    pub fn verdicts(&self, targets: &[Target]) -> Vec<Verdict> {
        targets
            .iter()
            .map(|t| {
                let mut v = Verdict::of(t, self.control_rows());
                v.pass &= self.ended_early.is_none();
                v
            })
            .collect()
    }
}

/// Run with any robot link and sensor, against `world` (which the backends must be driving).
/// `progress` is called with the fraction done, now and then.
pub fn run_with<R, S>(
    spec: &RunSpec,
    world: &SharedWorld,
    robot: R,
    sensor: S,
    progress: &mut dyn FnMut(f64),
) -> Result<RunResult>
where
    R: RobotLink,
    S: ForceSensor,
    R::Error: Send + Sync + 'static,
    S::Error: Send + Sync + 'static,
{
    run_recorded(spec, world, robot, sensor, None, progress)
}

/// [`run_with`], handing every cycle's [`Record`] to `recorder` as well (dropped at the end, so the
/// writer can drain and finish).
pub fn run_recorded<R, S>(
    spec: &RunSpec,
    world: &SharedWorld,
    robot: R,
    sensor: S,
    mut recorder: Option<Recorder>,
    progress: &mut dyn FnMut(f64),
) -> Result<RunResult>
where
    R: RobotLink,
    S: ForceSensor,
    R::Error: Send + Sync + 'static,
    S::Error: Send + Sync + 'static,
{
    let law = spec.tuning.cell_law().map_err(|e| anyhow!(e))?;
    let mut lp = ControlLoop::with_law(robot, sensor, law, spec.tuning.loop_config());
    let steps = spec.steps();
    let started = Instant::now();
    let every = (steps / 200).max(1);
    let mut k = 0u64;
    let mut rezeros = Vec::new();
    let mut also = |r: &controller::CycleReport, _: &Row| {
        if let Some(e) = r.rezero {
            rezeros.push(e);
        }
        if let Some(tx) = &mut recorder {
            tx.push(Record::from_report(r, r.set_point));
        }
        k += 1;
        if k.is_multiple_of(every) {
            progress(k as f64 / steps as f64);
        }
    };
    let mut sink = WorldSink::new(world, steps as usize, &mut also);
    let limits = RunLimits {
        // An outside robot is the clock: the run lasts the scenario's duration of its time (cycles it
        // sent that never arrived count), ending after the first cycle at or past `duration − period`
        // (a simulated run's last row; the half period more absorbs rounding); the simulated robots
        // are counted in cycles.
        cycles: (!spec.external).then_some(steps),
        duration: spec
            .external
            .then_some(spec.scenario.duration - 1.5 * spec.plant.period),
        stop: Some(crate::stop::flag()),
        // An outside robot that sends `FcCmd` runs its own program: the session is its to end.
        robot_session: if spec.external && spec.scenario.program.is_none() {
            RobotSession::RobotWhenProcess
        } else {
            RobotSession::Run
        },
    };
    let outcome = controller::run::run(&mut lp, limits, &mut sink);
    let (ended_early, interrupted) = sim_end(&outcome);
    let fault = matches!(outcome.end, End::Fault(_));
    let (rows, control) = sink.finish(spec.plant.period);
    progress(1.0);
    let wall = started.elapsed();
    drop(recorder);
    let stats = lp.stats();
    let law_events = lp.law().counters();
    drop(lp);
    let metrics = Metrics::compute(&rows[..control], 0.0, f64::INFINITY);
    Ok(RunResult {
        rows,
        control,
        stats,
        law_events,
        metrics,
        wall,
        ended_early,
        fault,
        interrupted,
        stop_note: outcome.stop_note(),
        rezeros,
    })
}

/// What a simulated run's end means to its summary: why it ended early (if it did), and whether the
/// operator stopped it (`Some(true)` when the robot then got `Stop`).
fn sim_end<E: std::fmt::Display>(o: &Outcome<E>) -> (Option<String>, Option<bool>) {
    let stop_failed = match &o.stop {
        Some(Err(e)) => Some(e.to_string()),
        _ => None,
    };
    match &o.end {
        End::Stopped(_) => (None, Some(o.stopped())),
        End::RobotEnded(_) => {
            println!("{}", o.end);
            (None, None)
        }
        End::Fault(e) => (
            Some(match stop_failed {
                Some(s) => format!("{e}; could not send Stop: {s}"),
                None => e.to_string(),
            }),
            None,
        ),
        End::LinkLost(e) => (Some(e.to_string()), None),
        End::Program(Some(_)) => (Some(o.end.to_string()), None),
        End::Done | End::Program(None) => (
            stop_failed.map(|s| format!("could not send Stop at the end: {s}")),
            None,
        ),
    }
}

/// Run with the in-process robot and sensor (no wire).
pub fn run_inproc(spec: &RunSpec, progress: &mut dyn FnMut(f64)) -> Result<RunResult> {
    let world = spec.world();
    run_with(
        spec,
        &world,
        InProcRobot::new(world.clone()),
        InProcSensor::new(world.clone()),
        progress,
    )
}

/// Start the MCAP recording of a simulated run at `path`: the scenario and the tuning attached (TOML),
/// the plant and names as metadata. A lockstep run waits for the writer when the queue is full; one
/// on the wall clock drops and counts, like a cell.
pub fn start_recording(
    spec: &RunSpec,
    path: &std::path::Path,
    realtime: bool,
    live: Option<crate::recorder::LiveSink>,
) -> Result<(Recorder, crate::recorder::Recording)> {
    use crate::recorder::{Full, RecorderOptions};
    let mut meta = std::collections::BTreeMap::new();
    meta.insert("scenario".to_string(), spec.scenario.name.clone());
    meta.insert("plant".to_string(), spec.plant_label.clone());
    meta.insert("tuning".to_string(), spec.tuning.name.clone());
    meta.insert("period_s".to_string(), spec.plant.period.to_string());
    let opts = RecorderOptions {
        full: if realtime { Full::Drop } else { Full::Wait },
        attachments: vec![
            (
                format!("scenario-{}.toml", spec.scenario.name),
                "application/toml".into(),
                toml_text(&spec.scenario).into_bytes(),
            ),
            (
                format!("tuning-{}.toml", spec.tuning.name),
                "application/toml".into(),
                toml_text(&spec.tuning).into_bytes(),
            ),
        ],
        metadata: vec![("forcecell.sim".into(), meta)],
        ..RecorderOptions::default()
    };
    crate::recorder::start(path, opts, live)
}

/// TOML text of a serialisable value (a comment saying why in its place if it cannot be written).
fn toml_text<T: serde::Serialize>(v: &T) -> String {
    toml::to_string(v).unwrap_or_else(|e| format!("# cannot be written as TOML: {e}\n"))
}
