//! Runs a scenario: builds the simulated world, wires a robot link and a force sensor to the control loop,
//! records every step and computes the metrics.

use std::time::{Duration, Instant};

use anyhow::{Result, anyhow};
use controller::{ControlLoop, EventCounts, ForceLaw, LoopStats, Tuning};
use hal::{ForceSensor, RobotLink};
use sim::{InProcRobot, InProcSensor, InnerLoopModel, SharedWorld, World};

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
        let mut tuning = load_tuning(tuning.unwrap_or(&scenario.tuning))?;
        tuning.law.apply(&scenario.controller);
        // The law's model of the cell is the cell's: here, the simulated plant's and sensor's.
        tuning
            .law
            .set_cell(::scenario::run::cell_model(&model, &scenario.sensor));
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
        let w = World::new(
            self.scenario.environment.plant(),
            self.plant,
            self.scenario.sensor.clone(),
            self.scenario.start_position(),
        )
        .with_form(self.scenario.environment.form.clone());
        match &self.scenario.program {
            Some(p) => w.with_program(p.clone()),
            None => w,
        }
        .shared()
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
    /// One row per step.
    pub rows: Vec<Row>,
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
    /// Stopped by SIGINT/SIGTERM ([`crate::stop::requested`]) before the end; `Some(true)` when the
    /// robot then got `Stop`, `Some(false)` when it could not (no cycle came).
    pub interrupted: Option<bool>,
}

/// A scenario target checked against a run (the same check as the controller's scenario tests).
pub type Verdict = ::scenario::run::Check;

impl RunResult {
    /// Check every target of the scenario. A run the loop ended early (a fault backed the tool off)
    /// meets none: what it measured before the fault is not the scenario's course.
    pub fn verdicts(&self, targets: &[Target]) -> Vec<Verdict> {
        targets
            .iter()
            .map(|t| {
                let mut v = Verdict::of(t, &self.rows);
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
    let law = spec.tuning.law.build().map_err(|e| anyhow!(e))?;
    let mut lp = ControlLoop::new(robot, sensor, law, spec.tuning.loop_config());
    let steps = spec.steps();
    let mut rows = Vec::with_capacity(steps as usize);
    let started = Instant::now();
    let mut ended_early = None;
    let every = (steps / 200).max(1);
    let mut interrupted = None;
    // Whether the world runs a program is fixed for the run: only then is its end looked up each cycle.
    let has_program = sim::world::lock(world).program().is_some();
    let program_done = || {
        has_program
            .then(|| {
                sim::world::lock(world)
                    .program()
                    .map(|p| (p.done(), p.aborted().map(str::to_string)))
            })
            .flatten()
    };
    let mut finished = false;
    // An outside robot that sends `FcCmd` runs its own program: the session is its to end.
    let mut robot_driven = false;
    let mut k = 0u64;
    loop {
        if k >= steps && !robot_driven {
            finished = true;
            break;
        }
        k += 1;
        if crate::stop::requested() {
            break;
        }
        if let Some((true, aborted)) = program_done() {
            // The robot program ended (its `RSI_OFF`): end the correction motion cleanly.
            if let Some(why) = aborted {
                ended_early = Some(format!("the robot program aborted: {why}"));
            }
            finished = true;
            break;
        }
        match lp.cycle() {
            Ok(r) => {
                robot_driven = spec.external && r.cycle.process.is_some() && !has_program;
                let rec = Record::from_report(&r, r.set_point);
                rows.push(rec.row);
                if let Some(tx) = &mut recorder {
                    tx.push(rec);
                }
            }
            Err(e) => {
                let robot_gone = matches!(e, controller::LoopError::Robot(_));
                if robot_driven && robot_gone {
                    // The robot program ended its session (RSI_OFF): the normal end of its pass.
                    println!("the robot ended its session ({e})");
                } else if !crate::stop::requested() {
                    ended_early = Some(e.to_string());
                    if !robot_gone {
                        // A fault has backed the tool off: end the robot's correction motion
                        // with `Stop` (and the fault's code in `FcState` where the link has it).
                        if let Err(stop) = lp.stop() {
                            ended_early = Some(format!("{e}; could not send Stop: {stop}"));
                        }
                    }
                }
                break;
            }
        }
        if k.is_multiple_of(every) {
            progress(k as f64 / steps as f64);
        }
    }
    if finished {
        // The scenario's course or the simulated program is over: end the robot's correction
        // motion cleanly with `Stop` rather than falling silent (a timeout stop on a real KRC).
        if let Err(e) = lp.stop() {
            ended_early.get_or_insert(format!("could not send Stop at the end: {e}"));
        }
    } else if let (false, Some((false, _))) = (crate::stop::requested(), program_done()) {
        ended_early.get_or_insert(format!(
            "the robot program did not finish within the scenario's {} s",
            spec.scenario.duration
        ));
    }
    if crate::stop::requested() {
        // The operator's stop: end the robot's correction motion as `run` does (bounded: the link's
        // waits end on the stop flag).
        interrupted = Some(lp.stop().is_ok());
    }
    progress(1.0);
    let wall = started.elapsed();
    drop(recorder);
    let stats = lp.stats();
    let law_events = lp.law().counters();
    drop(lp);
    let truth = sim::world::lock(world).truth_log();
    ::scenario::run::fill_truth(&mut rows, &truth, spec.plant.period);
    let metrics = Metrics::compute(&rows, 0.0, f64::INFINITY);
    Ok(RunResult {
        rows,
        stats,
        law_events,
        metrics,
        wall,
        ended_early,
        interrupted,
    })
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
