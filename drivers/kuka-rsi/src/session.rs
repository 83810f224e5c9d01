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
//! 2. [`RsiSession::offer_arrived`] for every datagram read (a burst: all of them, oldest first), with
//!    the kernel's arrival stamp when it has one (what late replies are measured from), then
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
use crate::layout::Layout;
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

impl RobSlots {
    /// Every slot the session reads from a `<Rob>` (bit `slot` set).
    fn read_mask(&self) -> u128 {
        let six = |s: &[usize; 6]| s.iter().fold(0u128, |m, &k| m | 1u128 << k);
        six(&self.rist)
            | six(&self.rsol)
            | self.delay.map_or(0, |d| 1u128 << d)
            | self.process.map_or(0, |p| p.mask())
    }
}

struct Track {
    last_ipoc: u64,
    last_rx: Instant,
    /// When the last datagram arrived (its kernel stamp; else when it was read).
    last_arrival: Instant,
    peer: SocketAddr,
    /// The last plausible `RIst` and `RSol` positions (m) and their IPOC.
    plausible: Option<([hal::Vector3<f64>; 2], u64)>,
    /// Cycles of this session so far.
    n: u32,
    /// Seconds per IPOC count, and the robot time and IPOC it counts from.
    unit: f64,
    t_base: f64,
    v_base: u64,
    /// Smallest IPOC step seen, most decimals seen in RIst X Y Z, the first RIst X Y Z (mm), and
    /// whether they changed since.
    min_step: u64,
    decimals: u8,
    first_xyz: [f64; 3],
    moved: bool,
}

#[derive(Clone, Copy)]
struct Accepted {
    cycle: Cycle,
    ipoc: Ipoc,
    peer: SocketAddr,
    rx_at: Instant,
    /// When the datagram arrived (the kernel's receive stamp), when the shell knows it.
    arrived: Option<Instant>,
}

#[derive(Clone, Copy)]
struct InFlight {
    rx_at: Instant,
    arrived: Option<Instant>,
    stop: bool,
    handed: Option<Instant>,
}

/// The PC side of one RSI link without I/O; see the [module docs](self).
pub struct RsiSession {
    cfg: LinkConfig,
    rob: Schema,
    /// The robot's `<Rob>` layout, learnt from its last well-formed message (read faster).
    rob_layout: Box<Layout>,
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
    /// The datagram's receive time and arrival (when known) of the reply just written, whether it
    /// carries `Stop`, and when the shell handed it to the socket, until the shell says it left (or
    /// failed).
    in_flight: Option<InFlight>,
    shaper: Shaper,
    last_wire: [f64; 6],
    /// The last orientations converted (`RIst`, `RSol`, the correction's rotation).
    memo: Memos,
    stopped: bool,
    diag: Diagnostics,
    /// Datagrams rejected while waiting for the robot, for the rate-limited report.
    rejects: crate::diag::RejectLog,
}

/// The session's kept orientation conversions ([`wire::Memo`]).
#[derive(Clone, Copy, Debug, Default)]
struct Memos {
    actual: wire::Memo<hal::UnitQuaternion<f64>>,
    programmed: wire::Memo<hal::UnitQuaternion<f64>>,
    correction: wire::Memo<[f64; 3]>,
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
            // Only the values the session reads are converted; the others (the axis positions
            // AIPos and ASPos of forcecell's config, a user's extra SEND channels) are checked.
            rob_layout: Box::new(Layout::reading(cfg.max_datagram, rob_slots.read_mask())),
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
            memo: Memos::default(),
            stopped: false,
            diag: Diagnostics::default(),
            rejects: crate::diag::RejectLog::new(crate::diag::REJECT_REPORT_INTERVAL),
            cfg,
        })
    }

    /// The lines due at `now` (host time) about the datagrams rejected while no robot session has
    /// started: one per class of rejection at most once per [`REJECT_REPORT_INTERVAL`], naming the
    /// sender and the reason ("from 10.0.0.5, expected 192.168.1.10"; "malformed: no complete
    /// `<RSol>`, which the Ethernet config lists").
    ///
    /// [`REJECT_REPORT_INTERVAL`]: crate::diag::REJECT_REPORT_INTERVAL
    pub fn rejection_lines(&mut self, now: Instant) -> Vec<String> {
        let mut lines = Vec::new();
        let (rob, cfg) = (&self.rob, &self.cfg);
        self.rejects.due(now, |d| {
            let reason = match d.why {
                Rejected::Foreign => match cfg.robot {
                    RobotFilter::Ip(ip) => format!("from {}, expected {ip}", d.from.ip()),
                    RobotFilter::Exact(a) => format!("from {}, expected {a}", d.from),
                    RobotFilter::Any => format!(
                        "from {}, not the robot whose session this link follows",
                        d.from
                    ),
                },
                Rejected::Oversized => format!(
                    "oversized: {} bytes or more, above max_datagram {}",
                    d.len, cfg.max_datagram
                ),
                Rejected::Malformed(ParseError::MissingElement { element }) => format!(
                    "malformed: no complete <{}>, which the Ethernet config lists",
                    rob.element_name(element).unwrap_or("?")
                ),
                Rejected::Malformed(e) => format!("malformed: {e}"),
                other => other.to_string(),
            };
            lines.push(format!(
                "waiting for the robot: {} datagram{} from {} dropped: {reason}",
                d.count,
                if d.count == 1 { "" } else { "s" },
                d.from
            ));
        });
        lines
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
        self.offer_arrived(datagram, from, rx_at, None)
    }

    /// [`offer`](Self::offer) a datagram that `arrived` at the socket before it was read at `rx_at`
    /// (the kernel's receive stamp on the caller's clock; `None` when the kernel gave none). A reply's
    /// lateness is measured from its datagram's arrival; without one, from `rx_at` (counted as
    /// `unstamped`). An arrival after `rx_at` (a clock step) is taken as `rx_at`.
    pub fn offer_arrived(
        &mut self,
        datagram: &[u8],
        from: SocketAddr,
        rx_at: Instant,
        arrived: Option<Instant>,
    ) -> Result<(), Rejected> {
        if self.stopped {
            return Err(Rejected::Stopped);
        }
        let waiting = self.track.is_none();
        let mut a = self.accept(datagram, from, rx_at).inspect_err(|&r| {
            let class = match r {
                Rejected::Foreign => Some(crate::diag::RejectClass::Foreign),
                Rejected::Oversized => Some(crate::diag::RejectClass::Oversized),
                Rejected::Malformed(_) => Some(crate::diag::RejectClass::Malformed),
                Rejected::Stale { .. } => Some(crate::diag::RejectClass::Stale),
                Rejected::Stopped => None,
            };
            if let (true, Some(c)) = (waiting, class) {
                self.rejects.note(c, from, r, datagram.len());
            }
        })?;
        a.arrived = arrived.map(|t| t.min(rx_at));
        if let Some(t) = self.track.as_mut() {
            t.last_arrival = a.arrived.unwrap_or(rx_at);
        }
        if let Some(old) = self.candidate.take() {
            self.diag.counters.skipped += 1;
            a.cycle.new_session |= old.cycle.new_session;
        }
        self.candidate = Some(a);
        Ok(())
    }

    /// When the robot's next datagram is due: one period after the last one arrived (`None`: no
    /// session).
    pub fn next_due(&self) -> Option<Instant> {
        self.track
            .as_ref()
            .map(|t| t.last_arrival + self.cfg.period)
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
        if let Err(e) = self
            .rob_layout
            .parse(&self.rob, datagram, &mut self.rx_frame)
        {
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
                last_ipoc: v,
                last_rx: rx_at,
                last_arrival: rx_at,
                peer: from,
                plausible: None,
                n: 0,
                unit: self.cfg.ipoc_unit,
                t_base: 0.0,
                v_base: v,
                min_step: u64::MAX,
                decimals: 0,
                first_xyz: [0.0; 3],
                moved: false,
            });
            self.diag.measured = crate::diag::Measured::default();
            // A new RSI_ON starts the robot's relative total from zero; the rate limit starts from the
            // correction the robot reports in effect (set below, once the poses are decoded).
            self.last_wire = [0.0; 6];
        }
        let Some(s) = self.track.as_mut() else {
            unreachable!("a session was just found or started");
        };
        if !new_session {
            // Robot cycles between this IPOC and the last one that never arrived, in whole cycles of
            // the IPOC unit in effect (the measured one, once the first cycles adopted it).
            let ticks = (self.cfg.period.as_secs_f64() / s.unit).round();
            let ticks = if ticks >= 1.0 { ticks as u64 } else { 1 };
            c.missed += ((v - s.last_ipoc) / ticks).saturating_sub(1);
        }
        // The first cycles: the IPOC step and the positions' decimals (sans-IO detectors; the
        // application prints `Diagnostics::advisories`).
        let f = &self.rx_frame;
        if s.n < crate::diag::PROBE_CYCLES {
            let xyz = [0, 1, 2].map(|k| f.get(self.rob_slots.rist[k]));
            if s.n == 0 {
                s.first_xyz = xyz;
            } else {
                s.min_step = s.min_step.min(v - s.last_ipoc);
            }
            s.moved |= xyz != s.first_xyz;
            for x in xyz {
                s.decimals = s.decimals.max(crate::diag::decimals_of(x));
            }
            s.n += 1;
            if s.n == crate::diag::PROBE_CYCLES {
                let m = &mut self.diag.measured;
                if s.moved {
                    m.position_resolution = Some(10f64.powi(-i32::from(s.decimals)) * 1e-3);
                }
                if s.min_step != u64::MAX {
                    m.ipoc_step = Some(s.min_step);
                    // A step that disagrees with the period by more than half: the robot side counts
                    // in other units. Its step is adopted as one cycle, from here on (robot time
                    // stays continuous).
                    let period = self.cfg.period.as_secs_f64();
                    let stepped = s.min_step as f64 * s.unit;
                    if !(0.5 * period..=1.5 * period).contains(&stepped) {
                        s.t_base += (s.last_ipoc - s.v_base) as f64 * s.unit;
                        s.v_base = s.last_ipoc;
                        s.unit = period / s.min_step as f64;
                    }
                    m.ipoc_unit = Some(s.unit);
                }
            }
        }
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
            t: s.t_base + (v - s.v_base) as f64 * s.unit,
            period: self.cfg.period.as_secs_f64(),
            actual: wire::pose_from_wire_with(f.get6(self.rob_slots.rist), &mut self.memo.actual),
            programmed: wire::pose_from_wire_with(
                f.get6(self.rob_slots.rsol),
                &mut self.memo.programmed,
            ),
            late_replies: delay,
            missed: c.missed,
            replied_late: c.late,
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
                    let dt = v.saturating_sub(at) as f64 * s.unit;
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
            arrived: None,
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
        let wire_total = wire::offset_to_wire_with(&t, &r, &mut self.memo.correction);
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
        self.in_flight = Some(InFlight {
            rx_at: p.rx_at,
            arrived: p.arrived,
            stop: correction.stop,
            handed: None,
        });
        Ok(Some(Outgoing { len, to: p.peer }))
    }

    /// The shell hands the reply written last to the socket at `now` (optional: it splits the
    /// turnaround [`sent`](Self::sent) records into the time before the send call and the call).
    pub fn sending(&mut self, now: Instant) {
        if let Some(f) = &mut self.in_flight {
            f.handed = Some(now);
        }
    }

    /// The reply written last left at `now`: its receive→send turnaround is recorded, and the part
    /// of it before the send call when the shell said ([`sending`](Self::sending)); its
    /// arrival→send time too, late above `late_after` (from the receive time where the arrival is
    /// unknown: counted `unstamped`). A reply carrying `Stop` finishes the session.
    pub fn sent(&mut self, now: Instant) {
        let Some(f) = self.in_flight.take() else {
            return;
        };
        self.stopped |= f.stop;
        self.diag
            .latency
            .record(now.saturating_duration_since(f.rx_at));
        if let Some(h) = f.handed {
            self.diag
                .before_send
                .record(h.saturating_duration_since(f.rx_at));
        }
        let since_arrival = now.saturating_duration_since(f.arrived.unwrap_or(f.rx_at));
        self.diag.from_arrival.record(since_arrival);
        let c = &mut self.diag.counters;
        c.answered += 1;
        if f.arrived.is_none() {
            c.unstamped += 1;
        }
        if since_arrival > self.cfg.late_after {
            c.late += 1;
        }
    }

    /// The reply written last could not be sent (a `Stop` in it did not finish the session: the
    /// next cycle can carry it again).
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

#[cfg(test)]
mod tests {
    //! The session on a virtual clock: no sockets, no sleeps.
    use super::*;
    use crate::config::EthernetConfig;
    use crate::process::ProcessChannels;
    use hal::{ProcessCommand, ProcessFault, ProcessMode, ProcessPhase, ProcessState};

    const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];

    fn robot() -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], 40_000))
    }

    fn session(process: bool) -> RsiSession {
        let mut eth = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false);
        if process {
            eth = eth.with_process(ProcessChannels::default());
        }
        RsiSession::new(LinkConfig::new(eth, RobotFilter::Ip(robot().ip()))).unwrap()
    }

    /// A `<Rob>` as the robot writes it: pose `z` mm, the given command.
    fn rob(s: &RsiSession, ipoc: u64, z: f64, cmd: Option<ProcessCommand>) -> Vec<u8> {
        let schema = s.rob_schema();
        let mut f = Frame::new();
        f.set6(
            schema.six("RIst", POSE).unwrap(),
            [500.0, 0.0, z, 0.0, 0.0, 180.0],
        );
        f.set6(
            schema.six("RSol", POSE).unwrap(),
            [500.0, 0.0, z, 0.0, 0.0, 180.0],
        );
        for a in ["A1", "A2", "A3", "A4", "A5", "A6"] {
            for t in ["AIPos", "ASPos"] {
                f.set(schema.slot(t, a).unwrap(), 0.0);
            }
        }
        f.set(schema.slot("Delay", "D").unwrap(), 0.0);
        if let Some(c) = cmd {
            CommandSlots::find(schema)
                .unwrap()
                .unwrap()
                .encode(&c, &mut f);
        }
        f.set_ipoc(Ipoc::new(ipoc));
        let mut buf = [0u8; 2048];
        let n = schema.write(&f, &mut buf).unwrap();
        buf[..n].to_vec()
    }

    fn press(seg: i64) -> ProcessCommand {
        ProcessCommand {
            mode: ProcessMode::Press,
            force: 20.0,
            ramp: 0.5,
            segment: seg,
        }
    }

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// A robot side that steps the IPOC by 1 per 4 ms cycle and sends positions at 0.1 mm: both are
    /// measured in the first cycles; the step is adopted as one cycle from then on, robot time
    /// staying continuous.
    #[test]
    fn the_first_cycles_measure_the_ipoc_step_and_the_position_resolution() {
        let mut s = session(false);
        let t0 = Instant::now();
        let mut ts = Vec::new();
        for k in 0..60u64 {
            let d = rob(&s, 7000 + k, 300.0 + 0.1 * k as f64, None);
            ts.push(s.receive(&d, robot(), t0 + ms(4 * k)).unwrap().t);
        }
        let m = s.diagnostics().measured;
        assert_eq!(m.ipoc_step, Some(1));
        assert_eq!(m.ipoc_unit, Some(0.004));
        let q = m.position_resolution.unwrap();
        assert!((q - 1e-4).abs() < 1e-12, "{q}");
        // Before the judgement 1 ms a cycle (the configured unit), after it 4 ms, never a jump back.
        assert!((ts[1] - 0.001).abs() < 1e-12);
        assert!(ts.windows(2).all(|w| w[1] > w[0]));
        assert!((ts[59] - ts[58] - 0.004).abs() < 1e-12, "{ts:?}");
        let a = s.diagnostics().advisories(0.004, 70e3);
        assert_eq!(a.len(), 2, "{a:?}");
        // A robot that counts milliseconds and sends 4 decimals: nothing measured is wrong.
        let mut s = session(false);
        for k in 0..60u64 {
            let d = rob(&s, 9000 + 4 * k, 300.0 + 0.0123 * k as f64, None);
            s.receive(&d, robot(), t0 + ms(4 * k)).unwrap();
        }
        let m = s.diagnostics().measured;
        assert_eq!((m.ipoc_step, m.ipoc_unit), (Some(4), Some(0.001)));
        assert!(s.diagnostics().advisories(0.004, 70e3).is_empty());
    }

    #[test]
    fn first_cycle_starts_a_session_and_carries_the_command() {
        let mut s = session(true);
        let t0 = Instant::now();
        assert_eq!(s.wait_budget(t0).unwrap(), None, "no session: wait freely");
        let d = rob(&s, 1000, 300.0, Some(press(3)));
        let c = s.receive(&d, robot(), t0).unwrap();
        assert!(c.new_session);
        assert_eq!((c.seq, c.t), (1000, 0.0));
        assert_eq!(c.process, Some(press(3)));
        assert!((c.actual.position.z - 0.3).abs() < 1e-12, "SI inside");
        assert_eq!(s.diagnostics().counters.sessions, 1);
        let d = rob(&s, 1004, 300.0, Some(press(4)));
        let c = s.receive(&d, robot(), t0 + ms(4)).unwrap();
        assert!(!c.new_session);
        assert!((c.t - 0.004).abs() < 1e-12);
        assert_eq!(c.process.unwrap().segment, 4);
    }

    #[test]
    fn without_fc_cmd_the_cycle_has_no_process() {
        let mut s = session(false);
        let d = rob(&s, 1000, 300.0, None);
        let c = s.receive(&d, robot(), Instant::now()).unwrap();
        assert_eq!(c.process, None);
        assert!(!s.has_process_command() && !s.has_process_state());
    }

    #[test]
    fn ipoc_jump_or_reset_starts_a_new_session() {
        let mut s = session(true);
        let t0 = Instant::now();
        let cmd = Some(press(1));
        assert!(
            s.receive(&rob(&s, 1000, 300.0, cmd), robot(), t0)
                .unwrap()
                .new_session
        );
        // Forward by more than session_jump (1000 IPOC units).
        let c = s
            .receive(&rob(&s, 5000, 300.0, cmd), robot(), t0 + ms(4))
            .unwrap();
        assert!(c.new_session);
        assert_eq!(c.t, 0.0, "robot time restarts");
        // Back to a small IPOC: RSI_OFF .. RSI_ON with a reset counter.
        let c = s
            .receive(&rob(&s, 10, 300.0, cmd), robot(), t0 + ms(8))
            .unwrap();
        assert!(c.new_session);
        assert_eq!(s.diagnostics().counters.sessions, 3);
    }

    #[test]
    fn stale_and_duplicate_ipocs_are_rejected_and_counted() {
        let mut s = session(true);
        let t0 = Instant::now();
        let cmd = Some(press(1));
        s.receive(&rob(&s, 1000, 300.0, cmd), robot(), t0).unwrap();
        s.receive(&rob(&s, 1004, 300.0, cmd), robot(), t0 + ms(4))
            .unwrap();
        let dup = rob(&s, 1004, 300.0, cmd);
        assert_eq!(
            s.receive(&dup, robot(), t0 + ms(5)),
            Err(Rejected::Stale {
                ipoc: 1004,
                last: 1004
            })
        );
        let old = rob(&s, 1000, 300.0, cmd);
        assert!(matches!(
            s.receive(&old, robot(), t0 + ms(6)),
            Err(Rejected::Stale { .. })
        ));
        assert_eq!(s.diagnostics().counters.stale, 2);
        assert_eq!(s.diagnostics().counters.missed, 0, "none lost so far");
        // 1008 and 1012 never arrived: two robot cycles missed (4 ms each, IPOC in ms).
        let after_gap = s
            .receive(&rob(&s, 1016, 300.0, cmd), robot(), t0 + ms(16))
            .unwrap();
        assert_eq!(s.diagnostics().counters.missed, 2);
        assert_eq!(
            after_gap.missed, 2,
            "the cycle carries the count to the loop"
        );
        use hal::Error as _;
        assert_eq!(
            Rejected::Stale { ipoc: 1, last: 2 }.kind(),
            ErrorKind::Stale
        );
    }

    #[test]
    fn an_implausible_pose_is_delivered_unusable_and_counted() {
        let mut s = session(false);
        let t0 = Instant::now();
        s.receive(&rob(&s, 1000, 300.0, None), robot(), t0).unwrap();
        // 100 mm in 4 ms is 25 m/s: no arm under RSI moves like that.
        let c = s
            .receive(&rob(&s, 1004, 400.0, None), robot(), t0 + ms(4))
            .unwrap();
        assert!(!c.actual.is_finite() && !c.programmed.is_finite());
        assert_eq!(s.diagnostics().counters.implausible, 1);
        // It must still be answered.
        let mut out = [0u8; 1024];
        assert!(s.reply(&Correction::default(), &mut out).unwrap().is_some());
        // A pose consistent with the last plausible one is usable again.
        let c = s
            .receive(&rob(&s, 1008, 300.1, None), robot(), t0 + ms(8))
            .unwrap();
        assert!(c.actual.is_finite());
    }

    #[test]
    fn reply_before_a_cycle_and_reply_twice_are_errors() {
        let mut s = session(true);
        let mut out = [0u8; 1024];
        assert!(matches!(
            s.reply(&Correction::default(), &mut out),
            Err(LinkError::NoCycle)
        ));
        let t0 = Instant::now();
        s.receive(&rob(&s, 1000, 300.0, Some(press(1))), robot(), t0)
            .unwrap();
        let o = s
            .reply(&Correction::along_z(1e-5), &mut out)
            .unwrap()
            .unwrap();
        assert_eq!(o.to, robot());
        s.sending(t0 + Duration::from_micros(20));
        s.sent(t0 + Duration::from_micros(50));
        assert!(matches!(
            s.reply(&Correction::default(), &mut out),
            Err(LinkError::NoCycle)
        ));
        let d = s.diagnostics();
        assert_eq!((d.counters.answered, d.counters.late), (1, 0));
        // The turnaround, and its part before the send call.
        assert_eq!(d.latency.max(), Duration::from_micros(50));
        assert_eq!(d.before_send.max(), Duration::from_micros(20));
        assert_eq!(d.before_send.count(), 1);
    }

    #[test]
    fn the_stop_reply_carries_fc_state_and_ends_the_session() {
        let mut s = session(true);
        let t0 = Instant::now();
        s.receive(&rob(&s, 1000, 300.0, Some(press(1))), robot(), t0)
            .unwrap();
        let mut out = [0u8; 1024];
        let stop = Correction {
            stop: true,
            process: ProcessState {
                phase: ProcessPhase::Fault,
                force: 31.456,
                fault: ProcessFault::ForceLimit,
            },
            ..Correction::default()
        };
        let o = s.reply(&stop, &mut out).unwrap().unwrap();
        assert!(!s.is_stopped(), "not before it left");
        s.sent(t0 + Duration::from_micros(30));
        let text = core::str::from_utf8(&out[..o.len]).unwrap();
        assert_eq!(
            text,
            "<Sen Type=\"ImFree\"><RKorr X=\"0.0000\" Y=\"0.0000\" Z=\"0.0000\" A=\"0.0000\" B=\"0.0000\" C=\"0.0000\"/><Stop>1</Stop><FcState State=\"9\" F=\"31.46\" Fault=\"2\"/><IPOC>1000</IPOC></Sen>"
        );
        assert!(s.is_stopped());
        let d = rob(&s, 1004, 300.0, Some(press(1)));
        assert_eq!(s.receive(&d, robot(), t0 + ms(4)), Err(Rejected::Stopped));
        assert!(matches!(
            s.reply(&Correction::default(), &mut out),
            Err(LinkError::Stopped)
        ));
    }

    #[test]
    fn a_stop_that_could_not_be_sent_does_not_finish_the_session() {
        let mut s = session(false);
        let t0 = Instant::now();
        s.receive(&rob(&s, 1000, 300.0, None), robot(), t0).unwrap();
        let mut out = [0u8; 1024];
        let stop = Correction {
            stop: true,
            ..Correction::default()
        };
        s.reply(&stop, &mut out).unwrap().unwrap();
        s.send_failed();
        assert!(!s.is_stopped());
        assert_eq!(s.diagnostics().counters.send_errors, 1);
        s.receive(&rob(&s, 1004, 300.0, None), robot(), t0 + ms(4))
            .unwrap();
        s.reply(&stop, &mut out).unwrap().unwrap();
        s.sent(t0 + ms(4));
        assert!(s.is_stopped());
    }

    #[test]
    fn every_reply_carries_fc_state_and_a_nan_force_is_written_as_zero() {
        let mut s = session(true);
        let t0 = Instant::now();
        s.receive(&rob(&s, 1000, 300.0, Some(press(1))), robot(), t0)
            .unwrap();
        let mut out = [0u8; 1024];
        let c = Correction {
            process: ProcessState {
                phase: ProcessPhase::Approach,
                force: f64::NAN,
                fault: ProcessFault::None,
            },
            ..Correction::default()
        };
        let o = s.reply(&c, &mut out).unwrap().unwrap();
        let text = core::str::from_utf8(&out[..o.len]).unwrap();
        assert!(
            text.contains("<Stop>0</Stop><FcState State=\"1\" F=\"0.00\" Fault=\"0\"/>"),
            "{text}"
        );
    }

    #[test]
    fn a_bad_process_command_is_malformed_never_a_default() {
        let mut s = session(true);
        let t0 = Instant::now();
        let good = String::from_utf8(rob(&s, 1000, 300.0, Some(press(3)))).unwrap();
        for (from, to) in [
            ("Mode=\"1\"", "Mode=\"x\""),
            ("Mode=\"1\"", "Mode=\"1.5\""),
            ("Seg=\"3\"", "Seg=\"\""),
            ("F=\"20.0000\"", "F=\"nan\""),
            ("Ramp=\"0.5000\"", "Ramp=\"1e3\""),
        ] {
            assert!(good.contains(from), "{good}");
            let bad = good.replace(from, to);
            assert!(
                matches!(
                    s.receive(bad.as_bytes(), robot(), t0),
                    Err(Rejected::Malformed(ParseError::BadNumber { .. }))
                ),
                "{to}"
            );
        }
        // The whole element missing although the config declares it.
        let start = good.find("<FcCmd").unwrap();
        let end = start + good[start..].find("/>").unwrap() + 2;
        let bad = format!("{}{}", &good[..start], &good[end..]);
        assert!(matches!(
            s.receive(bad.as_bytes(), robot(), t0),
            Err(Rejected::Malformed(ParseError::MissingElement { .. }))
        ));
        assert_eq!(s.diagnostics().counters.malformed, 6);
        // An undefined mode is delivered as such (the process faults with "bad command").
        let odd = good.replace("Mode=\"1\"", "Mode=\"5\"");
        let c = s.receive(odd.as_bytes(), robot(), t0).unwrap();
        assert_eq!(c.process.unwrap().mode, ProcessMode::Unknown(5));
    }

    #[test]
    fn a_backlog_answers_only_the_newest_and_counts_the_rest() {
        let mut s = session(false);
        let t0 = Instant::now();
        for k in 0..3 {
            s.offer(&rob(&s, 1000 + 4 * k, 300.0, None), robot(), t0)
                .unwrap();
        }
        let c = s.take_cycle().unwrap();
        assert_eq!(c.seq, 1008);
        assert!(c.new_session, "the first of the burst started the session");
        assert_eq!(s.diagnostics().counters.skipped, 2);
        assert_eq!(s.take_cycle(), None);
    }

    #[test]
    fn watchdog_unanswered_and_late_on_the_passed_clock() {
        let mut s = session(false);
        let t0 = Instant::now();
        s.receive(&rob(&s, 1000, 300.0, None), robot(), t0).unwrap();
        // Not answered before the next wait: counted.
        assert_eq!(s.wait_budget(t0 + ms(1)).unwrap(), Some(ms(100)));
        assert_eq!(s.diagnostics().counters.unanswered, 1);
        assert_eq!(s.wait_budget(t0 + ms(40)).unwrap(), Some(ms(60)));
        s.receive(&rob(&s, 1004, 300.0, None), robot(), t0 + ms(41))
            .unwrap();
        let mut out = [0u8; 1024];
        s.reply(&Correction::default(), &mut out).unwrap();
        s.sent(t0 + ms(44));
        assert_eq!(s.diagnostics().counters.late, 1, "3 ms > late_after 2 ms");
        assert!(matches!(
            s.wait_budget(t0 + ms(141)),
            Err(LinkError::LinkLost { .. })
        ));
        assert!(!s.in_session());
        // The next datagram starts a new session even with a close IPOC.
        let c = s
            .receive(&rob(&s, 1008, 300.0, None), robot(), t0 + ms(150))
            .unwrap();
        assert!(c.new_session);
    }

    /// Lateness runs from the datagram's arrival (the kernel's stamp), not from when the shell read
    /// it: a datagram that waited in the socket while the loop was busy makes a late reply even when
    /// the loop answered it at once. Without an arrival, from the read (counted `unstamped`).
    #[test]
    fn late_replies_are_measured_from_the_arrival() {
        let mut s = session(false);
        let t0 = Instant::now();
        let mut out = [0u8; 1024];
        let us = Duration::from_micros;
        // Arrived at t0, read 10 ms later (the loop was stalled), answered 100 µs after the read.
        let d = rob(&s, 1000, 300.0, None);
        s.offer_arrived(&d, robot(), t0 + ms(10), Some(t0)).unwrap();
        assert_eq!(s.take_cycle().unwrap().replied_late, 0);
        s.reply(&Correction::default(), &mut out).unwrap();
        s.sent(t0 + ms(10) + us(100));
        let c = s.diagnostics().counters;
        assert_eq!((c.answered, c.late, c.unstamped), (1, 1, 0));
        assert_eq!(s.diagnostics().from_arrival.max(), ms(10) + us(100));
        assert_eq!(
            s.diagnostics().latency.max(),
            us(100),
            "read→send: the old measure, which saw nothing late"
        );
        // Arrived 1.5 ms before the read, answered 0.4 ms after: 1.9 ms, within late_after (2 ms).
        let d = rob(&s, 1004, 300.0, None);
        let read = t0 + ms(20);
        s.offer_arrived(&d, robot(), read, Some(read - us(1500)))
            .unwrap();
        let cycle = s.take_cycle().unwrap();
        assert_eq!(cycle.replied_late, 1, "the cycle carries the count so far");
        s.reply(&Correction::default(), &mut out).unwrap();
        s.sent(read + us(400));
        assert_eq!(s.diagnostics().counters.late, 1);
        // No arrival (no kernel stamp): measured from the read, and counted as such.
        let d = rob(&s, 1008, 300.0, None);
        let read = t0 + ms(30);
        s.offer(&d, robot(), read).unwrap();
        s.take_cycle().unwrap();
        s.reply(&Correction::default(), &mut out).unwrap();
        s.sent(read + ms(3));
        let c = s.diagnostics().counters;
        assert_eq!((c.answered, c.late, c.unstamped), (3, 2, 1));
        // An arrival after the read (a clock step between the two clocks) counts from the read.
        let d = rob(&s, 1012, 300.0, None);
        let read = t0 + ms(40);
        s.offer_arrived(&d, robot(), read, Some(read + ms(50)))
            .unwrap();
        s.take_cycle().unwrap();
        s.reply(&Correction::default(), &mut out).unwrap();
        s.sent(read + us(100));
        let c = s.diagnostics().counters;
        assert_eq!((c.answered, c.late, c.unstamped), (4, 2, 1));
        assert_eq!(s.diagnostics().from_arrival.count(), 4);
    }

    #[test]
    fn foreign_and_oversized_datagrams_are_rejected() {
        let mut s = session(false);
        let t0 = Instant::now();
        let d = rob(&s, 1000, 300.0, None);
        let other = SocketAddr::from(([127, 0, 0, 2], 40_000));
        assert_eq!(s.receive(&d, other, t0), Err(Rejected::Foreign));
        let mut big = d.clone();
        big.resize(s.config().max_datagram + 1, b' ');
        assert_eq!(s.receive(&big, robot(), t0), Err(Rejected::Oversized));
        let c = s.diagnostics().counters;
        assert_eq!((c.foreign, c.oversized, c.received), (1, 1, 2));
    }
}
