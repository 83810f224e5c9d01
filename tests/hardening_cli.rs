//! Absurd values get one clean `error:` line and exit status 2 — never a panic, an abort or a hang — and
//! an unwritable recording directory is found before the robot is started (issue 12). Each case is a
//! command a hostile user ran; the binary is run as a user runs it.

use std::path::Path;
use std::process::{Command, Output, Stdio};

fn forcecell(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .output()
        .expect("run forcecell")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Exit status 2 with an `error:` line containing every one of `needles`, and no panic.
#[track_caller]
fn refused(o: &Output, needles: &[&str]) {
    let t = text(o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.starts_with("error:"), "{t}");
    assert!(!t.contains("panicked") && !t.contains("Os {"), "{t}");
    for n in needles {
        assert!(err.contains(n), "{n:?} missing: {t}");
    }
}

fn scenario(dir: &Path, name: &str, body: &str) -> String {
    let file = format!("{name}.toml");
    std::fs::write(dir.join(&file), format!("name = \"{name}\"\n{body}")).unwrap();
    format!("./{file}")
}

const ENV: &str = "[environment]\nk_c = 70000.0\nx_c = 0.01\n";

#[test]
fn item1_a_plant_period_of_1e20_s_is_refused_with_the_reason() {
    let d = tempfile::tempdir().unwrap();
    let s = scenario(
        d.path(),
        "p1e20",
        &format!("duration = 0.5\nplant = {{period=1e20,tau=0.0,delay_cycles=0}}\n{ENV}"),
    );
    refused(
        &forcecell(&["sim", "-s", &s], d.path()),
        &["period", "10 kHz"],
    );
}

#[test]
fn item2_a_run_of_too_many_steps_is_refused_before_anything_is_allocated() {
    let d = tempfile::tempdir().unwrap();
    let s = scenario(
        d.path(),
        "p1e5",
        &format!("duration = 3600\nplant = {{period=1e-5,tau=0.0,delay_cycles=0}}\n{ENV}"),
    );
    refused(&forcecell(&["sim", "-s", &s], d.path()), &["period"]);
    // The shortest period accepted, for an hour: 36 million rows.
    let s = scenario(
        d.path(),
        "p1e4",
        &format!("duration = 3600\nplant = {{period=1e-4,tau=0.0,delay_cycles=0}}\n{ENV}"),
    );
    refused(
        &forcecell(&["sim", "-s", &s], d.path()),
        &["steps", "3600000"],
    );
}

#[test]
fn item3_a_surface_a_million_km_away_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let s = scenario(
        d.path(),
        "far",
        "duration = 0.5\nplant = \"p2\"\n[environment]\nk_c = 70000.0\nx_c = 1e9\n",
    );
    refused(&forcecell(&["sim", "-s", &s], d.path()), &["x_c", "±1 m"]);
    // Reached by a ramp, not only set at the start.
    let s = scenario(
        d.path(),
        "ramp",
        "duration = 10.0\n[environment]\nk_c = 70000.0\nx_c = 0.01\nx_c_events = [{kind = \"ramp\", start = 0.0, rate = 1.0}]\n",
    );
    refused(&forcecell(&["sim", "-s", &s], d.path()), &["x_c"]);
    let s = scenario(
        d.path(),
        "stiff",
        "duration = 0.5\n[environment]\nk_c = 1e300\nx_c = 0.01\n",
    );
    refused(&forcecell(&["sim", "-s", &s], d.path()), &["k_c", "steel"]);
}

#[test]
fn item4_plot_refuses_infinite_and_absurd_values() {
    let d = tempfile::tempdir().unwrap();
    let head = "t,f,f_true,f_r,x,x_cmd,x_r,kc_hat,xc_hat,k_c,x_c,fault\n";
    let row = "0,1,,5,0,0,0,0,0,,,0\n";
    for (name, bad, needle) in [
        ("inf", "inf,1,,5,0,0,0,0,0,,,0\n", "column 1"),
        ("big", "0.1,1e308,,5,0,0,0,0,0,,,0\n", "column 2"),
        ("neg", "0.1,-1e308,,5,0,0,0,0,0,,,0\n", "column 2"),
        ("late", "1e300,1,,5,0,0,0,0,0,,,0\n", "column 1"),
    ] {
        let csv = d.path().join(format!("{name}.csv"));
        std::fs::write(&csv, format!("{head}{row}{bad}")).unwrap();
        refused(
            &forcecell(&["plot", csv.to_str().unwrap()], d.path()),
            &["line 3", needle],
        );
    }
    // One trailing blank line is not an error.
    let csv = d.path().join("blank.csv");
    std::fs::write(&csv, format!("{head}{row}\n")).unwrap();
    let o = forcecell(&["plot", csv.to_str().unwrap()], d.path());
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn item5_tune_refuses_a_delay_of_1e8_s_and_a_period_of_1e300_s() {
    let d = tempfile::tempdir().unwrap();
    refused(
        &forcecell(&["tune", "--delay", "1e8"], d.path()),
        &["--delay", "[0, 1] s"],
    );
    refused(
        &forcecell(&["tune", "--delay", "1e6"], d.path()),
        &["--delay"],
    );
    refused(
        &forcecell(&["tune", "--period", "1e300"], d.path()),
        &["--period", "10 kHz"],
    );
    // Negative numbers after a flag need no `=`: they reach the bound check.
    refused(
        &forcecell(&["tune", "--lag", "-1"], d.path()),
        &["--lag", "-1 s"],
    );
    // At the edge it finishes, with an answer (no impedance is safe with a 1 s delay).
    let o = forcecell(&["tune", "--delay", "1"], d.path());
    assert!(
        o.status.code().is_some() && !text(&o).contains("panicked"),
        "{}",
        text(&o)
    );
}

#[test]
fn items6_to_8_sensor_values_are_refused_before_any_interface_is_opened() {
    let d = tempfile::tempdir().unwrap();
    // `nocan0` does not exist: a value error must come first.
    refused(
        &forcecell(
            &[
                "sensor", "ati", "--can", "nocan0", "read", "--rate", "1e-20",
            ],
            d.path(),
        ),
        &["--rate", "stale"],
    );
    refused(
        &forcecell(
            &["sim-sensor", "ati", "--can", "nocan0", "--seconds", "1e20"],
            d.path(),
        ),
        &["--seconds", "week"],
    );
    refused(
        &forcecell(
            &[
                "sensor",
                "ati",
                "--can",
                "nocan0",
                "--turnaround-us",
                "18446744073709551615",
                "info",
            ],
            d.path(),
        ),
        &["--turnaround-us", "10 s"],
    );
    refused(
        &forcecell(
            &["sim-sensor", "ati", "--can", "nocan0", "--fz", "nan"],
            d.path(),
        ),
        &["--fz"],
    );
}

#[test]
fn smaller_ones_are_refused_or_fixed() {
    let d = tempfile::tempdir().unwrap();
    refused(
        &forcecell(&["rsi-config", "--port", "0"], d.path()),
        &["port 0"],
    );
    refused(
        &forcecell(&["bench-scenarios", "zzz", "--out", "b"], d.path()),
        &["zzz", "b01"],
    );
    for (name, target, needle) in [
        (
            "minmax",
            "{metric = \"peak_force\", min = 5.0, max = 1.0}",
            "min 5 is above max 1",
        ),
        (
            "window",
            "{metric = \"peak_force\", max = 9.0, after = 2.0, until = 1.0}",
            "empty",
        ),
        ("nanmax", "{metric = \"peak_force\", max = nan}", "finite"),
    ] {
        let s = scenario(
            d.path(),
            name,
            &format!("duration = 0.5\ntargets = [{target}]\n{ENV}"),
        );
        refused(&forcecell(&["sim", "-s", &s], d.path()), &[needle]);
    }
    // PNG errors are one readable line, not a Debug dump.
    let s = scenario(d.path(), "short", &format!("duration = 0.05\n{ENV}"));
    let o = forcecell(
        &["sim", "-s", &s, "--out", "o", "--sensor", "inproc"],
        d.path(),
    );
    assert!(o.status.success(), "{}", text(&o));
    refused(
        &forcecell(
            &["plot", "o/short.csv", "--out", "/nonexistent/x.png"],
            d.path(),
        ),
        &["cannot write /nonexistent/x.png: No such file or directory"],
    );
}

const CELL: &str = r#"
tuning = "robust"
duration = 1.0
record = "RECORD"

[robot]
listen = "127.0.0.1:49152"
robot_ip = "127.0.0.1"

[sensor]
kind = "ati"
can = "nocan0"
"#;

/// `run` with the recording in `record`: refused before the sensor or the robot link is opened.
fn run_with_record(record: &str) -> Output {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("cell.toml"), CELL.replace("RECORD", record)).unwrap();
    forcecell(&["run", "--config", "cell.toml"], d.path())
}

#[test]
fn item14_an_unwritable_recording_directory_is_found_before_the_robot_is_started() {
    // /proc/sys/kernel exists, and no file can be created in it, not even by root.
    let o = run_with_record("/proc/sys/kernel");
    refused(
        &o,
        &["recording directory /proc/sys/kernel", "not writable"],
    );
    assert!(
        !text(&o).contains("nocan0"),
        "checked before the sensor: {}",
        text(&o)
    );
}

#[test]
fn item14_recording_names_are_unique_within_a_second() {
    let d = tempfile::tempdir().unwrap();
    let names: Vec<_> = (0..3)
        .map(|_| forcecell::cell::reserve_recording(d.path()).unwrap())
        .collect();
    assert!(
        names[0] != names[1] && names[1] != names[2] && names[0] != names[2],
        "{names:?}"
    );
    for n in &names {
        let head = std::fs::read_to_string(n).unwrap();
        assert_eq!(head.trim_end(), forcecell::record::HEADER);
    }
}

/// Mounts a tmpfs at a fresh directory with `opts`; unmounts on drop.
struct Tmpfs(tempfile::TempDir);

impl Tmpfs {
    fn mount(opts: &str) -> Self {
        let d = tempfile::tempdir().unwrap();
        let st = Command::new("mount")
            .args(["-t", "tmpfs", "-o", opts, "tmpfs"])
            .arg(d.path())
            .status()
            .expect("run mount");
        assert!(st.success(), "mount -t tmpfs -o {opts} (needs root)");
        Self(d)
    }
    fn path(&self) -> &Path {
        self.0.path()
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(self.0.path()).status();
    }
}

#[test]
#[ignore = "mounts a read-only and a full tmpfs: needs root (cargo test --release --test hardening_cli -- --ignored)"]
fn item14_read_only_and_full_filesystems_are_found_before_the_robot_is_started() {
    let ro = Tmpfs::mount("ro,size=64k");
    let o = run_with_record(ro.path().to_str().unwrap());
    refused(&o, &["not writable", "Read-only file system"]);
    assert!(!text(&o).contains("nocan0"), "{}", text(&o));

    let full = Tmpfs::mount("size=64k");
    // Fill it to the last byte.
    let _ = Command::new("dd")
        .args(["if=/dev/zero", "bs=4096", "count=64"])
        .arg(format!("of={}", full.path().join("filler").display()))
        .stderr(Stdio::null())
        .status();
    let o = run_with_record(full.path().to_str().unwrap());
    refused(&o, &["cannot take the trace", "No space left on device"]);
    assert!(!text(&o).contains("nocan0"), "{}", text(&o));
    let left: Vec<_> = std::fs::read_dir(full.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 1, "no empty CSV left behind: {left:?}");
}
