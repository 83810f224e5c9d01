//! `forcecell bench-scenarios`: every B scenario on P1 and P2 with the robust and the paper's tuning, one
//! table of scenario × plant × tuning → metric, target, pass/fail, and a CSV and PNG per run.
//!
//! Every run goes over the default wires, as `forcecell sim` runs it: the KUKA RSI driver against the
//! simulated KUKA controller over loopback UDP (lockstep), and the ATI driver against the simulated node
//! on the in-memory CAN bus. The table is what a user gets from the shipped command.
//!
//! A scenario whose plant is an explicit model (the B7 delay points) runs on that model only: its plant
//! *is* the experiment.

use std::path::Path;

use anyhow::Result;

use crate::args::RsiArgs;
use crate::plot;
use crate::rsi::RobotSide;
use crate::runner::RunSpec;
use crate::scenario::{PlantSpec, Scenario, builtin_names};

/// One line of the table.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BenchRow {
    /// Scenario name.
    pub scenario: String,
    /// Plant label.
    pub plant: String,
    /// Tuning name.
    pub tuning: String,
    /// Metric name.
    pub metric: String,
    /// Evaluation window, for humans.
    pub window: String,
    /// The measured value (in JSON a number, or `"inf"`, `"-inf"`, `"NaN"` as the table prints it).
    #[serde(serialize_with = "finite_or_text")]
    pub value: f64,
    /// The target, for humans.
    pub target: String,
    /// Whether the target is met.
    pub pass: bool,
}

/// A number as itself when finite, else as the table prints it (JSON has no infinity).
fn finite_or_text<S: serde::Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    if v.is_finite() {
        s.serialize_f64(*v)
    } else {
        s.serialize_str(&v.to_string())
    }
}

/// What to run.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Only scenarios whose name starts with one of these (empty: every `b*` scenario).
    pub only: Vec<String>,
    /// Plants (`p1`, `p2`).
    pub plants: Vec<String>,
    /// Tunings (`robust`, `paper`, or files).
    pub tunings: Vec<String>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            only: Vec::new(),
            plants: vec!["p1".into(), "p2".into()],
            tunings: vec!["robust".into(), "paper".into()],
        }
    }
}

/// The B scenarios that are not ours (listed in the table so the set is complete).
pub const ELSEWHERE: &[(&str, &str)] = &[(
    "b10-gravity",
    "gravity compensation: controller::gravity, asserted by its own test b10_two_kilogram_tool_reoriented_leaves_under_0_3_newton",
)];

/// The built-in B scenarios selected by `opts`, in name order.
pub fn scenarios(opts: &BenchOptions) -> Result<Vec<Scenario>> {
    let mut v: Vec<Scenario> = Scenario::builtins()?
        .into_iter()
        .filter(|s| s.name.starts_with('b'))
        .filter(|s| opts.only.is_empty() || opts.only.iter().any(|o| s.name.starts_with(o)))
        .collect();
    if let Some(o) = opts
        .only
        .iter()
        .find(|o| !v.iter().any(|s| s.name.starts_with(o.as_str())))
    {
        let names: Vec<&str> = builtin_names()
            .into_iter()
            .filter(|n| n.starts_with('b'))
            .collect();
        anyhow::bail!(
            "no B scenario starts with {o:?}; they are: {}",
            names.join(", ")
        );
    }
    v.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(v)
}

/// Run everything, writing `out/NAME-PLANT-TUNING.{csv,png}`, and return the table's rows. `progress` is
/// told which run starts.
pub fn run(
    opts: &BenchOptions,
    out: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<BenchRow>> {
    // Every filter and tuning checked before the output directory is created.
    let scenarios = scenarios(opts)?;
    for s in &scenarios {
        for tuning in &opts.tunings {
            RunSpec::new(s.clone(), None, Some(tuning))?;
        }
    }
    let dir = crate::output::OutDir::create(out, "output directory (--out)")?;
    let mut rows = Vec::new();
    for s in scenarios {
        let plants: Vec<Option<&str>> = match s.plant {
            PlantSpec::Model(_) => vec![None],
            PlantSpec::Name(_) => opts.plants.iter().map(|p| Some(p.as_str())).collect(),
        };
        for plant in plants {
            for tuning in &opts.tunings {
                let spec = RunSpec::new(s.clone(), plant, Some(tuning))?;
                let label = format!("{}-{}-{}", s.name, spec.plant_label, spec.tuning.name);
                progress(&label);
                let robot = RobotSide::start(&spec, &RsiArgs::default())?;
                let (run, _) = crate::ati::run_sim_with(robot, None, &mut |_| {})?;
                crate::output::write_csv(&out.join(format!("{label}.csv")), &run.rows)?;
                plot::write_png(
                    &out.join(format!("{label}.png")),
                    &format!(
                        "{} · plant {} · tuning {}",
                        s.name, spec.plant_label, spec.tuning.name
                    ),
                    &run.rows,
                )?;
                for v in run.verdicts(&s.targets) {
                    let t = &v.target;
                    rows.push(BenchRow {
                        scenario: s.name.clone(),
                        plant: spec.plant_label.clone(),
                        tuning: spec.tuning.name.clone(),
                        metric: t.metric.clone(),
                        window: format!(
                            "[{}, {}]",
                            t.after.unwrap_or(0.0),
                            t.until.map_or("end".to_string(), |u| u.to_string())
                        ),
                        value: v.value,
                        target: match (t.min, t.max) {
                            (Some(lo), Some(hi)) => format!("in [{lo}, {hi}]"),
                            (Some(lo), None) => format!(">= {lo}"),
                            (None, Some(hi)) => format!("<= {hi}"),
                            (None, None) => String::new(),
                        },
                        pass: v.pass,
                    });
                }
            }
        }
    }
    dir.keep();
    Ok(rows)
}

/// What the runs go over, for the table's heading.
pub const WIRES: &str = "over the default wires: KUKA RSI driver ↔ simulated KRC (loopback UDP, lockstep), ATI driver ↔ simulated node (in-memory CAN)";

/// The name of the bench's JSON summary in its output directory.
pub const SUMMARY: &str = "bench-scenarios.json";

/// The JSON summary of a bench: its provenance (command, version, start and end, the scenarios and
/// tunings, the wires), the targets met per tuning, and every row of the table with the same figures.
#[derive(Debug, serde::Serialize)]
pub struct BenchSummary<'a> {
    /// Where the figures came from.
    pub provenance: crate::provenance::Provenance,
    /// Targets met per tuning, in the table's order.
    pub met: Vec<Met>,
    /// The table's rows (a value the run could not measure is `null`).
    pub rows: &'a [BenchRow],
}

/// How many of its targets a tuning met.
#[derive(Debug, PartialEq, serde::Serialize)]
pub struct Met {
    /// The tuning's name.
    pub tuning: String,
    /// Targets met.
    pub met: usize,
    /// Targets.
    pub targets: usize,
}

/// The provenance of a bench started now with `opts`.
pub fn provenance(opts: &BenchOptions) -> crate::provenance::Provenance {
    let source = if opts.only.is_empty() {
        "every B scenario".to_string()
    } else {
        format!("B scenarios starting with {}", opts.only.join(", "))
    };
    let mut p = crate::provenance::Provenance::start("bench-scenarios", &source, None);
    p.tuning = opts.tunings.join(", ");
    p.robot = "KUKA RSI driver ↔ simulated KRC (loopback UDP, lockstep)".into();
    p.sensor = "ATI driver ↔ simulated node (in-memory CAN)".into();
    p
}

/// Write `out/bench-scenarios.json` ([`BenchSummary`]) through the output rule (a temporary file
/// renamed when complete); returns its path.
pub fn write_summary(
    out: &Path,
    mut provenance: crate::provenance::Provenance,
    rows: &[BenchRow],
) -> Result<std::path::PathBuf> {
    let mut met: Vec<Met> = Vec::new();
    for r in rows {
        match met.iter_mut().find(|m| m.tuning == r.tuning) {
            Some(m) => {
                m.met += usize::from(r.pass);
                m.targets += 1;
            }
            None => met.push(Met {
                tuning: r.tuning.clone(),
                met: usize::from(r.pass),
                targets: 1,
            }),
        }
    }
    let reason = met
        .iter()
        .map(|m| format!("{}: {} of {} targets met", m.tuning, m.met, m.targets))
        .collect::<Vec<_>>()
        .join("; ");
    provenance.finish(&reason, false, 0);
    let summary = BenchSummary {
        provenance,
        met,
        rows,
    };
    let path = out.join(SUMMARY);
    crate::output::replace(&path, |tmp| {
        let text = serde_json::to_string_pretty(&summary)?;
        std::fs::write(tmp, text + "\n")?;
        Ok(())
    })?;
    Ok(path)
}

/// The table as text.
pub fn table(rows: &[BenchRow]) -> String {
    let w = rows.iter().map(|r| r.tuning.len()).fold(7, usize::max);
    let mut s = format!(
        "{:<22} {:<18} {:<w$} {:<20} {:<12} {:>12}  {:<10} {}\n",
        "scenario", "plant", "tuning", "metric", "window s", "value", "target", "verdict"
    );
    for r in rows {
        s.push_str(&format!(
            "{:<22} {:<18} {:<w$} {:<20} {:<12} {:>12.4}  {:<10} {}\n",
            r.scenario,
            r.plant,
            r.tuning,
            r.metric,
            r.window,
            r.value,
            r.target,
            if r.pass { "pass" } else { "FAIL" }
        ));
    }
    for (name, what) in ELSEWHERE {
        s.push_str(&format!("{name:<22} {what}\n"));
    }
    let mut tunings: Vec<&str> = Vec::new();
    for r in rows {
        if !tunings.contains(&r.tuning.as_str()) {
            tunings.push(&r.tuning);
        }
    }
    for t in tunings {
        let v: Vec<&BenchRow> = rows.iter().filter(|r| r.tuning == t).collect();
        let p = v.iter().filter(|r| r.pass).count();
        s.push_str(&format!("{t}: {p} of {} targets met\n", v.len()));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_b_scenario_is_built_in_and_valid() {
        let names: Vec<String> = scenarios(&BenchOptions::default())
            .unwrap()
            .into_iter()
            .map(|s| s.name)
            .collect();
        for id in [
            "b01", "b02", "b03", "b04", "b05", "b06", "b07", "b08", "b09",
        ] {
            assert!(
                names.iter().any(|n| n.starts_with(id)),
                "{id} missing: {names:?}"
            );
        }
    }

    #[test]
    fn a_short_bench_writes_files_and_a_table() {
        let dir = tempfile::tempdir().unwrap();
        let opts = BenchOptions {
            only: vec!["b01".into()],
            plants: vec!["p2".into()],
            tunings: vec!["robust".into(), "paper".into()],
        };
        let rows = run(&opts, dir.path(), &mut |_| {}).unwrap();
        assert!(rows.iter().any(|r| r.tuning == "robust"));
        assert!(rows.iter().any(|r| r.tuning == "paper"));
        // The robust tuning meets B1 on P2; the paper's does not (it bounces).
        assert!(
            rows.iter().filter(|r| r.tuning == "robust").all(|r| r.pass),
            "{rows:?}"
        );
        assert!(
            rows.iter().filter(|r| r.tuning == "paper").any(|r| !r.pass),
            "{rows:?}"
        );
        let t = table(&rows);
        assert!(
            t.contains("b01-approach") && t.contains("b10-gravity"),
            "{t}"
        );
        assert!(dir.path().join("b01-approach-p2-robust.png").exists());
        assert!(dir.path().join("b01-approach-p2-paper.csv").exists());
    }
}
