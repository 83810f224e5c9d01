//! The hostile-input suite (issue 35): a few hundred hand-written and generated inputs given to the
//! release binary as a user gives them — named pipes, devices, directories, symbolic-link loops, huge
//! and empty files, huge and tiny numbers, NaN and infinities, duplicate keys, wrong types, every key of
//! the shipped cell file mutated — each asserted to end in **exactly one `error:` line, exit status 2,
//! within a generous time** (a hang detector, not a speed check), and with **no new or changed file** in
//! its directory. Then one test per defect of the issue, each naming what it proves.

use std::collections::BTreeMap;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// A case that runs longer than this is taken for a hang (the binary is killed, the case fails).
const HANG: Duration = Duration::from_secs(20);

/// The binary under test: this build's, or `FORCECELL_HOSTILE_BIN` (to run the suite against another
/// build, e.g. the one before a fix).
fn bin() -> PathBuf {
    std::env::var_os("FORCECELL_HOSTILE_BIN").map_or_else(
        || PathBuf::from(env!("CARGO_BIN_EXE_forcecell")),
        PathBuf::from,
    )
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The shipped cell file, on a CAN interface no machine has (so a cell file that parses still ends in
/// an error, after its recording directory was created: the cleanup is checked too).
fn base_cell() -> String {
    std::fs::read_to_string(root().join("examples/cell.toml"))
        .unwrap()
        .replace("can = \"can0\"", "can = \"nocan9\"")
}

/// A short scenario's recording and trace, made once: inputs of `plot` and `export`.
fn trace_fixture() -> &'static (Vec<u8>, Vec<u8>) {
    static T: OnceLock<(Vec<u8>, Vec<u8>)> = OnceLock::new();
    T.get_or_init(|| {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(
            d.path().join("short.toml"),
            "name = \"short\"\nduration = 0.05\n[environment]\nk_c = 70000.0\nx_c = 0.01\n",
        )
        .unwrap();
        let o = Command::new(bin())
            .args([
                "sim",
                "--scenario",
                "short.toml",
                "--robot",
                "inproc",
                "--sensor",
                "inproc",
                "--out",
                "o",
            ])
            .current_dir(d.path())
            .stdin(Stdio::null())
            .output()
            .unwrap();
        assert!(o.status.success(), "{o:?}");
        let stem = "o/short-p2-paper";
        let mcap = std::fs::read(d.path().join(format!("{stem}.mcap")));
        let stem = if mcap.is_ok() {
            stem.to_string()
        } else {
            // The file's name follows the scenario's plant and tuning: find it.
            let f = std::fs::read_dir(d.path().join("o"))
                .unwrap()
                .filter_map(|e| e.ok())
                .map(|e| e.path())
                .find(|p| p.extension().is_some_and(|e| e == "mcap"))
                .unwrap();
            f.with_extension("").display().to_string()
        };
        let at = |ext: &str| {
            let p = PathBuf::from(&stem).with_extension(ext);
            std::fs::read(d.path().join(p)).unwrap()
        };
        (at("mcap"), at("csv"))
    })
}

/// What a case puts in its directory before it runs.
#[derive(Clone)]
enum Setup {
    File(&'static str, Vec<u8>),
    Fifo(&'static str),
    Dir(&'static str),
    Symlink(&'static str, &'static str),
    /// A sparse file of this many bytes.
    Sparse(&'static str, u64),
    Trace,
}

#[derive(Clone)]
struct Case {
    name: String,
    args: Vec<String>,
    setup: Vec<Setup>,
}

fn case(name: impl Into<String>, args: &[&str], setup: Vec<Setup>) -> Case {
    Case {
        name: name.into(),
        args: args.iter().map(|s| s.to_string()).collect(),
        setup,
    }
}

/// Every file and directory under `dir`: type, size, modification time (ns), inode.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, (u32, u64, i64, i64, u64)> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let m = std::fs::symlink_metadata(&p).unwrap();
            if m.is_dir() {
                stack.push(p.clone());
            }
            let rel = p.strip_prefix(dir).unwrap().to_path_buf();
            out.insert(
                rel,
                (m.mode(), m.size(), m.mtime(), m.mtime_nsec(), m.ino()),
            );
        }
    }
    out
}

fn prepare(dir: &Path, setup: &[Setup]) {
    for s in setup {
        match s {
            Setup::File(n, b) => std::fs::write(dir.join(n), b).unwrap(),
            Setup::Fifo(n) => {
                let st = Command::new("mkfifo").arg(dir.join(n)).status().unwrap();
                assert!(st.success(), "mkfifo");
            }
            Setup::Dir(n) => std::fs::create_dir_all(dir.join(n)).unwrap(),
            Setup::Symlink(n, to) => std::os::unix::fs::symlink(to, dir.join(n)).unwrap(),
            Setup::Sparse(n, len) => std::fs::File::create(dir.join(n))
                .unwrap()
                .set_len(*len)
                .unwrap(),
            Setup::Trace => {
                let (mcap, csv) = trace_fixture();
                std::fs::create_dir_all(dir.join("out")).unwrap();
                std::fs::write(dir.join("out/t.mcap"), mcap).unwrap();
                std::fs::write(dir.join("out/t.csv"), csv).unwrap();
                std::fs::write(dir.join("keep.csv"), csv).unwrap();
            }
        }
    }
}

/// Run one case; `Err` says what went wrong.
fn check(c: &Case) -> Result<(), String> {
    let d = tempfile::tempdir().unwrap();
    prepare(d.path(), &c.setup);
    let before = snapshot(d.path());
    let mut child = Command::new(bin())
        .args(&c.args)
        .current_dir(d.path())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Drain the pipes on threads so a chatty child never blocks on them.
    let mut so = child.stdout.take().unwrap();
    let mut se = child.stderr.take().unwrap();
    let to = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = std::io::Read::read_to_end(&mut so, &mut s);
        s
    });
    let te = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = std::io::Read::read_to_end(&mut se, &mut s);
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break Some(st);
        }
        if start.elapsed() > HANG {
            // Ends only the child this case started, by its handle.
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let out = String::from_utf8_lossy(&to.join().unwrap()).into_owned();
    let err = String::from_utf8_lossy(&te.join().unwrap()).into_owned();
    let all = format!("{out}{err}");
    let Some(status) = status else {
        return Err(format!("still running after {HANG:?}: {all}"));
    };
    let errors = all.lines().filter(|l| l.starts_with("error:")).count();
    let mut why = Vec::new();
    if status.code() != Some(2) {
        why.push(format!("status {status}"));
    }
    if errors != 1 {
        why.push(format!("{errors} error: lines"));
    }
    if all.contains("panicked") {
        why.push("a panic".into());
    }
    let after = snapshot(d.path());
    if after != before {
        let new: Vec<_> = after
            .iter()
            .filter(|(k, v)| before.get(*k) != Some(v))
            .map(|(k, _)| k.display().to_string())
            .collect();
        let gone: Vec<_> = before
            .keys()
            .filter(|k| !after.contains_key(*k))
            .map(|k| k.display().to_string())
            .collect();
        why.push(format!("files new or changed {new:?}, gone {gone:?}"));
    }
    if why.is_empty() {
        Ok(())
    } else {
        Err(format!("{}: {all}", why.join(", ")))
    }
}

/// Values that no key of a cell, scenario or tuning file takes for what it means.
const HOSTILE_VALUES: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "1e300",
    "-1e300",
    "1e-300",
    "0",
    "-1",
    "4294967295",
    "18446744073709551616",
    "\"\"",
    "\"x\"",
    "[1, 2]",
    "{ a = 1 }",
    "true",
];

/// The cell file with `key`'s value (the first line `key = …`) replaced.
fn mutate(text: &str, key: &str, value: &str) -> String {
    let mut done = false;
    text.lines()
        .map(|l| {
            if !done && l.split('=').next().is_some_and(|k| k.trim() == key) {
                done = true;
                format!("{key} = {value}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The cell file with `ethernet_config = "path"` in its `[robot]` section.
fn with_ethernet_config(cell: &str, path: &str) -> String {
    let line = cell.lines().find(|l| l.starts_with("robot_ip")).unwrap();
    cell.replacen(line, &format!("{line}\nethernet_config = \"{path}\""), 1)
}

/// The keys `key = value` of a TOML text (one per line).
fn keys(text: &str) -> Vec<String> {
    text.lines()
        .filter(|l| !l.trim_start().starts_with(['#', '[']) && l.contains('='))
        .map(|l| l.split('=').next().unwrap().trim().to_string())
        .collect()
}

/// Paths that are no file to read, each with what makes it one.
fn hostile_paths() -> Vec<(&'static str, Vec<Setup>)> {
    vec![
        ("fifo.toml", vec![Setup::Fifo("fifo.toml")]),
        ("/dev/zero", vec![]),
        ("dir.toml", vec![Setup::Dir("dir.toml")]),
        ("loop.toml", vec![Setup::Symlink("loop.toml", "loop.toml")]),
        ("missing.toml", vec![]),
        ("huge.toml", vec![Setup::Sparse("huge.toml", 300 << 20)]),
        ("empty.toml", vec![Setup::File("empty.toml", Vec::new())]),
        (
            "binary.toml",
            vec![Setup::File("binary.toml", vec![0xff, 0xfe, 0, 1, 2, 0x80])],
        ),
    ]
}

fn cases() -> Vec<Case> {
    let cell = base_cell();
    let mut v = Vec::new();

    // Every key of the shipped cell file, each hostile value, for `run` (and some for `calibrate`).
    for key in keys(&cell) {
        for (i, val) in HOSTILE_VALUES.iter().enumerate() {
            let text = mutate(&cell, &key, val);
            let cmd = if i % 5 == 0 { "calibrate" } else { "run" };
            v.push(case(
                format!("cell {key} = {val} ({cmd})"),
                &[cmd, "--config", "c.toml"],
                vec![Setup::File("c.toml", text.into_bytes())],
            ));
        }
        // A duplicate key.
        let line = cell
            .lines()
            .find(|l| l.split('=').next().is_some_and(|k| k.trim() == key))
            .unwrap();
        let dup = cell.replacen(line, &format!("{line}\n{line}"), 1);
        v.push(case(
            format!("cell duplicate {key}"),
            &["run", "--config", "c.toml"],
            vec![Setup::File("c.toml", dup.into_bytes())],
        ));
    }
    // Unknown keys, sections, TOML that is not.
    for (n, text) in [
        ("unknown key", format!("{cell}\nbogus = 1\n")),
        ("unknown section", format!("{cell}\n[bogus]\na = 1\n")),
        ("truncated", cell[..cell.len() / 2].to_string()),
        ("not toml", "{{{{ ]]]".to_string()),
        ("no robot", cell.replace("[robot]", "[robotx]")),
        (
            "robotiq without port",
            cell.replace("kind = \"ati\"", "kind = \"robotiq\""),
        ),
        ("poll_hz 1e-300", mutate(&cell, "poll_hz", "1e-300")),
        ("poll_hz 0.5", mutate(&cell, "poll_hz", "0.5")),
        ("poll_hz 1e6", mutate(&cell, "poll_hz", "1e6")),
        (
            "watchdog 198 days",
            mutate(&cell, "watchdog_cycles", "4294967295"),
        ),
        ("watchdog 11 s", mutate(&cell, "watchdog_cycles", "2751")),
        ("duration 1e300", mutate(&cell, "duration", "1e300")),
        (
            "duration beyond 3.6 M cycles",
            mutate(&cell, "duration", "14400.5"),
        ),
        (
            "listen port 0",
            mutate(&cell, "listen", "\"192.168.1.100:0\""),
        ),
        ("listen ipv6", mutate(&cell, "listen", "\"[::1]:49152\"")),
        (
            "record is /dev/zero",
            mutate(&cell, "record", "\"/dev/zero\""),
        ),
        (
            "record unwritable",
            mutate(&cell, "record", "\"/proc/sys/kernel/x\""),
        ),
        ("record nested new", mutate(&cell, "record", "\"a/b/c\"")),
        ("tuning fifo", mutate(&cell, "tuning", "\"fifo.toml\"")),
    ] {
        v.push(case(
            format!("cell {n}"),
            &["run", "--config", "c.toml"],
            vec![
                Setup::File("c.toml", text.into_bytes()),
                Setup::Fifo("fifo.toml"),
            ],
        ));
    }
    // ethernet_config: each hostile path, and a real file that is no Ethernet config.
    for (p, setup) in hostile_paths() {
        let text = cell.replace("[sensor]", &format!("ethernet_config = \"{p}\"\n[sensor]"));
        let mut s = setup.clone();
        s.push(Setup::File("c.toml", text.into_bytes()));
        v.push(case(
            format!("ethernet_config {p}"),
            &["run", "--config", "c.toml"],
            s,
        ));
    }

    // Every command that reads a file, given each hostile path.
    for (p, setup) in hostile_paths() {
        let dotted = if p.starts_with('/') {
            p.to_string()
        } else {
            format!("./{p}")
        };
        for args in [
            vec!["run", "--config", p],
            vec!["calibrate", "--config", p],
            vec!["sim", "--scenario", &dotted, "--out", "o"],
            vec!["sim", "--tuning", &dotted, "--out", "o"],
            vec!["tune", "--tuning", &dotted],
            vec!["plot", p],
            vec!["plot", p, "--out", "x.png"],
            vec!["export", p, "--csv", "--out", "x.csv"],
            vec!["bench-scenarios", "b01", "--tuning", &dotted, "--out", "o"],
            vec![
                "rsi-config",
                "--tuning",
                &dotted,
                "--out",
                "o",
                "--ip",
                "192.168.1.100",
                "--robot-ip",
                "192.168.1.10",
            ],
            vec![
                "sim-sensor",
                "ati",
                "--can",
                "nocan9",
                "--replay",
                p,
                "--seconds",
                "1",
            ],
        ] {
            v.push(case(format!("{args:?}"), &args, setup.clone()));
        }
    }

    // Scenario and tuning files with each key mutated: `sim` refuses them, or (a valid mutation) refuses
    // `--robot inproc --realtime`, checked after the files; either way nothing is written.
    let scenario = std::fs::read_to_string(root().join("scenarios/paper-fig9.toml")).unwrap();
    for key in keys(&scenario) {
        for val in ["nan", "-inf", "1e300", "-1", "\"x\"", "[1]"] {
            v.push(case(
                format!("scenario {key} = {val}"),
                &[
                    "sim",
                    "--scenario",
                    "s.toml",
                    "--robot",
                    "inproc",
                    "--realtime",
                    "--out",
                    "o",
                ],
                vec![Setup::File(
                    "s.toml",
                    mutate(&scenario, &key, val).into_bytes(),
                )],
            ));
        }
    }
    let tuning = std::fs::read_to_string(root().join("tunings/robust.toml")).unwrap();
    for key in keys(&tuning) {
        for val in ["nan", "1e300", "-1", "\"x\""] {
            v.push(case(
                format!("tuning {key} = {val}"),
                &[
                    "sim",
                    "--tuning",
                    "t.toml",
                    "--robot",
                    "inproc",
                    "--realtime",
                    "--out",
                    "o",
                ],
                vec![Setup::File(
                    "t.toml",
                    mutate(&tuning, &key, val).into_bytes(),
                )],
            ));
        }
    }

    // Numbers on the command line.
    for args in [
        &["sim-sensor", "robotiq", "--seconds", "1e300"][..],
        &["sim-sensor", "robotiq", "--seconds", "nan"],
        &["sim-sensor", "robotiq", "--fz", "nan"],
        &["sim-sensor", "robotiq", "--fz", "1e300"],
        &["sim-sensor", "robotiq", "--fz", "301"],
        &["sim-sensor", "robotiq", "--noise", "-1"],
        &["sim-sensor", "robotiq", "--noise", "inf"],
        &["sim-sensor", "ati", "--can", "x", "--fz", "nan"],
        &["sim-sensor", "ati", "--can", "x", "--seconds", "-1"],
        &["rsi-config", "--wait-timeout", "1e300", "--out", "o"],
        &["rsi-config", "--wait-timeout", "2147484", "--out", "o"],
        &["rsi-config", "--wait-timeout", "nan", "--out", "o"],
        &["rsi-config", "--wait-timeout", "0", "--out", "o"],
        &["rsi-config", "--port", "0", "--out", "o"],
        &["rsi-config", "--port", "65536", "--out", "o"],
        &["rsi-config", "--feed-mm-s", "1e300", "--out", "o"],
        &["rsi-config", "--ramp", "nan", "--out", "o"],
        &["rsi-config", "--segments", "nan:10", "--out", "o"],
        &["rsi-config", "--tuning", "nope", "--out", "o"],
        &["tune", "--k-min", "nan"],
        &["tune", "--k-max", "1e300"],
        &["tune", "--period", "1e300"],
        &["tune", "--period", "0"],
        &["tune", "--lag", "-1"],
        &["tune", "--delay", "inf"],
        &["tune", "--f-r", "1e-300", "--k-min", "0"],
        &["sensor", "ati", "--can", "x", "read", "--rate", "1e-300"],
        &[
            "sensor",
            "ati",
            "--can",
            "x",
            "--turnaround-us",
            "18446744073709551616",
            "info",
        ],
        &["calibrate", "--config", "c.toml", "--poses", "1000000"],
    ] {
        v.push(case(format!("{args:?}"), args, vec![]));
    }

    // Options refused after files would once have been truncated: the earlier results survive.
    let prior = || {
        vec![
            Setup::Dir("o"),
            Setup::File("o/paper-fig9.csv", b"prior results\n".to_vec()),
            Setup::File("o/paper-fig9.mcap", b"prior recording\n".to_vec()),
        ]
    };
    for args in [
        &["sim", "--robot", "inproc", "--realtime", "--out", "o"][..],
        &["sim", "--can", "nocan9", "--sensor", "inproc", "--out", "o"],
        &["sim", "--can", "nocan9", "--out", "o"],
        &["sim", "--external-robot", "[::1]:6008", "--out", "o"],
        &["sim", "--external-robot", "192.0.2.1:6008", "--out", "o"],
        &["sim", "--live", "192.0.2.1:8765", "--out", "o"],
        &["sim", "--live", "nonsense", "--out", "o"],
        &["sim", "--scenario", "nope", "--out", "o"],
        &["sim", "--plant", "p9", "--out", "o"],
        &["sim", "--tuning", "nope", "--out", "o"],
    ] {
        v.push(case(format!("prior {args:?}"), args, prior()));
    }
    // Outputs that are no place to write, or an input.
    for args in [
        &["plot", "out/t.mcap", "--out", "keep.csv"][..],
        &["plot", "out/t.mcap", "--out", "out/t.mcap"],
        &["plot", "out/t.csv", "--out", "out/t.csv"],
        &["plot", "out/t.mcap", "--out", "x.jpg"],
        &["plot", "out/t.mcap", "--out", "noext"],
        &["plot", "out/t.mcap", "--out", "/nonexistent/x.png"],
        &["plot", "out/t.mcap", "--out", "out"],
        &["plot", "keep.csv", "--out", "keep.png/"],
        &["export", "out/t.mcap", "--csv", "--out", "out/t.mcap"],
        &["export", "out/t.mcap", "--csv", "--out", "x.png"],
        &[
            "export",
            "out/t.mcap",
            "--csv",
            "--out",
            "/nonexistent/x.csv",
        ],
        &[
            "export",
            "out/t.mcap",
            "--csv",
            "--out",
            "/proc/sys/kernel/x.csv",
        ],
        &["export", "keep.csv", "--csv"],
        &["export", "keep.csv", "--csv", "--out", "keep.csv"],
        &["sim", "--out", "keep.csv"],
        &["sim", "--out", "/proc/sys/kernel"],
        &[
            "rsi-config",
            "--out",
            "keep.csv",
            "--ip",
            "192.168.1.100",
            "--robot-ip",
            "192.168.1.10",
            "--poscorr-mm",
            "5",
            "--poscorrmon-mm",
            "6",
        ],
        &[
            "rsi-config",
            "--out",
            "/proc/sys/kernel/x",
            "--ip",
            "192.168.1.100",
            "--robot-ip",
            "192.168.1.10",
            "--poscorr-mm",
            "5",
            "--poscorrmon-mm",
            "6",
        ],
        &["bench-scenarios", "zzz", "--out", "new"],
        &["bench-scenarios", "b01", "--tuning", "nope", "--out", "new"],
        &["bench-scenarios", "--out", "keep.csv"],
    ] {
        v.push(case(format!("output {args:?}"), args, vec![Setup::Trace]));
    }
    v
}

#[test]
fn every_hostile_input_ends_in_one_error_line_status_2_and_leaves_every_file_as_it_was() {
    let cases = cases();
    assert!(cases.len() >= 300, "{} cases", cases.len());
    // The shared fixture first, once, outside the worker threads' timing.
    trace_fixture();
    let next = AtomicUsize::new(0);
    let failures = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..4 {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(c) = cases.get(i) else { break };
                    if let Err(e) = check(c) {
                        failures.lock().unwrap().push(format!("{}: {e}", c.name));
                    }
                }
            });
        }
    });
    let f = failures.into_inner().unwrap();
    assert!(
        f.is_empty(),
        "{} of {} cases failed:\n{}",
        f.len(),
        cases.len(),
        f.join("\n---\n")
    );
}

// ---- One test per defect of issue 35 (each failed on the binary before it). ----

struct Ran {
    code: Option<i32>,
    out: String,
    err: String,
}

fn forcecell(args: &[&str], dir: &Path) -> Ran {
    let o = Command::new(bin())
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    Ran {
        code: o.status.code(),
        out: String::from_utf8_lossy(&o.stdout).into_owned(),
        err: String::from_utf8_lossy(&o.stderr).into_owned(),
    }
}

#[track_caller]
fn refused(r: &Ran, needles: &[&str]) {
    assert_eq!(r.code, Some(2), "{}{}", r.out, r.err);
    assert!(r.err.starts_with("error:"), "{}", r.err);
    for n in needles {
        assert!(r.err.contains(n), "{n:?} missing: {}", r.err);
    }
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn defect1_a_tiny_poll_rate_is_refused_with_its_reason_not_a_panic() {
    let d = tempfile::tempdir().unwrap();
    for cmd in ["run", "calibrate"] {
        std::fs::write(
            d.path().join("c.toml"),
            mutate(&base_cell(), "poll_hz", "1e-300"),
        )
        .unwrap();
        let r = forcecell(&[cmd, "--config", "c.toml"], d.path());
        refused(&r, &["sensor.poll_hz", "stale"]);
        assert_eq!(names(d.path()), ["c.toml"], "no recordings/ left");
    }
}

#[test]
fn defect2_a_named_pipe_is_refused_at_once_wherever_a_file_is_read() {
    let d = tempfile::tempdir().unwrap();
    prepare(d.path(), &[Setup::Fifo("f")]);
    std::fs::write(
        d.path().join("c.toml"),
        with_ethernet_config(&base_cell(), "f"),
    )
    .unwrap();
    for args in [
        &["run", "--config", "f"][..],
        &["calibrate", "--config", "f"],
        &["run", "--config", "c.toml"],
        &["plot", "f"],
        &["export", "f", "--csv", "--out", "x.csv"],
    ] {
        // A hang here would block the test: the suite above runs the same with a kill-timeout.
        refused(&forcecell(args, d.path()), &["named pipe", "regular file"]);
    }
    assert_eq!(names(d.path()), ["c.toml", "f"]);
}

#[test]
fn defect3_reads_are_bounded_a_device_and_a_300_mib_file_are_refused() {
    let d = tempfile::tempdir().unwrap();
    refused(
        &forcecell(&["plot", "/dev/zero"], d.path()),
        &["/dev/zero", "a device"],
    );
    prepare(d.path(), &[Setup::Sparse("big.toml", 300 << 20)]);
    refused(
        &forcecell(&["run", "--config", "big.toml"], d.path()),
        &["big.toml", "314572800 bytes", "1048576"],
    );
}

#[test]
fn defect4_a_rejected_sim_leaves_the_previous_results_as_they_were() {
    let d = tempfile::tempdir().unwrap();
    let ok = forcecell(
        &[
            "sim", "--robot", "inproc", "--sensor", "inproc", "--out", "o",
        ],
        d.path(),
    );
    assert_eq!(ok.code, Some(0), "{}{}", ok.out, ok.err);
    let before = snapshot(d.path());
    let csv = std::fs::read(d.path().join("o/paper-fig9.csv")).unwrap();
    assert!(csv.len() > 10_000, "a real trace: {} bytes", csv.len());
    for args in [
        &["sim", "--robot", "inproc", "--realtime", "--out", "o"][..],
        &["sim", "--can", "nocan9", "--sensor", "inproc", "--out", "o"],
        &["sim", "--can", "nocan9", "--out", "o"],
        &["sim", "--external-robot", "[::1]:6008", "--out", "o"],
        &["sim", "--external-robot", "192.0.2.1:6008", "--out", "o"],
        &["sim", "--live", "192.0.2.1:8765", "--out", "o"],
    ] {
        let r = forcecell(args, d.path());
        assert_eq!(r.code, Some(2), "{args:?}: {}{}", r.out, r.err);
        assert_eq!(snapshot(d.path()), before, "{args:?} touched the results");
    }
}

#[test]
fn defect5_plot_and_export_never_write_over_an_input_or_in_a_format_their_name_does_not_say() {
    let d = tempfile::tempdir().unwrap();
    prepare(d.path(), &[Setup::Trace]);
    // The same file by another name is the same file.
    std::os::unix::fs::symlink("t.mcap", d.path().join("out/alias.csv")).unwrap();
    let before = snapshot(d.path());
    refused(
        &forcecell(&["plot", "out/t.mcap", "--out", "keep.csv"], d.path()),
        &["keep.csv", ".png"],
    );
    refused(
        &forcecell(&["plot", "out/t.mcap", "--out", "out/t.mcap"], d.path()),
        &["out/t.mcap"],
    );
    refused(
        &forcecell(
            &["export", "out/t.mcap", "--csv", "--out", "out/t.mcap"],
            d.path(),
        ),
        &["out/t.mcap"],
    );
    refused(
        &forcecell(
            &["export", "out/t.mcap", "--csv", "--out", "out/alias.csv"],
            d.path(),
        ),
        &["refusing to write over it"],
    );
    assert_eq!(snapshot(d.path()), before);
    std::fs::remove_file(d.path().join("out/alias.csv")).unwrap();
    // Replacing an existing output is `export`'s documented behaviour: whole, by rename, no temporary
    // file left.
    let ok = forcecell(
        &["export", "out/t.mcap", "--csv", "--out", "keep.csv"],
        d.path(),
    );
    assert_eq!(ok.code, Some(0), "{}{}", ok.out, ok.err);
    assert_eq!(
        std::fs::read(d.path().join("keep.csv")).unwrap(),
        trace_fixture().1,
        "the export of the recording is the run's own CSV"
    );
    assert_eq!(names(d.path()), ["keep.csv", "out"]);
    assert_eq!(names(&d.path().join("out")), ["t.csv", "t.mcap"]);
}

#[test]
fn defect6_cell_values_are_bounded_with_their_physical_reason() {
    let d = tempfile::tempdir().unwrap();
    for (key, value, needles) in [
        (
            "watchdog_cycles",
            "4294967295",
            &["watchdog_cycles", "1..=2500", "silent"][..],
        ),
        ("duration", "1e300", &["duration", "3600000 cycles"]),
        ("poll_hz", "0.5", &["poll_hz", "stale"]),
        ("poll_hz", "1e6", &["poll_hz", "10 kHz"]),
        ("listen", "\"192.168.1.100:0\"", &["port 0", "real port"]),
    ] {
        std::fs::write(d.path().join("c.toml"), mutate(&base_cell(), key, value)).unwrap();
        refused(
            &forcecell(&["run", "--config", "c.toml"], d.path()),
            needles,
        );
    }
    assert_eq!(names(d.path()), ["c.toml"]);
}

#[test]
fn defect7_the_simulated_robotiq_refuses_what_the_simulated_ati_refuses() {
    let d = tempfile::tempdir().unwrap();
    for (args, needle) in [
        (&["--seconds", "1e300"][..], "week"),
        (&["--fz", "nan"], "300 N"),
        (&["--fz", "1e300"], "300 N"),
        (&["--noise", "-1"], "standard deviation"),
    ] {
        let mut a = vec!["sim-sensor", "robotiq"];
        a.extend_from_slice(args);
        refused(&forcecell(&a, d.path()), &[needle]);
    }
}

#[test]
fn defect8_the_krl_wait_stays_within_a_32_bit_int() {
    let d = tempfile::tempdir().unwrap();
    refused(
        &forcecell(
            &["rsi-config", "--wait-timeout", "1e300", "--out", "o"],
            d.path(),
        ),
        &["--wait-timeout", "32-bit"],
    );
    assert_eq!(names(d.path()), Vec::<String>::new());
    let ok = forcecell(
        &[
            "rsi-config",
            "--wait-timeout",
            "2147483",
            "--out",
            "o",
            "--ip",
            "192.168.1.100",
            "--robot-ip",
            "192.168.1.10",
            "--poscorr-mm",
            "5",
            "--poscorrmon-mm",
            "6",
        ],
        d.path(),
    );
    assert_eq!(ok.code, Some(0), "{}{}", ok.out, ok.err);
    let src = std::fs::read_dir(d.path().join("o"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "src"))
        .unwrap();
    let krl = std::fs::read_to_string(src).unwrap();
    assert!(krl.contains("2147483000"), "{krl}");
    assert!(!krl.contains("18446744073709551615"), "{krl}");
}

#[test]
fn defect10_a_sensor_filter_faster_than_the_sensor_is_refused_not_clamped() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(
        d.path().join("s.toml"),
        "name = \"s\"\nduration = 0.1\n[environment]\nk_c = 70000.0\nx_c = 0.01\n[sensor]\nbandwidth = 1e12\n",
    )
    .unwrap();
    refused(
        &forcecell(&["sim", "--scenario", "s.toml", "--out", "o"], d.path()),
        &["bandwidth", "1800 Hz", "4 kHz"],
    );
    assert_eq!(names(d.path()), ["s.toml"]);
}

#[test]
fn defect11_no_empty_directory_is_left_behind() {
    let d = tempfile::tempdir().unwrap();
    // The shipped cell on a machine without its CAN interface: the recording directory was created,
    // the sensor could not be opened, the directory goes again.
    std::fs::write(d.path().join("c.toml"), base_cell()).unwrap();
    refused(
        &forcecell(&["run", "--config", "c.toml"], d.path()),
        &["nocan9"],
    );
    for args in [
        &["bench-scenarios", "zzz", "--out", "b"][..],
        &["bench-scenarios", "b01", "--tuning", "nope", "--out", "b"],
        &["sim", "--robot", "inproc", "--realtime", "--out", "a/b/c"],
        &["rsi-config", "--port", "0", "--out", "r"],
    ] {
        refused(&forcecell(args, d.path()), &[]);
    }
    assert_eq!(names(d.path()), ["c.toml"]);
}

/// The table of bounds in docs/cli.md, each row tried against the binary: its largest value is taken
/// (or refused only for another reason), the next one above is refused naming the key.
#[test]
fn the_documented_bounds_are_the_code_s_bounds() {
    let doc = std::fs::read_to_string(root().join("docs/cli.md")).unwrap();
    let table = doc
        .split("<!-- bounds:begin -->")
        .nth(1)
        .and_then(|t| t.split("<!-- bounds:end -->").next())
        .expect("docs/cli.md has the bounds table");
    let rows: Vec<Vec<String>> = table
        .lines()
        .filter(|l| l.starts_with("| `"))
        .map(|l| l.split('|').map(|c| c.trim().to_string()).collect())
        .collect();
    assert!(rows.len() >= 9, "{rows:?}");
    let d = tempfile::tempdir().unwrap();
    for row in rows {
        let (key, max) = (
            row[1].trim_matches('`'),
            row[3].replace(['\u{a0}', ' '], ""),
        );
        let above = if max.contains('.') || max.contains('e') {
            format!("{}", max.parse::<f64>().unwrap() * 1.001)
        } else {
            (max.parse::<u64>().unwrap() + 1).to_string()
        };
        let cell = |v: &str, k: &str| {
            std::fs::write(d.path().join("c.toml"), mutate(&base_cell(), k, v)).unwrap();
            forcecell(&["run", "--config", "c.toml"], d.path())
        };
        let cell_add = |lines: &str| {
            let base = base_cell();
            let at = base.lines().find(|l| l.starts_with("robot_ip")).unwrap();
            std::fs::write(
                d.path().join("c.toml"),
                base.replacen(at, &format!("{at}\n{lines}"), 1),
            )
            .unwrap();
            forcecell(&["run", "--config", "c.toml"], d.path())
        };
        let scenario = |v: &str| {
            std::fs::write(
                d.path().join("s.toml"),
                format!("name = \"s\"\nduration = 0.1\n[environment]\nk_c = 70000.0\nx_c = 0.01\n[sensor]\nbandwidth = {v}\n"),
            )
            .unwrap();
            forcecell(
                &[
                    "sim",
                    "--scenario",
                    "s.toml",
                    "--robot",
                    "inproc",
                    "--realtime",
                ],
                d.path(),
            )
        };
        let try_value = |v: &str| -> Ran {
            match key {
                "sensor.poll_hz" => cell(v, "poll_hz"),
                "robot.watchdog_cycles" => cell(v, "watchdog_cycles"),
                "robot.spin_us" => cell(v, "spin_us"),
                "duration" => cell(v, "duration"),
                "robot.listen" => cell(&format!("\"192.168.1.100:{v}\""), "listen"),
                // The rotation limits are commented out in the example: added (POSCORR's with the
                // largest monitor above it).
                "robot.poscorr_deg" => {
                    cell_add(&format!("poscorr_deg = {v}\nposcorrmon_deg = 45.0"))
                }
                "robot.poscorrmon_deg" => cell_add(&format!("poscorrmon_deg = {v}")),
                "[sensor] bandwidth" => scenario(v),
                "rsi-config --wait-timeout" => forcecell(
                    &[
                        "rsi-config",
                        "--wait-timeout",
                        v,
                        "--out",
                        "o",
                        "--ip",
                        "192.168.1.100",
                        "--robot-ip",
                        "192.168.1.10",
                        "--poscorr-mm",
                        "5",
                        "--poscorrmon-mm",
                        "6",
                    ],
                    d.path(),
                ),
                "sim-sensor robotiq --fz" => forcecell(
                    &["sim-sensor", "robotiq", "--fz", v, "--seconds", "0.05"],
                    d.path(),
                ),
                "sim-sensor robotiq --noise" => forcecell(
                    &["sim-sensor", "robotiq", "--noise", v, "--seconds", "0.05"],
                    d.path(),
                ),
                "sim-sensor --seconds" => forcecell(
                    &["sim-sensor", "ati", "--can", "nocan9", "--seconds", v],
                    d.path(),
                ),
                "sensor ati read --rate" => forcecell(
                    &["sensor", "ati", "--can", "nocan9", "read", "--rate", v],
                    d.path(),
                ),
                other => panic!("docs/cli.md bounds a key this test does not know: {other}"),
            }
        };
        let word = key
            .rsplit(['.', ' '])
            .next()
            .unwrap()
            .trim_start_matches('-');
        let at = try_value(&max);
        assert!(
            !at.err.contains("invalid value") && !at.err.contains(word),
            "{key} = {max} (the documented largest) refused: {}",
            at.err
        );
        let min = row[2].replace(['\u{a0}', ' '], "");
        let below = match min.strip_prefix('>') {
            Some(m) => m.to_string(),
            None if min.contains('.') => {
                let m: f64 = min.parse().unwrap();
                format!("{}", m - (m.abs() * 1e-3).max(1e-3))
            }
            None => (min.parse::<i64>().unwrap() - 1).to_string(),
        };
        let r = try_value(&below);
        assert_eq!(r.code, Some(2), "{key} = {below}: {}{}", r.out, r.err);
        assert!(
            r.err.contains(word) || r.err.contains("port 0"),
            "{key} = {below}: {}",
            r.err
        );
        let r = try_value(&above);
        assert_eq!(r.code, Some(2), "{key} = {above}: {}{}", r.out, r.err);
        assert!(
            r.err.contains(word) || key == "robot.listen",
            "{key} = {above}: {}",
            r.err
        );
    }
}
