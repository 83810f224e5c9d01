//! What `forcecell sim` prints and writes after a run: the summary, the targets' verdicts, the CSV and
//! the plots. The binary only calls it.

use std::path::Path;

use anyhow::Result;

use controller::{RezeroEvent, RezeroOutcome};

use crate::plot;
use crate::runner::{RunResult, RunSpec};

/// The summary's lines about re-zeroing the sensor between passes (`[process] rezero`): a count,
/// then each re-zero with the offset it removed and each refusal with why (the old zero kept);
/// `more` decisions that were not kept (a run's log is bounded). Nothing when there was none.
pub fn rezeros(events: &[RezeroEvent], more: u64) -> Vec<String> {
    if events.is_empty() && more == 0 {
        return Vec::new();
    }
    let done = events
        .iter()
        .filter(|e| e.outcome == RezeroOutcome::Done)
        .count();
    let mut out = vec![format!(
        "{:<20} {done} done, {} refused{}",
        "sensor re-zeros",
        events.len() - done,
        if more > 0 {
            format!(" ({more} more not listed)")
        } else {
            String::new()
        }
    )];
    let v = |v: &hal::Vector3<f64>| format!("({:+.3}, {:+.3}, {:+.3})", v.x, v.y, v.z);
    for e in events {
        out.push(match e.outcome {
            RezeroOutcome::Done => format!(
                "  at {:>8.3} s  re-zeroed: removed F {} N, T {} N·m (zero now F {} N)",
                e.t,
                v(&e.offset.force),
                v(&e.offset.torque),
                v(&e.zero.force)
            ),
            why => format!(
                "  at {:>8.3} s  refused ({why}): the old zero kept (F {} N over the window)",
                e.t,
                v(&e.offset.force)
            ),
        });
    }
    out
}

/// One line per pass with its mean force error (`scenario::metrics::pass_force_errors`: the true force
/// in a simulation), when a run has more than one pass: how a long program's error moves from pass to
/// pass (a drifting sensor, a wearing pad).
pub fn pass_lines(passes: &[::scenario::metrics::PassError]) -> Vec<String> {
    if passes.len() < 2 {
        return Vec::new();
    }
    passes
        .iter()
        .enumerate()
        .map(|(i, p)| {
            format!(
                "pass {:<3} {:>7.1}–{:<7.1} s  mean force error {:+.3} N",
                i + 1,
                p.start,
                p.end,
                p.mean_error
            )
        })
        .collect()
}

/// Print the summary of a simulated run (speed, how it ended, the metrics, every target's verdict),
/// write its CSV and plots into `out`, and return the exit status ([`crate::stop`]): an interrupted or
/// early-ended run first, then (with `check`) a missed target.
pub fn sim(spec: &RunSpec, run: &RunResult, out: &Path, check: bool) -> Result<u8> {
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
    if let Some(stop_sent) = run.interrupted {
        println!(
            "stopped by SIGINT/SIGTERM after {steps} steps; Stop {}",
            if stop_sent {
                "sent to the robot"
            } else {
                run.stop_note.as_str()
            }
        );
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
            // Per-cycle conditions by their schema names: "fault" means only the process fault.
            "conditions",
            ::scenario::telemetry::condition_counts(&run.rows),
        ),
        ("law events", {
            let e = &run.law_events;
            format!(
                "{} contacts, {} lift-offs, {} force-limit retracts; limited: {} velocity, {} acceleration, {} deviation, {} estimator bound",
                e.contacts,
                e.lift_offs,
                e.force_limits,
                e.velocity_limits,
                e.acceleration_limits,
                e.deviation_limits,
                e.estimator_bounds
            )
        }),
    ];
    println!();
    for (k, v) in table {
        println!("  {k:<20} {v}");
    }
    for line in rezeros(&run.rezeros, 0) {
        println!("  {line}");
    }
    for line in pass_lines(&::scenario::metrics::pass_force_errors(&run.rows)) {
        println!("  {line}");
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
    crate::output::write_csv(&csv, &run.rows)?;
    plot::write_png(
        &png,
        &format!(
            "{} · plant {} · tuning {}",
            spec.scenario.name, spec.plant_label, spec.tuning.name
        ),
        &run.rows,
    )?;
    println!("\nwrote {} and {}", csv.display(), png.display());
    if run.rows.iter().any(|r| r.segment.is_some()) {
        let pass_png = out.join(format!("{stem}-pass.png"));
        plot::write_pass_png(
            &pass_png,
            &format!(
                "{} along the path · plant {} · tuning {}",
                spec.scenario.name, spec.plant_label, spec.tuning.name
            ),
            &run.rows,
        )?;
        println!("wrote {} (the pass along the path)", pass_png.display());
    }
    let failed = verdicts.iter().any(|v| !v.pass);
    Ok(if run.interrupted.is_some() {
        crate::stop::INTERRUPTED
    } else if run.ended_early.is_some() && run.fault {
        crate::stop::FAULT
    } else if run.ended_early.is_some() {
        crate::stop::ENDED_EARLY
    } else if check && failed {
        crate::stop::CHECK_FAILED
    } else {
        crate::stop::OK
    })
}

#[cfg(test)]
mod pass_tests {
    use super::pass_lines;
    use ::scenario::metrics::PassError;

    #[test]
    fn a_line_per_pass_only_when_there_are_several() {
        let p = |start: f64, e: f64| PassError {
            start,
            end: start + 50.0,
            mean_error: e,
        };
        assert!(
            pass_lines(&[p(1.0, -0.2)]).is_empty(),
            "one pass: the summary says it"
        );
        let lines = pass_lines(&[p(1.0, -0.215), p(56.0, -0.683)]);
        assert_eq!(lines.len(), 2);
        assert!(
            lines[0].starts_with("pass 1") && lines[0].ends_with("-0.215 N"),
            "{lines:?}"
        );
        assert!(
            lines[1].contains("56.0–106.0") && lines[1].ends_with("-0.683 N"),
            "{lines:?}"
        );
    }
}
