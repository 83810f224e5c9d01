//! The `forcecell` binary as a user runs it: files written, clear one-line errors, no panics.

use std::path::Path;
use std::process::{Command, Output};

fn forcecell(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run forcecell")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A failure must be one `error:` line with a non-zero status, never a panic.
fn assert_clean_failure(o: &Output, needle: &str) {
    let err = stderr(o);
    assert!(!o.status.success(), "expected failure, got success: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    assert!(err.contains(needle), "stderr lacks {needle:?}: {err}");
    let lines = err.lines().filter(|l| !l.trim().is_empty()).count();
    assert!(lines <= 3, "error should be short: {err}");
}

#[test]
fn sim_writes_csv_and_png_for_both_paper_figures() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["paper-fig9", "paper-fig10"] {
        let o = forcecell(&["sim", "--scenario", name, "--out", "res"], dir.path());
        assert!(o.status.success(), "{}", stderr(&o));
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(
            stdout.contains("settling") && stdout.contains("final k̂_c"),
            "{stdout}"
        );
        let csv = std::fs::read_to_string(dir.path().join(format!("res/{name}.csv"))).unwrap();
        let header = csv.lines().next().unwrap();
        for col in ["t", "f", "f_r", "x", "x_cmd", "x_r", "kc_hat", "xc_hat"] {
            assert!(
                header.split(',').any(|c| c == col),
                "column {col} missing: {header}"
            );
        }
        assert_eq!(csv.lines().count(), 2001, "header + one row per 1 ms step");
        let png = std::fs::read(dir.path().join(format!("res/{name}.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        assert!(
            png.len() > 20_000,
            "a plot with content, got {} bytes",
            png.len()
        );
    }
}

#[test]
fn default_run_says_where_the_files_went() {
    let dir = tempfile::tempdir().unwrap();
    let o = forcecell(&["sim"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let wrote = stdout
        .lines()
        .find(|l| l.starts_with("wrote "))
        .expect("a 'wrote' line");
    for part in wrote.trim_start_matches("wrote ").split(" and ") {
        assert!(dir.path().join(part.trim()).is_file(), "{part} not written");
    }
}

#[test]
fn list_names_the_scenarios_and_tunings() {
    let dir = tempfile::tempdir().unwrap();
    let o = forcecell(&["sim", "--list"], dir.path());
    assert!(o.status.success());
    let s = String::from_utf8_lossy(&o.stdout);
    for n in [
        "paper-fig9",
        "paper-fig10",
        "paper-impedance",
        "paper",
        "impedance",
    ] {
        assert!(s.contains(n), "{n} missing from --list: {s}");
    }
}

#[test]
fn unknown_scenario_bad_file_and_bad_options_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let o = forcecell(&["sim", "--scenario", "nope"], dir.path());
    assert_clean_failure(&o, "unknown scenario");

    let o = forcecell(&["sim", "--scenario", "missing.toml"], dir.path());
    assert_clean_failure(&o, "missing.toml");

    std::fs::write(
        dir.path().join("broken.toml"),
        "name = \"b\"\nduration = [\n",
    )
    .unwrap();
    let o = forcecell(&["sim", "--scenario", "broken.toml"], dir.path());
    assert_clean_failure(&o, "broken.toml");

    std::fs::write(
        dir.path().join("neg.toml"),
        "name = \"neg\"\nduration = 1.0\n[environment]\nk_c = -5.0\nx_c = 0.01\n",
    )
    .unwrap();
    let o = forcecell(&["sim", "--scenario", "neg.toml"], dir.path());
    assert_clean_failure(&o, "k_c");

    std::fs::write(
        dir.path().join("nan.toml"),
        "name = \"nan\"\nduration = nan\n[environment]\nk_c = 5.0\nx_c = 0.01\n",
    )
    .unwrap();
    let o = forcecell(&["sim", "--scenario", "nan.toml"], dir.path());
    assert_clean_failure(&o, "duration");

    let o = forcecell(&["sim", "--plant", "p9"], dir.path());
    assert_clean_failure(&o, "p9");

    let o = forcecell(&["sim", "--tuning", "nope"], dir.path());
    assert_clean_failure(&o, "unknown tuning");
}

#[test]
fn a_scenario_file_runs_and_check_reports_missed_targets() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("mine.toml"),
        r#"
name = "mine"
duration = 0.5
plant = "p0"
tuning = "paper"
[environment]
k_c = 70000.0
x_c = 0.010
[[targets]]
metric = "peak_force"
max = 0.001        # unreachable on purpose: the tool touches the surface
"#,
    )
    .unwrap();
    let o = forcecell(&["sim", "-s", "mine.toml", "--out", "o"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("FAIL"));
    let o = forcecell(
        &["sim", "-s", "mine.toml", "--out", "o", "--check"],
        dir.path(),
    );
    assert_eq!(o.status.code(), Some(1));
}

#[test]
fn plot_replots_a_recording_and_refuses_garbage() {
    let dir = tempfile::tempdir().unwrap();
    let o = forcecell(&["sim", "-s", "paper-fig10", "--out", "r"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let o = forcecell(
        &["plot", "r/paper-fig10.csv", "--out", "again.png"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("2000 rows"));
    let png = std::fs::read(dir.path().join("again.png")).unwrap();
    assert_eq!(&png[..4], b"\x89PNG");
    std::fs::write(dir.path().join("junk.csv"), "hello,world\n1,2\n").unwrap();
    let o = forcecell(&["plot", "junk.csv"], dir.path());
    assert_clean_failure(&o, "not a forcecell trace");
}

#[test]
fn bench_scenarios_prints_one_table_and_writes_the_plots() {
    let dir = tempfile::tempdir().unwrap();
    let o = forcecell(
        &["bench-scenarios", "b01", "b09", "--out", "b", "--check"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let s = String::from_utf8_lossy(&o.stdout);
    for needle in [
        "over the default wires",
        "b01-approach",
        "b09-faults",
        "robust",
        "paper",
        "FAIL",
        "pass",
    ] {
        assert!(s.contains(needle), "{needle} missing: {s}");
    }
    // Two scenarios × two plants × two tunings.
    let pngs = std::fs::read_dir(dir.path().join("b"))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "png")
        })
        .count();
    assert_eq!(pngs, 8);
    // A JSON summary beside the bench: the same figures as the table, and where they came from.
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("b/bench-scenarios.json")).unwrap(),
    )
    .unwrap();
    let p = &json["provenance"];
    assert_eq!(p["command"], "bench-scenarios");
    assert_eq!(p["forcecell"], env!("CARGO_PKG_VERSION"));
    assert!(p["started"].as_str().unwrap().ends_with('Z'));
    assert!(p["ended"].as_str().unwrap().ends_with('Z'));
    assert_eq!(p["tuning"], "robust, paper");
    let rows = json["rows"].as_array().unwrap();
    let table_rows: Vec<&str> = s
        .lines()
        .filter(|l| l.starts_with("b01-") || l.starts_with("b09-"))
        .collect();
    assert_eq!(rows.len(), table_rows.len(), "{s}");
    for (r, line) in rows.iter().zip(&table_rows) {
        let words: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(r["scenario"], words[0], "{line}");
        assert!(line.contains(r["metric"].as_str().unwrap()), "{line}");
        let value = match r["value"].as_f64() {
            Some(v) => format!("{v:.4}"),
            None => r["value"].as_str().unwrap().to_string(),
        };
        assert!(line.contains(&value), "{value} not in {line}");
        assert_eq!(r["pass"], line.trim_end().ends_with("pass"), "{line}");
    }
    assert!(s.contains("summary b/bench-scenarios.json"), "{s}");
    // B9 over the wires: the simulated node reports the injected NaN as a saturated gauge (unusable,
    // as the board would), not as 0 N, so the robust law holds through it on both plants.
    for line in s
        .lines()
        .filter(|l| l.starts_with("b09-faults") && l.contains("robust"))
    {
        assert!(line.trim_end().ends_with("pass"), "{line}");
    }
    assert_eq!(
        s.lines()
            .filter(|l| l.starts_with("b09-faults") && l.contains("robust"))
            .count(),
        2
    );
}

/// The re-acquire search is the integrator's choice, and `bench-scenarios` shows what it costs over
/// the default wires: the shipped fast search meets B3's 50 ms contact-loss target on the 1 mm
/// retreat on P1 and P2, the gentle one (`robust-gentle`, which stops within 2·f_r) does not, and
/// `--check` says so; a tuning file that extends another runs the same way.
#[test]
fn bench_scenarios_compares_the_fast_and_the_gentle_search() {
    let dir = tempfile::tempdir().unwrap();
    let loss = |s: &str, tuning: &str| -> Vec<(f64, bool)> {
        s.lines()
            .filter(|l| l.starts_with("b03a-surface-retreat") && l.contains("contact_loss_time"))
            .filter(|l| l.split_whitespace().nth(2) == Some(tuning))
            .map(|l| {
                let w: Vec<&str> = l.split_whitespace().collect();
                (w[w.len() - 4].parse().unwrap(), w[w.len() - 1] == "pass")
            })
            .collect()
    };
    let fast = forcecell(
        &[
            "bench-scenarios",
            "b03a",
            "--out",
            "b",
            "--tuning",
            "robust",
            "--check",
        ],
        dir.path(),
    );
    assert!(fast.status.success(), "{}", stderr(&fast));
    let fast = loss(&String::from_utf8_lossy(&fast.stdout), "robust");
    assert_eq!(fast.len(), 2, "P1 and P2");
    assert!(fast.iter().all(|&(t, pass)| pass && t <= 0.05), "{fast:?}");
    std::fs::write(
        dir.path().join("mine.toml"),
        "extends = \"robust-gentle\"\nname = \"mine\"\n",
    )
    .unwrap();
    for tuning in ["robust-gentle", "mine.toml"] {
        let o = forcecell(
            &[
                "bench-scenarios",
                "b03a",
                "--out",
                "b",
                "--tuning",
                tuning,
                "--check",
            ],
            dir.path(),
        );
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        let name = tuning.trim_end_matches(".toml");
        let gentle = loss(&String::from_utf8_lossy(&o.stdout), name);
        assert_eq!(gentle.len(), 2, "P1 and P2");
        for (&(g, pass), &(f, _)) in gentle.iter().zip(&fast) {
            assert!(!pass && g > 0.05 && g > f, "gentle {g} s, fast {f} s");
        }
    }
}

/// The process columns (segment, mode, f_cmd, phase, fault) of a run without process channels are
/// empty, as docs/recordings.md says, not 0 (a phase "off" and a fault "none" would read as a process
/// that is there); a run with a robot program fills them; the export of the recording is the CSV.
#[test]
fn process_columns_are_empty_without_process_channels() {
    let dir = tempfile::tempdir().unwrap();
    let columns = |csv: &str| -> Vec<Vec<String>> {
        let text = std::fs::read_to_string(dir.path().join(csv)).unwrap();
        let mut lines = text.lines();
        let head: Vec<&str> = lines.next().unwrap().split(',').collect();
        let at: Vec<usize> = ["segment", "mode", "f_cmd", "phase", "fault"]
            .iter()
            .map(|c| head.iter().position(|h| h == c).unwrap())
            .collect();
        lines
            .map(|l| {
                let cols: Vec<&str> = l.split(',').collect();
                at.iter().map(|&i| cols[i].to_string()).collect()
            })
            .collect()
    };
    for robot in ["inproc", "rsi"] {
        let out = format!("plain-{robot}");
        let o = forcecell(
            &["sim", "--sensor", "inproc", "--robot", robot, "--out", &out],
            dir.path(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let rows = columns(&format!("{out}/paper-fig9.csv"));
        assert!(rows.len() > 100);
        for r in &rows {
            assert!(r.iter().all(String::is_empty), "{robot}: {r:?}");
        }
        let o = forcecell(
            &[
                "export",
                &format!("{out}/paper-fig9.mcap"),
                "--csv",
                "--out",
                &format!("{out}/export.csv"),
            ],
            dir.path(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        assert_eq!(
            std::fs::read(dir.path().join(format!("{out}/export.csv"))).unwrap(),
            std::fs::read(dir.path().join(format!("{out}/paper-fig9.csv"))).unwrap()
        );
    }
    let o = forcecell(
        &[
            "sim",
            "--sensor",
            "inproc",
            "--robot",
            "inproc",
            "-s",
            "pass-flat-20n",
            "--out",
            "p",
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let rows = columns("p/pass-flat-20n.csv");
    assert!(
        rows.iter().all(|r| r.iter().all(|c| !c.is_empty())),
        "a run with a robot program fills every process column"
    );
}
