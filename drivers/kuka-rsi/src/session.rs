//! [`RsiSession`]: everything the PC side of RSI decides, without I/O.
//!
//! Datagrams go in with the address they came from and the time they were received; cycles come
//! out. A correction goes in; the bytes of the reply and its destination come out, written into the
//! caller's buffer. Session tracking (IPOC, new sessions, stale or duplicate datagrams, the backlog's
//! newest datagram), the robot's plausibility, the watchdog, correction shaping and the late-reply
//! accounting all live here and read no clock: the caller passes the time. [`crate::RsiLink`] is the
//! thin socket shell around it; tests drive it on a virtual clock.
//!
//! One round, as the shell does it:
//! 1. [`RsiSession::wait_budget`] before blocking: how long the shell may wait (the watchdog), or
//!    [`LinkError::LinkLost`].
//! 2. [`RsiSession::offer`] for every datagram read (a burst: all of them, oldest first), then
//!    [`RsiSession::take_cycle`] for the newest good one. ([`RsiSession::receive`] does both for one.)
//! 3. [`RsiSession::reply`] writes `<Sen>`; the shell sends it to [`Outgoing::to`] and reports the
//!    time with [`RsiSession::sent`] (or [`RsiSession::send_failed`]).

use core::fmt;
use core::time::Duration;
use std::net::SocketAddr;
use std::time::Instant;

use hal::{Correction, Cycle, ErrorKind, Pose};

use crate::codec::{Frame, Ipoc, Schema};
use crate::diag::Diagnostics;
use crate::limits::{Shaper, split};
use crate::link::{CorrectionMode, LinkConfig, LinkError, RobotFilter};
use crate::process::{CommandSlots, StateSlots};
use crate::wire;
use crate::xml::ParseError;

/// Why a datagram gave no cycle. Each is counted in [`Diagnostics::counters`]; none ends the session.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Rejected {
    /// From a source the [`RobotFilter`] does not accept.
    Foreign,
    /// Larger than `max_datagram` (or truncated by the shell's buffer).
    Oversized,
    /// Not a `<Rob>` of this config (the parse error says where).
    Malformed(ParseError),
    /// An IPOC at or before the last one of the session: a duplicate or a reordered datagram.
    Stale {
        /// Its IPOC.
        ipoc: u64,
        /// The session's last IPOC.
        last: u64,
    },
    /// The session was stopped (`Stop` sent); nothing more is accepted.
    Stopped,
}

impl fmt::Display for Rejected {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Foreign => f.write_str("datagram from a source other than the robot"),
            Self::Oversized => f.write_str("datagram larger than max_datagram"),
            Self::Malformed(e) => write!(f, "malformed <Rob>: {e}"),
            Self::Stale { ipoc, last } => write!(
                f,
                "stale <Rob>: IPOC {ipoc} is not after the session's last {last} (duplicate or reordered)"
            ),
            Self::Stopped => f.write_str("the session was stopped"),
        }
    }
}

impl std::error::Error for Rejected {}

impl hal::Error for Rejected {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Malformed(_) | Self::Oversized => ErrorKind::Malformed,
            Self::Stale { .. } => ErrorKind::Stale,
            Self::Foreign | Self::Stopped => ErrorKind::Other,
        }
    }
}

/// Where a reply goes and how long it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Outgoing {
    /// Bytes written at the start of the caller's buffer.
    pub len: usize,
    /// The source of the datagram being answered.
    pub to: SocketAddr,
}

struct RobSlots {
    rist: [usize; 6],
    rsol: [usize; 6],
    delay: Option<usize>,
    process: Option<CommandSlots>,
}

struct SenSlots {
    rkorr: [Option<usize>; 6],
    stop: Option<usize>,
    process: Option<StateSlots>,
}

struct Track {
    ipoc0: u64,
    last_ipoc: u64,
    last_rx: Instant,
    peer: SocketAddr,
    /// The last plausible `RIst` and `RSol` positions (m) and their IPOC.
    plausible: Option<([hal::Vector3<f64>; 2], u64)>,
}

#[derive(Clone, Copy)]
struct Accepted {
    cycle: Cycle,
    ipoc: Ipoc,
    peer: SocketAddr,
    rx_at: Instant,
}

/// The PC side of one RSI link without I/O; see the [module docs](self).
pub struct RsiSession {
    cfg: LinkConfig,
    rob: Schema,
    sen: Schema,
    rob_slots: RobSlots,
    sen_slots: SenSlots,
    rx_frame: Box<Frame>,
    tx_frame: Box<Frame>,
    track: Option<Track>,
    /// The newest good datagram not yet handed out as a cycle.
    candidate: Option<Accepted>,
    /// The cycle handed out and not yet answered.
    pending: Option<Accepted>,
    /// Receive time of the reply just written, until the shell says it left.
    in_flight: Option<Instant>,
    shaper: Shaper,
    last_wire: [f64; 6],
    stopped: bool,
    diag: Diagnostics,
}

impl fmt::Debug for RsiSession {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("RsiSession")
            .field("robot", &self.cfg.robot)
            .field("in_session", &self.track.is_some())
            .field("counters", &self.diag.counters)
            .finish()
    }
}

impl RsiSession {
    /// Check the configuration and derive both schemas and the process channels.
    pub fn new(cfg: LinkConfig) -> Result<Self, LinkError> {
        cfg.validate().map_err(LinkError::Config)?;
        let rob = cfg
            .ethernet
            .rob_schema(cfg.precision)
            .map_err(|e| LinkError::Config(e.to_string()))?;
        let mut sen = cfg
            .ethernet
            .sen_schema(cfg.precision)
            .map_err(|e| LinkError::Config(e.to_string()))?;
        let pose = ["X", "Y", "Z", "A", "B", "C"];
        let need = |tag: &str| {
            rob.six(tag, pose).ok_or_else(|| {
                LinkError::Config(format!(
                    "the robot must send DEF_{tag} (add it to the SEND section)"
                ))
            })
        };
        let rob_slots = RobSlots {
            rist: need("RIst")?,
            rsol: need("RSol")?,
            delay: rob.slot("Delay", "D"),
            process: CommandSlots::find(&rob).map_err(LinkError::Config)?,
        };
        let sen_slots = SenSlots {
            rkorr: pose.map(|a| sen.slot("RKorr", a)),
            stop: sen.slot("Stop", ""),
            process: StateSlots::find(&mut sen).map_err(LinkError::Config)?,
        };
        let shaper = Shaper::new(cfg.limits, sen_slots.rkorr.map(|s| s.is_some()));
        Ok(Self {
            rob,
            sen,
            rob_slots,
            sen_slots,
            rx_frame: Box::default(),
            tx_frame: Box::default(),
            track: None,
            candidate: None,
            pending: None,
            in_flight: None,
            shaper,
            last_wire: [0.0; 6],
            stopped: false,
            diag: Diagnostics::default(),
            cfg,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &LinkConfig {
        &self.cfg
    }

    /// Counters and the latency distribution.
    pub fn diagnostics(&self) -> &Diagnostics {
        &self.diag
    }

    /// Change whose datagrams are accepted.
    pub fn set_robot_filter(&mut self, robot: RobotFilter) {
        self.cfg.robot = robot;
    }

    /// True after a stop was written.
    pub fn is_stopped(&self) -> bool {
        self.stopped
    }

    /// True while a robot session is running (first good datagram seen, watchdog not fired).
    pub fn in_session(&self) -> bool {
        self.track.is_some()
    }

    /// The `<Rob>` schema in use.
    pub fn rob_schema(&self) -> &Schema {
        &self.rob
    }

    /// The `<Sen>` schema in use.
    pub fn sen_schema(&self) -> &Schema {
        &self.sen
    }

    /// True when the config declares the robot program's `FcCmd`: every cycle carries `process`.
    pub fn has_process_command(&self) -> bool {
        self.rob_slots.process.is_some()
    }

    /// True when the config declares `FcState`: every reply carries the correction's `process`.
    pub fn has_process_state(&self) -> bool {
        self.sen_slots.process.is_some()
    }

    /// Call before waiting for the next cycle: an unanswered cycle is counted and forgotten, and the
    /// watchdog is judged at `now`. Returns how long the caller may wait for a datagram (`None`: no
    /// session yet, wait as long as the caller likes), or [`LinkError::LinkLost`] when the robot has
    /// been silent for `watchdog_cycles` periods (the session ends; the next datagram starts a new one).
    pub fn wait_budget(&mut self, now: Instant) -> Result<Option<Duration>, LinkError> {
        if self.pending.take().is_some() {
            self.diag.counters.unanswered += 1;
        }
        let watchdog = self.cfg.period * self.cfg.watchdog_cycles;
        let Some(t) = &self.track else {
            return Ok(None);
        };
        let silent = now.saturating_duration_since(t.last_rx);
        if silent >= watchdog {
            self.track = None;
            self.candidate = None;
            return Err(LinkError::LinkLost { silent_for: silent });
        }
        // A full watchdog while nothing ate into it: the value stays the same cycle after cycle, so
        // the shell need not change its socket timeout (no system call in the steady state).
        Ok(Some(if silent < self.cfg.period {
            watchdog
        } else {
            watchdog - silent
        }))
    }

    /// Judge one datagram received from `from` at `rx_at`. A good, current `<Rob>` becomes the
    /// candidate for the next cycle; a candidate it supersedes (a backlog) counts as skipped.
    /// `datagram` must be what the socket delivered, up to `max_datagram + 1` bytes (a longer one is
    /// oversized, whether or not the shell's buffer truncated it).
    pub fn offer(
        &mut self,
        datagram: &[u8],
        from: SocketAddr,
        rx_at: Instant,
    ) -> Result<(), Rejected> {
        if self.stopped {
            return Err(Rejected::Stopped);
        }
        let mut a = self.accept(datagram, from, rx_at)?;
        if let Some(old) = self.candidate.take() {
            self.diag.counters.skipped += 1;
            a.cycle.new_session |= old.cycle.new_session;
        }
        self.candidate = Some(a);
        Ok(())
    }

    /// The newest good datagram offered since the last call, as the cycle to answer next.
    pub fn take_cycle(&mut self) -> Option<Cycle> {
        let a = self.candidate.take()?;
        if self.pending.replace(a).is_some() {
            self.diag.counters.unanswered += 1;
        }
        Some(a.cycle)
    }

    /// [`offer`](Self::offer) one datagram and [`take_cycle`](Self::take_cycle) it.
    pub fn receive(
        &mut self,
        datagram: &[u8],
        from: SocketAddr,
        rx_at: Instant,
    ) -> Result<Cycle, Rejected> {
        self.offer(datagram, from, rx_at)?;
        Ok(self.take_cycle().expect("offer left a candidate"))
    }

    fn allowed(&self, from: SocketAddr) -> bool {
        match self.cfg.robot {
            RobotFilter::Exact(a) => from == a,
            RobotFilter::Ip(ip) => from.ip() == ip,
            RobotFilter::Any => self.track.as_ref().is_none_or(|s| s.peer == from),
        }
    }

    fn accept(
        &mut self,
        datagram: &[u8],
        from: SocketAddr,
        rx_at: Instant,
    ) -> Result<Accepted, Rejected> {
        let allowed = self.allowed(from);
        let c = &mut self.diag.counters;
        c.received += 1;
        if !allowed {
            c.foreign += 1;
            return Err(Rejected::Foreign);
        }
        if datagram.len() > self.cfg.max_datagram {
            c.oversized += 1;
            return Err(Rejected::Oversized);
        }
        if let Err(e) = self.rob.parse(datagram, &mut self.rx_frame) {
            c.malformed += 1;
            self.diag.last_malformed = Some(e);
            return Err(Rejected::Malformed(e));
        }
        let ipoc = *self.rx_frame.ipoc();
        let v = ipoc.value();
        let jump = self.cfg.session_jump;
        let new_session = match &self.track {
            None => true,
            Some(s) if v > s.last_ipoc.saturating_add(jump) => true,
            Some(s) if v.saturating_add(jump) < s.last_ipoc => true,
            Some(s) if v <= s.last_ipoc => {
                c.stale += 1;
                return Err(Rejected::Stale {
                    ipoc: v,
                    last: s.last_ipoc,
                });
            }
            Some(_) => false,
        };
        if new_session {
            c.sessions += 1;
            self.track = Some(Track {
                ipoc0: v,
                last_ipoc: v,
                last_rx: rx_at,
                peer: from,
                plausible: None,
            });
            // A new RSI_ON starts the robot's relative total from zero; the rate limit starts from the
            // correction the robot reports in effect (set below, once the poses are decoded).
            self.last_wire = [0.0; 6];
        }
        let Some(s) = self.track.as_mut() else {
            unreachable!("a session was just found or started");
        };
        s.last_ipoc = v;
        s.last_rx = rx_at;
        s.peer = from;
        let f = &self.rx_frame;
        let delay = self
            .rob_slots
            .delay
            .map_or(0, |d| f.get(d).clamp(0.0, u32::MAX as f64) as u32);
        self.diag.robot_delay = delay;
        if delay > 0 {
            c.delay_alarms += 1;
        }
        let mut cycle = Cycle {
            seq: v,
            t: (v - s.ipoc0) as f64 * self.cfg.ipoc_unit,
            period: self.cfg.period.as_secs_f64(),
            actual: wire::pose_from_wire(f.get6(self.rob_slots.rist)),
            programmed: wire::pose_from_wire(f.get6(self.rob_slots.rsol)),
            late_replies: delay,
            new_session,
            process: self.rob_slots.process.map(|p| p.decode(f)),
        };
        // The one plausibility check of the robot's poses: a jump no arm makes in the IPOC time since
        // the last plausible pose is a counted fault. The cycle is still delivered (it must be answered,
        // with the last command) but its poses are marked unusable, so no controller acts on them.
        let now = [cycle.actual.position, cycle.programmed.position];
        if now.iter().all(|p| p.iter().all(|v| v.is_finite())) {
            let plausible = match s.plausible {
                Some((last, at)) => {
                    let dt = v.saturating_sub(at) as f64 * self.cfg.ipoc_unit;
                    // 0.1 mm slack: the wire's decimals and the robot's own jitter.
                    let reach = self.cfg.max_speed * dt + 1e-4;
                    now.iter().zip(&last).all(|(p, q)| (p - q).norm() <= reach)
                }
                None => true,
            };
            if plausible {
                s.plausible = Some((now, v));
            } else {
                c.implausible += 1;
                cycle.actual = unusable();
                cycle.programmed = unusable();
            }
        }
        if new_session {
            let t = cycle.tool_offset();
            let r =
                (cycle.programmed.orientation.inverse() * cycle.actual.orientation).scaled_axis();
            self.shaper.reset_to([t.x, t.y, t.z, r.x, r.y, r.z]);
        }
        Ok(Accepted {
            cycle,
            ipoc,
            peer: from,
            rx_at,
        })
    }

    /// Answer the cycle last taken: shape the correction (non-finite → hold; envelope; rate), convert
    /// it to mm/deg (and to an increment in relative mode), and write `<Sen>` with the cycle's IPOC —
    /// and `FcState` from `correction.process` when the config declares it — into `out`.
    /// `Ok(None)`: the config says ONLYSEND, nothing to send. Errors: [`LinkError::NoCycle`] (no cycle
    /// taken, or answered already), [`LinkError::NoStopElement`], [`LinkError::Stopped`].
    pub fn reply(
        &mut self,
        correction: &Correction,
        out: &mut [u8],
    ) -> Result<Option<Outgoing>, LinkError> {
        if self.stopped {
            return Err(LinkError::Stopped);
        }
        if correction.stop && self.sen_slots.stop.is_none() {
            return Err(LinkError::NoStopElement);
        }
        let p = self.pending.take().ok_or(LinkError::NoCycle)?;
        let total = self.shaper.shape(correction, &mut self.diag.counters);
        let (t, r) = split(total);
        let wire_total = wire::offset_to_wire(&t, &r);
        let values = match self.cfg.mode {
            CorrectionMode::Absolute => wire_total,
            CorrectionMode::Relative => core::array::from_fn(|i| wire_total[i] - self.last_wire[i]),
        };
        self.last_wire = wire_total;
        if self.cfg.ethernet.onlysend {
            self.diag.counters.suppressed += 1;
            self.stopped |= correction.stop;
            return Ok(None);
        }
        for (slot, v) in self.sen_slots.rkorr.iter().zip(values) {
            if let Some(s) = *slot {
                self.tx_frame.set(s, v);
            }
        }
        if let Some(s) = self.sen_slots.stop {
            self.tx_frame
                .set(s, if correction.stop { 1.0 } else { 0.0 });
        }
        if let Some(ps) = self.sen_slots.process {
            ps.encode(&correction.process, &mut self.tx_frame);
        }
        self.tx_frame.set_ipoc(p.ipoc);
        let len = self
            .sen
            .write(&self.tx_frame, out)
            .map_err(LinkError::Encode)?;
        self.stopped |= correction.stop;
        self.in_flight = Some(p.rx_at);
        Ok(Some(Outgoing { len, to: p.peer }))
    }

    /// The reply written last left at `now`: its receive→send turnaround is recorded (late above
    /// `late_after`).
    pub fn sent(&mut self, now: Instant) {
        let Some(rx_at) = self.in_flight.take() else {
            return;
        };
        let turnaround = now.saturating_duration_since(rx_at);
        self.diag.latency.record(turnaround);
        let c = &mut self.diag.counters;
        c.answered += 1;
        if turnaround > self.cfg.late_after {
            c.late += 1;
        }
    }

    /// The reply written last could not be sent.
    pub fn send_failed(&mut self) {
        self.in_flight = None;
        self.diag.counters.send_errors += 1;
    }
}

/// A pose no controller can use (every component NaN).
fn unusable() -> Pose {
    Pose {
        position: hal::Vector3::repeat(f64::NAN),
        orientation: hal::UnitQuaternion::from_euler_angles(f64::NAN, f64::NAN, f64::NAN),
    }
}
