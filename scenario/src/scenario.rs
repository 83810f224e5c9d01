//! Scenarios: a simulated cell (workpiece, robot inner loop, sensor), a duration, a default tuning and the
//! targets it is judged by. TOML files under `scenarios/` are built in; any other file can be named by path.

use std::path::Path;

use anyhow::{Context, Result, anyhow, bail};
use controller::Overrides;
use serde::{Deserialize, Serialize};
use sim::{
    ContactPlant, Event, Geometry, InnerLoopModel, Program, Schedule, SensorParams, SurfaceForm,
};

pub use crate::tuning::{builtin_tuning_names, load_tuning, tuning_from_toml};

pub(crate) mod builtin {
    include!(concat!(env!("OUT_DIR"), "/builtin.rs"));
}

/// The robot's inner loop: a name (`p0`, `p1`, `p2`) or explicit values.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PlantSpec {
    /// `p0`, `p1` or `p2`.
    Name(String),
    /// Explicit period, lag and delay.
    Model(InnerLoopModel),
}

impl Default for PlantSpec {
    fn default() -> Self {
        Self::Name("p0".into())
    }
}

impl PlantSpec {
    /// The model, or an error naming the valid choices.
    pub fn model(&self) -> Result<InnerLoopModel> {
        let m = match self {
            Self::Name(n) => InnerLoopModel::by_name(n)
                .ok_or_else(|| anyhow!("unknown plant {n:?}: choose p0, p1 or p2"))?,
            Self::Model(m) => *m,
        };
        m.validate().map_err(|e| anyhow!("plant: {e}"))?;
        Ok(m)
    }

    /// A short label.
    pub fn label(&self) -> String {
        match self {
            Self::Name(n) => n.to_ascii_lowercase(),
            Self::Model(m) => format!(
                "T{}ms-tau{}ms-d{}",
                m.period * 1e3,
                m.tau * 1e3,
                m.delay_cycles
            ),
        }
    }
}

/// The workpiece.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Environment {
    /// Stiffness at t = 0, N/m.
    pub k_c: f64,
    /// Surface position at t = 0, m (along the tool normal, from the programmed path).
    pub x_c: f64,
    /// Damping, N·s/m.
    #[serde(default)]
    pub c_e: f64,
    /// Changes of the stiffness.
    #[serde(default)]
    pub k_c_events: Vec<Event>,
    /// Changes of the surface position.
    #[serde(default)]
    pub x_c_events: Vec<Event>,
    /// The part's form along the path (tilt, waviness, steps, edge), added to the surface under the
    /// tool as a robot program moves it.
    #[serde(default)]
    pub form: SurfaceForm,
    /// A curved part, its pad and tool (`docs/curved-parts.md`); absent: the 1-DOF plant.
    #[serde(default)]
    pub geometry: Option<Geometry>,
}

impl Environment {
    /// The contact plant.
    pub fn plant(&self) -> ContactPlant {
        ContactPlant {
            k_c: Schedule {
                base: self.k_c,
                events: self.k_c_events.clone(),
            },
            x_c: Schedule {
                base: self.x_c,
                events: self.x_c_events.clone(),
            },
            c_e: self.c_e,
        }
    }
}

/// A metric limit the scenario is judged by.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Target {
    /// Metric name (see [`crate::metrics::Metrics::get`]).
    pub metric: String,
    /// Upper limit.
    #[serde(default)]
    pub max: Option<f64>,
    /// Lower limit.
    #[serde(default)]
    pub min: Option<f64>,
    /// Evaluate from this time on, s.
    #[serde(default)]
    pub after: Option<f64>,
    /// Evaluate up to this time, s.
    #[serde(default)]
    pub until: Option<f64>,
}

/// A scenario as written in TOML.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Name; output files are called after it.
    pub name: String,
    /// One line for humans.
    #[serde(default)]
    pub description: String,
    /// Simulated time, s.
    pub duration: f64,
    /// The robot's inner loop.
    #[serde(default)]
    pub plant: PlantSpec,
    /// Default tuning (built-in name or file path); [`DEFAULT_TUNING`] when the file names none.
    #[serde(default = "default_tuning")]
    pub tuning: String,
    /// Whether the file named its tuning (else it runs [`DEFAULT_TUNING`], and the run says so).
    #[serde(skip)]
    pub tuning_named: bool,
    /// Start position along the normal, m; default 1 mm short of the surface.
    #[serde(default)]
    pub x0: Option<f64>,
    /// The workpiece.
    pub environment: Environment,
    /// The force sensor's imperfections.
    #[serde(default)]
    pub sensor: SensorParams,
    /// Overrides of the tuning's values.
    #[serde(default)]
    pub controller: Overrides,
    /// Overrides of the tuning's force process (`[loop.process]`).
    #[serde(default)]
    pub process: ProcessOverrides,
    /// Targets.
    #[serde(default)]
    pub targets: Vec<Target>,
    /// A robot program the simulated controller runs over the process channels (`FcCmd`/`FcState`):
    /// the run ends when it does (within `duration`), with `Stop`.
    #[serde(default)]
    pub program: Option<Program>,
    /// The removal model (pad, tool speed, Preston's coefficient): `sim` maps what a programmed pass
    /// removed when it is given.
    #[serde(default)]
    pub removal: Option<crate::removal::RemovalConfig>,
}

/// Values of the tuning's force process (`[loop.process]`) a scenario may override.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ProcessOverrides {
    /// Re-zero the sensor in free air between passes (`loop.process.rezero`; docs/rezero.md).
    pub rezero: Option<bool>,
}

impl ProcessOverrides {
    /// Apply to a loop's process configuration.
    pub fn apply(&self, p: &mut controller::ProcessConfig) {
        if let Some(r) = self.rezero {
            p.rezero = r;
        }
    }
}

/// The tuning a scenario that names none runs: the shipped robust law (the paper's law faults where
/// a real cell's delay and noise are; it is only ever chosen by name).
pub const DEFAULT_TUNING: &str = "robust";

fn default_tuning() -> String {
    DEFAULT_TUNING.into()
}

/// The longest simulated run accepted, s.
pub const MAX_DURATION: f64 = 3600.0;
/// The most steps a run may take: one hour at 1 kHz (a row each, kept in memory for the metrics).
pub const MAX_STEPS: u64 = 3_600_000;
/// The farthest the simulated surface may lie from the programmed path, m.
pub const MAX_SURFACE: f64 = 1.0;
/// The stiffest simulated surface, N/m.
pub const MAX_STIFFNESS: f64 = 1e10;

/// The range a schedule spans over `[0, duration]`: its value at every breakpoint (piecewise linear
/// between them), widened by every sine's amplitude. Non-finite when the schedule is.
fn extent(s: &sim::Schedule, duration: f64) -> (f64, f64) {
    let mut times = vec![0.0, duration];
    for e in &s.events {
        match *e {
            Event::Step { at, .. } | Event::Scale { at, .. } => times.push(at),
            Event::Ramp { start, end, .. } => {
                times.extend([Some(start), end].into_iter().flatten())
            }
            Event::Sine { start, .. } => times.push(start),
        }
    }
    let no_sine = sim::Schedule {
        base: s.base,
        events: s
            .events
            .iter()
            .filter(|e| !matches!(e, Event::Sine { .. }))
            .copied()
            .collect(),
    };
    let swing: f64 = s
        .events
        .iter()
        .map(|e| match e {
            Event::Sine { amplitude, .. } => amplitude.abs(),
            _ => 0.0,
        })
        .sum();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    // Just before each breakpoint too: a step ends a ramp's run-up there.
    for t in times.into_iter().flat_map(|t| [t, t - 1e-9]) {
        let v = no_sine.at(t.clamp(0.0, duration));
        if v.is_nan() {
            return (f64::NAN, f64::NAN);
        }
        lo = lo.min(v - swing);
        hi = hi.max(v + swing);
    }
    (lo, hi)
}

impl Scenario {
    /// Parse and validate TOML text; `origin` names the source in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self> {
        Self::from_toml_at(text, origin, None)
    }

    /// [`from_toml`](Self::from_toml) for a file in `dir`: a height map it names is read from there
    /// (under the one input rule, at most [`MAX_MAP_FILE`] bytes).
    pub fn from_toml_at(text: &str, origin: &str, dir: Option<&Path>) -> Result<Self> {
        let mut s: Self =
            toml::from_str(text).map_err(|e| anyhow!("{origin}: {}", one_line(&e.to_string())))?;
        if let (Some(m), Some(dir)) = (s.environment.form.height_map.as_mut(), dir) {
            let file = dir.join(&m.file);
            let csv = crate::input::read_text(&file, "height map", MAX_MAP_FILE)
                .with_context(|| format!("{origin}: environment.form.height_map"))?;
            m.load(&csv)
                .map_err(|e| anyhow!("{origin}: environment: {e}"))?;
        }
        s.tuning_named = text
            .parse::<toml::Table>()
            .is_ok_and(|t| t.contains_key("tuning"));
        s.validate()
            .with_context(|| format!("{origin}: invalid scenario"))?;
        Ok(s)
    }

    /// Load a built-in scenario by name, or a TOML file by path (anything ending in `.toml` or
    /// containing a path separator).
    pub fn load(spec: &str) -> Result<Self> {
        if names_a_file(spec) {
            let path = Path::new(spec);
            return Self::from_toml_at(&read_toml_file(path, "scenario")?, spec, path.parent());
        }
        Self::from_toml(builtin_text(builtin::SCENARIOS, "scenario", spec)?, spec)
    }

    /// Every built-in scenario, parsed.
    pub fn builtins() -> Result<Vec<Self>> {
        builtin::SCENARIOS
            .iter()
            .map(|(n, t)| Self::from_toml(t, n))
            .collect()
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<()> {
        if self.name.is_empty()
            || !self
                .name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            bail!(
                "name {:?} must be non-empty letters, digits, '-' or '_' (it names the output files)",
                self.name
            );
        }
        if !(self.duration.is_finite() && self.duration > 0.0 && self.duration <= MAX_DURATION) {
            bail!(
                "duration must be in (0, {MAX_DURATION}] s, got {}",
                self.duration
            );
        }
        let model = self.plant.model()?;
        let steps = self.duration / model.period;
        if steps > MAX_STEPS as f64 {
            bail!(
                "duration {} s at a {} s period is {steps:.0} steps; at most {MAX_STEPS} are recorded (one row each, kept in memory)",
                self.duration,
                model.period
            );
        }
        let plant = self.environment.plant();
        plant.validate().map_err(|e| anyhow!("environment: {e}"))?;
        self.environment
            .form
            .validate()
            .map_err(|e| anyhow!("environment: {e}"))?;
        if let Some(p) = &self.program {
            p.validate().map_err(|e| anyhow!("program: {e}"))?;
        }
        if let Some(r) = &self.removal {
            r.validate().map_err(|e| anyhow!("{e}"))?;
        }
        if let Some(g) = &self.environment.geometry {
            g.validate().map_err(|e| anyhow!("environment: {e}"))?;
        }
        let (lo, hi) = extent(&plant.x_c, self.duration);
        if !(lo >= -MAX_SURFACE && hi <= MAX_SURFACE) {
            bail!(
                "environment: the surface x_c must stay within ±{MAX_SURFACE} m of the programmed path (RSI corrects by millimetres), it reaches [{lo}, {hi}] m"
            );
        }
        let (_, k_hi) = extent(&plant.k_c, self.duration);
        if !(k_hi.is_finite() && k_hi <= MAX_STIFFNESS) {
            bail!(
                "environment: k_c must stay at most {MAX_STIFFNESS:e} N/m (stiffer than steel on steel), it reaches {k_hi:e} N/m"
            );
        }
        self.sensor.validate().map_err(|e| anyhow!("sensor: {e}"))?;
        if let Some(x0) = self.x0
            && !(x0.is_finite() && x0.abs() < 1.0)
        {
            bail!("x0 must be a finite position within ±1 m, got {x0}");
        }
        for t in &self.targets {
            if t.max.is_none() && t.min.is_none() {
                bail!("target {:?} has neither max nor min", t.metric);
            }
            for (n, v) in [
                ("max", t.max),
                ("min", t.min),
                ("after", t.after),
                ("until", t.until),
            ] {
                if v.is_some_and(|v| !v.is_finite()) {
                    bail!("target {:?}: {n} must be a finite number", t.metric);
                }
            }
            if let (Some(lo), Some(hi)) = (t.min, t.max)
                && lo > hi
            {
                bail!(
                    "target {:?}: min {lo} is above max {hi}, it can never pass",
                    t.metric
                );
            }
            if let (Some(a), Some(u)) = (t.after, t.until)
                && a >= u
            {
                bail!(
                    "target {:?}: the window [after {a}, until {u}] s is empty, it can never pass",
                    t.metric
                );
            }
            if !crate::metrics::METRIC_NAMES.contains(&t.metric.as_str()) {
                bail!(
                    "target metric {:?} is unknown; known: {}",
                    t.metric,
                    crate::metrics::METRIC_NAMES.join(", ")
                );
            }
        }
        Ok(())
    }

    /// Start position, m.
    pub fn start_position(&self) -> f64 {
        self.x0.unwrap_or(self.environment.x_c - 0.001)
    }
}

/// The largest height map file read, bytes (a 2000 × 2000 grid of 7-character values).
pub const MAX_MAP_FILE: u64 = 32 << 20;

/// The largest scenario or tuning file read, bytes (a device or a wrong path is an error, not a hang).
pub const MAX_FILE: u64 = crate::input::MAX_CONFIG;

/// Whether `spec` names a file (it ends in `.toml` or holds a path separator), not a built-in.
pub(crate) fn names_a_file(spec: &str) -> bool {
    spec.ends_with(".toml") || spec.contains('/')
}

/// A `kind` ("scenario", "tuning") file's text, read under the one input rule ([`crate::input`]):
/// a regular file of at most [`MAX_FILE`] bytes, a FIFO never waited on.
pub(crate) fn read_toml_file(path: &Path, kind: &str) -> Result<String> {
    crate::input::read_text(path, &format!("{kind} file"), MAX_FILE)
}

/// The text of the built-in `kind` named `spec` in `table`, or an error that lists the names.
pub(crate) fn builtin_text(
    table: &'static [(&'static str, &'static str)],
    kind: &str,
    spec: &str,
) -> Result<&'static str> {
    table
        .iter()
        .find(|(n, _)| *n == spec)
        .map(|(_, t)| *t)
        .ok_or_else(|| {
            let names: Vec<&str> = table.iter().map(|(n, _)| *n).collect();
            anyhow!(
                "unknown {kind} {spec:?}; built-in: {} (or give a .toml file)",
                names.join(", ")
            )
        })
}

/// Names of the built-in scenarios.
pub fn builtin_names() -> Vec<&'static str> {
    builtin::SCENARIOS.iter().map(|(n, _)| *n).collect()
}

/// toml's errors span several lines with a source excerpt; keep the message and the position.
pub fn one_line(s: &str) -> String {
    let mut lines = s.lines().filter(|l| !l.trim().is_empty());
    let head = lines.next().unwrap_or_default().trim().to_string();
    let tail: Vec<_> = lines
        .filter(|l| !l.trim_start().starts_with('|') && !l.contains(" | "))
        .map(str::trim)
        .collect();
    if tail.is_empty() {
        head
    } else {
        format!("{head}: {}", tail.join(" "))
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_height_map_is_read_beside_the_scenario_file() {
        let dir = std::env::temp_dir().join(format!("forcecell-height-map-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let text = include_str!("../../scenarios/raster-step.toml").replace(
            "steps = [{ at = 0.05, height = 0.0003, along = \"x\" }]",
            "height_map = { file = \"part.csv\", spacing = 0.05, scale = 1e-6 }",
        );
        let path = dir.join("mapped.toml");
        std::fs::write(&path, &text).unwrap();
        // Missing file: one error naming it.
        let e = format!("{:#}", Scenario::load(path.to_str().unwrap()).unwrap_err());
        assert!(e.contains("part.csv"), "{e}");
        // 3 × 3 points, 50 mm apart, in µm: 300 µm at the far corner.
        std::fs::write(dir.join("part.csv"), "0,0,0\n0,0,0\n0,0,300\n").unwrap();
        let s = Scenario::load(path.to_str().unwrap()).unwrap();
        let form = &s.environment.form;
        assert!((form.height_at(0.1, 0.1) - 3e-4).abs() < 1e-15);
        assert!((form.height_at(0.075, 0.075) - 0.75e-4).abs() < 1e-15);
        // Given as text (no directory to read it from): refused, not run as a flat part.
        assert!(Scenario::from_toml(&text, "t.toml").is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    use super::*;

    #[test]
    fn every_builtin_scenario_and_tuning_parses() {
        assert!(builtin_names().contains(&"paper-fig9"));
        for s in Scenario::builtins().unwrap() {
            load_tuning(&s.tuning).unwrap();
        }
        for n in builtin_tuning_names() {
            load_tuning(n).unwrap();
        }
    }

    #[test]
    fn a_scenario_without_a_tuning_runs_the_robust_law_and_knows_it() {
        let text = "name = \"t\"\nduration = 1.0\n[environment]\nk_c = 1e4\nx_c = 0.001\n";
        let s = Scenario::from_toml(text, "t.toml").unwrap();
        assert_eq!((s.tuning.as_str(), s.tuning_named), ("robust", false));
        let named = format!("tuning = \"paper\"\n{text}");
        let s = Scenario::from_toml(&named, "t.toml").unwrap();
        assert_eq!((s.tuning.as_str(), s.tuning_named), ("paper", true));
        assert!(Scenario::builtins().unwrap().iter().all(|s| s.tuning_named));
    }

    #[test]
    fn errors_are_one_line_and_name_the_problem() {
        let e = Scenario::load("no-such-scenario").unwrap_err().to_string();
        assert!(e.contains("paper-fig9"), "{e}");
        let e = Scenario::from_toml("name = \"x\"\nduration = 1.0\n", "t.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("environment") && !e.contains('\n'), "{e}");
        let bad = "name = \"x\"\nduration = -1.0\n[environment]\nk_c = 1.0\nx_c = 0.0\n";
        let e = format!("{:#}", Scenario::from_toml(bad, "t.toml").unwrap_err());
        assert!(e.contains("duration"), "{e}");
        let bad =
            "name = \"x\"\nduration = 1.0\nplant = \"p9\"\n[environment]\nk_c = 1.0\nx_c = 0.0\n";
        let e = format!("{:#}", Scenario::from_toml(bad, "t.toml").unwrap_err());
        assert!(e.contains("p9") && e.contains("p2"), "{e}");
        let e = format!("{:#}", load_tuning("nope").unwrap_err());
        assert!(e.contains("paper"), "{e}");
        // A device or a directory is no file to read.
        for path in ["/dev/zero", "/tmp/"] {
            let e = format!("{:#}", Scenario::load(path).unwrap_err());
            assert!(e.contains("no scenario file"), "{e}");
        }
    }
}
