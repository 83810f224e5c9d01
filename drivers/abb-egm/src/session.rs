//! [`EgmSession`]: everything the external-device side of EGM path correction decides, without I/O.
//!
//! Datagrams go in with the address they came from and the time they were received; cycles come out.
//! A correction goes in; an `EgmSensorPathCorr` and its destination come out, written into the caller's
//! buffer. Source filtering, sessions and sequence numbers, the backlog's newest datagram, plausibility,
//! the watchdog, correction shaping and the turnaround accounting live here and read no clock: the
//! caller passes the time. [`crate::EgmLink`] is the thin socket shell around it; tests drive it on a
//! virtual clock.
//!
//! One round, as the shell does it:
//! 1. [`EgmSession::wait_budget`] before blocking: how long the shell may wait (the watchdog), or
//!    [`LinkError::LinkLost`].
//! 2. [`EgmSession::offer`] for every datagram read (oldest first), then [`EgmSession::take_cycle`]
//!    for the newest good one. ([`EgmSession::receive`] does both for one.)
//! 3. [`EgmSession::reply`] writes the path correction; the shell sends it to [`Outgoing::to`] and
//!    reports the time with [`EgmSession::sent`] (or [`EgmSession::send_failed`]).
//!
//! # From `EgmRobot` to a [`Cycle`]
//! `seq`: the header's `seqno`, unwrapped to 64 bits within a session. `t`: the header's `tm` (ms)
//! since the session's first message, or, without `tm`, the feedback's `time` clock. `actual`: the
//! feedback pose; `programmed`: the planned pose (both required: mm → m, quaternion `u0..u3` as sent).
//! `process`: `RAPIDfromRobot.dnum` when the link is configured for the process command.
//! `late_replies`: 0 (EGM reports no counter of its own).

use core::fmt;
use core::time::Duration;
use std::net::SocketAddr;
use std::time::Instant;

use hal::{Correction, Cycle, ErrorKind, Pose, Vector3};
use prost::Message;

use crate::diag::Diagnostics;
use crate::limits::Shaper;
use crate::link::{LinkConfig, LinkError, RobotFilter};
use crate::msg::{
    EgmHeader, EgmPathCorr, EgmRobot, EgmSensorPathCorr, MessageType, MotorStateType,
    RapidCtrlExecStateType,
};
use crate::process::ProcessError;
use crate::wire::{self, PoseError};

/// Why a datagram is not a usable `EgmRobot`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum Malformed {
    /// Not protobuf of the `EgmRobot` layout (the decoder refused it).
    Protobuf,
    /// No header sequence number.
    NoSequence,
    /// The header's `mtype` is not `MSGTYPE_DATA` (the number received).
    WrongType(i32),
    /// Neither the header's `tm` nor the feedback's `time`.
    NoTime,
    /// The feedback pose is unusable.
    Feedback(PoseError),
    /// The planned pose is unusable.
    Planned(PoseError),
    /// The process command in `RAPIDfromRobot` breaks the contract.
    Process(ProcessError),
}

impl fmt::Display for Malformed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Protobuf => f.write_str("not an EgmRobot message (protobuf decoding failed)"),
            Self::NoSequence => f.write_str("EgmRobot without header.seqno"),
            Self::WrongType(t) => write!(f, "EgmRobot header.mtype {t} is not MSGTYPE_DATA (2)"),
            Self::NoTime => f.write_str("EgmRobot with neither header.tm nor feedBack.time"),
            Self::Feedback(e) => write!(f, "feedBack.cartesian unusable: {e:?}"),
            Self::Planned(e) => write!(f, "planned.cartesian unusable: {e:?}"),
            Self::Process(e) => write!(f, "process command: {e}"),
        }
    }
}

/// Why a datagram gave no cycle. Each is counted in [`Diagnostics::counters`]; none ends the session.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum Rejected {
    /// From a source the [`RobotFilter`] does not accept.
    Foreign,
    /// Larger than `max_datagram` (or truncated by the shell's buffer).
    Oversized,
    /// Not a usable `EgmRobot`.
    Malformed(Malformed),
    /// A sequence number at or just before the last one of the session: a duplicate or reordered datagram.
    Stale {
        /// Its sequence number.
        seqno: u32,
        /// The session's last.
        last: u32,
    },
    /// The session was stopped; nothing more is accepted.
    Stopped,
}

impl fmt::Display for Rejected {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Foreign => f.write_str("datagram from a source other than the robot"),
            Self::Oversized => f.write_str("datagram larger than max_datagram"),
            Self::Malformed(m) => write!(f, "malformed EgmRobot: {m}"),
            Self::Stale { seqno, last } => write!(
                f,
                "stale EgmRobot: seqno {seqno} is not after the session's last {last} (duplicate or reordered)"
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

struct Track {
    /// The session's unwrapped sequence number of the last message.
    seq: u64,
    last_seqno: u32,
    /// Time base: the first message's `tm` (ms) or feedback clock (µs).
    t0: TimeBase,
    last_t: f64,
    last_rx: Instant,
    peer: SocketAddr,
    /// The last plausible feedback and planned positions (m) and their time (s).
    plausible: Option<([Vector3<f64>; 2], f64)>,
}

#[derive(Clone, Copy)]
enum TimeBase {
    Tm(u32),
    ClockUs(u64),
}

#[derive(Clone, Copy)]
struct Accepted {
    cycle: Cycle,
    peer: SocketAddr,
    rx_at: Instant,
    /// When the datagram arrived (the kernel's receive stamp), when the shell knows it.
    arrived: Option<Instant>,
}

/// The external-device side of one EGM path-correction link without I/O; see the [module docs](self).
pub struct EgmSession {
    cfg: LinkConfig,
    rx: Box<EgmRobot>,
    track: Option<Track>,
    candidate: Option<Accepted>,
    pending: Option<Accepted>,
    in_flight: Option<(Instant, Option<Instant>, bool)>,
    shaper: Shaper,
    tx_seqno: u32,
    stopped: bool,
    diag: Diagnostics,
}

impl fmt::Debug for EgmSession {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("EgmSession")
            .field("robot", &self.cfg.robot)
            .field("in_session", &self.track.is_some())
            .field("counters", &self.diag.counters)
            .finish()
    }
}

/// Split a `tm`/clock difference into seconds.
fn elapsed(base: TimeBase, h: &EgmHeader, clock_us: Option<u64>) -> Option<f64> {
    match base {
        TimeBase::Tm(t0) => {
            h.tm.map(|tm| wire::ms_from_wire(u64::from(tm.wrapping_sub(t0))))
        }
        TimeBase::ClockUs(t0) => clock_us.map(|us| us.saturating_sub(t0) as f64 * 1e-6),
    }
}

impl EgmSession {
    /// Check the configuration.
    pub fn new(cfg: LinkConfig) -> Result<Self, LinkError> {
        cfg.validate().map_err(LinkError::Config)?;
        Ok(Self {
            rx: Box::default(),
            track: None,
            candidate: None,
            pending: None,
            in_flight: None,
            shaper: Shaper::new(cfg.limits, cfg.axes),
            tx_seqno: 0,
            stopped: false,
            diag: Diagnostics::default(),
            cfg,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &LinkConfig {
        &self.cfg
    }

    /// Counters, the robot's status and the latency distribution.
    pub fn diagnostics(&self) -> &Diagnostics {
        &self.diag
    }

    pub(crate) fn diagnostics_mut(&mut self) -> &mut Diagnostics {
        &mut self.diag
    }

    /// Change whose datagrams are accepted.
    pub fn set_robot_filter(&mut self, robot: RobotFilter) {
        self.cfg.robot = robot;
    }

    /// True after a stop was sent.
    pub fn is_stopped(&self) -> bool {
        self.stopped
    }

    /// True while a robot session is running (first good datagram seen, watchdog not fired).
    pub fn in_session(&self) -> bool {
        self.track.is_some()
    }

    /// Call before waiting for the next cycle: an unanswered cycle is counted and forgotten, and the
    /// watchdog is judged at `now`. Returns how long the caller may wait (`None`: no session yet), or
    /// [`LinkError::LinkLost`] when the robot has been silent for `watchdog_cycles` periods (the session
    /// ends; the next datagram starts a new one).
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
        // The same value cycle after cycle in the steady state: the shell need not touch its socket.
        Ok(Some(if silent < self.cfg.period {
            watchdog
        } else {
            watchdog - silent
        }))
    }

    /// Judge one datagram received from `from` at `rx_at`. A good, current `EgmRobot` becomes the
    /// candidate for the next cycle; a candidate it supersedes (a backlog) counts as skipped.
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
        let mut a = self.accept(datagram, from, rx_at)?;
        a.arrived = arrived.map(|t| t.min(rx_at));
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

    fn malformed(&mut self, m: Malformed) -> Rejected {
        self.diag.counters.malformed += 1;
        self.diag.last_malformed = Some(m);
        Rejected::Malformed(m)
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
        if self.rx.decode_into(datagram).is_err() {
            return Err(self.malformed(Malformed::Protobuf));
        }
        // Everything judged before any state changes: a malformed datagram leaves no trace but its count.
        let m = &*self.rx;
        let header = m.header.unwrap_or_default();
        let Some(seqno) = header.seqno else {
            return Err(self.malformed(Malformed::NoSequence));
        };
        if let Some(t) = header.mtype
            && t != MessageType::Data as i32
        {
            return Err(self.malformed(Malformed::WrongType(t)));
        }
        let fb = m.feed_back.as_ref();
        let clock_us = fb
            .and_then(|f| f.time)
            .and_then(|c| c.sec?.checked_mul(1_000_000)?.checked_add(c.usec?));
        if header.tm.is_none() && clock_us.is_none() {
            return Err(self.malformed(Malformed::NoTime));
        }
        let pose = |p: Option<&crate::msg::EgmPose>| {
            wire::pose_from_wire(
                p.and_then(|p| p.pos.as_ref()),
                p.and_then(|p| p.orient.as_ref()),
            )
        };
        let actual = match pose(fb.and_then(|f| f.cartesian.as_ref())) {
            Ok(p) => p,
            Err(e) => return Err(self.malformed(Malformed::Feedback(e))),
        };
        let programmed = match pose(m.planned.as_ref().and_then(|p| p.cartesian.as_ref())) {
            Ok(p) => p,
            Err(e) => return Err(self.malformed(Malformed::Planned(e))),
        };
        let process = match self.cfg.process {
            None => None,
            Some(slots) => {
                let dnum = m.rapid_from_robot.as_ref().map_or(&[][..], |r| &r.dnum[..]);
                match slots.decode(dnum) {
                    Ok(cmd) => Some(cmd),
                    Err(e) => return Err(self.malformed(Malformed::Process(e))),
                }
            }
        };
        let status = crate::diag::RobotStatus {
            motors: m.motor_state.and_then(|s| s.state),
            rapid: m.rapid_exec_state.and_then(|s| s.state),
            mci: m.mci_state.and_then(|s| s.state),
            move_index: m.move_index,
        };

        // Sessions and sequence numbers (wrapping u32).
        let jump = self.cfg.session_jump;
        let c = &mut self.diag.counters;
        let new_session = match &self.track {
            None => true,
            Some(s) => {
                let ahead = seqno.wrapping_sub(s.last_seqno);
                let behind = s.last_seqno.wrapping_sub(seqno);
                if ahead == 0 || (ahead > jump && behind <= jump) {
                    c.stale += 1;
                    return Err(Rejected::Stale {
                        seqno,
                        last: s.last_seqno,
                    });
                }
                ahead > jump
            }
        };
        if new_session {
            c.sessions += 1;
            let t0 = match header.tm {
                Some(tm) => TimeBase::Tm(tm),
                None => TimeBase::ClockUs(clock_us.unwrap_or(0)),
            };
            self.track = Some(Track {
                seq: u64::from(seqno),
                last_seqno: seqno,
                t0,
                last_t: 0.0,
                last_rx: rx_at,
                peer: from,
                plausible: None,
            });
            // EGMActMove starts with no correction in effect; a simulated cell may start its tool off
            // the path, and that offset is the correction in effect: the rate limit starts there.
            let offset = programmed
                .orientation
                .inverse_transform_vector(&(actual.position - programmed.position));
            self.shaper.restart(offset);
        }
        let Some(s) = self.track.as_mut() else {
            unreachable!("a session was just found or started");
        };
        if !new_session {
            s.seq += u64::from(seqno.wrapping_sub(s.last_seqno));
        }
        s.last_seqno = seqno;
        s.last_rx = rx_at;
        s.peer = from;
        // A time that does not advance (or a base the message no longer carries) keeps the last one:
        // the cycle still comes, its `t` never goes back.
        let t = elapsed(s.t0, &header, clock_us)
            .filter(|t| *t >= s.last_t)
            .unwrap_or(s.last_t);
        s.last_t = t;
        if status.motors == Some(MotorStateType::MotorsOff as i32) {
            c.motors_off += 1;
        }
        if status.rapid == Some(RapidCtrlExecStateType::RapidStopped as i32) {
            c.rapid_stopped += 1;
        }
        self.diag.robot = status;
        let mut cycle = Cycle {
            seq: s.seq,
            t,
            period: self.cfg.period.as_secs_f64(),
            actual,
            programmed,
            late_replies: 0,
            missed: 0,
            replied_late: c.late,
            new_session,
            process,
        };
        // The plausibility check, as for RSI: a jump no arm makes in the time since the last plausible
        // pose is a counted fault; the cycle is still delivered (and answered) with unusable poses.
        let now = [actual.position, programmed.position];
        let plausible = match s.plausible {
            Some((last, at)) => {
                let reach = self.cfg.max_speed * (t - at).max(self.cfg.period.as_secs_f64()) + 1e-4;
                now.iter().zip(last).all(|(p, l)| (p - l).norm() <= reach)
            }
            None => true,
        };
        if plausible {
            s.plausible = Some((now, t));
        } else {
            c.implausible += 1;
            cycle.actual = unusable();
            cycle.programmed = unusable();
        }
        Ok(Accepted {
            cycle,
            peer: from,
            rx_at,
            arrived: None,
        })
    }

    /// Write the path correction for the cycle last taken into `out`, at `now` (the measurement's age
    /// is the configured sensor age plus the time since the cycle arrived). `Ok(None)` never happens
    /// today (every cycle is answered); it is kept for a link that only listens.
    pub fn reply(
        &mut self,
        correction: &Correction,
        now: Instant,
        out: &mut [u8],
    ) -> Result<Option<Outgoing>, LinkError> {
        if self.stopped {
            return Err(LinkError::Stopped);
        }
        let p = self.pending.take().ok_or(LinkError::NoCycle)?;
        let c = &mut self.diag.counters;
        if correction.rotation.iter().any(|r| *r != 0.0) {
            c.rotation_dropped += 1;
        }
        let total = self.shaper.shape(&correction.translation, c);
        let age = self.cfg.sensor_age + now.saturating_duration_since(p.rx_at);
        self.tx_seqno = self.tx_seqno.wrapping_add(1);
        let msg = EgmSensorPathCorr {
            header: Some(EgmHeader {
                seqno: Some(self.tx_seqno),
                tm: None,
                mtype: Some(MessageType::PathCorrection as i32),
            }),
            path_corr: Some(EgmPathCorr {
                pos: Some(wire::correction_to_wire(&total, &self.cfg.sensor_frame)),
                age: Some(wire::ms_to_wire(age)),
            }),
        };
        let len = msg.encoded_len();
        let mut buf = &mut out[..];
        msg.encode(&mut buf).map_err(|_| LinkError::Encode {
            need: len,
            have: out.len(),
        })?;
        self.in_flight = Some((p.rx_at, p.arrived, correction.stop));
        Ok(Some(Outgoing { len, to: p.peer }))
    }

    /// The reply written last left at `now`: its receive→send turnaround is recorded, and its
    /// arrival→send time, late above `late_after` (from the receive time where the arrival is unknown:
    /// counted `unstamped`); a reply carrying `stop` finishes the session.
    pub fn sent(&mut self, now: Instant) {
        let Some((rx_at, arrived, stop)) = self.in_flight.take() else {
            return;
        };
        self.stopped |= stop;
        self.diag
            .latency
            .record(now.saturating_duration_since(rx_at));
        let since_arrival = now.saturating_duration_since(arrived.unwrap_or(rx_at));
        self.diag.from_arrival.record(since_arrival);
        let c = &mut self.diag.counters;
        c.answered += 1;
        if arrived.is_none() {
            c.unstamped += 1;
        }
        if since_arrival > self.cfg.late_after {
            c.late += 1;
        }
    }

    /// The reply written last could not be sent (a `stop` in it did not finish the session).
    pub fn send_failed(&mut self) {
        self.in_flight = None;
        self.diag.counters.send_errors += 1;
    }
}

/// A pose no controller can use (every component NaN).
fn unusable() -> Pose {
    Pose {
        position: Vector3::repeat(f64::NAN),
        orientation: hal::UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(
            f64::NAN,
            f64::NAN,
            f64::NAN,
            f64::NAN,
        )),
    }
}

#[cfg(test)]
mod tests {
    //! The session on a virtual clock: no sockets, no sleeps.
    use super::*;
    use crate::msg::{EgmFeedBack, EgmPlanned, EgmPose, EgmRapiddata};
    use crate::process::CommandSlots;
    use hal::{ProcessCommand, ProcessMode, UnitQuaternion};

    fn robot() -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], 40_000))
    }

    fn session(process: bool) -> EgmSession {
        let mut c = LinkConfig::new(
            SocketAddr::from(([127, 0, 0, 1], 0)),
            RobotFilter::Ip(robot().ip()),
        );
        c.process = process.then(CommandSlots::default);
        EgmSession::new(c).unwrap()
    }

    fn tool_down(z_mm: f64) -> EgmPose {
        let (pos, orient) = wire::pose_to_wire(&Pose {
            position: Vector3::new(0.5, 0.0, z_mm / 1000.0),
            orientation: UnitQuaternion::from_euler_angles(core::f64::consts::PI, 0.0, 0.0),
        });
        EgmPose {
            pos: Some(pos),
            orient: Some(orient),
            euler: None,
        }
    }

    /// An `EgmRobot` as a controller writes it: tool at `z` mm (feedback and planned), `tm` ms.
    fn rob(seqno: u32, tm: u32, z: f64, cmd: Option<ProcessCommand>) -> Vec<u8> {
        let mut dnum = Vec::new();
        if let Some(c) = cmd {
            CommandSlots::default().encode(&c, &mut dnum);
        }
        EgmRobot {
            header: Some(EgmHeader {
                seqno: Some(seqno),
                tm: Some(tm),
                mtype: Some(MessageType::Data as i32),
            }),
            feed_back: Some(EgmFeedBack {
                cartesian: Some(tool_down(z)),
                ..EgmFeedBack::default()
            }),
            planned: Some(EgmPlanned {
                cartesian: Some(tool_down(300.0)),
                ..EgmPlanned::default()
            }),
            rapid_from_robot: cmd.map(|_| EgmRapiddata {
                dig_val: None,
                dnum,
            }),
            ..EgmRobot::default()
        }
        .encode_to_vec()
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

    #[test]
    fn first_cycle_starts_a_session_in_si_with_the_command() {
        let mut s = session(true);
        let t0 = Instant::now();
        assert_eq!(s.wait_budget(t0).unwrap(), None, "no session: wait freely");
        let c = s
            .receive(&rob(10, 5000, 301.0, Some(press(3))), robot(), t0)
            .unwrap();
        assert!(c.new_session);
        assert_eq!((c.seq, c.t), (10, 0.0));
        assert_eq!(c.process, Some(press(3)));
        assert!((c.actual.position.z - 0.301).abs() < 1e-12, "mm → m");
        assert!((c.programmed.position.z - 0.3).abs() < 1e-12);
        assert!(
            (c.tool_offset().z + 0.001).abs() < 1e-12,
            "tool z points down"
        );
        let c = s
            .receive(&rob(11, 5004, 301.0, Some(press(4))), robot(), t0 + ms(4))
            .unwrap();
        assert!(!c.new_session);
        assert_eq!(c.seq, 11);
        assert!((c.t - 0.004).abs() < 1e-12);
        assert_eq!(s.diagnostics().counters.sessions, 1);
    }

    #[test]
    fn sequence_numbers_wrap_restart_and_reject_duplicates() {
        let mut s = session(false);
        let t0 = Instant::now();
        s.receive(&rob(u32::MAX, 0, 300.0, None), robot(), t0)
            .unwrap();
        let c = s
            .receive(&rob(0, 4, 300.0, None), robot(), t0 + ms(4))
            .unwrap();
        assert!(!c.new_session, "a wrap is not a new session");
        assert_eq!(c.seq, u64::from(u32::MAX) + 1);
        assert_eq!(
            s.receive(&rob(0, 8, 300.0, None), robot(), t0 + ms(8)),
            Err(Rejected::Stale { seqno: 0, last: 0 })
        );
        assert!(matches!(
            s.receive(&rob(u32::MAX - 3, 8, 300.0, None), robot(), t0 + ms(8)),
            Err(Rejected::Stale { .. })
        ));
        // EGMActMove again: the controller's counter restarts far away.
        let c = s
            .receive(&rob(5000, 90_000, 300.0, None), robot(), t0 + ms(12))
            .unwrap();
        assert!(c.new_session);
        assert_eq!(c.t, 0.0, "robot time restarts");
        let n = s.diagnostics().counters;
        assert_eq!((n.sessions, n.stale), (2, 2));
    }

    #[test]
    fn bad_messages_are_malformed_and_never_reach_a_cycle() {
        let mut s = session(true);
        let t0 = Instant::now();
        let good = rob(1, 0, 300.0, Some(press(1)));
        // Truncated protobuf.
        assert_eq!(
            s.receive(&good[..good.len() - 3], robot(), t0),
            Err(Rejected::Malformed(Malformed::Protobuf))
        );
        let mut m = EgmRobot::decode(&good[..]).unwrap();
        type Spoil = Box<dyn Fn(&mut EgmRobot)>;
        let variants: Vec<(Spoil, Malformed)> = vec![
            (
                Box::new(|m| m.header.as_mut().unwrap().seqno = None),
                Malformed::NoSequence,
            ),
            (
                Box::new(|m| m.header.as_mut().unwrap().mtype = Some(4)),
                Malformed::WrongType(4),
            ),
            (
                Box::new(|m| m.header.as_mut().unwrap().tm = None),
                Malformed::NoTime,
            ),
            (
                Box::new(|m| {
                    let p = m.feed_back.as_mut().unwrap().cartesian.as_mut().unwrap();
                    p.pos.as_mut().unwrap().x = Some(f64::NAN);
                }),
                Malformed::Feedback(PoseError::NonFinite),
            ),
            (
                Box::new(|m| m.planned = None),
                Malformed::Planned(PoseError::Missing),
            ),
            (
                Box::new(|m| {
                    let q = m.feed_back.as_mut().unwrap().cartesian.as_mut().unwrap();
                    q.orient.as_mut().unwrap().u1 = Some(2.0);
                }),
                Malformed::Feedback(PoseError::NotUnit),
            ),
            (
                Box::new(|m| m.rapid_from_robot.as_mut().unwrap().dnum.truncate(2)),
                Malformed::Process(ProcessError::Missing { need: 4, got: 2 }),
            ),
            (
                Box::new(|m| m.rapid_from_robot.as_mut().unwrap().dnum[1] = f64::INFINITY),
                Malformed::Process(ProcessError::NonFinite),
            ),
        ];
        let n = variants.len() as u64;
        for (spoil, why) in variants {
            let mut bad = m.clone();
            spoil(&mut bad);
            assert_eq!(
                s.receive(&bad.encode_to_vec(), robot(), t0),
                Err(Rejected::Malformed(why)),
                "{why:?}"
            );
        }
        assert!(!s.in_session(), "nothing bad started a session");
        assert_eq!(s.diagnostics().counters.malformed, n + 1);
        // A mode outside 0..2 is delivered as such.
        m.rapid_from_robot.as_mut().unwrap().dnum[0] = 7.0;
        let c = s.receive(&m.encode_to_vec(), robot(), t0).unwrap();
        assert_eq!(c.process.unwrap().mode, ProcessMode::Unknown(7));
    }

    /// Lateness runs from the datagram's arrival (the kernel's stamp), not from when it was read.
    #[test]
    fn late_replies_are_measured_from_the_arrival() {
        let mut s = session(false);
        let t0 = Instant::now();
        let mut out = [0u8; 256];
        let us = Duration::from_micros;
        // Arrived at t0, read 10 ms later, answered 100 µs after the read: late.
        s.offer_arrived(&rob(1, 0, 300.0, None), robot(), t0 + us(10_000), Some(t0))
            .unwrap();
        assert_eq!(s.take_cycle().unwrap().replied_late, 0);
        s.reply(&Correction::default(), t0 + us(10_050), &mut out)
            .unwrap();
        s.sent(t0 + us(10_100));
        let c = s.diagnostics().counters;
        assert_eq!((c.answered, c.late, c.unstamped), (1, 1, 0));
        assert_eq!(s.diagnostics().latency.max(), us(100), "read→send");
        assert_eq!(s.diagnostics().from_arrival.max(), us(10_100));
        // No arrival: from the read, counted unstamped; the cycle carries the late count so far.
        let read = t0 + us(20_000);
        let c = s.receive(&rob(2, 4, 300.0, None), robot(), read).unwrap();
        assert_eq!(c.replied_late, 1);
        s.reply(&Correction::default(), read, &mut out).unwrap();
        s.sent(read + us(500));
        let c = s.diagnostics().counters;
        assert_eq!((c.answered, c.late, c.unstamped), (2, 1, 1));
    }

    #[test]
    fn the_reply_is_a_path_correction_in_mm_with_its_age() {
        let mut s = session(false);
        let t0 = Instant::now();
        s.receive(&rob(1, 0, 300.0, None), robot(), t0).unwrap();
        let mut out = [0u8; 256];
        let mut corr = Correction::along_z(0.0002);
        corr.rotation.x = 0.01;
        let o = s
            .reply(&corr, t0 + Duration::from_micros(2600), &mut out)
            .unwrap()
            .unwrap();
        assert_eq!(o.to, robot());
        s.sent(t0 + Duration::from_micros(2700));
        let m = EgmSensorPathCorr::decode(&out[..o.len]).unwrap();
        let h = m.header.unwrap();
        assert_eq!(
            (h.seqno, h.mtype),
            (Some(1), Some(MessageType::PathCorrection as i32))
        );
        let pc = m.path_corr.unwrap();
        let pos = pc.pos.unwrap();
        assert_eq!((pos.x, pos.y), (Some(0.0), Some(0.0)));
        assert!((pos.z.unwrap() - 0.2).abs() < 1e-12, "m → mm");
        assert_eq!(pc.age, Some(3), "2.6 ms since the cycle arrived, rounded");
        let c = s.diagnostics().counters;
        assert_eq!((c.answered, c.late, c.rotation_dropped), (1, 1, 1));
        assert!(matches!(
            s.reply(&corr, t0, &mut out),
            Err(LinkError::NoCycle)
        ));
    }

    #[test]
    fn nan_is_held_never_sent_and_the_envelope_applies() {
        let mut s = session(false);
        let t0 = Instant::now();
        let mut out = [0u8; 256];
        let mut sent = Vec::new();
        for k in 0..40u32 {
            s.receive(
                &rob(k + 1, 4 * k, 300.0, None),
                robot(),
                t0 + ms(4 * u64::from(k)),
            )
            .unwrap();
            let c = if k == 30 {
                Correction::along_z(f64::NAN)
            } else {
                Correction::along_z(0.02)
            };
            let o = s.reply(&c, t0, &mut out).unwrap().unwrap();
            let z = EgmSensorPathCorr::decode(&out[..o.len])
                .unwrap()
                .path_corr
                .unwrap()
                .pos
                .unwrap()
                .z
                .unwrap();
            sent.push(z);
        }
        assert!(
            sent.iter().all(|z| z.is_finite() && *z <= 4.5 + 1e-9),
            "{sent:?}"
        );
        assert!((sent[0] - 0.25).abs() < 1e-12, "rate-limited from 0");
        assert_eq!(sent[30], sent[29], "NaN holds the last total");
        assert!((sent[39] - 4.5).abs() < 1e-9);
        assert_eq!(s.diagnostics().counters.nonfinite_held, 1);
    }

    #[test]
    fn backlog_foreign_oversized_watchdog_and_stop() {
        let mut s = session(false);
        let t0 = Instant::now();
        for k in 0..3 {
            s.offer(&rob(1 + k, 4 * k, 300.0, None), robot(), t0)
                .unwrap();
        }
        assert_eq!(s.take_cycle().unwrap().seq, 3);
        assert_eq!(s.diagnostics().counters.skipped, 2);
        let other = SocketAddr::from(([127, 0, 0, 2], 40_000));
        assert_eq!(
            s.receive(&rob(4, 12, 300.0, None), other, t0),
            Err(Rejected::Foreign)
        );
        let mut big = rob(4, 12, 300.0, None);
        big.resize(5000, 0);
        assert_eq!(s.receive(&big, robot(), t0), Err(Rejected::Oversized));
        // Not answered before the next wait: counted.
        assert_eq!(s.wait_budget(t0 + ms(1)).unwrap(), Some(ms(100)));
        assert_eq!(s.diagnostics().counters.unanswered, 1);
        assert!(matches!(
            s.wait_budget(t0 + ms(100)),
            Err(LinkError::LinkLost { .. })
        ));
        assert!(!s.in_session());
        let c = s
            .receive(&rob(5, 16, 300.0, None), robot(), t0 + ms(120))
            .unwrap();
        assert!(
            c.new_session,
            "the first datagram after a lost link starts a session"
        );
        let mut out = [0u8; 256];
        let stop = Correction {
            stop: true,
            ..Correction::default()
        };
        s.reply(&stop, t0, &mut out).unwrap();
        assert!(!s.is_stopped(), "not before it left");
        s.sent(t0);
        assert!(s.is_stopped());
        assert_eq!(
            s.receive(&rob(6, 20, 300.0, None), robot(), t0),
            Err(Rejected::Stopped)
        );
    }

    #[test]
    fn an_implausible_jump_is_delivered_unusable_and_counted() {
        let mut s = session(false);
        let t0 = Instant::now();
        s.receive(&rob(1, 0, 300.0, None), robot(), t0).unwrap();
        let c = s.receive(&rob(2, 4, 400.0, None), robot(), t0).unwrap();
        assert!(!c.actual.is_finite() && !c.programmed.is_finite());
        assert_eq!(s.diagnostics().counters.implausible, 1);
        let c = s.receive(&rob(3, 8, 300.1, None), robot(), t0).unwrap();
        assert!(c.actual.is_finite());
    }
}
