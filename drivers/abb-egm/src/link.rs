//! [`EgmLink`]: the external-device side of EGM path correction over a real UDP socket, as a
//! [`hal::RobotLink`].

use core::fmt;
use core::time::Duration;
use std::io;
use std::net::{IpAddr, SocketAddr, UdpSocket};
use std::time::Instant;

use hal::{Correction, Cycle, ErrorKind, ProcessState, RobotLink};
use udp::Receiver;

use crate::diag::Diagnostics;
use crate::limits::{CorrectionRange, Limits};
use crate::process::{CommandSlots, StateChannel};
use crate::session::EgmSession;
use crate::wire::SensorFrame;

/// Whose datagrams the link accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RobotFilter {
    /// Any source; the first one to start a session is then the only one accepted until the link is lost.
    Any,
    /// Any port of this address (a real controller's source port is its own choice).
    Ip(IpAddr),
    /// Exactly this address and port.
    Exact(SocketAddr),
}

/// Everything the link needs besides the socket.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkConfig {
    /// Where to listen: the address and port the robot's UDPUC transmission protocol entry names
    /// (EGM's customary port is 6510).
    pub bind: SocketAddr,
    /// Whose datagrams to accept.
    pub robot: RobotFilter,
    /// The robot's EGM cycle (4 ms).
    pub period: Duration,
    /// Robot silent for this many periods within a session → [`ErrorKind::LinkLost`].
    pub watchdog_cycles: u32,
    /// How long `next_cycle` waits for a session's first datagram before a (transient)
    /// [`ErrorKind::Timeout`]; `None` waits for ever.
    pub first_contact_timeout: Option<Duration>,
    /// Larger datagrams are dropped and counted as oversized.
    pub max_datagram: usize,
    /// The driver's envelope and rate limit.
    pub limits: Limits,
    /// The robot's configured path-correction range; `limits` must lie inside.
    pub range: CorrectionRange,
    /// Which translation axes of the tool frame (x, y, z) the link carries; the others are sent as 0.
    pub axes: [bool; 3],
    /// The sensor frame the RAPID program gives `EGMActMove`, relative to the tool.
    pub sensor_frame: SensorFrame,
    /// The process command in `RAPIDfromRobot.dnum`; `None`: no process channels (`Cycle::process`
    /// is `None`, force control runs as configured).
    pub process: Option<CommandSlots>,
    /// A sequence number further ahead than this (or further behind) starts a new session; one at or
    /// within this behind the last is a duplicate or reordered datagram and is dropped.
    pub session_jump: u32,
    /// A reply sent more than this after its datagram arrived (the kernel's receive stamp) counts as
    /// late.
    pub late_after: Duration,
    /// The fastest the robot's tool can move, m/s (plausibility of the reported poses).
    pub max_speed: f64,
    /// Age of the force measurement when its cycle arrives (the sensor chain's delay), added to the
    /// turnaround in `EgmPathCorr.age`.
    pub sensor_age: Duration,
    /// The state channel is called when the phase or fault changes, or the force moved by more than
    /// this, N (a slow transport is not called every cycle for the force's noise).
    pub state_force_deadband: f64,
}

impl LinkConfig {
    /// Defaults: listen on `bind`, 4 ms, watchdog 25 cycles (100 ms), 4 KiB datagrams,
    /// [`Limits::default`] inside a 5 mm range, all three axes, the tool as the sensor frame, no process
    /// channels, new session on a jump of more than 250 sequence numbers, late above 2 ms, 3 m/s, sensor
    /// age 0, state force deadband 1 N.
    pub fn new(bind: SocketAddr, robot: RobotFilter) -> Self {
        Self {
            bind,
            robot,
            period: Duration::from_millis(4),
            watchdog_cycles: 25,
            first_contact_timeout: None,
            max_datagram: 4096,
            limits: Limits::default(),
            range: CorrectionRange::default(),
            axes: [true; 3],
            sensor_frame: SensorFrame::default(),
            process: None,
            session_jump: 250,
            late_after: Duration::from_millis(2),
            max_speed: 3.0,
            sensor_age: Duration::ZERO,
            state_force_deadband: 1.0,
        }
    }

    /// Check the values.
    pub fn validate(&self) -> Result<(), String> {
        self.limits.validate(&self.range)?;
        if self.period.is_zero() || self.watchdog_cycles == 0 {
            return Err("period and watchdog_cycles must be > 0".into());
        }
        if !(64..=RX_BUFFER - 1).contains(&self.max_datagram) {
            return Err(format!(
                "max_datagram must be 64..{} bytes, got {}",
                RX_BUFFER - 1,
                self.max_datagram
            ));
        }
        if self.session_jump == 0 || self.session_jump >= u32::MAX / 2 {
            return Err(format!(
                "session_jump must be 1..{}, got {}",
                u32::MAX / 2,
                self.session_jump
            ));
        }
        if !(self.max_speed.is_finite() && self.max_speed > 0.0 && self.max_speed <= 100.0) {
            return Err(format!(
                "max_speed must be in (0, 100] m/s, got {}",
                self.max_speed
            ));
        }
        if !(self.state_force_deadband.is_finite() && self.state_force_deadband >= 0.0) {
            return Err(format!(
                "state_force_deadband must be ≥ 0 N, got {}",
                self.state_force_deadband
            ));
        }
        if !self.axes.iter().any(|a| *a) {
            return Err("axes: the link must carry at least one axis".into());
        }
        Ok(())
    }
}

/// What went wrong on the link.
#[derive(Debug)]
#[non_exhaustive]
pub enum LinkError {
    /// The listening address could not be bound.
    Bind {
        /// The address.
        addr: SocketAddr,
        /// The OS error.
        source: io::Error,
    },
    /// The configuration is invalid.
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
    /// The reply did not fit the send buffer (a bug: a path correction is about 50 bytes).
    Encode {
        /// Bytes needed.
        need: usize,
        /// Bytes available.
        have: usize,
    },
}

impl fmt::Display for LinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Bind { addr, source } if source.kind() == io::ErrorKind::AddrInUse => write!(
                f,
                "cannot listen on {addr}: the port is already in use — stop the other program (another \
                 forcecell or EGM client?) or choose another port in the robot's UDPUC entry"
            ),
            Self::Bind { addr, source } => write!(f, "cannot listen on {addr}: {source}"),
            Self::Config(s) => write!(f, "EGM configuration: {s}"),
            Self::Io(e) => write!(f, "EGM socket: {e}"),
            Self::LinkLost { silent_for } => write!(
                f,
                "link lost: the robot sent nothing for {:.1} ms (EGM stopped, program stopped, E-stop, or network)",
                silent_for.as_secs_f64() * 1e3
            ),
            Self::NoContact { waited } => write!(
                f,
                "no EgmRobot message within {:.1} s — is the RAPID program in EGMActMove/EGMMoveL, and does \
                 the UDPUC entry name this address and port?",
                waited.as_secs_f64()
            ),
            Self::Stopped => f.write_str("the link was stopped"),
            Self::NoCycle => f.write_str("reply without an unanswered cycle"),
            Self::Encode { need, have } => {
                write!(
                    f,
                    "cannot encode the path correction: {need} bytes, {have} available"
                )
            }
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
            Self::Config(_) => ErrorKind::Config,
            Self::LinkLost { .. } => ErrorKind::LinkLost,
            Self::NoContact { .. } => ErrorKind::Timeout,
            Self::Stopped | Self::NoCycle | Self::Encode { .. } => ErrorKind::Other,
        }
    }
}

/// Largest datagram the link can be configured to take.
const RX_BUFFER: usize = 65536;
const TX_BUFFER: usize = 512;
/// A UDP receive error that only means "nothing usable arrived yet"; shared with the simulated
/// controller.
pub use udp::is_transient;

/// The external-device side of EGM path correction: a UDP server answering the robot's cycles.
///
/// A thin shell around [`EgmSession`], which makes every decision: the shell reads the clock, receives
/// and sends. Two system calls per cycle in the steady state: one blocking `recvmsg` and one
/// `sendto` ([`udp::Receiver`]: only a datagram that had already waited in the socket may have
/// company, and only then is the queue drained). The watchdog is the socket's receive timeout, set only when its value changes. Each
/// datagram's arrival comes with it (`SO_TIMESTAMPNS`, in the same call): a reply's lateness runs
/// from there, as on the RSI link.
pub struct EgmLink {
    session: EgmSession,
    sock: UdpSocket,
    rx: Receiver,
    tx: Box<[u8]>,
    timeout_set: Option<Duration>,
    state: Option<Box<dyn StateChannel>>,
    published: Option<ProcessState>,
}

impl fmt::Debug for EgmLink {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("EgmLink")
            .field("local", &self.sock.local_addr().ok())
            .field("session", &self.session)
            .finish()
    }
}

impl EgmLink {
    /// Bind the configured address (never sharing the port) and get ready for the robot.
    pub fn bind(cfg: LinkConfig) -> Result<Self, LinkError> {
        let session = EgmSession::new(cfg)?;
        let cfg = session.config();
        let addr = cfg.bind;
        let sock = UdpSocket::bind(addr).map_err(|source| LinkError::Bind { addr, source })?;
        Ok(Self {
            rx: Receiver::new(&sock, cfg.max_datagram),
            tx: vec![0; TX_BUFFER].into_boxed_slice(),
            sock,
            session,
            timeout_set: None,
            state: None,
            published: None,
        })
    }

    /// What the state channel did, if it has something to say ([`StateChannel::report`]).
    pub fn state_report(&self) -> Option<String> {
        self.state.as_ref().and_then(|c| c.report())
    }

    /// Where the process state goes back to the RAPID program (see [`crate::process`]). Without one,
    /// the state of each correction is dropped.
    pub fn set_state_channel(&mut self, channel: Box<dyn StateChannel>) {
        self.state = Some(channel);
        self.published = None;
    }

    /// The address actually bound.
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.sock.local_addr()
    }

    /// Counters, the robot's status and the latency distribution.
    pub fn diagnostics(&self) -> &Diagnostics {
        self.session.diagnostics()
    }

    /// The configuration.
    pub fn config(&self) -> &LinkConfig {
        self.session.config()
    }

    /// The sans-IO session inside.
    pub fn session(&self) -> &EgmSession {
        &self.session
    }

    /// Change whose datagrams are accepted.
    pub fn set_robot_filter(&mut self, robot: RobotFilter) {
        self.session.set_robot_filter(robot);
    }

    /// True after a stop was sent.
    pub fn is_stopped(&self) -> bool {
        self.session.is_stopped()
    }

    fn set_timeout(&mut self, t: Option<Duration>) -> Result<(), LinkError> {
        let t = t.map(|d| d.max(Duration::from_micros(1)));
        if self.timeout_set != t {
            self.sock.set_read_timeout(t).map_err(LinkError::Io)?;
            self.timeout_set = t;
        }
        Ok(())
    }

    /// True when the kernel stamps each datagram's arrival (`SO_TIMESTAMPNS` accepted): replies'
    /// lateness is measured from it. False: from the receive call's return (say so once).
    pub fn kernel_stamps(&self) -> bool {
        self.rx.stamped()
    }

    fn publish(&mut self, state: &ProcessState) {
        let Some(ch) = self.state.as_mut() else {
            return;
        };
        let band = self.session.config().state_force_deadband;
        if let Some(p) = &self.published
            && p.phase == state.phase
            && p.fault == state.fault
            && ((p.force - state.force).abs() <= band || (p.force.is_nan() && state.force.is_nan()))
        {
            return;
        }
        let c = &mut self.session.diagnostics_mut().counters;
        match ch.publish(state) {
            Ok(()) => {
                c.states_published += 1;
                self.published = Some(*state);
            }
            Err(_) => c.state_errors += 1,
        }
    }
}

impl RobotLink for EgmLink {
    type Error = LinkError;

    /// The newest robot cycle. A cycle left unanswered is counted and forgotten. After
    /// [`ErrorKind::LinkLost`] the next call waits for a new session.
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
            self.set_timeout(remaining)?;
            let session = &mut self.session;
            self.rx
                .recv_all(&self.sock, Some(now), |bytes, from, arrived, rx_at| {
                    // Rejected datagrams are counted by the session.
                    let _ = session.offer_arrived(bytes, from, rx_at, arrived);
                })
                .map_err(LinkError::Io)?;
            if let Some(c) = self.session.take_cycle() {
                return Ok(c);
            }
            now = Instant::now();
        }
    }

    /// Publish the process state if it changed (the state channel), shape the correction, and send
    /// the path correction to the datagram's source.
    fn reply(&mut self, correction: &Correction) -> Result<(), LinkError> {
        if self.session.is_stopped() {
            return Err(LinkError::Stopped);
        }
        self.publish(&correction.process);
        let Some(out) = self
            .session
            .reply(correction, Instant::now(), &mut self.tx)?
        else {
            return Ok(());
        };
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
        is_send::<EgmLink>();
        is_send::<EgmSession>();
    }
}
