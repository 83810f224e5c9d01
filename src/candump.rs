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
    let reader = socketcan::dump::Reader::from_file(path)
        .with_context(|| format!("cannot read {}", path.display()))?;
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
