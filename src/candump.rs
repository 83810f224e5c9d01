//! CAN traffic logs in candump's `-L` format (`(SECONDS.MICROS) IFACE ID#DATA`, one frame a line),
//! written and read with the `socketcan` crate's `dump` module: a field trace can be examined with
//! can-utils (`log2asc`, `canplayer`) or replayed.
//!
//! [`CanLog`] wraps any [`CanTransport`] and logs every frame it sends and receives. It runs where the
//! transport runs (the sensor's poll thread, never the control loop's); the file is flushed at least
//! once a second and when the log is dropped. A write error is reported once and logging stops; the
//! bus traffic is never held up by the log.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{Context, Result};
use ati_can::{Base, BusEvent, CanTransport, Clock, Frame, TransportError};
use socketcan::dump::CanDumpRecord;
use socketcan::{
    CanAnyFrame, CanDataFrame, CanRemoteFrame, EmbeddedFrame, ExtendedId, Frame as _, Id,
    StandardId,
};

/// A frame in the `socketcan` crate's form.
pub fn to_socketcan(frame: &Frame) -> Option<CanAnyFrame> {
    let id: Id = if frame.is_extended() {
        ExtendedId::new(frame.id())?.into()
    } else {
        StandardId::new(u16::try_from(frame.id()).ok()?)?.into()
    };
    Some(if frame.is_remote() {
        CanAnyFrame::Remote(CanRemoteFrame::new_remote(id, frame.dlc().into())?)
    } else {
        CanAnyFrame::Normal(CanDataFrame::new(id, frame.data())?)
    })
}

/// A frame back from the `socketcan` crate's form (data and remote frames; others are `None`).
pub fn from_socketcan(frame: &CanAnyFrame) -> Option<Frame> {
    match frame {
        CanAnyFrame::Normal(d) if d.is_extended() => Frame::extended(d.raw_id(), d.data()),
        CanAnyFrame::Normal(d) => Frame::standard(u16::try_from(d.raw_id()).ok()?, d.data()),
        CanAnyFrame::Remote(r) => Frame::remote(r.raw_id(), r.is_extended(), r.dlc() as u8),
        _ => None,
    }
}

/// A candump `-L` log file being written.
pub struct CandumpWriter {
    out: Option<BufWriter<File>>,
    iface: String,
    last_flush: Instant,
    /// Frames written.
    pub frames: u64,
    /// Frames lost after a write error.
    pub lost: u64,
}

impl CandumpWriter {
    /// Create (or truncate) `path`; frames are logged as seen on `iface`.
    pub fn create(path: &Path, iface: &str) -> Result<Self> {
        let f = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        Ok(Self {
            out: Some(BufWriter::new(f)),
            iface: iface.to_string(),
            last_flush: Instant::now(),
            frames: 0,
            lost: 0,
        })
    }

    /// Log one frame at wall-clock time `at`.
    pub fn log(&mut self, frame: &Frame, at: SystemTime) {
        let Some(out) = &mut self.out else {
            self.lost += 1;
            return;
        };
        let Some(frame) = to_socketcan(frame) else {
            return;
        };
        let t_us = at
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX));
        let rec = CanDumpRecord {
            t_us,
            device: self.iface.clone(),
            frame,
            direction: None,
        };
        let mut r = writeln!(out, "{rec}");
        if r.is_ok() && self.last_flush.elapsed() >= Duration::from_secs(1) {
            self.last_flush = Instant::now();
            r = out.flush();
        }
        match r {
            Ok(()) => self.frames += 1,
            Err(e) => {
                eprintln!("CAN log: cannot write: {e}; logging stops, the bus goes on");
                self.out = None;
                self.lost += 1;
            }
        }
    }

    /// Flush what is buffered.
    pub fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.out {
            Some(o) => o.flush(),
            None => Ok(()),
        }
    }
}

impl Drop for CandumpWriter {
    fn drop(&mut self) {
        let _ = self.flush();
    }
}

/// A transport that logs every frame it sends and receives to a candump log.
pub struct CanLog<T> {
    inner: T,
    log: CandumpWriter,
}

impl<T> CanLog<T> {
    /// Log `inner`'s traffic to `log`.
    pub fn new(inner: T, log: CandumpWriter) -> Self {
        Self { inner, log }
    }
}

impl<T: CanTransport> CanTransport for CanLog<T> {
    fn send(&mut self, frame: &Frame) -> Result<(), TransportError> {
        self.inner.send(frame)?;
        self.log.log(frame, SystemTime::now());
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<BusEvent>, TransportError> {
        let ev = self.inner.recv(timeout)?;
        if let Some(BusEvent::Frame(f)) = &ev {
            self.log.log(f, SystemTime::now());
        }
        Ok(ev)
    }

    fn accept_only(&mut self, base: Base) -> Result<(), TransportError> {
        self.inner.accept_only(base)
    }

    fn clock(&self) -> Clock {
        self.inner.clock()
    }
}

/// Read a candump `-L` log: every frame with its time in µs since the Unix epoch and its interface.
/// Errors name the line.
pub fn read_log(path: &Path) -> Result<Vec<(u64, String, Frame)>> {
    let file = crate::input::open(path, "CAN log", crate::input::MAX_CAN_LOG)?;
    let reader =
        socketcan::dump::Reader::from_reader(std::io::Read::take(file, crate::input::MAX_CAN_LOG));
    let mut out = Vec::new();
    for (n, rec) in reader.enumerate() {
        let rec = rec.with_context(|| format!("{}: line {}", path.display(), n + 1))?;
        let frame = from_socketcan(&rec.frame).with_context(|| {
            format!(
                "{}: line {}: not a classic data or remote frame",
                path.display(),
                n + 1
            )
        })?;
        out.push((rec.t_us, rec.device, frame));
    }
    Ok(out)
}

/// A SocketCAN transport on `iface`, logging to `can_log` when given.
pub fn open_logged(iface: &str, can_log: Option<&Path>) -> Result<Box<dyn CanTransport + Send>> {
    let t = ati_can::SocketCanTransport::open(iface)?;
    Ok(match can_log {
        Some(path) => Box::new(CanLog::new(t, CandumpWriter::create(path, iface)?)),
        None => Box::new(t),
    })
}

/// A recorded field trace answering the driver as the sensor did: `forcecell sim-sensor ati --replay`.
///
/// The ATI board only speaks when asked, so a log is not replayed blindly onto the bus (answers sent
/// on the log's clock would miss the live driver's requests). Instead the log is cut into exchanges —
/// each request the driver sent, with the answer frames that followed it and their delays — and every
/// request the live driver sends is answered with the next recorded exchange for the same request,
/// after the recorded delay. The driver therefore gets the recorded identity, calibration, status
/// words and gauge counts in the recorded order, with the recorded turnaround, and a request that went
/// unanswered in the field goes unanswered again. Start-up requests (firmware, serial, matrix, units,
/// …) are answered again from their last recorded exchange when the driver asks more often than the
/// log did; polls are not: past the log's last poll the replay falls silent (the trace has ended).
pub struct Replay {
    base: Base,
    exchanges: std::collections::BTreeMap<(u8, Vec<u8>), std::collections::VecDeque<Exchange>>,
    /// Polls in the log.
    pub recorded_polls: u64,
    /// Polls answered from the log.
    pub replayed_polls: u64,
    /// Requests that the log has no exchange for (not answered).
    pub unknown: u64,
    /// Polls asked for after the log's last one (not answered).
    pub past_end: u64,
}

type Exchange = Vec<(Duration, Frame)>;

/// An exchange being read from the log: its key, request time (µs), expected answer layout and the
/// frames so far.
type Open = ((u8, Vec<u8>), u64, &'static [(u8, u8)], Exchange);

fn key(frame: &Frame) -> (u8, Vec<u8>) {
    ((frame.id() & 0xF) as u8, frame.data().to_vec())
}

impl Replay {
    /// Cut a candump log's frames (as [`read_log`] returns them) into exchanges on `base`. Frames of
    /// other ids are left out (the driver filters them too). Fails when the log holds no request on
    /// `base`.
    pub fn from_log(records: &[(u64, String, Frame)], base: Base) -> Result<Self> {
        use ati_can::Request;
        let mut replay = Self {
            base,
            exchanges: Default::default(),
            recorded_polls: 0,
            replayed_polls: 0,
            unknown: 0,
            past_end: 0,
        };
        let mut cur: Option<Open> = None;
        let close = |cur: &mut Option<Open>, replay: &mut Self| {
            if let Some((k, _, _, answers)) = cur.take() {
                if k.0 == ati_can::codec::op::POLL {
                    replay.recorded_polls += 1;
                }
                replay.exchanges.entry(k).or_default().push_back(answers);
            }
        };
        for (t_us, _, frame) in records {
            let Ok(opcode) = base.opcode_of(frame) else {
                continue;
            };
            // The answer frame the open exchange waits for next?
            let expected = cur
                .as_ref()
                .and_then(|(_, _, layout, got)| layout.get(got.len()).copied());
            if expected == Some((opcode, frame.dlc())) {
                if let Some((_, t0, _, got)) = &mut cur {
                    got.push((Duration::from_micros(t_us.saturating_sub(*t0)), *frame));
                }
            } else if let Ok(req) = Request::decode(frame, base) {
                close(&mut cur, &mut replay);
                cur = Some((key(frame), *t_us, req.answer_layout(), Vec::new()));
            } else if let Some((_, t0, _, got)) = &mut cur {
                // An unexpected frame after a request (a duplicate, a late answer): replayed as seen.
                got.push((Duration::from_micros(t_us.saturating_sub(*t0)), *frame));
            }
        }
        close(&mut cur, &mut replay);
        if replay.exchanges.is_empty() {
            anyhow::bail!("the log holds no ATI request on base {base}");
        }
        Ok(replay)
    }

    /// The recorded answer to a request frame, with each frame's delay after the request; `None`
    /// when the log has none (a request it never saw, or a poll past its end).
    pub fn answer(&mut self, request: &Frame) -> Option<Exchange> {
        let k = key(request);
        let poll = k.0 == ati_can::codec::op::POLL;
        let Some(queue) = self.exchanges.get_mut(&k) else {
            self.unknown += 1;
            return None;
        };
        if poll {
            let next = queue.pop_front();
            match next {
                Some(_) => self.replayed_polls += 1,
                None => self.past_end += 1,
            }
            next
        } else if queue.len() > 1 {
            queue.pop_front()
        } else {
            queue.front().cloned()
        }
    }

    /// The base it answers on.
    pub fn base(&self) -> Base {
        self.base
    }
}

impl ati_can::Responder for Replay {
    fn on_frame(&mut self, frame: &Frame, _now: Duration, out: &mut dyn FnMut(Duration, Frame)) {
        if ati_can::Request::decode(frame, self.base).is_err() {
            return;
        }
        for (delay, answer) in self.answer(frame).into_iter().flatten() {
            out(delay, answer);
        }
    }
}
