//! [`RsiLink`]: the PC side of RSI over a real UDP socket, as a [`hal::RobotLink`].

use core::fmt;
use core::time::Duration;
use std::io;
use std::net::{IpAddr, SocketAddr, UdpSocket};
use std::time::Instant;

use hal::{Correction, Cycle, ErrorKind, Pose, RobotLink};

use crate::codec::{Frame, Ipoc, Schema, WriteError};
use crate::config::EthernetConfig;
use crate::diag::Diagnostics;
use crate::limits::{Limits, PoscorrLimits, Shaper, split};
use crate::wire;

/// How the robot interprets `RKorr`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum CorrectionMode {
    /// `RSI_ON(#ABSOLUTE)`: each reply is the total offset from the programmed path (recommended,
    /// with HOLDON = 1).
    #[default]
    Absolute,
    /// `RSI_ON(#RELATIVE)`: each reply is an increment the robot adds up (HOLDON = 0 recommended).
    Relative,
}

/// Whose datagrams the link accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RobotFilter {
    /// Any source; the first one to start a session is then the only one accepted until the
    /// link is lost (for `--external-robot`).
    Any,
    /// Any port of this address (a real KRC: its source port is ephemeral).
    Ip(IpAddr),
    /// Exactly this address and port.
    Exact(SocketAddr),
}

/// Everything the link needs besides the socket.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkConfig {
    /// The robot's Ethernet config: which elements to expect and send, where to listen.
    pub ethernet: EthernetConfig,
    /// Listen here instead of the config's `IP_NUMBER:PORT` (tests bind `127.0.0.1:0`).
    pub bind: Option<SocketAddr>,
    /// Whose datagrams to accept.
    pub robot: RobotFilter,
    /// The robot's interpolation cycle (4 ms `#IPO_FAST`, 12 ms `#IPO`).
    pub period: Duration,
    /// Seconds per IPOC unit (0.001 for RSI 3; 0.012 for RSI 2.x, which steps IPOC by 1 per cycle).
    pub ipoc_unit: f64,
    /// Robot silent for this many periods within a session → [`ErrorKind::LinkLost`].
    pub watchdog_cycles: u32,
    /// How long `next_cycle` waits for the first datagram of a session before returning a
    /// (transient) [`ErrorKind::Timeout`]; `None` waits for ever.
    pub first_contact_timeout: Option<Duration>,
    /// Larger datagrams are dropped and counted as oversized.
    pub max_datagram: usize,
    /// Absolute or relative corrections.
    pub mode: CorrectionMode,
    /// The driver's envelope and rate limits.
    pub limits: Limits,
    /// The robot's POSCORR limits; `limits` must lie inside.
    pub poscorr: PoscorrLimits,
    /// The robot's POSCORRMON limits; `limits` must lie inside.
    pub poscorrmon: PoscorrLimits,
    /// An IPOC further than this from the last one (either way) starts a new session; an older
    /// IPOC within it is a duplicate or reordered datagram and is dropped.
    pub session_jump: u64,
    /// Decimals written in `<Sen>`.
    pub precision: u8,
    /// A receive→send turnaround above this counts as a late reply.
    pub late_after: Duration,
    /// The fastest the robot's tool can move, m/s: a reported pose (`RIst` or `RSol`) further from
    /// the last plausible one than this speed allows in the IPOC time between them is a counted fault
    /// (`implausible`), never a control input.
    pub max_speed: f64,
}

impl LinkConfig {
    /// Defaults for `ethernet`: 4 ms, accept `robot`, watchdog 25 cycles (100 ms), 8 KiB datagrams,
    /// absolute mode, [`Limits::default`], new session on an IPOC jump of more than 1 s, 4 decimals,
    /// late above 2 ms.
    pub fn new(ethernet: EthernetConfig, robot: RobotFilter) -> Self {
        Self {
            ethernet,
            bind: None,
            robot,
            period: Duration::from_millis(4),
            ipoc_unit: 0.001,
            watchdog_cycles: 25,
            first_contact_timeout: None,
            max_datagram: 8192,
            mode: CorrectionMode::Absolute,
            limits: Limits::default(),
            poscorr: PoscorrLimits::default(),
            poscorrmon: PoscorrLimits::MONITOR_DEFAULT,
            session_jump: 1000,
            precision: 4,
            late_after: Duration::from_millis(2),
            max_speed: Self::DEFAULT_MAX_SPEED,
        }
    }

    /// Default [`max_speed`](Self::max_speed), m/s: faster than an arm moves while RSI corrects it
    /// (raise it for fast moves under RSI).
    pub const DEFAULT_MAX_SPEED: f64 = 3.0;

    /// Check the values.
    pub fn validate(&self) -> Result<(), String> {
        self.ethernet.validate().map_err(|e| e.to_string())?;
        self.limits.validate(&self.poscorr, &self.poscorrmon)?;
        if self.period.is_zero() || self.watchdog_cycles == 0 {
            return Err("period and watchdog_cycles must be > 0".into());
        }
        if !(self.ipoc_unit.is_finite() && self.ipoc_unit > 0.0) {
            return Err(format!("ipoc_unit must be > 0 s, got {}", self.ipoc_unit));
        }
        if !(64..=RX_BUFFER - 1).contains(&self.max_datagram) {
            return Err(format!(
                "max_datagram must be 64..{} bytes, got {}",
                RX_BUFFER - 1,
                self.max_datagram
            ));
        }
        if self.precision > 9 {
            return Err(format!("precision must be 0..=9, got {}", self.precision));
        }
        if !(self.max_speed.is_finite() && self.max_speed > 0.0 && self.max_speed <= 100.0) {
            return Err(format!(
                "max_speed must be in (0, 100] m/s (the fastest the robot's tool moves), got {}",
                self.max_speed
            ));
        }
        Ok(())
    }

    fn bind_addr(&self) -> SocketAddr {
        self.bind
            .unwrap_or_else(|| SocketAddr::from((self.ethernet.ip, self.ethernet.port)))
    }
}

/// What went wrong on the link.
#[derive(Debug)]
#[non_exhaustive]
pub enum LinkError {
    /// The listening address could not be bound (typically: the port is held by another program;
    /// the link never shares a port).
    Bind {
        /// The address.
        addr: SocketAddr,
        /// The OS error.
        source: io::Error,
    },
    /// The configuration is invalid or lacks what the driver needs.
    Config(String),
    /// A socket error.
    Io(io::Error),
    /// The robot fell silent past the watchdog.
    LinkLost {
        /// How long it had been silent.
        silent_for: Duration,
    },
    /// No robot datagram arrived within `first_contact_timeout` (transient: call again to keep waiting).
    NoContact {
        /// How long this call waited.
        waited: Duration,
    },
    /// A stop was sent; the link is finished.
    Stopped,
    /// `reply` without a cycle to answer (none yet, or it was answered already).
    NoCycle,
    /// A stop was asked for but the config has no `Stop` RECEIVE element.
    NoStopElement,
    /// The reply could not be encoded (a bug: shaped values are always finite and small).
    Encode(WriteError),
}

impl fmt::Display for LinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Bind { addr, source } if source.kind() == io::ErrorKind::AddrInUse => write!(
                f,
                "cannot listen on {addr}: the port is already in use — stop the other program (another \
                 forcecell or RSI driver?) or choose another PORT; RSI needs the port to itself"
            ),
            Self::Bind { addr, source } => write!(f, "cannot listen on {addr}: {source}"),
            Self::Config(s) => write!(f, "RSI configuration: {s}"),
            Self::Io(e) => write!(f, "RSI socket: {e}"),
            Self::LinkLost { silent_for } => write!(
                f,
                "link lost: the robot sent nothing for {:.1} ms (RSI stopped, E-stop, or network)",
                silent_for.as_secs_f64() * 1e3
            ),
            Self::NoContact { waited } => write!(
                f,
                "no datagram from the robot within {:.1} s — is RSI_ON running and IP_NUMBER/PORT right?",
                waited.as_secs_f64()
            ),
            Self::Stopped => f.write_str("the link was stopped"),
            Self::NoCycle => f.write_str("reply without an unanswered cycle"),
            Self::NoStopElement => {
                f.write_str("cannot stop: the Ethernet config has no Stop RECEIVE element")
            }
            Self::Encode(e) => write!(f, "cannot encode <Sen>: {e}"),
        }
    }
}

impl std::error::Error for LinkError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Bind { source, .. } => Some(source),
            Self::Io(e) => Some(e),
            _ => None,
        }
    }
}

impl hal::Error for LinkError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Bind { .. } | Self::Io(_) => ErrorKind::Io,
            Self::Config(_) | Self::NoStopElement => ErrorKind::Config,
            Self::LinkLost { .. } => ErrorKind::LinkLost,
            Self::NoContact { .. } => ErrorKind::Timeout,
            Self::Stopped | Self::NoCycle | Self::Encode(_) => ErrorKind::Other,
        }
    }
}

const RX_BUFFER: usize = 65536;
const TX_BUFFER: usize = 16384;

struct RobSlots {
    rist: [usize; 6],
    rsol: [usize; 6],
    delay: Option<usize>,
}

struct SenSlots {
    rkorr: [Option<usize>; 6],
    stop: Option<usize>,
}

struct Session {
    ipoc0: u64,
    last_ipoc: u64,
    last_rx: Instant,
    peer: SocketAddr,
    /// The last plausible `RIst` and `RSol` positions (m) and their IPOC.
    plausible: Option<([hal::Vector3<f64>; 2], u64)>,
}

struct Pending {
    ipoc: Ipoc,
    rx_at: Instant,
    peer: SocketAddr,
}

/// The PC side of RSI: a UDP server on the configured address answering the robot's cycles.
pub struct RsiLink {
    cfg: LinkConfig,
    sock: UdpSocket,
    rob: Schema,
    sen: Schema,
    rob_slots: RobSlots,
    sen_slots: SenSlots,
    rx: Box<[u8]>,
    tx: Box<[u8]>,
    rx_frame: Box<Frame>,
    tx_frame: Box<Frame>,
    session: Option<Session>,
    pending: Option<Pending>,
    shaper: Shaper,
    last_wire: [f64; 6],
    stopped: bool,
    timeout_set: Option<Duration>,
    diag: Diagnostics,
}

impl fmt::Debug for RsiLink {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("RsiLink")
            .field("local", &self.sock.local_addr().ok())
            .field("robot", &self.cfg.robot)
            .field("counters", &self.diag.counters)
            .finish()
    }
}

/// What [`RsiLink::accept`] made of one good datagram.
struct Accepted {
    cycle: Cycle,
    ipoc: Ipoc,
    peer: SocketAddr,
    rx_at: Instant,
}

impl RsiLink {
    /// Bind the configured address (never sharing the port) and get ready for the robot.
    pub fn bind(cfg: LinkConfig) -> Result<Self, LinkError> {
        cfg.validate().map_err(LinkError::Config)?;
        let rob = cfg
            .ethernet
            .rob_schema(cfg.precision)
            .map_err(|e| LinkError::Config(e.to_string()))?;
        let sen = cfg
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
        };
        let sen_slots = SenSlots {
            rkorr: pose.map(|a| sen.slot("RKorr", a)),
            stop: sen.slot("Stop", ""),
        };
        let addr = cfg.bind_addr();
        // std's bind sets no SO_REUSEADDR / SO_REUSEPORT: a held port fails here, loudly.
        let sock = UdpSocket::bind(addr).map_err(|source| LinkError::Bind { addr, source })?;
        let shaper = Shaper::new(cfg.limits, sen_slots.rkorr.map(|s| s.is_some()));
        Ok(Self {
            sock,
            rob,
            sen,
            rob_slots,
            sen_slots,
            rx: vec![0; RX_BUFFER].into_boxed_slice(),
            tx: vec![0; TX_BUFFER].into_boxed_slice(),
            rx_frame: Box::default(),
            tx_frame: Box::default(),
            session: None,
            pending: None,
            shaper,
            last_wire: [0.0; 6],
            stopped: false,
            timeout_set: None,
            diag: Diagnostics::default(),
            cfg,
        })
    }

    /// The address actually bound (useful after binding port 0).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.sock.local_addr()
    }

    /// Counters and the latency distribution.
    pub fn diagnostics(&self) -> &Diagnostics {
        &self.diag
    }

    /// The configuration.
    pub fn config(&self) -> &LinkConfig {
        &self.cfg
    }

    /// Change whose datagrams are accepted (e.g. once a simulated controller has bound its port).
    pub fn set_robot_filter(&mut self, robot: RobotFilter) {
        self.cfg.robot = robot;
    }

    /// True after a stop was sent.
    pub fn is_stopped(&self) -> bool {
        self.stopped
    }

    /// The `<Rob>` schema in use.
    pub fn rob_schema(&self) -> &Schema {
        &self.rob
    }

    fn allowed(&self, from: SocketAddr) -> bool {
        match self.cfg.robot {
            RobotFilter::Exact(a) => from == a,
            RobotFilter::Ip(ip) => from.ip() == ip,
            RobotFilter::Any => self.session.as_ref().is_none_or(|s| s.peer == from),
        }
    }

    /// Judge one datagram of `n` bytes in `self.rx`; `Some` for a good, current `<Rob>`.
    fn accept(&mut self, n: usize, from: SocketAddr, rx_at: Instant) -> Option<Accepted> {
        let allowed = self.allowed(from);
        let c = &mut self.diag.counters;
        c.received += 1;
        if !allowed {
            c.foreign += 1;
            return None;
        }
        if n > self.cfg.max_datagram || n >= self.rx.len() {
            c.oversized += 1;
            return None;
        }
        if let Err(e) = self.rob.parse(&self.rx[..n], &mut self.rx_frame) {
            c.malformed += 1;
            self.diag.last_malformed = Some(e);
            return None;
        }
        let ipoc = *self.rx_frame.ipoc();
        let v = ipoc.value();
        let jump = self.cfg.session_jump;
        let new_session = match &self.session {
            None => true,
            Some(s) if v > s.last_ipoc.saturating_add(jump) => true,
            Some(s) if v.saturating_add(jump) < s.last_ipoc => true,
            Some(s) if v <= s.last_ipoc => {
                c.stale += 1;
                return None;
            }
            Some(_) => false,
        };
        if new_session {
            c.sessions += 1;
            self.session = Some(Session {
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
        let s = self.session.as_mut()?;
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
            actual: pose(f.get6(self.rob_slots.rist)),
            programmed: pose(f.get6(self.rob_slots.rsol)),
            late_replies: delay,
            new_session,
            process: None,
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
        Some(Accepted {
            cycle,
            ipoc,
            peer: from,
            rx_at,
        })
    }

    fn set_timeout(&mut self, t: Option<Duration>) -> Result<(), LinkError> {
        let t = t.map(|d| d.max(Duration::from_micros(1)));
        if self.timeout_set != t {
            self.sock.set_read_timeout(t).map_err(LinkError::Io)?;
            self.timeout_set = t;
        }
        Ok(())
    }

    /// Block until one good datagram arrives, the watchdog fires, or first contact times out.
    fn wait_first(&mut self) -> Result<Accepted, LinkError> {
        let started = Instant::now();
        let watchdog = self.cfg.period * self.cfg.watchdog_cycles;
        loop {
            let now = Instant::now();
            let remaining = match &self.session {
                Some(s) => {
                    let silent = now.duration_since(s.last_rx);
                    if silent >= watchdog {
                        self.session = None;
                        return Err(LinkError::LinkLost { silent_for: silent });
                    }
                    // A full watchdog when nothing ate into it (keeps the steady state free of syscalls).
                    Some(if silent < self.cfg.period {
                        watchdog
                    } else {
                        watchdog - silent
                    })
                }
                None => match self.cfg.first_contact_timeout {
                    Some(t) => {
                        let waited = now.duration_since(started);
                        if waited >= t {
                            return Err(LinkError::NoContact { waited });
                        }
                        Some(t - waited)
                    }
                    None => None,
                },
            };
            self.set_timeout(remaining)?;
            match self.sock.recv_from(&mut self.rx) {
                Ok((n, from)) => {
                    if let Some(a) = self.accept(n, from, Instant::now()) {
                        return Ok(a);
                    }
                }
                Err(e) if is_transient(&e) => {}
                Err(e) => return Err(LinkError::Io(e)),
            }
        }
    }

    /// Read whatever is already queued without waiting; the newest good datagram wins, every good
    /// one it supersedes counts as skipped.
    fn drain(&mut self) -> Result<Option<Accepted>, LinkError> {
        self.sock.set_nonblocking(true).map_err(LinkError::Io)?;
        let mut newest: Option<Accepted> = None;
        let result = loop {
            match self.sock.recv_from(&mut self.rx) {
                Ok((n, from)) => {
                    if let Some(mut a) = self.accept(n, from, Instant::now()) {
                        if let Some(old) = newest.take() {
                            self.diag.counters.skipped += 1;
                            a.cycle.new_session |= old.cycle.new_session;
                        }
                        newest = Some(a);
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break Ok(newest),
                Err(e) if is_transient(&e) => {}
                Err(e) => break Err(LinkError::Io(e)),
            }
        };
        self.sock.set_nonblocking(false).map_err(LinkError::Io)?;
        result
    }
}

/// A pose no controller can use (every component NaN).
fn unusable() -> Pose {
    Pose {
        position: hal::Vector3::repeat(f64::NAN),
        orientation: hal::UnitQuaternion::from_euler_angles(f64::NAN, f64::NAN, f64::NAN),
    }
}

fn pose(v: [f64; 6]) -> Pose {
    wire::pose_from_wire(v)
}

/// A UDP receive error that only means "nothing usable arrived yet" (timeout, signal, or an ICMP
/// port-unreachable echoed back by the kernel); shared with the simulated controller.
pub fn is_transient(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock
            | io::ErrorKind::TimedOut
            | io::ErrorKind::Interrupted
            | io::ErrorKind::ConnectionRefused
            | io::ErrorKind::ConnectionReset
    )
}

impl RobotLink for RsiLink {
    type Error = LinkError;

    /// The newest robot cycle. A cycle left unanswered is counted (`unanswered`) and forgotten.
    /// After [`ErrorKind::LinkLost`] the next call waits for a new session.
    fn next_cycle(&mut self) -> Result<Cycle, LinkError> {
        if self.stopped {
            return Err(LinkError::Stopped);
        }
        if self.pending.take().is_some() {
            self.diag.counters.unanswered += 1;
        }
        // A backlog (the application was late) is drained before waiting, so only its newest
        // datagram is answered. The wait wakes on the first datagram to arrive; when the network
        // delivered several at once (a burst after a stall), whatever else is queued already is read
        // too and the newest answered — a reply to an older one would reach the robot stale.
        let a = match self.drain()? {
            Some(a) => a,
            None => {
                let first = self.wait_first()?;
                match self.drain()? {
                    Some(mut newer) => {
                        self.diag.counters.skipped += 1;
                        newer.cycle.new_session |= first.cycle.new_session;
                        newer
                    }
                    None => first,
                }
            }
        };
        self.pending = Some(Pending {
            ipoc: a.ipoc,
            rx_at: a.rx_at,
            peer: a.peer,
        });
        Ok(a.cycle)
    }

    /// Shape the correction (non-finite → hold; envelope; rate), convert it to mm/deg (and to an
    /// increment in relative mode), and send `<Sen>` with the cycle's IPOC to the datagram's source.
    fn reply(&mut self, correction: &Correction) -> Result<(), LinkError> {
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
        let out = match self.cfg.mode {
            CorrectionMode::Absolute => wire_total,
            CorrectionMode::Relative => core::array::from_fn(|i| wire_total[i] - self.last_wire[i]),
        };
        self.last_wire = wire_total;
        if self.cfg.ethernet.onlysend {
            self.diag.counters.suppressed += 1;
            return Ok(());
        }
        for (slot, v) in self.sen_slots.rkorr.iter().zip(out) {
            if let Some(s) = *slot {
                self.tx_frame.set(s, v);
            }
        }
        if let Some(s) = self.sen_slots.stop {
            self.tx_frame
                .set(s, if correction.stop { 1.0 } else { 0.0 });
        }
        self.tx_frame.set_ipoc(p.ipoc);
        let n = self
            .sen
            .write(&self.tx_frame, &mut self.tx)
            .map_err(LinkError::Encode)?;
        if let Err(e) = self.sock.send_to(&self.tx[..n], p.peer) {
            self.diag.counters.send_errors += 1;
            return Err(LinkError::Io(e));
        }
        let turnaround = p.rx_at.elapsed();
        self.diag.latency.record(turnaround);
        let c = &mut self.diag.counters;
        c.answered += 1;
        if turnaround > self.cfg.late_after {
            c.late += 1;
        }
        if correction.stop {
            self.stopped = true;
        }
        Ok(())
    }
}
