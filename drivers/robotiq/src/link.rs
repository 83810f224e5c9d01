//! The stream's health as a pure state machine: bytes with their arrival time go in, the newest sample
//! (with its age) or the reason there is none comes out. [`RawReader`] is the thin I/O shell that reads a
//! port and feeds it; the background thread of [`crate::Ft300`] and the lockstep adaptor of the simulation
//! both use it.

use core::time::Duration;
use std::io::{ErrorKind as IoKind, Read};

use hal::{Sample, Wrench};

use crate::codec::{Counts, Event, StreamDecoder};
use crate::error::RobotiqError;

/// Limits of a stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkConfig {
    /// No byte for this long: [`Health::Stale`] (spec: 80 ms).
    pub stale_after: Duration,
    /// No valid frame for this long: [`Health::Lost`] (spec: 160 ms).
    pub lost_after: Duration,
    /// A sample older than this is not handed out even while bytes arrive (their frames all failing).
    pub max_age: Duration,
    /// Frames in the CRC window (at most 64).
    pub crc_window: u32,
    /// More failed frames than this in the window: [`Health::Corrupt`].
    pub max_crc_errors: u32,
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            stale_after: Duration::from_millis(80),
            lost_after: Duration::from_millis(160),
            max_age: Duration::from_millis(80),
            crc_window: 32,
            max_crc_errors: 8,
        }
    }
}

impl LinkConfig {
    /// Check the values.
    pub fn validate(&self) -> Result<(), RobotiqError> {
        let bad = |m: &str| Err(RobotiqError::Config(m.into()));
        if self.stale_after.is_zero() || self.lost_after.is_zero() || self.max_age.is_zero() {
            return bad("stale_after, lost_after and max_age must be positive");
        }
        if self.crc_window == 0 || self.crc_window > 64 {
            return bad("crc_window must be in 1..=64");
        }
        if self.max_crc_errors >= self.crc_window {
            return bad("max_crc_errors must be below crc_window");
        }
        Ok(())
    }
}

/// The driver's view of the stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Health {
    /// No valid frame yet.
    Waiting,
    /// Frames arrive and pass their CRC.
    Ok,
    /// No byte for longer than `stale_after`.
    Stale,
    /// No valid frame for longer than `lost_after`.
    Lost,
    /// Too many CRC failures in the recent window.
    Corrupt,
}

/// What the link has counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Bytes received.
    pub bytes: u64,
    /// Good frames.
    pub frames: u64,
    /// Frames whose CRC failed.
    pub crc_errors: u64,
    /// Bytes skipped while resynchronising.
    pub skipped: u64,
    /// Times the health went to [`Health::Stale`].
    pub stale_events: u64,
    /// Times the health went to [`Health::Lost`].
    pub lost_events: u64,
    /// Times the health went to [`Health::Corrupt`].
    pub corrupt_events: u64,
}

impl Counters {
    /// Failed frames per frame candidate since the start (0 when there was none).
    pub fn crc_error_rate(&self) -> f64 {
        let n = self.frames + self.crc_errors;
        if n == 0 {
            0.0
        } else {
            self.crc_errors as f64 / n as f64
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Latest {
    counts: Counts,
    seq: u64,
    stamp: Duration,
}

/// The stream's state. Times are durations since any fixed epoch the caller chooses.
#[derive(Clone, Debug)]
pub struct LinkState {
    cfg: LinkConfig,
    decoder: StreamDecoder,
    opened: Duration,
    last_byte: Option<Duration>,
    latest: Option<Latest>,
    window: u64,
    window_len: u32,
    bias: [f64; 6],
    observed: Health,
    counters: Counters,
}

impl LinkState {
    /// A stream opened at `now`.
    pub fn new(cfg: LinkConfig, now: Duration) -> Self {
        Self {
            cfg,
            decoder: StreamDecoder::new(),
            opened: now,
            last_byte: None,
            latest: None,
            window: 0,
            window_len: 0,
            bias: [0.0; 6],
            observed: Health::Waiting,
            counters: Counters::default(),
        }
    }

    /// The limits.
    pub fn config(&self) -> &LinkConfig {
        &self.cfg
    }

    fn record(&mut self, crc_failed: bool) {
        let w = self.cfg.crc_window;
        let mask = if w >= 64 { u64::MAX } else { (1u64 << w) - 1 };
        self.window = ((self.window << 1) | u64::from(crc_failed)) & mask;
        self.window_len = (self.window_len + 1).min(w);
    }

    /// CRC failures in the recent window.
    pub fn window_errors(&self) -> u32 {
        self.window.count_ones()
    }

    /// Bytes that arrived at `now`. Returns how many good frames they completed.
    pub fn on_bytes(&mut self, bytes: &[u8], now: Duration) -> usize {
        if bytes.is_empty() {
            return 0;
        }
        self.last_byte = Some(now);
        let mut frames = 0;
        let mut decoder = core::mem::take(&mut self.decoder);
        decoder.feed(bytes, |e| match e {
            Event::Frame(counts) => {
                frames += 1;
                self.record(false);
                let seq = self.latest.map_or(1, |l| l.seq + 1);
                self.latest = Some(Latest {
                    counts,
                    seq,
                    stamp: now,
                });
            }
            Event::CrcError => self.record(true),
        });
        self.decoder = decoder;
        let d = self.decoder.counters();
        self.counters.bytes = d.bytes;
        self.counters.frames = d.frames;
        self.counters.crc_errors = d.crc_errors;
        self.counters.skipped = d.skipped;
        frames
    }

    /// The health at `now` (no side effects; see [`LinkState::observe`]).
    pub fn health_at(&self, now: Duration) -> Health {
        let Some(l) = self.latest else {
            return if now.saturating_sub(self.opened) > self.cfg.lost_after {
                Health::Lost
            } else {
                Health::Waiting
            };
        };
        if now.saturating_sub(l.stamp) > self.cfg.lost_after {
            Health::Lost
        } else if self
            .last_byte
            .is_none_or(|b| now.saturating_sub(b) > self.cfg.stale_after)
        {
            Health::Stale
        } else if self.window_errors() > self.cfg.max_crc_errors {
            Health::Corrupt
        } else {
            Health::Ok
        }
    }

    /// Evaluate the health at `now` and count transitions into fault states. The reader calls this after
    /// every read (and every read timeout), so the counters see every episode.
    pub fn observe(&mut self, now: Duration) -> Health {
        let h = self.health_at(now);
        if h != self.observed {
            match h {
                Health::Stale => self.counters.stale_events += 1,
                Health::Lost => self.counters.lost_events += 1,
                Health::Corrupt => self.counters.corrupt_events += 1,
                Health::Ok | Health::Waiting => {}
            }
            self.observed = h;
        }
        h
    }

    /// The counters.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Sequence number of the newest good frame (0: none yet).
    pub fn seq(&self) -> u64 {
        self.latest.map_or(0, |l| l.seq)
    }

    /// The newest good frame's channels, without zero, and its sequence number.
    pub fn latest_counts(&self) -> Option<(Counts, u64)> {
        self.latest.map(|l| (l.counts, l.seq))
    }

    /// The host-side zero, N and N·m.
    pub fn bias(&self) -> Wrench {
        Wrench::from_array(self.bias)
    }

    /// Set the host-side zero.
    pub fn set_bias(&mut self, bias: Wrench) {
        self.bias = bias.to_array();
    }

    /// The newest sample at `now`, zero removed, or why there is none.
    pub fn sample_at(&self, now: Duration) -> Result<Sample, RobotiqError> {
        let since_open = now.saturating_sub(self.opened);
        match self.health_at(now) {
            Health::Ok => {}
            Health::Waiting => return Err(RobotiqError::NotReady),
            Health::Stale => {
                return Err(RobotiqError::Stale {
                    age: self
                        .latest
                        .map_or(since_open, |l| now.saturating_sub(l.stamp)),
                });
            }
            Health::Lost => {
                return Err(RobotiqError::LinkLost {
                    since: self
                        .latest
                        .map_or(since_open, |l| now.saturating_sub(l.stamp)),
                });
            }
            Health::Corrupt => {
                return Err(RobotiqError::Corrupt {
                    errors: self.window_errors(),
                    window: self.cfg.crc_window,
                });
            }
        }
        let Some(l) = self.latest else {
            return Err(RobotiqError::NotReady);
        };
        let age = now.saturating_sub(l.stamp);
        if age > self.cfg.max_age {
            return Err(RobotiqError::Stale { age });
        }
        let raw = l.counts.to_wrench().to_array();
        let mut w = [0.0; 6];
        for i in 0..6 {
            w[i] = raw[i] - self.bias[i];
        }
        Ok(Sample {
            wrench: Wrench::from_array(w),
            seq: l.seq,
            age,
        })
    }
}

/// Reads a raw stream port: one `read` (which returns when bytes are there or after the port's own
/// timeout — never a fixed sleep) and hands the bytes to a [`LinkState`].
pub struct RawReader<R> {
    port: R,
    buf: [u8; 256],
}

impl<R: Read> RawReader<R> {
    /// A reader on `port`; the port's read timeout bounds how long one [`RawReader::poll`] blocks.
    pub fn new(port: R) -> Self {
        Self {
            port,
            buf: [0; 256],
        }
    }

    /// The port.
    pub fn port_mut(&mut self) -> &mut R {
        &mut self.port
    }

    /// Give the port back.
    pub fn into_inner(self) -> R {
        self.port
    }

    /// One read: the bytes (empty after a read timeout). `Err` only for real I/O failures.
    pub fn poll(&mut self) -> std::io::Result<&[u8]> {
        match self.port.read(&mut self.buf) {
            Ok(n) => Ok(&self.buf[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    IoKind::TimedOut | IoKind::WouldBlock | IoKind::Interrupted
                ) =>
            {
                Ok(&[])
            }
            Err(e) => Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::encode_frame;
    use hal::Error as _;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn frame(fz: i16) -> [u8; 16] {
        encode_frame(Counts([0, 0, fz, 0, 0, 0]))
    }

    #[test]
    fn health_goes_waiting_ok_stale_lost_and_recovers() {
        let mut s = LinkState::new(LinkConfig::default(), ms(0));
        assert_eq!(s.observe(ms(5)), Health::Waiting);
        assert!(matches!(s.sample_at(ms(5)), Err(RobotiqError::NotReady)));
        assert_eq!(s.on_bytes(&frame(500), ms(10)), 1);
        assert_eq!(s.observe(ms(12)), Health::Ok);
        let smp = s.sample_at(ms(13)).unwrap();
        assert_eq!(smp.seq, 1);
        assert_eq!(smp.age, ms(3));
        assert!((smp.wrench.force.z - 5.0).abs() < 1e-12);
        assert_eq!(s.observe(ms(91)), Health::Stale);
        assert_eq!(
            s.sample_at(ms(91)).unwrap_err().kind(),
            hal::ErrorKind::Stale
        );
        assert_eq!(s.observe(ms(171)), Health::Lost);
        assert_eq!(
            s.sample_at(ms(171)).unwrap_err().kind(),
            hal::ErrorKind::LinkLost
        );
        s.on_bytes(&frame(600), ms(200));
        assert_eq!(s.observe(ms(200)), Health::Ok);
        assert_eq!(s.sample_at(ms(200)).unwrap().seq, 2);
        let c = s.counters();
        assert_eq!((c.stale_events, c.lost_events, c.frames), (1, 1, 2));
    }

    #[test]
    fn bytes_without_valid_frames_end_in_lost_not_stale() {
        let mut s = LinkState::new(LinkConfig::default(), ms(0));
        s.on_bytes(&frame(1), ms(0));
        for t in (10..=200).step_by(10) {
            s.on_bytes(&[0x55; 16], ms(t));
            let h = s.observe(ms(t));
            if t <= 80 {
                // bytes arrive: not stale; the sample gets old but stays within max_age
                assert_eq!(h, Health::Ok, "t={t}");
            } else if t <= 160 {
                assert_eq!(h, Health::Ok);
                assert!(matches!(
                    s.sample_at(ms(t)),
                    Err(RobotiqError::Stale { .. })
                ));
            } else {
                assert_eq!(h, Health::Lost, "t={t}");
            }
        }
    }

    #[test]
    fn crc_failures_make_the_link_corrupt_until_the_window_clears() {
        let cfg = LinkConfig::default();
        let mut s = LinkState::new(cfg, ms(0));
        let mut t = 0;
        for i in 0..20 {
            t += 10;
            let mut f = frame(i);
            if i % 2 == 0 {
                f[4] ^= 0x80;
            }
            s.on_bytes(&f, ms(t));
        }
        assert_eq!(s.observe(ms(t)), Health::Corrupt);
        assert!(matches!(
            s.sample_at(ms(t)),
            Err(RobotiqError::Corrupt { errors: 10, .. })
        ));
        for i in 0..32 {
            t += 10;
            s.on_bytes(&frame(i), ms(t));
        }
        assert_eq!(s.observe(ms(t)), Health::Ok);
        assert_eq!(s.counters().corrupt_events, 1);
        assert_eq!(s.counters().crc_errors, 10);
    }

    #[test]
    fn bias_is_removed() {
        let mut s = LinkState::new(LinkConfig::default(), ms(0));
        s.on_bytes(&frame(250), ms(1));
        s.set_bias(Wrench::from_array([0.0, 0.0, 2.0, 0.0, 0.0, 0.0]));
        let w = s.sample_at(ms(2)).unwrap().wrench;
        assert!((w.force.z - 0.5).abs() < 1e-12);
    }

    #[test]
    fn config_is_checked() {
        assert!(LinkConfig::default().validate().is_ok());
        let bad = LinkConfig {
            crc_window: 65,
            ..LinkConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
