//! The recorder: each control cycle's [`Record`] goes into a preallocated, bounded, wait-free queue
//! (no allocation, no lock, no system call in the cycle); a writer thread streams it to an MCAP file
//! and, optionally, to live viewers.
//!
//! * The loop side is [`Recorder::push`]: one copy into a fixed-capacity single-producer ring
//!   ([`rtrb`]). When the ring is full the record is dropped and counted ([`Full::Drop`], the real-time
//!   setting). A lockstep simulation, which has no deadline, may instead wait for room ([`Full::Wait`]).
//! * The writer thread ([`Recording`]) turns each record into one JSON message per channel
//!   ([`CHANNELS`], each with a JSON schema Foxglove can plot) and finishes an MCAP chunk and flushes the
//!   file at least every [`RecorderOptions::flush_every`] (1 s): a killed process leaves a file readable
//!   up to the last flush. [`Recording::finish`] writes the summary and index.
//! * A write error (a full disk, a vanished directory) is reported once on stderr; the writer then
//!   discards and counts, the loop is never held up, and [`RecordingSummary`] says what was lost.
//!
//! Time: each message's `log_time` and `publish_time` is the cycle time `t` in ns (robot time on a
//! cell, simulated time in `sim`).

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow};
use controller::{ContactState, CycleReport, Events};
use serde::Serialize;

use crate::record::Row;

/// One control cycle as recorded. SI units (s, N, N·m, m, N/m); NaN where a value is unknown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record {
    /// The trace row (force, positions, estimates, fault; truth columns NaN).
    pub row: Row,
    /// The wrench the loop read (gravity-compensated on a cell that compensates), sensor frame:
    /// `[Fx, Fy, Fz, Tx, Ty, Tz]`.
    pub wrench: [f64; 6],
    /// The sensor's wrench before compensation (NaN where no compensation runs).
    pub wrench_raw: [f64; 6],
    /// The sensor driver's measurement counter (0 when no sample).
    pub sensor_seq: u64,
    /// Age of the sample when read, s (NaN when no sample).
    pub sensor_age: f64,
    /// The robot cycle's sequence number (RSI IPOC on a KUKA).
    pub robot_seq: u64,
    /// The robot cycle's period, s.
    pub period: f64,
    /// Replies the robot reported late so far.
    pub late_replies: u64,
    /// Contact state code ([`ContactState::code`]), or [`NO_STATE`] for laws without a state machine.
    pub state: u8,
    /// The law's events of this step, one bit each in [`EVENT_NAMES`] order.
    pub events: u16,
}

/// The state code of a law without a contact state machine.
pub const NO_STATE: u8 = 255;

/// Names of the [`Record::events`] bits, lowest bit first.
pub const EVENT_NAMES: [&str; 8] = [
    "contact",
    "lift_off",
    "force_limit",
    "velocity_limit",
    "acceleration_limit",
    "deviation_limit",
    "estimator_bound",
    "bad_input",
];

/// The events of one step as bits in [`EVENT_NAMES`] order.
pub fn event_bits(e: &Events) -> u16 {
    [
        e.contact,
        e.lift_off,
        e.force_limit,
        e.velocity_limit,
        e.acceleration_limit,
        e.deviation_limit,
        e.estimator_bound,
        e.bad_input,
    ]
    .iter()
    .enumerate()
    .fold(0, |acc, (i, &b)| acc | (u16::from(b) << i))
}

/// A state code's name.
pub fn state_name(code: u8) -> &'static str {
    match code {
        0 => "approach",
        1 => "contact",
        2 => "reacquire",
        3 => "retract",
        _ => "none",
    }
}

/// A fault code's name (codes of [`crate::record::fault_code`]).
pub fn fault_name(code: u8) -> &'static str {
    match code {
        0 => "none",
        1 => "sensor error",
        2 => "non-finite sample",
        3 => "non-finite pose",
        4 => "non-finite command",
        5 => "step limited",
        6 => "envelope limited",
        7 => "backing off after a fault",
        _ => "unknown",
    }
}

const NAN6: [f64; 6] = [f64::NAN; 6];

impl Record {
    /// The record of an answered cycle with set-point `f_r`; the process segment, command and state
    /// come from the cycle and the correction sent ([`Row::from_report`]).
    pub fn from_report(r: &CycleReport, f_r: f64) -> Self {
        let (raw, sensor_seq, sensor_age) = match r.sample {
            Some(s) => (s.wrench.to_array(), s.seq, s.age.as_secs_f64()),
            None => (NAN6, 0, f64::NAN),
        };
        // Where the loop compensates gravity, the wrench it used and the raw one beside it.
        let (wrench, wrench_raw) = if r.compensated {
            (r.wrench.map_or(NAN6, |w| w.to_array()), raw)
        } else {
            (raw, NAN6)
        };
        Self {
            row: Row::from_report(r, f_r),
            wrench,
            wrench_raw,
            sensor_seq,
            sensor_age,
            robot_seq: r.cycle.seq,
            period: r.cycle.period,
            late_replies: u64::from(r.cycle.late_replies),
            state: r.out.state.map_or(NO_STATE, ContactState::code),
            events: event_bits(&r.out.events),
        }
    }
}

/// What the loop side does when the queue is full.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Full {
    /// Drop the record and count it: never blocks (the real-time setting).
    Drop,
    /// Wait for the writer to make room (only for a lockstep simulation, which has no deadline).
    Wait,
}

/// How a recording is made.
#[derive(Clone, Debug)]
pub struct RecorderOptions {
    /// Records the queue holds (preallocated).
    pub capacity: usize,
    /// The longest time between two flushes of the file.
    pub flush_every: Duration,
    /// What a full queue does.
    pub full: Full,
    /// Files attached to the recording: (name, media type, content).
    pub attachments: Vec<(String, String, Vec<u8>)>,
    /// Metadata records: (name, key/value pairs).
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
}

impl Default for RecorderOptions {
    fn default() -> Self {
        Self {
            capacity: 8192,
            flush_every: Duration::from_secs(1),
            full: Full::Drop,
            attachments: Vec::new(),
            metadata: Vec::new(),
        }
    }
}

/// The loop's end of the recorder: a fixed-capacity ring, filled without allocating, locking or a
/// system call (with [`Full::Drop`]).
pub struct Recorder {
    tx: rtrb::Producer<Record>,
    full: Full,
    dropped: Arc<AtomicU64>,
}

impl Recorder {
    /// Hand one record to the writer. Returns false when it was dropped (queue full, or the writer gone).
    pub fn push(&mut self, rec: Record) -> bool {
        let mut rec = rec;
        loop {
            match self.tx.push(rec) {
                Ok(()) => return true,
                Err(rtrb::PushError::Full(back)) => {
                    if self.full == Full::Drop || self.tx.is_abandoned() {
                        self.dropped.fetch_add(1, Ordering::Relaxed);
                        return false;
                    }
                    rec = back;
                    thread::yield_now();
                }
            }
        }
    }

    /// Records dropped so far because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

/// A recorder's queue of `capacity` records (allocated here, once) and its consumer end, for a writer
/// of one's own (tests, benchmarks); [`start`] uses it with the MCAP writer.
pub fn queue(capacity: usize, full: Full) -> (Recorder, rtrb::Consumer<Record>) {
    let (tx, rx) = rtrb::RingBuffer::new(capacity.max(1));
    (
        Recorder {
            tx,
            full,
            dropped: Arc::new(AtomicU64::new(0)),
        },
        rx,
    )
}

/// Where the writer thread also sends every message (the live view): the channel's index in
/// [`CHANNELS`], the log time in ns and the JSON payload. Called on the writer thread, never the loop's.
pub type LiveSink = Box<dyn FnMut(usize, u64, &[u8]) + Send>;

/// A channel of the recording.
#[derive(Clone, Copy, Debug)]
pub struct ChannelDef {
    /// Topic, e.g. `/force`.
    pub topic: &'static str,
    /// Schema name.
    pub schema: &'static str,
    /// The JSON schema.
    pub json_schema: &'static str,
}

// Plain `"type":"number"` fields (a value that is not known is written as `null`): Foxglove Studio's
// JSON-schema reader refuses type unions such as `["number","null"]` and leaves the channel unplottable.
macro_rules! num_schema {
    ($title:literal, $field0:literal: $desc0:literal $(, $field:literal: $desc:literal)* $(,)?) => {
        concat!(
            r#"{"title":""#, $title, r#"","type":"object","properties":{"#,
            r#"""#, $field0, r#"":{"type":"number","description":""#, $desc0, r#" (null: unknown)"}"#,
            $( r#",""#, $field, r#"":{"type":"number","description":""#, $desc, r#" (null: unknown)"}"#, )*
            r#"}}"#
        )
    };
}

const WRENCH_SCHEMA: &str = r#"{"title":"forcecell.Wrench","type":"object","properties":{"force":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}},"description":"N, sensor frame"},"torque":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}},"description":"N·m, sensor frame"}}}"#;

/// Every channel a recording (and the live view) carries, in a fixed order.
pub const CHANNELS: [ChannelDef; 10] = [
    ChannelDef {
        topic: "/force",
        schema: "forcecell.Force",
        json_schema: num_schema!("forcecell.Force", "t": "cycle time, s", "f": "measured normal force, N", "f_r": "set-point, N", "error": "f - f_r, N"),
    },
    ChannelDef {
        topic: "/wrench",
        schema: "forcecell.Wrench",
        json_schema: WRENCH_SCHEMA,
    },
    ChannelDef {
        topic: "/wrench_raw",
        schema: "forcecell.Wrench",
        json_schema: WRENCH_SCHEMA,
    },
    ChannelDef {
        topic: "/position",
        schema: "forcecell.Position",
        json_schema: num_schema!("forcecell.Position", "x": "measured position along the normal, m", "x_cmd": "commanded position, m", "x_r": "impedance reference, m"),
    },
    ChannelDef {
        topic: "/estimates",
        schema: "forcecell.Estimates",
        json_schema: num_schema!("forcecell.Estimates", "kc_hat": "stiffness estimate, N/m", "xc_hat": "surface estimate, m"),
    },
    ChannelDef {
        topic: "/state",
        schema: "forcecell.State",
        json_schema: r#"{"title":"forcecell.State","type":"object","properties":{"state":{"type":"integer","description":"0 approach, 1 contact, 2 reacquire, 3 retract, 255 none"},"state_name":{"type":"string"},"segment":{"type":"integer","description":"the robot program's path segment (null: no process command)"},"fault":{"type":"integer","description":"0 none, 1 sensor error, 2 non-finite sample, 3 non-finite pose, 4 non-finite command, 5 step limited, 6 envelope limited, 7 backing off after a fault"},"fault_name":{"type":"string"},"events":{"type":"integer","description":"bits: contact, lift_off, force_limit, velocity_limit, acceleration_limit, deviation_limit, estimator_bound, bad_input"},"event_names":{"type":"array","items":{"type":"string"}}}}"#,
    },
    ChannelDef {
        topic: "/rsi",
        schema: "forcecell.Robot",
        json_schema: r#"{"title":"forcecell.Robot","type":"object","properties":{"seq":{"type":"integer","description":"cycle sequence (RSI IPOC)"},"period":{"type":"number","description":"s"},"late_replies":{"type":"integer"}}}"#,
    },
    ChannelDef {
        topic: "/sensor",
        schema: "forcecell.Sensor",
        json_schema: r#"{"title":"forcecell.Sensor","type":"object","properties":{"ok":{"type":"boolean"},"seq":{"type":"integer"},"age":{"type":"number","description":"s (null: no sample)"}}}"#,
    },
    ChannelDef {
        topic: "/truth",
        schema: "forcecell.Truth",
        json_schema: num_schema!("forcecell.Truth", "f_true": "true contact force, N", "k_c": "true stiffness, N/m", "x_c": "true surface position, m"),
    },
    ChannelDef {
        topic: "/process",
        schema: "forcecell.Process",
        json_schema: r#"{"title":"forcecell.Process","type":"object","properties":{"segment":{"type":"integer","description":"the robot program's path segment (RSI FcCmd); null: the link carries no process command"},"mode":{"type":"integer","description":"commanded mode: 0 off, 1 press, 2 release, other numbers as sent (a bad command)"},"mode_name":{"type":"string"},"f_cmd":{"type":"number","description":"commanded force, N"},"phase":{"type":"integer","description":"reported phase (RSI FcState): 0 off, 1 approach, 2 ramp, 3 pressing, 4 release, 9 fault"},"phase_name":{"type":"string"},"fault":{"type":"integer","description":"latched process fault: 0 none, 1 sensor lost, 2 force limit, 3 correction limit, 4 bad command, 5 contact lost, 6 hold timeout"},"fault_name":{"type":"string"}}}"#,
    },
];

/// Index of the `/process` channel.
pub const PROCESS: usize = 9;

/// A process mode number's name ([`hal::ProcessMode::code`]).
pub fn mode_name(code: Option<i64>) -> &'static str {
    match code {
        None => "none",
        Some(0) => "off",
        Some(1) => "press",
        Some(2) => "release",
        Some(_) => "unknown",
    }
}

/// A process phase number's name ([`hal::ProcessPhase::code`]).
pub fn phase_name(code: Option<u8>) -> &'static str {
    match code.and_then(|c| hal::ProcessPhase::from_code(i64::from(c))) {
        None => "unknown",
        Some(hal::ProcessPhase::Off) => "off",
        Some(hal::ProcessPhase::Approach) => "approach",
        Some(hal::ProcessPhase::Ramp) => "ramp",
        Some(hal::ProcessPhase::Pressing) => "pressing",
        Some(hal::ProcessPhase::Release) => "release",
        Some(hal::ProcessPhase::Fault) => "fault",
    }
}

/// A process fault number's name ([`hal::ProcessFault::code`]).
pub fn process_fault_name(code: Option<u8>) -> &'static str {
    code.and_then(|c| hal::ProcessFault::from_code(i64::from(c)))
        .map_or("unknown", hal::ProcessFault::name)
}

/// Index of the `/truth` channel (written at the end of a simulation).
pub const TRUTH: usize = 8;

#[derive(Serialize)]
struct Xyz {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Serialize)]
struct WrenchMsg {
    force: Xyz,
    torque: Xyz,
}

fn wrench_msg(w: &[f64; 6]) -> WrenchMsg {
    WrenchMsg {
        force: Xyz {
            x: w[0],
            y: w[1],
            z: w[2],
        },
        torque: Xyz {
            x: w[3],
            y: w[4],
            z: w[5],
        },
    }
}

/// The JSON message of channel `i` for `rec`, or `None` when the channel has nothing this cycle.
pub fn encode(i: usize, rec: &Record, buf: &mut Vec<u8>) -> Option<()> {
    use serde_json::json;
    buf.clear();
    let r = &rec.row;
    let v = match i {
        0 => json!({"t": r.t, "f": r.f, "f_r": r.f_r, "error": r.f - r.f_r}),
        1 => serde_json::to_value(wrench_msg(&rec.wrench)).ok()?,
        2 if rec.wrench_raw.iter().any(|v| v.is_finite()) => {
            serde_json::to_value(wrench_msg(&rec.wrench_raw)).ok()?
        }
        3 => json!({"x": r.x, "x_cmd": r.x_cmd, "x_r": r.x_r}),
        4 => json!({"kc_hat": r.kc_hat, "xc_hat": r.xc_hat}),
        5 => {
            let names: Vec<&str> = EVENT_NAMES
                .iter()
                .enumerate()
                .filter(|(b, _)| rec.events & (1 << b) != 0)
                .map(|(_, n)| *n)
                .collect();
            json!({"state": rec.state, "state_name": state_name(rec.state), "segment": r.segment,
                   "fault": r.fault, "fault_name": fault_name(r.fault), "events": rec.events, "event_names": names})
        }
        6 => json!({"seq": rec.robot_seq, "period": rec.period, "late_replies": rec.late_replies}),
        7 => {
            json!({"ok": rec.wrench.iter().all(|v| v.is_finite()), "seq": rec.sensor_seq, "age": rec.sensor_age})
        }
        TRUTH if r.f_true.is_finite() || r.k_c.is_finite() || r.x_c.is_finite() => {
            json!({"f_true": r.f_true, "k_c": r.k_c, "x_c": r.x_c})
        }
        PROCESS => json!({
            "segment": r.segment, "mode": r.mode, "mode_name": mode_name(r.mode), "f_cmd": r.f_cmd,
            "phase": r.phase, "phase_name": phase_name(r.phase),
            "fault": r.process_fault, "fault_name": process_fault_name(r.process_fault),
        }),
        _ => return None,
    };
    serde_json::to_writer(&mut *buf, &v).ok()?;
    Some(())
}

/// A time in s as MCAP nanoseconds (negative and non-finite times become 0).
pub fn nanos(t: f64) -> u64 {
    if t.is_finite() && t > 0.0 {
        (t * 1e9).round() as u64
    } else {
        0
    }
}

/// What a recording wrote and what it lost.
#[derive(Clone, Debug, Default)]
pub struct RecordingSummary {
    /// The file.
    pub path: PathBuf,
    /// Records written.
    pub written: u64,
    /// Records dropped because the queue was full.
    pub dropped: u64,
    /// Records lost after a write error.
    pub lost: u64,
    /// The write error, if one happened (reported once when it happened).
    pub error: Option<String>,
    /// Time of the last record known to be on disk (at the last successful flush), s.
    pub flushed_until: Option<f64>,
    /// Whether the file was finished (summary and index written).
    pub finished: bool,
    /// Bytes in the file.
    pub bytes: u64,
}

impl std::fmt::Display for RecordingSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {} cycles recorded ({:.1} MB{})",
            self.path.display(),
            self.written,
            self.bytes as f64 / 1e6,
            if self.finished {
                ", finished with summary and index"
            } else {
                ", NOT finished"
            }
        )?;
        if self.dropped > 0 {
            write!(f, "; {} dropped (queue full)", self.dropped)?;
        }
        if let Some(e) = &self.error {
            write!(
                f,
                "; recording failed: {e}; {} cycles lost after it{}",
                self.lost,
                match self.flushed_until {
                    Some(t) => format!(", the file holds the run up to t = {t:.3} s"),
                    None => ", nothing was flushed".into(),
                }
            )?;
        }
        Ok(())
    }
}

type McapWriter = mcap::Writer<BufWriter<File>>;

/// The writer thread's end: finish it with [`Recording::finish`].
pub struct Recording {
    path: PathBuf,
    thread: Option<thread::JoinHandle<RecordingSummary>>,
    truth: Option<mpsc::Sender<Vec<Row>>>,
    dropped: Arc<AtomicU64>,
}

/// Open `path` (created or truncated), write the header, schemas, channels, attachments and
/// metadata, and start the writer thread. Errors here (an unwritable directory) are returned;
/// errors later are reported once and counted.
pub fn start(
    path: &Path,
    opts: RecorderOptions,
    live: Option<LiveSink>,
) -> Result<(Recorder, Recording)> {
    let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Lz4))
        .profile("")
        .library(concat!("forcecell ", env!("CARGO_PKG_VERSION")))
        .chunk_size(Some(512 * 1024))
        // Each chunk is built in memory and written whole when it is finished (at most a second
        // later): a killed run leaves complete chunks only, never one with an unpatched length.
        .disable_seeking(true)
        .create(BufWriter::with_capacity(256 * 1024, file))
        .with_context(|| format!("cannot write {}", path.display()))?;
    // Attachments and metadata first, outside any chunk; the schemas and channels then open the first
    // chunk, which is finished only once it holds messages (see `Writer::flush`): a chunk without
    // messages has no message index, and Foxglove Studio refuses to read a file with one.
    for (name, media_type, data) in &opts.attachments {
        w.attach(&mcap::Attachment {
            log_time: 0,
            create_time: 0,
            name: name.clone(),
            media_type: media_type.clone(),
            data: Cow::Borrowed(data),
        })?;
    }
    for (name, metadata) in &opts.metadata {
        w.write_metadata(&mcap::records::Metadata {
            name: name.clone(),
            metadata: metadata.clone(),
        })?;
    }
    w.flush()
        .with_context(|| format!("cannot write {}", path.display()))?;
    // Schemas and channels are added with each channel's first message: they open a chunk, and a run
    // stopped before its first cycle must not leave a chunk that holds no message (no message index:
    // Foxglove refuses the file).
    let ids = [None; CHANNELS.len()];
    let (recorder, rx) = queue(opts.capacity, opts.full);
    let dropped = recorder.dropped.clone();
    let (truth_tx, truth_rx) = mpsc::channel();
    let mut writer = Writer {
        w: Some(w),
        ids,
        path: path.to_path_buf(),
        summary: RecordingSummary {
            path: path.to_path_buf(),
            ..RecordingSummary::default()
        },
        live,
        buf: Vec::with_capacity(512),
        seq: 0,
        last_t: None,
        unflushed: 0,
    };
    let flush_every = opts.flush_every;
    let d2 = dropped.clone();
    let thread = thread::Builder::new()
        .name("recorder".into())
        .spawn(move || {
            writer.run(rx, truth_rx, flush_every);
            let mut s = writer.summary;
            s.dropped = d2.load(Ordering::Relaxed);
            s
        })
        .context("cannot start the recorder thread")?;
    Ok((
        recorder,
        Recording {
            path: path.to_path_buf(),
            thread: Some(thread),
            truth: Some(truth_tx),
            dropped,
        },
    ))
}

impl Recording {
    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Records dropped so far because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Wait for the writer to drain the queue (the [`Recorder`] must be dropped first), write the
    /// simulation's truth rows (if any) on `/truth`, then the summary and index.
    pub fn finish(mut self, truth: Vec<Row>) -> Result<RecordingSummary> {
        if let Some(tx) = self.truth.take() {
            let _ = tx.send(truth);
        }
        self.thread
            .take()
            .ok_or_else(|| anyhow!("the recording was already finished"))?
            .join()
            .map_err(|_| anyhow!("the recorder thread panicked"))
    }
}

impl Drop for Recording {
    fn drop(&mut self) {
        self.truth.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Writer {
    w: Option<McapWriter>,
    /// Channel ids, once each channel's first message added it.
    ids: [Option<u16>; CHANNELS.len()],
    path: PathBuf,
    summary: RecordingSummary,
    live: Option<LiveSink>,
    buf: Vec<u8>,
    seq: u32,
    last_t: Option<f64>,
    /// Messages written since the last flush.
    unflushed: u64,
}

impl Writer {
    fn run(
        &mut self,
        mut rx: rtrb::Consumer<Record>,
        truth: mpsc::Receiver<Vec<Row>>,
        flush_every: Duration,
    ) {
        let mut last_flush = Instant::now();
        loop {
            let mut n = 0;
            while let Ok(rec) = rx.pop() {
                self.record(&rec);
                n += 1;
                if n == 4096 {
                    break;
                }
            }
            if last_flush.elapsed() >= flush_every {
                self.flush();
                last_flush = Instant::now();
            }
            if n == 0 {
                if rx.is_abandoned() && rx.is_empty() {
                    break;
                }
                thread::sleep(Duration::from_millis(2));
            }
        }
        // The truth of a simulation comes after the run (the world knows it only then).
        if let Ok(rows) = truth.recv() {
            for r in &rows {
                self.message(TRUTH, &Record::from_row(*r));
            }
        }
        self.finish();
    }

    fn record(&mut self, rec: &Record) {
        if self.w.is_none() {
            if self.summary.error.is_some() {
                self.summary.lost += 1;
            }
            return;
        }
        for i in 0..CHANNELS.len() {
            if i != TRUTH {
                self.message(i, rec);
            }
        }
        if self.w.is_some() {
            self.summary.written += 1;
            self.last_t = Some(rec.row.t);
        }
    }

    fn message(&mut self, i: usize, rec: &Record) {
        if encode(i, rec, &mut self.buf).is_none() {
            return;
        }
        let t = nanos(rec.row.t);
        if let Some(live) = &mut self.live {
            live(i, t, &self.buf);
        }
        let Some(w) = &mut self.w else { return };
        let channel_id = match self.ids[i] {
            Some(id) => id,
            None => {
                let c = &CHANNELS[i];
                let added = w
                    .add_schema(c.schema, "jsonschema", c.json_schema.as_bytes())
                    .and_then(|schema| w.add_channel(schema, c.topic, "json", &BTreeMap::new()));
                match added {
                    Ok(id) => {
                        self.ids[i] = Some(id);
                        id
                    }
                    Err(e) => {
                        self.fail(e);
                        if i != TRUTH {
                            self.summary.lost += 1;
                        }
                        return;
                    }
                }
            }
        };
        self.seq = self.seq.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: self.seq,
            log_time: t,
            publish_time: t,
        };
        self.unflushed += 1;
        if let Err(e) = w.write_to_known_channel(&header, &self.buf) {
            self.fail(e);
            if i != TRUTH {
                self.summary.lost += 1;
            }
        }
    }

    fn flush(&mut self) {
        let Some(w) = &mut self.w else { return };
        // Nothing new: finishing the open chunk now would write one without messages.
        if self.unflushed == 0 {
            return;
        }
        self.unflushed = 0;
        match w.flush() {
            Ok(()) => self.summary.flushed_until = self.last_t,
            Err(e) => self.fail(e),
        }
    }

    /// Report once, stop writing; the file keeps what was flushed.
    fn fail(&mut self, e: mcap::McapError) {
        if self.summary.error.is_none() {
            let msg = format!("{:#}", anyhow::Error::new(e));
            eprintln!(
                "recording: cannot write {}: {msg}; the run goes on without recording",
                self.path.display()
            );
            self.summary.error = Some(msg);
        }
        if let Some(w) = self.w.take() {
            // Do not let the writer's drop try to finish a failed file.
            let _ = w.into_inner();
        }
    }

    fn finish(&mut self) {
        let Some(mut w) = self.w.take() else {
            self.summary.bytes = std::fs::metadata(&self.path).map_or(0, |m| m.len());
            return;
        };
        let result = w.finish().map_err(|e| e.to_string()).and_then(|_| {
            let mut inner = w.into_inner();
            inner.flush().map_err(|e| e.to_string())?;
            inner
                .into_inner()
                .map_err(|e| e.to_string())?
                .sync_all()
                .map_err(|e| e.to_string())
        });
        match result {
            Ok(()) => {
                self.summary.finished = true;
                self.summary.flushed_until = self.last_t;
            }
            Err(e) => {
                if self.summary.error.is_none() {
                    eprintln!("recording: cannot finish {}: {e}", self.path.display());
                    self.summary.error = Some(e);
                }
            }
        }
        self.summary.bytes = std::fs::metadata(&self.path).map_or(0, |m| m.len());
    }
}

impl Record {
    /// A record holding only a trace row (the other fields unknown).
    pub fn from_row(row: Row) -> Self {
        Self {
            row,
            wrench: NAN6,
            wrench_raw: NAN6,
            sensor_seq: 0,
            sensor_age: f64::NAN,
            robot_seq: 0,
            period: f64::NAN,
            late_replies: 0,
            state: NO_STATE,
            events: 0,
        }
    }
}

/// What [`read_mcap`] found.
#[derive(Debug)]
pub struct ReadBack {
    /// One row per recorded cycle, truth columns filled from `/truth` where present.
    pub rows: Vec<Row>,
    /// Set when the file ends early (not finished: a killed run); the rows are those before the end.
    pub truncated: Option<String>,
}

fn num(v: &serde_json::Value, k: &str) -> f64 {
    v.get(k)
        .and_then(serde_json::Value::as_f64)
        .unwrap_or(f64::NAN)
}

/// Read a forcecell MCAP recording back into trace rows (for `export` and `plot`). A file that ends
/// early (a killed run) is read up to its last complete record and marked [`ReadBack::truncated`].
pub fn read_mcap(bytes: &[u8]) -> Result<ReadBack> {
    let mut rows: BTreeMap<u64, Row> = BTreeMap::new();
    let mut truncated = None;
    let mut any = false;
    let stream = mcap::MessageStream::new(bytes).context("not an MCAP file")?;
    for m in stream {
        let m = match m {
            Ok(m) => m,
            Err(e) => {
                truncated = Some(e.to_string());
                break;
            }
        };
        any = true;
        let v: serde_json::Value = match serde_json::from_slice(&m.data) {
            Ok(v) => v,
            Err(e) => anyhow::bail!(
                "{} message at {} ns is not JSON: {e}",
                m.channel.topic,
                m.log_time
            ),
        };
        let row = rows.entry(m.log_time).or_insert_with(|| Row {
            t: m.log_time as f64 * 1e-9,
            ..nan_row()
        });
        match m.channel.topic.as_str() {
            "/force" => {
                row.t = v.get("t").and_then(|t| t.as_f64()).unwrap_or(row.t);
                row.f = num(&v, "f");
                row.f_r = num(&v, "f_r");
            }
            "/position" => {
                row.x = num(&v, "x");
                row.x_cmd = num(&v, "x_cmd");
                row.x_r = num(&v, "x_r");
            }
            "/estimates" => {
                row.kc_hat = num(&v, "kc_hat");
                row.xc_hat = num(&v, "xc_hat");
            }
            "/state" => {
                row.fault = v.get("fault").and_then(|f| f.as_u64()).unwrap_or(0) as u8;
            }
            "/truth" => {
                row.f_true = num(&v, "f_true");
                row.k_c = num(&v, "k_c");
                row.x_c = num(&v, "x_c");
            }
            // Recordings before the process channel leave these unknown (`/state`'s `segment` was
            // always 0 then).
            "/process" => {
                let int = |k| v.get(k).and_then(serde_json::Value::as_i64);
                row.segment = int("segment");
                row.mode = int("mode");
                row.f_cmd = num(&v, "f_cmd");
                row.phase = int("phase").and_then(|c| u8::try_from(c).ok());
                row.process_fault = int("fault").and_then(|c| u8::try_from(c).ok());
            }
            _ => {}
        }
    }
    if !any && truncated.is_some() {
        anyhow::bail!(
            "no message could be read: {}",
            truncated.unwrap_or_default()
        );
    }
    // A row that only `/truth` touched (its cycle's messages were lost) is not a recorded cycle.
    let rows = rows.into_values().filter(|r| !r.f_r.is_nan()).collect();
    Ok(ReadBack { rows, truncated })
}

/// A row with every value unknown.
fn nan_row() -> Row {
    Row {
        t: f64::NAN,
        f: f64::NAN,
        f_true: f64::NAN,
        f_r: f64::NAN,
        x: f64::NAN,
        x_cmd: f64::NAN,
        x_r: f64::NAN,
        kc_hat: f64::NAN,
        xc_hat: f64::NAN,
        k_c: f64::NAN,
        x_c: f64::NAN,
        fault: 0,
        segment: None,
        mode: None,
        f_cmd: f64::NAN,
        phase: None,
        process_fault: None,
        s: f64::NAN,
    }
}

/// Read a trace from a file: an MCAP recording (by its magic) or a CSV. Returns the rows and, for an
/// MCAP file that ends early, why.
pub fn load_trace(path: &Path) -> Result<(Vec<Row>, Option<String>)> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    if bytes.starts_with(mcap::MAGIC) {
        let back = read_mcap(&bytes).with_context(|| format!("{}", path.display()))?;
        Ok((back.rows, back.truncated))
    } else {
        let text = String::from_utf8(bytes)
            .map_err(|_| anyhow!("{}: neither an MCAP file nor a CSV trace", path.display()))?;
        let rows = crate::record::read_csv(&text).with_context(|| format!("{}", path.display()))?;
        Ok((rows, None))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A channel field's description, from its JSON schema.
    fn description(topic: &str, field: &str) -> String {
        let def = CHANNELS.iter().find(|c| c.topic == topic).unwrap();
        let schema: serde_json::Value = serde_json::from_str(def.json_schema).unwrap();
        schema["properties"][field]["description"]
            .as_str()
            .unwrap_or_else(|| panic!("{topic} {field}: no description"))
            .to_owned()
    }

    /// `c name` for each code, joined as a schema lists them.
    fn legend(codes: impl IntoIterator<Item = u8>, name: impl Fn(u8) -> &'static str) -> String {
        codes
            .into_iter()
            .map(|c| format!("{c} {}", name(c)))
            .collect::<Vec<_>>()
            .join(", ")
    }

    #[test]
    fn every_schema_legend_names_the_codes_as_the_recording_does() {
        let cases = [
            ("/state", "state", legend([0, 1, 2, 3, 255], state_name)),
            ("/state", "fault", legend(0..=7, fault_name)),
            (
                "/process",
                "mode",
                legend(0..=2, |c| mode_name(Some(i64::from(c)))),
            ),
            (
                "/process",
                "phase",
                legend([0, 1, 2, 3, 4, 9], |c| phase_name(Some(c))),
            ),
            ("/process", "fault", hal::ProcessFault::legend()),
        ];
        for (topic, field, want) in cases {
            let d = description(topic, field);
            // The list after any "…: " lead, item by item (a longer name is no match).
            let listed: Vec<&str> = d.rsplit(": ").next().unwrap().split(", ").collect();
            for item in want.split(", ") {
                assert!(
                    listed.contains(&item),
                    "{topic} {field}: {d:?} does not list {item:?}"
                );
            }
        }
        // Past the listed codes the names say so (a new code must be listed above).
        assert_eq!(fault_name(8), "unknown");
        assert_eq!(process_fault_name(Some(7)), "unknown");
        assert_eq!(phase_name(Some(5)), "unknown");
    }
}
