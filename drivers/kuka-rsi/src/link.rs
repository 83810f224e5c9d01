//! [`RsiLink`]: the PC side of RSI over a real UDP socket, as a [`hal::RobotLink`].

use core::fmt;
use core::time::Duration;
use std::io;
use std::net::{IpAddr, SocketAddr, UdpSocket};
use std::os::fd::AsFd;
use std::time::Instant;

use hal::{Correction, Cycle, ErrorKind, RobotLink};
use nix::poll::{PollFd, PollFlags, ppoll};
use nix::sys::time::TimeSpec;
use udp::Receiver;

use crate::codec::{Schema, WriteError};
use crate::config::EthernetConfig;
use crate::diag::Diagnostics;
use crate::limits::{Limits, PoscorrLimits};
use crate::session::RsiSession;

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
    /// A reply sent more than this after its datagram arrived (the kernel's receive stamp) counts as
    /// late.
    pub late_after: Duration,
    /// The fastest the robot's tool can move, m/s: a reported pose (`RIst` or `RSol`) further from
    /// the last plausible one than this speed allows in the IPOC time between them is a counted fault
    /// (`implausible`), never a control input.
    pub max_speed: f64,
    /// Poll for the next datagram instead of sleeping from this long before it is due (one period
    /// after the last one arrived) until this long after; zero (the default): always sleep in the
    /// receive call. Polling keeps the loop's CPU from idling (and its caches warm) when the
    /// datagram lands, at the cost of that CPU time each cycle; it only helps when the loop has a
    /// CPU of its own (docs/performance.md). At most a quarter of the period.
    pub spin: Duration,
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
            spin: Duration::ZERO,
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
        if self.spin > self.period / 4 {
            return Err(format!(
                "spin must be at most a quarter of the period ({:?}), got {:?}",
                self.period / 4,
                self.spin
            ));
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
            Self::NoStopElement => f.write_str(
                "cannot stop: this configuration has no Stop channel (RECEIVE element Stop)",
            ),
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

/// Largest datagram the link can be configured to take (`max_datagram` stays below it).
const RX_BUFFER: usize = 65536;
const TX_BUFFER: usize = 16384;

/// The PC side of RSI: a UDP server on the configured address answering the robot's cycles.
///
/// A thin shell around [`RsiSession`], which makes every decision: the shell only reads the clock,
/// receives and sends. Two system calls per cycle in the steady state: one blocking `recvmsg` and
/// one `sendto` ([`udp::Receiver`]: a datagram that had already waited in the socket when the call
/// began may have company after a stall, and only then is the queue drained with non-blocking
/// reads, so the newest is answered). The socket stays blocking; the watchdog is its receive
/// timeout (`SO_RCVTIMEO`), set only when its value changes. With [`LinkConfig::spin`] a `ppoll`
/// comes first and the datagram is taken by non-blocking reads (as many as the polling makes).
///
/// The socket asks the kernel for each datagram's arrival time (`SO_TIMESTAMPNS`: a software stamp
/// taken when the datagram reaches the network stack, delivered in the same `recvmsg` as a control
/// message, no extra system call). The session measures a reply's lateness from it, so a datagram
/// that waited in the socket while the loop was busy counts. Where the kernel gives no stamp
/// ([`kernel_stamps`](Self::kernel_stamps) is false, or a datagram came without one) lateness is
/// measured from the receive call's return, counted as `unstamped`.
pub struct RsiLink {
    session: RsiSession,
    sock: UdpSocket,
    rx: Receiver,
    tx: Box<[u8]>,
    timeout_set: Option<Duration>,
}

impl fmt::Debug for RsiLink {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("RsiLink")
            .field("local", &self.sock.local_addr().ok())
            .field("session", &self.session)
            .finish()
    }
}

impl RsiLink {
    /// Bind the configured address (never sharing the port) and get ready for the robot.
    pub fn bind(cfg: LinkConfig) -> Result<Self, LinkError> {
        let session = RsiSession::new(cfg)?;
        let cfg = session.config();
        let addr = cfg.bind_addr();
        // std's bind sets no SO_REUSEADDR / SO_REUSEPORT: a held port fails here, loudly.
        let sock = UdpSocket::bind(addr).map_err(|source| LinkError::Bind { addr, source })?;
        Ok(Self {
            rx: Receiver::new(&sock, cfg.max_datagram),
            tx: vec![0; TX_BUFFER].into_boxed_slice(),
            sock,
            session,
            timeout_set: None,
        })
    }

    /// True when the kernel stamps each datagram's arrival (`SO_TIMESTAMPNS` accepted): replies'
    /// lateness is measured from it. False: from the receive call's return (say so once).
    pub fn kernel_stamps(&self) -> bool {
        self.rx.stamped()
    }

    /// The address actually bound (useful after binding port 0).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.sock.local_addr()
    }

    /// Counters and the latency distribution.
    pub fn diagnostics(&self) -> &Diagnostics {
        self.session.diagnostics()
    }

    /// The configuration.
    pub fn config(&self) -> &LinkConfig {
        self.session.config()
    }

    /// The sans-IO session inside.
    pub fn session(&self) -> &RsiSession {
        &self.session
    }

    /// Change whose datagrams are accepted (e.g. once a simulated controller has bound its port).
    pub fn set_robot_filter(&mut self, robot: RobotFilter) {
        self.session.set_robot_filter(robot);
    }

    /// The lines due now about datagrams rejected while waiting for the robot
    /// ([`RsiSession::rejection_lines`]), for the application to print.
    pub fn rejection_lines(&mut self) -> Vec<String> {
        self.session.rejection_lines(Instant::now())
    }

    /// True after a stop was sent.
    pub fn is_stopped(&self) -> bool {
        self.session.is_stopped()
    }

    /// The `<Rob>` schema in use.
    pub fn rob_schema(&self) -> &Schema {
        self.session.rob_schema()
    }

    fn set_timeout(&mut self, t: Option<Duration>) -> Result<(), LinkError> {
        let t = t.map(|d| d.max(Duration::from_micros(1)));
        if self.timeout_set != t {
            self.sock.set_read_timeout(t).map_err(LinkError::Io)?;
            self.timeout_set = t;
        }
        Ok(())
    }

    /// Read what the robot sent ([`udp::Receiver::recv_all`]: waiting up to the socket's timeout
    /// when `waiting_since`, the clock read before the call, is given) and offer every datagram to
    /// the session. Returns how many were read (0 on a timeout or nothing queued).
    fn receive_burst(&mut self, waiting_since: Option<Instant>) -> Result<usize, LinkError> {
        let session = &mut self.session;
        self.rx
            .recv_all(&self.sock, waiting_since, |bytes, from, arrived, rx_at| {
                // Rejected datagrams are counted by the session; nothing else to do here.
                let _ = session.offer_arrived(bytes, from, rx_at, arrived);
            })
            .map_err(LinkError::Io)
    }
}

/// A UDP receive error that only means "nothing usable arrived yet" (timeout, signal, or an ICMP
/// port-unreachable echoed back by the kernel); shared with the simulated controller.
pub use udp::is_transient;

impl RobotLink for RsiLink {
    type Error = LinkError;

    /// The newest robot cycle. A cycle left unanswered is counted (`unanswered`) and forgotten.
    /// After [`ErrorKind::LinkLost`] the next call waits for a new session.
    fn next_cycle(&mut self) -> Result<Cycle, LinkError> {
        if self.session.is_stopped() {
            return Err(LinkError::Stopped);
        }
        let started = Instant::now();
        let first_contact = self.session.config().first_contact_timeout;
        let mut now = started;
        loop {
            let remaining = match self.session.wait_budget(now)? {
                Some(d) => Some(d),
                None => match first_contact {
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
            // With `spin`: sleep only until shortly before the datagram is due, then poll for it.
            let spin = self.session.config().spin;
            let due = self.session.next_due().filter(|_| !spin.is_zero());
            if let (Some(due), Some(budget)) = (due, remaining) {
                let sleep_until = due.checked_sub(spin).unwrap_or(due);
                if now < sleep_until {
                    // Until then, or until a datagram is there (whichever first): `ppoll`, whose
                    // timeout is in nanoseconds (the socket's counts in scheduler ticks, up to 4 ms).
                    let wait = budget.min(sleep_until - now);
                    let mut fds = [PollFd::new(self.sock.as_fd(), PollFlags::POLLIN)];
                    match ppoll(&mut fds, Some(TimeSpec::from_duration(wait)), None) {
                        Ok(_) | Err(nix::errno::Errno::EINTR) => {}
                        Err(e) => return Err(LinkError::Io(io::Error::from(e))),
                    }
                }
                let until = due + spin;
                while Instant::now() < until {
                    if self.receive_burst(None)? == 0 {
                        core::hint::spin_loop();
                    } else if let Some(c) = self.session.take_cycle() {
                        return Ok(c);
                    }
                }
                // Not there yet: sleep in the receive call as without `spin`.
                now = Instant::now();
                let Some(remaining) = self.session.wait_budget(now)? else {
                    continue;
                };
                self.set_timeout(Some(remaining))?;
            } else {
                self.set_timeout(remaining)?;
            }
            self.receive_burst(Some(now))?;
            if let Some(c) = self.session.take_cycle() {
                return Ok(c);
            }
            now = Instant::now();
        }
    }

    /// Shape the correction (non-finite → hold; envelope; rate), convert it to mm/deg (and to an
    /// increment in relative mode), and send `<Sen>` with the cycle's IPOC to the datagram's source.
    fn reply(&mut self, correction: &Correction) -> Result<(), LinkError> {
        let Some(out) = self.session.reply(correction, &mut self.tx)? else {
            return Ok(());
        };
        self.session.sending(Instant::now());
        match self.sock.send_to(&self.tx[..out.len], out.to) {
            Ok(_) => {
                self.session.sent(Instant::now());
                Ok(())
            }
            Err(e) => {
                self.session.send_failed();
                Err(LinkError::Io(e))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_and_session_can_move_to_another_thread() {
        fn is_send<T: Send>() {}
        is_send::<RsiLink>();
        is_send::<RsiSession>();
    }
}
