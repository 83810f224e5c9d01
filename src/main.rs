//! `forcecell` — simulate a polishing cell, or deploy the controller on a real one.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use forcecell::runner::{RunResult, RunSpec, run_inproc};
use forcecell::scenario::Scenario;
use forcecell::{plot, record};
use indicatif::{ProgressBar, ProgressStyle};

#[derive(Parser)]
#[command(
    name = "forcecell",
    version,
    about = "Adaptive force control for robotic polishing cells",
    propagate_version = true
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a cell: run a scenario, print a summary, write DIR/NAME.csv and DIR/NAME.png.
    Sim(SimArgs),
    /// Plot a recorded trace (CSV written by `sim` or `run`) to PNG and print its metrics.
    Plot(PlotArgs),
}

#[derive(Args)]
struct PlotArgs {
    /// The trace, CSV.
    csv: PathBuf,
    /// The PNG to write (default: the CSV's path with .png).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Args)]
struct SimArgs {
    /// Built-in scenario name or a scenario TOML file.
    #[arg(long, short, default_value = "paper-fig9")]
    scenario: String,
    /// Robot inner loop: p0 (ideal), p1 (1 kHz, 10 ms lag, 4 ms delay), p2 (RSI-like 4 ms, 12 ms delay).
    #[arg(long, value_parser = ["p0", "p1", "p2"])]
    plant: Option<String>,
    /// Built-in tuning name or a tuning TOML file (default: the scenario's).
    #[arg(long)]
    tuning: Option<String>,
    /// Output directory.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// List the built-in scenarios and tunings, then exit.
    #[arg(long)]
    list: bool,
    /// Exit with status 1 when a scenario target is missed.
    #[arg(long)]
    check: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Sim(a) => sim(a),
        Command::Plot(a) => plot_trace(a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn sim(a: SimArgs) -> Result<ExitCode> {
    if a.list {
        list()?;
        return Ok(ExitCode::SUCCESS);
    }
    let scenario = Scenario::load(&a.scenario)?;
    let spec = RunSpec::new(scenario, a.plant.as_deref(), a.tuning.as_deref())?;
    println!(
        "forcecell sim: {} — {}",
        spec.scenario.name, spec.scenario.description
    );
    println!(
        "plant {} (period {} ms, lag {} ms, delay {} ms) · tuning {} · {} steps",
        spec.plant_label,
        spec.plant.period * 1e3,
        spec.plant.tau * 1e3,
        spec.plant.delay() * 1e3,
        spec.tuning.name,
        spec.steps()
    );
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("cannot create output directory {}", a.out.display()))?;
    let mut bar = DelayedBar::new(Duration::from_millis(300));
    let run = run_inproc(&spec, &mut |frac| bar.update(frac))?;
    bar.finish();
    report(&spec, &run, &a.out, a.check)
}

fn plot_trace(a: PlotArgs) -> Result<ExitCode> {
    let text = std::fs::read_to_string(&a.csv)
        .with_context(|| format!("cannot read {}", a.csv.display()))?;
    let rows = record::read_csv(&text).with_context(|| format!("{}", a.csv.display()))?;
    if rows.is_empty() {
        anyhow::bail!("{}: the trace has no rows", a.csv.display());
    }
    let m = forcecell::metrics::Metrics::compute(&rows, 0.0, f64::INFINITY);
    println!(
        "{} rows, {:.3} s: peak {:.2} N, settle {} s, steady-state error {:.4} N, RMS {:.4} N, {} contact losses",
        rows.len(),
        rows.last().map_or(0.0, |r| r.t),
        m.peak_force,
        m.settle_time,
        m.ss_error,
        m.rms_error,
        m.contact_losses
    );
    let png = a.out.unwrap_or_else(|| a.csv.with_extension("png"));
    let title = a
        .csv
        .file_stem()
        .map_or("trace".into(), |s| s.to_string_lossy().into_owned());
    plot::write_png(&png, &title, &rows)?;
    println!("wrote {}", png.display());
    Ok(ExitCode::SUCCESS)
}

fn list() -> Result<()> {
    println!("built-in scenarios:");
    for s in Scenario::builtins()? {
        println!(
            "  {:<22} {:>5} s  {:<3} {:<10} {}",
            s.name,
            s.duration,
            s.plant.label(),
            s.tuning,
            s.description
        );
    }
    println!("built-in tunings:");
    for n in forcecell::scenario::builtin_tuning_names() {
        let t = forcecell::scenario::load_tuning(n)?;
        println!("  {:<22} {}", t.name, t.description);
    }
    Ok(())
}

fn report(spec: &RunSpec, run: &RunResult, out: &Path, check: bool) -> Result<ExitCode> {
    let m = &run.metrics;
    let steps = run.rows.len();
    let rate = steps as f64 / run.wall.as_secs_f64().max(1e-9);
    println!(
        "ran {steps} steps in {:.2} s wall ({:.0} steps/s)",
        run.wall.as_secs_f64(),
        rate
    );
    if let Some(why) = &run.ended_early {
        println!("the loop ended early: {why}");
    }
    let f_r = run.rows.last().map_or(f64::NAN, |r| r.f_r);
    let settle = if m.settle_time.is_finite() {
        format!("{:.3} s after first contact", m.settle_time)
    } else {
        "not settled".to_string()
    };
    let last = run.rows.last();
    let table = [
        (
            "first contact",
            if m.first_contact.is_nan() {
                "never".into()
            } else {
                format!("{:.3} s", m.first_contact)
            },
        ),
        (
            "peak force",
            format!("{:.2} N (set-point {f_r} N)", m.peak_force),
        ),
        ("settling (±2 %)", settle),
        ("overshoot", format!("{:.1} %", m.overshoot_pct)),
        (
            "steady-state error",
            format!(
                "{:.4} N (|mean f − f_r| over the last 0.1 s; ripple ±{:.4} N)",
                m.ss_error, m.ss_ripple
            ),
        ),
        (
            "RMS error",
            format!("{:.4} N (from first contact)", m.rms_error),
        ),
        (
            "contact losses",
            format!(
                "{} (longest {:.3} s)",
                m.contact_losses, m.contact_loss_time
            ),
        ),
        (
            "final k̂_c",
            format!(
                "{:.0} N/m (true {:.0} N/m)",
                m.kc_hat,
                last.map_or(f64::NAN, |r| r.k_c)
            ),
        ),
        (
            "final x̂_c",
            format!(
                "{:.4} mm (true {:.4} mm)",
                m.xc_hat * 1e3,
                last.map_or(f64::NAN, |r| r.x_c * 1e3)
            ),
        ),
        (
            "faults",
            format!(
                "{} sensor, {} non-finite, {} limited",
                run.stats.sensor_faults, run.stats.nonfinite_inputs, run.stats.limited
            ),
        ),
    ];
    println!();
    for (k, v) in table {
        println!("  {k:<20} {v}");
    }
    let verdicts = run.verdicts(&spec.scenario.targets);
    if !verdicts.is_empty() {
        println!("\ntargets:");
        for v in &verdicts {
            let t = &v.target;
            let window = format!(
                "[{}, {}] s",
                t.after.unwrap_or(0.0),
                t.until.map_or("end".to_string(), |u| u.to_string())
            );
            let limit = match (t.min, t.max) {
                (Some(lo), Some(hi)) => format!("in [{lo}, {hi}]"),
                (Some(lo), None) => format!("≥ {lo}"),
                (None, Some(hi)) => format!("≤ {hi}"),
                (None, None) => String::new(),
            };
            println!(
                "  {:<18} {:<14} {:<12} {:>12.4}  {}",
                t.metric,
                window,
                limit,
                v.value,
                if v.pass { "pass" } else { "FAIL" }
            );
        }
    }
    let stem = spec.file_stem();
    let csv = out.join(format!("{stem}.csv"));
    let png = out.join(format!("{stem}.png"));
    record::write_csv_file(&csv, &run.rows)?;
    plot::write_png(
        &png,
        &format!(
            "{} · plant {} · tuning {}",
            spec.scenario.name, spec.plant_label, spec.tuning.name
        ),
        &run.rows,
    )?;
    println!("\nwrote {} and {}", csv.display(), png.display());
    let failed = verdicts.iter().any(|v| !v.pass);
    Ok(if check && failed {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}

/// A progress bar that appears only when a run takes more than a moment (and stderr is a terminal).
struct DelayedBar {
    start: Instant,
    delay: Duration,
    bar: Option<ProgressBar>,
}

impl DelayedBar {
    fn new(delay: Duration) -> Self {
        Self {
            start: Instant::now(),
            delay,
            bar: None,
        }
    }

    fn update(&mut self, frac: f64) {
        if self.bar.is_none() && self.start.elapsed() >= self.delay && frac < 1.0 {
            let b = ProgressBar::new(1000);
            b.set_style(
                ProgressStyle::with_template("{bar:40} {percent:>3}% simulated, eta {eta}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            self.bar = Some(b);
        }
        if let Some(b) = &self.bar {
            b.set_position((frac * 1000.0) as u64);
        }
    }

    fn finish(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}
