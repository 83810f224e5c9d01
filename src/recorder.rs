//! The recorder: each control cycle's [`Record`] goes into a preallocated, bounded, wait-free queue
//! (no allocation, no lock, no system call in the cycle); a writer thread streams it to an MCAP file
//! and, optionally, to live viewers.
//!
//! * The loop side is [`Recorder::push`]: one copy into a fixed-capacity single-producer ring
//!   ([`rtrb`]). When the ring is full the record is dropped and counted ([`Full::Drop`], the real-time
//!   setting). A lockstep simulation, which has no deadline, may instead wait for room ([`Full::Wait`]).
//! * The writer thread ([`Recording`]) turns each record into one protobuf message on `/cycle` (the
//!   schema is [`scenario::telemetry`]'s table, embedded in the file as a `FileDescriptorSet`: Foxglove
//!   and any protobuf reader decode it without a copy of ours), compresses chunks with zstd, and
//!   finishes a chunk and flushes the file at least every [`RecorderOptions::flush_every`] (1 s): a
//!   killed process leaves a file readable up to the last flush. A simulation's truth goes on `/truth`
//!   at the end. [`Recording::finish`] writes the summary and index.
//! * A write error (a full disk, a vanished directory) is reported once on stderr; the writer then
//!   discards and counts, the loop is never held up, and [`RecordingSummary`] says what was lost.
//! * [`read_mcap`] reads these recordings back, and every JSON recording written before them (one
//!   channel per group of fields: `/force`, `/position`, `/state`, `/process`, …).
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

use ::scenario::telemetry;
use anyhow::{Context, Result, anyhow};

pub use ::scenario::telemetry::{CHANNELS, Channel, NO_STATE, Record};

use crate::record::Row;

/// The uncompressed size at which a chunk is finished (it is finished at each flush too).
const CHUNK_SIZE: u64 = 1024 * 1024;

/// Index of the `/truth` channel in [`CHANNELS`] (written at the end of a simulation).
pub const TRUTH: usize = 1;

/// The encoding of every message, and of every schema, as MCAP and the Foxglove WebSocket protocol
/// name it.
pub const ENCODING: &str = "protobuf";

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
/// [`CHANNELS`], the log time in ns and the protobuf payload. Called on the writer thread, never the
/// loop's.
pub type LiveSink = Box<dyn FnMut(usize, u64, &[u8]) + Send>;

/// The message of channel `i` for `rec` (cleared first), or `None` when the channel has nothing this
/// cycle (the truth where the world knows none).
pub fn encode(i: usize, rec: &Record, buf: &mut Vec<u8>) -> Option<()> {
    buf.clear();
    let c = CHANNELS.get(i)?;
    c.has(rec).then(|| telemetry::encode(c.message, rec, buf))
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
            "{}: {} cycles recorded ({:.1} MB{}{})",
            self.path.display(),
            self.written,
            self.bytes as f64 / 1e6,
            if self.written > 0 {
                format!(", {:.0} B a cycle", self.bytes as f64 / self.written as f64)
            } else {
                String::new()
            },
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
    // Streamed to NAME.partial, renamed to NAME by `finish`: an existing recording of that name is
    // replaced only by a finished one, and a killed run leaves NAME.partial (readable up to its last
    // flush).
    let final_path = path;
    let partial = partial_path(path);
    let path = partial.as_path();
    let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = mcap::WriteOptions::new()
        // zstd on this thread (no compression threads of its own beside the control loop): the cycles
        // of a chunk differ little from one to the next.
        .compression(Some(mcap::Compression::Zstd))
        .compression_threads(0)
        .profile("")
        .library(concat!("forcecell ", env!("CARGO_PKG_VERSION")))
        .chunk_size(Some(CHUNK_SIZE))
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
            path: final_path.to_path_buf(),
            ..RecordingSummary::default()
        },
        live,
        buf: Vec::with_capacity(512),
        schemas: CHANNELS
            .iter()
            .map(telemetry::file_descriptor_set)
            .collect(),
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
            path: final_path.to_path_buf(),
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
            .and_then(|s| {
                let partial = partial_path(&self.path);
                std::fs::rename(&partial, &self.path).with_context(|| {
                    format!(
                        "cannot rename {} to {}",
                        partial.display(),
                        self.path.display()
                    )
                })?;
                Ok(s)
            })
    }
}

/// Where a recording to `path` is streamed until it is finished: `path` with `.partial` appended.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut p = path.as_os_str().to_owned();
    p.push(".partial");
    PathBuf::from(p)
}

impl Drop for Recording {
    fn drop(&mut self) {
        self.truth.take();
        if let Some(t) = self.thread.take() {
            // Not finished (the command failed): a recording that holds no cycle is removed; one
            // that does stays as NAME.partial beside any earlier NAME.
            if let Ok(s) = t.join()
                && s.flushed_until.is_none()
            {
                let _ = std::fs::remove_file(partial_path(&self.path));
            }
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
    /// Each channel's schema (a `FileDescriptorSet`).
    schemas: Vec<Vec<u8>>,
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
                    .add_schema(&c.schema_name(), ENCODING, &self.schemas[i])
                    .and_then(|schema| w.add_channel(schema, c.topic, ENCODING, &BTreeMap::new()));
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
        let header = mcap::records::MessageHeader {
            channel_id,
            // No counter of the writer's own (MCAP: 0, "not assigned"): the cycle's own sequence
            // numbers are in the message, and a counter would cost 3–4 compressed bytes a cycle.
            sequence: 0,
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

/// What [`read_mcap`] found.
#[derive(Debug)]
pub struct ReadBack {
    /// One row per recorded cycle, truth columns filled from `/truth` where present.
    pub rows: Vec<Row>,
    /// The robot's measured tool pose of each row (`robot.pose`: x, y, z in m, rotation vector in
    /// rad; NaN where the file carries none).
    pub poses: Vec<[f64; 6]>,
    /// Set when the file ends early (not finished: a killed run); the rows are those before the end.
    pub truncated: Option<String>,
}

fn num(v: &serde_json::Value, k: &str) -> f64 {
    v.get(k)
        .and_then(serde_json::Value::as_f64)
        .unwrap_or(f64::NAN)
}

/// One message of a JSON recording (written before the protobuf schema: a channel per group of
/// fields) into its row.
fn read_json_message(topic: &str, v: &serde_json::Value, row: &mut Row) {
    match topic {
        "/force" => {
            row.t = v.get("t").and_then(|t| t.as_f64()).unwrap_or(row.t);
            row.f = num(v, "f");
            row.f_r = num(v, "f_r");
        }
        "/position" => {
            row.x = num(v, "x");
            row.x_cmd = num(v, "x_cmd");
            row.x_r = num(v, "x_r");
        }
        "/estimates" => {
            row.kc_hat = num(v, "kc_hat");
            row.xc_hat = num(v, "xc_hat");
        }
        // `/state`'s `fault` was the cycle's condition.
        "/state" => {
            row.condition = v.get("fault").and_then(|f| f.as_u64()).unwrap_or(0) as u8;
        }
        "/truth" => {
            row.f_true = num(v, "f_true");
            row.k_c = num(v, "k_c");
            row.x_c = num(v, "x_c");
        }
        // Recordings before the process channel leave these unknown (`/state`'s `segment` was
        // always 0 then).
        "/process" => {
            let int = |k| v.get(k).and_then(serde_json::Value::as_i64);
            row.segment = int("segment");
            row.mode = int("mode");
            row.f_cmd = num(v, "f_cmd");
            row.phase = int("phase").and_then(|c| u8::try_from(c).ok());
            row.fault = int("fault").and_then(|c| u8::try_from(c).ok());
        }
        _ => {}
    }
}

/// Read a forcecell MCAP recording back into trace rows (for `export` and `plot`): a protobuf one
/// (`/cycle`, `/truth`) or a JSON one written before. A file that ends early (a killed run) is read up
/// to its last complete record and marked [`ReadBack::truncated`].
pub fn read_mcap(bytes: &[u8]) -> Result<ReadBack> {
    let mut rows: BTreeMap<u64, Row> = BTreeMap::new();
    let mut poses: BTreeMap<u64, [f64; 6]> = BTreeMap::new();
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
        let topic = m.channel.topic.as_str();
        let row = rows.entry(m.log_time).or_insert_with(|| Row {
            t: m.log_time as f64 * 1e-9,
            ..Row::unknown()
        });
        match m.channel.message_encoding.as_str() {
            ENCODING => {
                let Some(c) = CHANNELS.iter().find(|c| c.topic == topic) else {
                    continue;
                };
                let mut rec = Record::from_row(*row);
                telemetry::decode(c.message, &m.data, &mut rec).with_context(|| {
                    format!(
                        "{topic} message at {} ns is not a {}",
                        m.log_time,
                        c.schema_name()
                    )
                })?;
                if c.message.name == telemetry::CYCLE.name {
                    rec.row.moment = [rec.wrench[3], rec.wrench[4]];
                }
                *row = rec.row;
                if rec.pose.iter().all(|v| v.is_finite()) {
                    poses.insert(m.log_time, rec.pose);
                }
            }
            _ => {
                let v: serde_json::Value = match serde_json::from_slice(&m.data) {
                    Ok(v) => v,
                    Err(e) => {
                        anyhow::bail!("{topic} message at {} ns is not JSON: {e}", m.log_time)
                    }
                };
                read_json_message(topic, &v, row);
            }
        }
    }
    if !any && truncated.is_some() {
        anyhow::bail!(
            "no message could be read: {}",
            truncated.unwrap_or_default()
        );
    }
    // A row that only `/truth` touched (its cycle's messages were lost) is not a recorded cycle.
    let (rows, poses) = rows
        .into_iter()
        .filter(|(_, r)| !r.f_r.is_nan())
        .map(|(k, r)| (r, poses.get(&k).copied().unwrap_or([f64::NAN; 6])))
        .unzip();
    Ok(ReadBack {
        rows,
        poses,
        truncated,
    })
}

/// Read a trace from a file: an MCAP recording (by its magic) or a CSV. Returns the rows and, for an
/// MCAP file that ends early, why.
pub fn load_trace(path: &Path) -> Result<(Vec<Row>, Option<String>)> {
    let bytes = crate::input::read(path, "trace", crate::input::MAX_TRACE)?;
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
