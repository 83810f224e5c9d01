//! MCAP recordings on real files: written → read back → the same values; a `sim` killed with SIGKILL
//! leaves a file readable up to its last flush; a full disk is reported once and counted while the loop
//! side never blocks; the JSON recordings written before the protobuf schema still read.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use forcecell::record::Row;
use forcecell::recorder::{self, CHANNELS, Full, NO_STATE, Record, RecorderOptions};
use scenario::telemetry;

fn record(k: u64) -> Record {
    let t = k as f64 * 0.004;
    let mut rec = Record::from_row(Row {
        t,
        f: if k % 7 == 3 {
            f64::NAN
        } else {
            5.0 + 0.01 * k as f64
        },
        f_true: f64::NAN,
        f_r: 5.0,
        x: 0.0101 + 1e-7 * k as f64,
        x_cmd: 0.0102 - 3e-8 * k as f64,
        x_r: 0.0103,
        kc_hat: 50_000.0 + k as f64 / 3.0,
        xc_hat: 0.009 + 1e-9 * k as f64,
        k_c: f64::NAN,
        x_c: f64::NAN,
        condition: (k % 3) as u8,
        // The process: no command for the first cycles, then pressing segment by segment, a bad
        // command (mode 7) that latches a fault, and a release.
        segment: (k >= 50).then_some((k / 500) as i64),
        mode: match k {
            0..50 => None,
            1000..1010 => Some(7),
            2500.. => Some(2),
            _ => Some(1),
        },
        f_cmd: if k < 50 {
            f64::NAN
        } else {
            5.0 + (k / 500) as f64
        },
        phase: Some(match k {
            0..50 => 0,
            50..100 => 1,
            100..200 => 2,
            1000..1500 => 9,
            2500.. => 4,
            _ => 3,
        }),
        fault: Some(if (1000..1500).contains(&k) { 4 } else { 0 }),
        s: f64::NAN,
        tilt_error: f64::NAN,
        rotation: f64::NAN,
        moment: [f64::NAN; 2],
    });
    rec.wrench = [0.1, -0.2, 5.0 + k as f64, 0.01, 0.02, -0.03];
    rec.wrench_raw = [0.1, -0.2, 25.0, 0.01, 0.02, -0.03];
    rec.state = if k < 10 { 0 } else { 1 };
    rec.events = u16::from(k == 10);
    rec.robot_seq = k;
    rec.period = 0.004;
    rec
}

fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

fn assert_same_row(got: &Row, want: &Row) {
    let g = [
        got.t, got.f, got.f_true, got.f_r, got.x, got.x_cmd, got.x_r, got.kc_hat, got.xc_hat,
        got.k_c, got.x_c,
    ];
    let w = [
        want.t,
        want.f,
        want.f_true,
        want.f_r,
        want.x,
        want.x_cmd,
        want.x_r,
        want.kc_hat,
        want.xc_hat,
        want.k_c,
        want.x_c,
    ];
    for (i, (a, b)) in g.iter().zip(w).enumerate() {
        assert!(
            same(*a, b),
            "column {i}: read {a}, wrote {b} ({got:?} vs {want:?})"
        );
    }
    assert_eq!(got.condition, want.condition);
    assert_eq!(
        (got.segment, got.mode, got.phase, got.fault),
        (want.segment, want.mode, want.phase, want.fault),
        "process columns at t = {}",
        want.t
    );
    assert!(same(got.f_cmd, want.f_cmd), "f_cmd at t = {}", want.t);
}

/// A channel's schema: a protobuf `FileDescriptorSet` holding its message, every field of the
/// telemetry table with its number, and each enum's codes.
fn assert_protobuf_schema(c: &telemetry::Channel, data: &[u8]) {
    use prost::Message as _;
    let set = prost_types::FileDescriptorSet::decode(data).expect("a FileDescriptorSet");
    let file = &set.file[0];
    assert_eq!(file.package(), "forcecell");
    let msg = file
        .message_type
        .iter()
        .find(|m| format!("forcecell.{}", m.name()) == c.schema_name())
        .unwrap_or_else(|| panic!("{}: no {}", c.topic, c.schema_name()));
    let fields: Vec<(&str, i32)> = msg.field.iter().map(|f| (f.name(), f.number())).collect();
    let want: Vec<(&str, i32)> = c
        .message
        .fields
        .iter()
        .map(|f| (f.name, f.number as i32))
        .collect();
    assert_eq!(fields, want, "{}", c.topic);
}

#[test]
fn records_round_trip_through_an_mcap_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rt.mcap");
    let opts = RecorderOptions {
        full: Full::Wait,
        capacity: 64,
        attachments: vec![(
            "cell.toml".into(),
            "application/toml".into(),
            b"tuning = \"robust\"\n".to_vec(),
        )],
        ..RecorderOptions::default()
    };
    let (mut tx, recording) = recorder::start(&path, opts, None).unwrap();
    let n = 3_000;
    let mut truth = Vec::new();
    for k in 0..n {
        assert!(tx.push(record(k)), "a waiting queue never drops");
        let mut row = record(k).row;
        row.f_true = 5.5;
        row.k_c = 70_000.0;
        row.x_c = 0.01 - k as f64 * 1e-9;
        truth.push(row);
    }
    drop(tx);
    let summary = recording.finish(truth.clone()).unwrap();
    assert!(summary.finished, "{summary}");
    assert_eq!(summary.written, n);
    assert_eq!(summary.dropped + summary.lost, 0);
    assert!(summary.error.is_none());

    let bytes = std::fs::read(&path).unwrap();
    let back = recorder::read_mcap(&bytes).unwrap();
    assert!(back.truncated.is_none(), "{:?}", back.truncated);
    assert_eq!(back.rows.len(), n as usize);
    for (got, want) in back.rows.iter().zip(&truth) {
        assert_same_row(got, want);
    }

    // The indexed view: every channel with its schema, the attachment, the message counts.
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a summary section");
    let topics: Vec<&str> = summary
        .channels
        .values()
        .map(|c| c.topic.as_str())
        .collect();
    for c in &CHANNELS {
        assert!(topics.contains(&c.topic), "{} missing: {topics:?}", c.topic);
        let ch = summary
            .channels
            .values()
            .find(|ch| ch.topic == c.topic)
            .unwrap();
        assert_eq!(ch.message_encoding, "protobuf");
        let schema = ch.schema.as_ref().expect("a schema");
        assert_eq!(schema.encoding, "protobuf");
        assert_eq!(schema.name, c.schema_name());
        assert_protobuf_schema(c, &schema.data);
    }
    // Foxglove Studio reads a chunk only through its message index: a chunk without messages (the
    // schemas alone, an idle second) has none and makes it refuse the whole file.
    assert!(!summary.chunk_indexes.is_empty());
    for ci in &summary.chunk_indexes {
        assert!(
            ci.message_index_length > 0 && !ci.message_index_offsets.is_empty(),
            "a chunk without message indexes: {ci:?}"
        );
    }
    let stats = summary.stats.unwrap();
    // One message a cycle on `/cycle`, and the truth of each on `/truth`.
    assert_eq!(stats.message_count, 2 * n);
    assert_eq!(stats.attachment_count, 1);
    let att = &summary.attachment_indexes[0];
    let a = mcap::read::attachment(&bytes, att).unwrap();
    assert_eq!(&a.data[..], b"tuning = \"robust\"\n");

    // Each cycle's message carries what was pushed: the wrench, the raw one, the state and its
    // events, the process command and state.
    let mut seen_raw = 0;
    let mut seen_contact_event = false;
    let mut seen_process_fault = false;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic != "/cycle" {
            continue;
        }
        let mut rec = Record::unknown();
        telemetry::decode(&telemetry::CYCLE, &m.data, &mut rec).unwrap();
        let k = (m.log_time as f64 / 4e6).round() as u64;
        let want = record(k);
        assert_eq!(rec.wrench[2], 5.0 + k as f64);
        assert_eq!(rec.robot_seq, k);
        if rec.wrench_raw[2] == 25.0 {
            seen_raw += 1;
        }
        assert_eq!((rec.state, rec.events), (want.state, want.events));
        let r = rec.row;
        match k {
            10 => {
                assert_eq!(telemetry::event_names(rec.events).next(), Some("contact"));
                assert_eq!(rec.state, 1, "contact");
                seen_contact_event = true;
                assert_eq!((r.segment, r.mode, r.phase), (None, None, Some(0)));
            }
            1005 => {
                assert_eq!((r.segment, r.mode, r.f_cmd), (Some(2), Some(7), 7.0));
                assert_eq!((r.phase, r.fault), (Some(9), Some(4)));
                seen_process_fault = true;
            }
            2600 => assert_eq!((r.segment, r.mode, r.phase), (Some(5), Some(2), Some(4))),
            _ => {}
        }
    }
    assert_eq!(seen_raw, n);
    assert!(seen_contact_event);
    assert!(seen_process_fault);
    assert_ne!(record(0).state, NO_STATE);
}

/// A JSON recording as forcecell wrote them before the protobuf schema: one channel per group of
/// fields, each message exactly as the JSON writer shaped it (`/state`'s `fault` was the cycle's
/// condition, `/process`'s the process fault). Returns the file's bytes.
fn json_recording(cycles: u32) -> Vec<u8> {
    use std::collections::BTreeMap;
    let mut buf = std::io::Cursor::new(Vec::new());
    let mut w = mcap::Writer::new(&mut buf).unwrap();
    let mut ids = BTreeMap::new();
    for (topic, schema) in [
        ("/force", "forcecell.Force"),
        ("/wrench", "forcecell.Wrench"),
        ("/position", "forcecell.Position"),
        ("/estimates", "forcecell.Estimates"),
        ("/state", "forcecell.State"),
        ("/rsi", "forcecell.Robot"),
        ("/sensor", "forcecell.Sensor"),
        ("/truth", "forcecell.Truth"),
        ("/process", "forcecell.Process"),
    ] {
        let id = w
            .add_schema(schema, "jsonschema", br#"{"type":"object"}"#)
            .unwrap();
        ids.insert(
            topic,
            w.add_channel(id, topic, "json", &BTreeMap::new()).unwrap(),
        );
    }
    for k in 0..cycles {
        let t = u64::from(k + 1) * 4_000_000;
        let secs = t as f64 * 1e-9;
        // Cycle 1 held on a non-finite sample (condition 2) while the process had latched a force
        // limit (fault 2): the same number, two meanings, as the JSON channels had it.
        let (cond, cond_name) = if k == 1 {
            (2, "non-finite sample")
        } else {
            (0, "none")
        };
        let f = if k == 1 {
            "null".to_string()
        } else {
            format!("{}", 5.0 + f64::from(k))
        };
        for (topic, msg) in [
            ("/force", format!(r#"{{"t":{secs},"f":{f},"f_r":5.0,"error":0.0}}"#)),
            ("/wrench", r#"{"force":{"x":0.1,"y":-0.2,"z":5.0},"torque":{"x":0.01,"y":0.02,"z":-0.03}}"#.to_string()),
            ("/position", r#"{"x":0.01,"x_cmd":0.011,"x_r":0.012}"#.to_string()),
            ("/estimates", r#"{"kc_hat":50000.0,"xc_hat":0.009}"#.to_string()),
            ("/state", format!(r#"{{"state":1,"state_name":"contact","segment":3,"fault":{cond},"fault_name":"{cond_name}","events":0,"event_names":[]}}"#)),
            ("/rsi", format!(r#"{{"seq":{k},"period":0.004,"late_replies":0}}"#)),
            ("/sensor", r#"{"ok":true,"seq":7,"age":0.0}"#.to_string()),
            ("/process", r#"{"segment":3,"mode":1,"mode_name":"press","f_cmd":12.5,"phase":9,"phase_name":"fault","fault":2,"fault_name":"force limit"}"#.to_string()),
            ("/truth", r#"{"f_true":5.5,"k_c":70000.0,"x_c":0.01}"#.to_string()),
        ] {
            let header = mcap::records::MessageHeader { channel_id: ids[topic], sequence: k, log_time: t, publish_time: t };
            w.write_to_known_channel(&header, msg.as_bytes()).unwrap();
        }
    }
    w.finish().unwrap();
    drop(w);
    buf.into_inner()
}

/// Every JSON recording written so far still reads, with the names of today: `export --csv` gives
/// the cycle's condition and the process fault in their own columns, and `plot` draws it.
#[test]
fn a_json_recording_from_before_the_protobuf_schema_still_reads() {
    let dir = tempfile::tempdir().unwrap();
    let old = dir.path().join("json.mcap");
    std::fs::write(&old, json_recording(3)).unwrap();
    let (rows, truncated) = recorder::load_trace(&old).unwrap();
    assert!(truncated.is_none());
    assert_eq!(rows.len(), 3);
    assert!(rows[1].f.is_nan());
    assert_eq!(
        (rows[2].f, rows[2].x_cmd, rows[2].kc_hat),
        (7.0, 0.011, 50_000.0)
    );
    assert_eq!((rows[1].condition, rows[1].fault), (2, Some(2)));
    assert_eq!((rows[0].condition, rows[0].fault), (0, Some(2)));
    assert_eq!(
        (rows[2].segment, rows[2].mode, rows[2].f_cmd, rows[2].phase),
        (Some(3), Some(1), 12.5, Some(9))
    );
    assert_eq!(
        (rows[2].f_true, rows[2].k_c, rows[2].x_c),
        (5.5, 70_000.0, 0.01)
    );
    let exe = env!("CARGO_BIN_EXE_forcecell");
    let o = Command::new(exe)
        .args(["export", "json.mcap", "--csv", "--out", "json.csv"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(dir.path().join("json.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(forcecell::record::HEADER));
    assert_eq!(
        lines.nth(1),
        Some("0.008,,5.5,5,0.01,0.011,0.012,50000,0.009,70000,0.01,2,3,1,12.5,9,2"),
        "{csv}"
    );
    let o = Command::new(exe)
        .args(["plot", "json.mcap", "--out", "json.png"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.path().join("json.png").metadata().unwrap().len() > 1000);
}

/// A recording made before the `/process` channel (its `/state` carried `segment: 0`) still reads:
/// the process columns are unknown, everything else is there.
#[test]
fn a_recording_without_the_process_channel_still_reads() {
    use std::collections::BTreeMap;
    let mut buf = std::io::Cursor::new(Vec::new());
    let mut w = mcap::Writer::new(&mut buf).unwrap();
    let mut ids = BTreeMap::new();
    for topic in ["/force", "/position", "/estimates", "/state"] {
        let schema = w
            .add_schema(topic, "jsonschema", br#"{"type":"object"}"#)
            .unwrap();
        ids.insert(
            topic,
            w.add_channel(schema, topic, "json", &BTreeMap::new())
                .unwrap(),
        );
    }
    for k in 0..3u32 {
        let t = u64::from(k + 1) * 4_000_000;
        for (topic, msg) in [
            ("/force", format!(r#"{{"t":{},"f":5.0,"f_r":5.0,"error":0.0}}"#, t as f64 * 1e-9)),
            ("/position", r#"{"x":0.01,"x_cmd":0.011,"x_r":0.012}"#.to_string()),
            ("/estimates", r#"{"kc_hat":50000.0,"xc_hat":0.009}"#.to_string()),
            ("/state", r#"{"state":1,"state_name":"contact","segment":0,"fault":0,"fault_name":"none","events":0,"event_names":[]}"#.to_string()),
        ] {
            let header = mcap::records::MessageHeader { channel_id: ids[topic], sequence: k, log_time: t, publish_time: t };
            w.write_to_known_channel(&header, msg.as_bytes()).unwrap();
        }
    }
    w.finish().unwrap();
    drop(w);
    let dir = tempfile::tempdir().unwrap();
    let old = dir.path().join("old.mcap");
    std::fs::write(&old, buf.into_inner()).unwrap();

    let (rows, truncated) = recorder::load_trace(&old).unwrap();
    assert!(truncated.is_none());
    assert_eq!(rows.len(), 3);
    assert_eq!(
        (rows[2].f, rows[2].x_cmd, rows[2].kc_hat),
        (5.0, 0.011, 50_000.0)
    );
    assert_eq!(
        (rows[2].segment, rows[2].mode, rows[2].phase, rows[2].fault),
        (None, None, None, None)
    );
    // `export` writes the process columns empty; `plot` draws it.
    let exe = env!("CARGO_BIN_EXE_forcecell");
    let o = Command::new(exe)
        .args(["export", "old.mcap", "--csv", "--out", "old.csv"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(dir.path().join("old.csv")).unwrap();
    assert!(csv.starts_with(forcecell::record::HEADER), "{csv}");
    assert!(csv.lines().nth(1).unwrap().ends_with(",0,,,,,"), "{csv}");
    let o = Command::new(exe)
        .args(["plot", "old.mcap", "--out", "old.png"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn sim_writes_an_mcap_whose_export_is_the_csv() {
    let dir = tempfile::tempdir().unwrap();
    let exe = env!("CARGO_BIN_EXE_forcecell");
    let o = Command::new(exe)
        .args(["sim", "--out", "res"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("finished with summary and index"),
        "{stdout}"
    );
    let o = Command::new(exe)
        .args([
            "export",
            "res/paper-fig9.mcap",
            "--csv",
            "--out",
            "res/exported.csv",
        ])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(dir.path().join("res/paper-fig9.csv")).unwrap();
    let exported = std::fs::read_to_string(dir.path().join("res/exported.csv")).unwrap();
    assert!(csv.lines().count() > 1000);
    assert_eq!(exported, csv, "the export is the CSV the run wrote");
    let o = Command::new(exe)
        .args(["plot", "res/paper-fig9.mcap", "--out", "res/from-mcap.png"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        dir.path()
            .join("res/from-mcap.png")
            .metadata()
            .unwrap()
            .len()
            > 1000
    );
}

fn wait_for(what: &str, limit: Duration, mut ok: impl FnMut() -> bool) {
    let start = Instant::now();
    while !ok() {
        assert!(start.elapsed() < limit, "gave up waiting for {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A `sim --realtime` killed with SIGKILL after two flushes of messages; returns its recording.
fn killed_recording(dir: &Path) -> std::path::PathBuf {
    let scenario = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/paper-fig9.toml"),
    )
    .unwrap()
    .replace("name = \"paper-fig9\"", "name = \"long\"")
    .replace("duration = 2.0", "duration = 60.0");
    std::fs::write(dir.join("long.toml"), scenario).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_forcecell"))
        .args([
            "sim",
            "--scenario",
            "long.toml",
            "--plant",
            "p2",
            // The paper's tuning on P2 trips the force limit, which now ends the run (fault 2): the
            // robust tuning runs the whole minute.
            "--tuning",
            "robust",
            "--realtime",
            "--out",
            "res",
        ])
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Streamed under .partial until finished: a killed run leaves that name.
    let path = dir.join("res/long-p2-robust.mcap.partial");
    let len = || path.metadata().map_or(0, |m| m.len());
    // The header and attachments are flushed at once; wait for two flushes of messages.
    wait_for("the recording to start", Duration::from_secs(30), || {
        len() > 0
    });
    let first = len();
    wait_for("a first flush of messages", Duration::from_secs(30), || {
        len() > first
    });
    let second = len();
    wait_for("a second flush", Duration::from_secs(30), || len() > second);
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    path
}

#[test]
fn a_killed_sim_leaves_an_mcap_readable_up_to_its_last_flush() {
    let dir = tempfile::tempdir().unwrap();
    let path = killed_recording(dir.path());
    let bytes = std::fs::read(&path).unwrap();
    let back = recorder::read_mcap(&bytes).unwrap();
    assert!(
        back.truncated.is_some(),
        "a killed run cannot have finished the file"
    );
    assert!(
        mcap::Summary::read(&bytes).is_err() || mcap::Summary::read(&bytes).unwrap().is_none(),
        "no summary in a killed file"
    );
    assert!(
        back.rows.len() > 100,
        "at least the first flush: {} rows",
        back.rows.len()
    );
    for w in back.rows.windows(2) {
        assert!(
            w[1].t > w[0].t,
            "cycles in order: {} then {}",
            w[0].t,
            w[1].t
        );
    }
    for r in &back.rows {
        assert!(
            r.f_r == 5.0 && r.x_cmd.is_finite() && r.t.is_finite(),
            "{r:?}"
        );
    }
}

/// The `mcap` Python package (the reference reader) streams a killed recording up to its last
/// flush: every message forcecell's reader found, then the end of the data. Needs `pip install mcap`;
/// `FORCECELL_MCAP_PYTHON` names the interpreter (default `python3`).
#[test]
#[ignore = "needs the mcap Python package: pip install mcap; FORCECELL_MCAP_PYTHON=path/to/python"]
fn the_mcap_python_reader_reads_a_killed_recording_up_to_its_last_flush() {
    let dir = tempfile::tempdir().unwrap();
    let path = killed_recording(dir.path());
    let python = std::env::var("FORCECELL_MCAP_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = r#"
import sys
from collections import Counter
from mcap.stream_reader import StreamReader
from mcap.records import Channel, Message
topics, counts, end = {}, Counter(), "end of file"
try:
    for rec in StreamReader(open(sys.argv[1], "rb"), skip_magic=False).records:
        if isinstance(rec, Channel):
            topics[rec.id] = rec.topic
        elif isinstance(rec, Message):
            counts[topics[rec.channel_id]] += 1
except Exception as e:
    end = type(e).__name__
print(counts["/cycle"], counts["/truth"], end)
"#;
    let out = Command::new(&python)
        .args(["-c", script])
        .arg(&path)
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let f: Vec<&str> = text.split_whitespace().collect();
    let back = recorder::read_mcap(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(f[0].parse::<usize>().unwrap(), back.rows.len(), "{text}");
    assert_eq!(f[1], "0", "a killed simulation wrote no truth: {text}");
    assert!(back.rows.len() > 100, "{text}");
}

/// Google's protobuf runtime (through the `mcap` and `mcap-protobuf-support` Python packages, with
/// nothing of ours but the file) decodes every message of every channel of a `sim` recording with
/// the schema the file carries, finds the codes' names there, and reads the values `export --csv`
/// writes: every cycle, every column, bit for bit. Needs `pip install mcap mcap-protobuf-support
/// protobuf`; `FORCECELL_MCAP_PYTHON` names the interpreter (default `python3`).
#[test]
#[ignore = "needs Python packages: pip install mcap mcap-protobuf-support protobuf; FORCECELL_MCAP_PYTHON=path/to/python"]
fn the_protobuf_runtime_decodes_every_channel_as_the_export_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let exe = env!("CARGO_BIN_EXE_forcecell");
    // A programmed pass at 250 Hz: process command, phases and segments, contact and truth.
    let o = Command::new(exe)
        .args([
            "sim",
            "--scenario",
            "pass-flat-20n",
            "--plant",
            "p2",
            "--out",
            "res",
        ])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mcap = dir.path().join("res/pass-flat-20n-p2-robust.mcap");
    let csv = dir.path().join("res/exported.csv");
    let o = Command::new(exe)
        .arg("export")
        .arg(&mcap)
        .args(["--csv", "--out"])
        .arg(&csv)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let python = std::env::var("FORCECELL_MCAP_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = r#"
import csv, math, sys
from collections import Counter
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

rows, counts, schemas = {}, Counter(), {}
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    for schema, channel, message, m in reader.iter_decoded_messages():
        assert schema.encoding == "protobuf" and channel.message_encoding == "protobuf", channel.topic
        counts[channel.topic] += 1
        schemas[channel.topic] = type(m).DESCRIPTOR
        row = rows.setdefault(message.log_time, {})
        if channel.topic == "/cycle":
            p = m.process
            mode = p.mode_code if p.HasField("mode_code") else (p.mode if p.HasField("mode") else None)
            row.update(t=m.t, f=m.force.f, f_r=m.force.f_r, x=m.position.x, x_cmd=m.position.x_cmd,
                       x_r=m.position.x_r, kc_hat=m.estimates.kc_hat, xc_hat=m.estimates.xc_hat,
                       condition=m.state.condition,
                       segment=p.segment if p.HasField("segment") else None, mode=mode,
                       f_cmd=p.f_cmd, phase=p.phase if p.HasField("phase") else None,
                       fault=p.fault if p.HasField("fault") else None)
            assert m.HasField("wrench") and m.HasField("sensor") and m.HasField("robot")
            assert m.force.error == m.force.error or math.isnan(m.force.f)
        elif channel.topic == "/truth":
            row.update(f_true=m.f_true, k_c=m.k_c, x_c=m.x_c)
        else:
            raise SystemExit("unexpected channel " + channel.topic)

# The codes' names travel in the schema.
state = schemas["/cycle"].fields_by_name["state"].message_type
print("names", state.fields_by_name["condition"].enum_type.values_by_number[2].name,
      state.fields_by_name["state"].enum_type.values_by_number[1].name,
      schemas["/cycle"].fields_by_name["process"].message_type.fields_by_name["fault"].enum_type.values_by_number[2].name)

def same(text, value):
    if value is None:
        return text == ""
    if isinstance(value, float):
        return text == "" if math.isnan(value) else float(text) == value
    return text != "" and int(text) == value

cycles = [rows[k] for k in sorted(rows) if "t" in rows[k]]
with open(sys.argv[2]) as f:
    table = list(csv.DictReader(f))
assert len(table) == len(cycles), (len(table), len(cycles))
for line, (want, got) in enumerate(zip(table, cycles), 2):
    for col, text in want.items():
        assert same(text, got.get(col)), (line, col, text, got.get(col))
print("rows", len(cycles), counts["/cycle"], counts["/truth"], len(table[0]))
"#;
    let out = Command::new(&python)
        .args(["-c", script])
        .arg(&mcap)
        .arg(&csv)
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(
        lines[0], "names NON_FINITE_SAMPLE CONTACT FORCE_LIMIT",
        "{text}"
    );
    let f: Vec<&str> = lines[1].split_whitespace().collect();
    let back = recorder::read_mcap(&std::fs::read(&mcap).unwrap()).unwrap();
    let n = back.rows.len().to_string();
    assert_eq!(f[1..4], [n.as_str(), n.as_str(), n.as_str()], "{text}");
    assert_eq!(f[4], "17", "every column compared: {text}");
    assert!(back.rows.len() > 500, "{text}");
}

/// Needs root: mounts a 256 KiB tmpfs (the CI and the dev machines run as root).
#[test]
fn a_full_disk_is_reported_once_counted_and_never_blocks_the_loop() {
    let dir = tempfile::tempdir().unwrap();
    let mnt = dir.path().join("tiny");
    std::fs::create_dir(&mnt).unwrap();
    let st = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=256k", "tmpfs"])
        .arg(&mnt)
        .status()
        .expect("run mount");
    assert!(
        st.success(),
        "cannot mount a tmpfs (this test needs root): {st}"
    );
    struct Unmount<'a>(&'a Path);
    impl Drop for Unmount<'_> {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(self.0).status();
        }
    }
    let _guard = Unmount(&mnt);

    let path = mnt.join("full.mcap");
    let opts = RecorderOptions {
        full: Full::Drop,
        capacity: 1024,
        flush_every: Duration::from_millis(10),
        ..RecorderOptions::default()
    };
    let (mut tx, recording) = recorder::start(&path, opts, None).unwrap();
    // Some tens of bytes a cycle (compressed chunks of ~200 cycles): 256 KiB holds some thousands;
    // push 40 000, 200 at a time, so that some flushes land before the disk is full.
    let n = 40_000u64;
    let mut accepted = 0;
    for k in 0..n {
        accepted += u64::from(tx.push(record(k)));
        if k % 200 == 199 {
            std::thread::sleep(Duration::from_millis(15));
        }
    }
    drop(tx);
    let s = recording.finish(Vec::new()).unwrap();
    let err = s.error.clone().expect("the write error is reported");
    assert!(
        err.contains("No space") || err.contains("space"),
        "ENOSPC: {err}"
    );
    assert!(!s.finished);
    assert_eq!(
        s.written + s.lost + s.dropped,
        n,
        "every cycle written, lost or dropped: {s:?}"
    );
    assert_eq!(s.dropped, n - accepted);
    assert!(s.lost > 0, "{s:?}");
    assert!(s.to_string().contains("lost"), "{s}");
    // What was flushed before the disk filled reads back intact.
    let bytes = std::fs::read(&path).unwrap();
    let back = recorder::read_mcap(&bytes).unwrap();
    assert!(back.truncated.is_some());
    assert!(!back.rows.is_empty());
    for (got, k) in back.rows.iter().zip(0..) {
        assert_same_row(got, &record(k).row);
    }
}

#[test]
fn an_unwritable_directory_is_an_error_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("no/such/dir/x.mcap");
    let Err(e) = recorder::start(&path, RecorderOptions::default(), None) else {
        panic!("created a file in a missing directory")
    };
    assert!(format!("{e:#}").contains("cannot create"), "{e:#}");
}

/// A run stopped before its first cycle (a signal during start-up) records nothing: the file is still a
/// finished MCAP, and it holds no chunk without a message index (Foxglove refuses such a file).
#[test]
fn a_recording_with_no_cycle_has_no_chunk_without_messages() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.mcap");
    let (tx, recording) = recorder::start(&path, RecorderOptions::default(), None).unwrap();
    drop(tx);
    let summary = recording.finish(Vec::new()).unwrap();
    assert!(summary.finished, "{summary:?}");
    let bytes = std::fs::read(&path).unwrap();
    let s = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a summary section");
    assert!(
        s.chunk_indexes.iter().all(|c| c.message_index_length > 0),
        "{:?}",
        s.chunk_indexes
    );
    assert_eq!(recorder::read_mcap(&bytes).unwrap().rows.len(), 0);
}

/// Every message path of the Foxglove layout shipped in `docs/` names a field of the schema.
#[test]
fn the_foxglove_layout_plots_fields_of_the_schema() {
    let layout: serde_json::Value =
        serde_json::from_str(include_str!("../docs/foxglove-layout.json")).unwrap();
    let mut paths = Vec::new();
    for panel in layout["configById"].as_object().unwrap().values() {
        for p in panel["paths"].as_array().unwrap() {
            paths.push(p["value"].as_str().unwrap().to_string());
        }
    }
    assert!(paths.len() > 10, "{paths:?}");
    for path in &paths {
        let (topic, fields) = path[1..].split_once('.').unwrap();
        let channel = CHANNELS
            .iter()
            .find(|c| c.topic[1..] == *topic)
            .unwrap_or_else(|| panic!("{path}: no channel {topic}"));
        let mut msg = channel.message;
        let mut names = fields.split('.').peekable();
        while let Some(name) = names.next() {
            let field = msg
                .fields
                .iter()
                .find(|f| f.name == name)
                .unwrap_or_else(|| panic!("{path}: no field {name} in {}", msg.name));
            match field.ty {
                telemetry::Type::Message(m) => msg = m,
                _ => assert!(names.peek().is_none(), "{path}: {name} is no message"),
            }
        }
    }
}
