//! A simulated ABB IRC5 running EGM path correction over real UDP: the robot side, the clock master.
//!
//! Every cycle it sends an `EgmRobot` (header with its sequence number and time, the feedback and planned
//! tool poses, motors on, RAPID running and, when configured, the RAPID program's process command in
//! `RAPIDfromRobot.dnum`) to the external device, takes the first good `EgmSensorPathCorr` that arrives
//! within the cycle's window (the period in real time; a reply that comes later is read in the next
//! window, as a controller reading its queue would: EGM echoes no sequence number to match replies to
//! cycles), clamps it per axis to the configured path-correction range, filters it (an optional
//! first-order low-pass, the MotionProcess's filter) and moves a [`Mechanism`] with it. Without a good
//! correction it holds the last one; after `comm_timeout` such cycles in a row it ends the session, as
//! EGM does on its communication timeout. It uses the driver's codec for the opposite direction.
//!
//! The process state comes back as the RAPID program's variables ([`RapidVariables`], the
//! [`abb_egm::StateChannel`] the driver writes), read at the end of each cycle.
//!
//! The decisions live in [`Irc5Core`], which does no I/O and reads no clock; [`Irc5`] is its socket
//! shell. Timing is real time or lockstep, as for the simulated KRC ([`Timing`]). What this does **not**
//! model: the correction's age (logged, not used to place the correction on the path), the controller's
//! own path planning, and anything ABB's documentation describes that was not checked here.

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use abb_egm::msg::{
    EgmFeedBack, EgmHeader, EgmMciState, EgmMotorState, EgmPlanned, EgmPose, EgmRapidCtrlExecState,
    EgmRapiddata, EgmRobot, EgmSensorPathCorr, MciStateType, MessageType, MotorStateType,
    RapidCtrlExecStateType,
};
use abb_egm::process::{STATE_NUMBERS, state_from_numbers, state_to_numbers};
use abb_egm::{CommandSlots, CorrectionRange, ProcessError, SensorFrame, StateChannel, wire};
use hal::{Correction, Pose, ProcessCommand, ProcessState};
use prost::Message;

use crate::krc::{Mechanism, Timing};

/// The RAPID program's process-state variables: what the driver's state channel writes (standing in
/// for Robot Web Services) and the program reads. Cheap to clone; all clones share the variables.
#[derive(Clone, Debug, Default)]
pub struct RapidVariables(Arc<Mutex<Option<[f64; STATE_NUMBERS]>>>);

impl RapidVariables {
    /// The numbers last written, if any.
    pub fn read(&self) -> Option<[f64; STATE_NUMBERS]> {
        *self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Write the numbers (as a client of the controller would).
    pub fn write(&self, v: [f64; STATE_NUMBERS]) {
        *self.0.lock().unwrap_or_else(|e| e.into_inner()) = Some(v);
    }

    /// Write number `index` alone (one `PERS num`, as Robot Web Services writes it); the others keep
    /// their values, the module's initial zeros (OFF, 0 N, no fault) before any write.
    pub fn write_one(&self, index: usize, value: f64) {
        let mut v = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let mut all = v.unwrap_or([0.0; STATE_NUMBERS]);
        if let Some(slot) = all.get_mut(index) {
            *slot = value;
            *v = Some(all);
        }
    }
}

impl StateChannel for RapidVariables {
    fn publish(&mut self, state: &ProcessState) -> Result<(), String> {
        self.write(state_to_numbers(state));
        Ok(())
    }
}

/// The simulated controller's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Irc5Config {
    /// The external device (the UDPUC entry's remote address and port; a loopback address).
    pub target: SocketAddr,
    /// Where the controller binds (default `127.0.0.1:0`).
    pub bind: SocketAddr,
    /// Real time or lockstep.
    pub timing: Timing,
    /// EGM cycle.
    pub period: Duration,
    /// Sequence number of the first message.
    pub seqno_base: u32,
    /// `tm` of the first message, ms.
    pub tm_base: u32,
    /// Per-axis bound of the path correction (sensor frame), m.
    pub range: CorrectionRange,
    /// The MotionProcess's low-pass filter on the correction, Hz (`None`: applied as received).
    pub filter_hz: Option<f64>,
    /// Cycles in a row without a good correction that end the session.
    pub comm_timeout: u32,
    /// `EGMActMove \SensorFrame` relative to the tool.
    pub sensor_frame: SensorFrame,
    /// Send the mechanism's process command in `RAPIDfromRobot.dnum` at these slots.
    pub process: Option<CommandSlots>,
    /// End after this many cycles (`None`: until aborted, timed out or silent).
    pub cycles: Option<u64>,
    /// From this cycle on the controller sends nothing.
    pub silent_from: Option<u64>,
    /// `(cycle, seqno)`: EGM restarts here (sequence and `tm` start again, the correction is reset).
    pub new_session: Option<(u64, u32)>,
    /// Cycles before whose message a datagram that is not protobuf is sent.
    pub garbage: Vec<u64>,
    /// Keep a per-cycle log in the report.
    pub log: bool,
}

impl Irc5Config {
    /// Lockstep (1 s deadline) at 4 ms against `target`, 5 mm range, no filter, comm timeout 100
    /// cycles, the tool as sensor frame, no process command.
    pub fn new(target: SocketAddr) -> Self {
        Self {
            target,
            bind: SocketAddr::from(([127, 0, 0, 1], 0)),
            timing: Timing::Lockstep {
                deadline: Duration::from_secs(1),
            },
            period: Duration::from_millis(4),
            seqno_base: 1,
            tm_base: 100_000,
            range: CorrectionRange::default(),
            filter_hz: None,
            comm_timeout: 100,
            sensor_frame: SensorFrame::default(),
            process: None,
            cycles: None,
            silent_from: None,
            new_session: None,
            garbage: Vec::new(),
            log: false,
        }
    }

    fn validate(&self) -> Result<(), String> {
        if !(self.range.translation.is_finite() && self.range.translation > 0.0) {
            return Err(format!(
                "range must be > 0 m, got {}",
                self.range.translation
            ));
        }
        if let Some(f) = self.filter_hz
            && !(f.is_finite() && f > 0.0)
        {
            return Err(format!("filter_hz must be > 0 Hz, got {f}"));
        }
        if self.period.is_zero() || self.comm_timeout == 0 {
            return Err("period and comm_timeout must be > 0".into());
        }
        Ok(())
    }
}

/// Why the controller stopped.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Irc5End {
    /// The configured number of cycles ran.
    Completed,
    /// `comm_timeout` cycles in a row without a good correction.
    CommTimeout,
    /// The controller went silent (fault injection).
    Silent,
    /// Aborted from outside.
    Aborted,
    /// A socket error.
    Io(String),
}

/// One cycle as the controller saw it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Irc5Cycle {
    /// Sequence number sent.
    pub seqno: u32,
    /// A good correction arrived for this cycle.
    pub on_time: bool,
    /// The correction applied (after clamp and filter), mm, sensor frame.
    pub correction: [f64; 3],
    /// The range clamped something.
    pub clamped: bool,
    /// The age of the correction received, ms.
    pub age: Option<u32>,
    /// The process command sent.
    pub command: Option<ProcessCommand>,
    /// The process state the RAPID program read at the end of the cycle.
    pub state: Option<ProcessState>,
}

/// What happened.
#[derive(Clone, Debug, PartialEq)]
pub struct Irc5Report {
    /// Why it ended.
    pub end: Irc5End,
    /// Cycles run.
    pub cycles: u64,
    /// Cycles with a good correction.
    pub good: u64,
    /// Cycles without one (the last correction held).
    pub late: u64,
    /// Replies that are not a usable `EgmSensorPathCorr`.
    pub bad: u64,
    /// Replies whose header says another message type.
    pub wrong_type: u64,
    /// Replies from a source other than the external device.
    pub foreign_replies: u64,
    /// Cycles in which the range clamped.
    pub clamped: u64,
    /// Largest correction age received, ms.
    pub max_age: u32,
    /// RAPID state variables that broke the contract (not passed to the program).
    pub bad_state: u64,
    /// The last such error.
    pub last_bad_state: Option<ProcessError>,
    /// Per-cycle log (when asked for).
    pub log: Vec<Irc5Cycle>,
}

impl Irc5Report {
    fn empty() -> Self {
        Self {
            end: Irc5End::Completed,
            cycles: 0,
            good: 0,
            late: 0,
            bad: 0,
            wrong_type: 0,
            foreign_replies: 0,
            clamped: 0,
            max_age: 0,
            bad_state: 0,
            last_bad_state: None,
            log: Vec::new(),
        }
    }
}

/// What [`Irc5Core::on_reply`] made of one datagram.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// A usable path correction: the newest for this cycle.
    Good,
    /// From a source other than the external device.
    Foreign,
    /// Not a usable `EgmSensorPathCorr`.
    Bad,
    /// Its header's `mtype` is not `MSGTYPE_PATH_CORRECTION`.
    WrongType,
}

#[derive(Clone, Copy)]
struct Sent {
    seqno: u32,
    command: Option<ProcessCommand>,
    /// The newest good correction received for this cycle: mm, sensor frame, and its age.
    got: Option<([f64; 3], u32)>,
}

/// The simulated controller's decisions without I/O; see the [module docs](self).
///
/// One cycle: [`next_cycle`](Self::next_cycle) → send its bytes → [`on_reply`](Self::on_reply) for each
/// datagram received until the shell's deadline → [`end_cycle`](Self::end_cycle).
pub struct Irc5Core {
    cfg: Irc5Config,
    vars: RapidVariables,
    report: Irc5Report,
    msg: EgmRobot,
    buf: Vec<u8>,
    /// The correction received last (held without a new one), mm.
    wanted: [f64; 3],
    /// The correction applied (filtered), mm.
    applied: [f64; 3],
    late_count: u32,
    seqno_base: u32,
    tm_base: u32,
    session_start: u64,
    n: u64,
    started: bool,
    sent: Option<Sent>,
}

impl Irc5Core {
    /// A controller whose RAPID program reads its process state from `vars`.
    pub fn new(cfg: Irc5Config, vars: RapidVariables) -> Result<Self, String> {
        cfg.validate()?;
        Ok(Self {
            vars,
            report: Irc5Report::empty(),
            msg: EgmRobot::default(),
            buf: Vec::with_capacity(1024),
            wanted: [0.0; 3],
            applied: [0.0; 3],
            late_count: 0,
            seqno_base: cfg.seqno_base,
            tm_base: cfg.tm_base,
            session_start: 0,
            n: 0,
            started: false,
            sent: None,
            cfg,
        })
    }

    /// The report so far.
    pub fn report(&self) -> &Irc5Report {
        &self.report
    }

    /// Cycles begun so far.
    pub fn cycle_index(&self) -> u64 {
        self.n
    }

    /// When the reply window of a cycle begun at `cycle_start` and sent at `sent_at` closes.
    pub fn reply_deadline(&self, cycle_start: Instant, sent_at: Instant) -> Instant {
        match self.cfg.timing {
            Timing::Realtime => cycle_start + self.cfg.period,
            Timing::Lockstep { deadline } => sent_at + deadline,
        }
    }

    fn pose(p: &Pose) -> EgmPose {
        let (pos, orient) = wire::pose_to_wire(p);
        EgmPose {
            pos: Some(pos),
            orient: Some(orient),
            euler: None,
        }
    }

    /// Begin the next cycle and write its `EgmRobot`; `Err` when the run ends before it.
    pub fn next_cycle(&mut self, mech: &mut dyn Mechanism) -> Result<&[u8], Irc5End> {
        let cfg = &self.cfg;
        if !self.started {
            self.started = true;
            // A simulated cell may start with its tool off the path: that offset is the correction in
            // effect, so a late first reply holds it instead of dropping the tool onto the path.
            let (actual, programmed) = mech.poses();
            let offset = programmed
                .orientation
                .inverse_transform_vector(&(actual.position - programmed.position));
            let w = wire::correction_to_wire(&offset, &cfg.sensor_frame);
            self.wanted = [w.x, w.y, w.z].map(|v| v.unwrap_or(0.0));
            self.applied = self.wanted;
        }
        let n = self.n;
        if cfg.cycles.is_some_and(|c| n >= c) {
            return Err(Irc5End::Completed);
        }
        if cfg.silent_from.is_some_and(|s| n >= s) {
            return Err(Irc5End::Silent);
        }
        if let Some((at, seqno)) = cfg.new_session
            && at == n
        {
            // EGMActMove again: new sequence and time, no correction in effect.
            self.seqno_base = seqno;
            self.tm_base = self.tm_base.wrapping_add(10_000);
            self.session_start = n;
            self.wanted = [0.0; 3];
            self.applied = [0.0; 3];
            self.late_count = 0;
        }
        let k = n - self.session_start;
        let seqno = self.seqno_base.wrapping_add(k as u32);
        let tm = self
            .tm_base
            .wrapping_add((k as f64 * cfg.period.as_secs_f64() * 1e3).round() as u32);
        let (actual, programmed) = mech.poses();
        let command = cfg.process.map(|slots| {
            let c = mech.process_command().unwrap_or(ProcessCommand {
                mode: hal::ProcessMode::Off,
                force: 0.0,
                ramp: 0.0,
                segment: 0,
            });
            let r = self
                .msg
                .rapid_from_robot
                .get_or_insert_with(EgmRapiddata::default);
            r.dnum.clear();
            slots.encode(&c, &mut r.dnum);
            c
        });
        if command.is_none() {
            self.msg.rapid_from_robot = None;
        }
        self.msg.header = Some(EgmHeader {
            seqno: Some(seqno),
            tm: Some(tm),
            mtype: Some(MessageType::Data as i32),
        });
        self.msg.feed_back = Some(EgmFeedBack {
            cartesian: Some(Self::pose(&actual)),
            ..EgmFeedBack::default()
        });
        self.msg.planned = Some(EgmPlanned {
            cartesian: Some(Self::pose(&programmed)),
            ..EgmPlanned::default()
        });
        self.msg.motor_state = Some(EgmMotorState {
            state: Some(MotorStateType::MotorsOn as i32),
        });
        self.msg.mci_state = Some(EgmMciState {
            state: Some(MciStateType::MciRunning as i32),
        });
        self.msg.rapid_exec_state = Some(EgmRapidCtrlExecState {
            state: Some(RapidCtrlExecStateType::RapidRunning as i32),
        });
        self.buf.clear();
        self.msg
            .encode(&mut self.buf)
            .map_err(|e| Irc5End::Io(format!("cannot encode EgmRobot: {e}")))?;
        self.sent = Some(Sent {
            seqno,
            command,
            got: None,
        });
        Ok(&self.buf)
    }

    /// Judge one datagram received from `from` during the current cycle.
    pub fn on_reply(&mut self, bytes: &[u8], from: SocketAddr) -> Verdict {
        if from != self.cfg.target {
            self.report.foreign_replies += 1;
            return Verdict::Foreign;
        }
        let Ok(m) = EgmSensorPathCorr::decode(bytes) else {
            self.report.bad += 1;
            return Verdict::Bad;
        };
        if m.header.and_then(|h| h.mtype) != Some(MessageType::PathCorrection as i32) {
            self.report.wrong_type += 1;
            return Verdict::WrongType;
        }
        let pc = m.path_corr.unwrap_or_default();
        let (Some(pos), Some(age)) = (pc.pos, pc.age) else {
            self.report.bad += 1;
            return Verdict::Bad;
        };
        let (Some(x), Some(y), Some(z)) = (pos.x, pos.y, pos.z) else {
            self.report.bad += 1;
            return Verdict::Bad;
        };
        if ![x, y, z].iter().all(|v| v.is_finite()) {
            self.report.bad += 1;
            return Verdict::Bad;
        }
        if let Some(s) = self.sent.as_mut() {
            s.got = Some(([x, y, z], age));
        }
        Verdict::Good
    }

    /// True when the current cycle has its good correction.
    pub fn answered(&self) -> bool {
        self.sent.is_some_and(|s| s.got.is_some())
    }

    /// End the current cycle: take the newest good correction (or hold the last), clamp, filter, move
    /// `mech`, and hand the RAPID program its state variables. `Err` on the communication timeout.
    pub fn end_cycle(&mut self, mech: &mut dyn Mechanism) -> Result<(), Irc5End> {
        let Some(sent) = self.sent.take() else {
            return Ok(());
        };
        let cfg = &self.cfg;
        let r = &mut self.report;
        match sent.got {
            Some((v, age)) => {
                self.wanted = v;
                r.good += 1;
                r.max_age = r.max_age.max(age);
                self.late_count = 0;
            }
            None => {
                r.late += 1;
                self.late_count += 1;
            }
        }
        let lim = wire::m_to_mm(cfg.range.translation);
        let clamped_v = self.wanted.map(|v| v.clamp(-lim, lim));
        let clamped = clamped_v != self.wanted;
        r.clamped += u64::from(clamped);
        let k = match cfg.filter_hz {
            None => 1.0,
            Some(f) => 1.0 - (-2.0 * core::f64::consts::PI * f * cfg.period.as_secs_f64()).exp(),
        };
        for (a, w) in self.applied.iter_mut().zip(clamped_v) {
            *a += k * (w - *a);
        }
        let state = match self.vars.read().map(state_from_numbers) {
            Some(Ok(s)) => Some(s),
            Some(Err(e)) => {
                r.bad_state += 1;
                r.last_bad_state = Some(e);
                None
            }
            None => None,
        };
        if let Some(s) = state {
            mech.process_state(s);
        }
        r.cycles += 1;
        if cfg.log {
            r.log.push(Irc5Cycle {
                seqno: sent.seqno,
                on_time: sent.got.is_some(),
                correction: self.applied,
                clamped,
                age: sent.got.map(|g| g.1),
                command: sent.command,
                state,
            });
        }
        let a = self.applied;
        let c = abb_egm::msg::EgmCartesian {
            x: Some(a[0]),
            y: Some(a[1]),
            z: Some(a[2]),
        };
        let translation = wire::correction_from_wire(&c, &cfg.sensor_frame).unwrap_or_default();
        mech.advance(&Correction {
            translation,
            ..Correction::default()
        });
        self.n += 1;
        if self.late_count >= cfg.comm_timeout {
            return Err(Irc5End::CommTimeout);
        }
        Ok(())
    }
}

/// The simulated controller: [`Irc5Core`] behind a UDP socket.
pub struct Irc5 {
    cfg: Irc5Config,
    vars: RapidVariables,
    sock: UdpSocket,
    abort: Arc<AtomicBool>,
}

impl Irc5 {
    /// Bind the controller's socket (loopback only).
    pub fn new(cfg: Irc5Config) -> io::Result<Self> {
        let bad = |e: String| io::Error::new(io::ErrorKind::InvalidInput, e);
        if !cfg.target.ip().is_loopback() || !cfg.bind.ip().is_loopback() {
            return Err(bad(
                "the simulated controller only talks on loopback addresses".into(),
            ));
        }
        cfg.validate().map_err(bad)?;
        let sock = UdpSocket::bind(cfg.bind)?;
        Ok(Self {
            cfg,
            vars: RapidVariables::default(),
            sock,
            abort: Arc::new(AtomicBool::new(false)),
        })
    }

    /// The controller's own address (what a driver's robot filter must accept).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.sock.local_addr()
    }

    /// The RAPID program's process-state variables (give a clone to the driver as its state channel).
    pub fn rapid_variables(&self) -> RapidVariables {
        self.vars.clone()
    }

    /// A flag that aborts [`Irc5::run`] at the next cycle when set.
    pub fn abort_handle(&self) -> Arc<AtomicBool> {
        self.abort.clone()
    }

    /// Run EGM until it ends.
    pub fn run(&mut self, mech: &mut dyn Mechanism) -> Irc5Report {
        let mut core = match Irc5Core::new(self.cfg.clone(), self.vars.clone()) {
            Ok(c) => c,
            Err(e) => {
                let mut r = Irc5Report::empty();
                r.end = Irc5End::Io(e);
                return r;
            }
        };
        let end = self.go(&mut core, mech);
        let mut report = core.report;
        report.end = end;
        report
    }

    fn go(&self, core: &mut Irc5Core, mech: &mut dyn Mechanism) -> Irc5End {
        let cfg = &self.cfg;
        let start = Instant::now();
        let mut rx = vec![0u8; 65536];
        loop {
            if self.abort.load(Ordering::Relaxed) {
                return Irc5End::Aborted;
            }
            let n = core.cycle_index();
            let cycle_start = match cfg.timing {
                Timing::Realtime => start + cfg.period * (n as u32),
                Timing::Lockstep { .. } => Instant::now(),
            };
            if cfg.timing == Timing::Realtime {
                let now = Instant::now();
                if cycle_start > now {
                    std::thread::sleep(cycle_start - now);
                }
            }
            let garbage = cfg.garbage.contains(&n);
            let datagram = match core.next_cycle(mech) {
                Ok(d) => d,
                Err(end) => return end,
            };
            if garbage && let Err(e) = self.sock.send_to(b"\xff\xff not protobuf", cfg.target) {
                return Irc5End::Io(e.to_string());
            }
            if let Err(e) = self.sock.send_to(datagram, cfg.target) {
                return Irc5End::Io(e.to_string());
            }
            let deadline = core.reply_deadline(cycle_start, Instant::now());
            // Until the cycle's good correction or the deadline (the end of the period in real time).
            loop {
                if core.answered() {
                    break;
                }
                let now = Instant::now();
                if now >= deadline {
                    break;
                }
                if let Err(e) = self.sock.set_read_timeout(Some(deadline - now)) {
                    return Irc5End::Io(e.to_string());
                }
                match self.sock.recv_from(&mut rx) {
                    Ok((len, from)) => {
                        core.on_reply(&rx[..len], from);
                    }
                    Err(e) if abb_egm::link::is_transient(&e) => {}
                    Err(e) => return Irc5End::Io(e.to_string()),
                }
            }
            if !core.answered() && self.abort.load(Ordering::Relaxed) {
                return Irc5End::Aborted;
            }
            if let Err(end) = core.end_cycle(mech) {
                return end;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    //! The controller's core without sockets or clocks.
    use super::*;
    use crate::krc::RigidArm;
    use abb_egm::msg::{EgmCartesian, EgmPathCorr};
    use hal::{ProcessMode, ProcessPhase, Vector3};

    fn pc() -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], 6510))
    }

    fn core(tweak: impl FnOnce(&mut Irc5Config)) -> (Irc5Core, RapidVariables) {
        let mut cfg = Irc5Config::new(pc());
        cfg.log = true;
        tweak(&mut cfg);
        let vars = RapidVariables::default();
        (Irc5Core::new(cfg, vars.clone()).unwrap(), vars)
    }

    fn arm() -> RigidArm {
        RigidArm::new(Pose::from_position(Vector3::new(0.5, 0.0, 0.3)))
    }

    fn corr(z_mm: f64, mtype: MessageType) -> Vec<u8> {
        EgmSensorPathCorr {
            header: Some(EgmHeader {
                seqno: Some(1),
                tm: None,
                mtype: Some(mtype as i32),
            }),
            path_corr: Some(EgmPathCorr {
                pos: Some(EgmCartesian {
                    x: Some(0.0),
                    y: Some(0.0),
                    z: Some(z_mm),
                }),
                age: Some(2),
            }),
        }
        .encode_to_vec()
    }

    #[test]
    fn a_good_correction_moves_the_arm_and_the_message_decodes() {
        let (mut c, _) = core(|_| {});
        let mut m = arm();
        let bytes = c.next_cycle(&mut m).unwrap().to_vec();
        let r = EgmRobot::decode(&bytes[..]).unwrap();
        assert_eq!(r.header.unwrap().seqno, Some(1));
        let p = r.feed_back.unwrap().cartesian.unwrap().pos.unwrap();
        assert_eq!((p.x, p.z), (Some(500.0), Some(300.0)));
        assert_eq!(
            c.on_reply(&corr(1.5, MessageType::PathCorrection), pc()),
            Verdict::Good
        );
        c.end_cycle(&mut m).unwrap();
        assert!((m.correction.translation.z - 0.0015).abs() < 1e-12);
        let rep = c.report();
        assert_eq!((rep.cycles, rep.good, rep.max_age), (1, 1, 2));
    }

    #[test]
    fn bad_replies_are_judged_held_and_reach_the_comm_timeout() {
        let (mut c, _) = core(|k| k.comm_timeout = 3);
        let mut m = arm();
        c.next_cycle(&mut m).unwrap();
        c.on_reply(&corr(1.0, MessageType::PathCorrection), pc());
        c.end_cycle(&mut m).unwrap();
        let other = SocketAddr::from(([127, 0, 0, 1], 1));
        let mut end = Ok(());
        for (bytes, from, v) in [
            (corr(2.0, MessageType::Correction), pc(), Verdict::WrongType),
            (b"\x0a\xff".to_vec(), pc(), Verdict::Bad),
            (
                corr(2.0, MessageType::PathCorrection),
                other,
                Verdict::Foreign,
            ),
        ] {
            c.next_cycle(&mut m).unwrap();
            assert_eq!(c.on_reply(&bytes, from), v);
            end = c.end_cycle(&mut m);
        }
        assert_eq!(end, Err(Irc5End::CommTimeout));
        assert!(
            (m.correction.translation.z - 0.001).abs() < 1e-12,
            "the last good correction is held"
        );
        let r = c.report();
        assert_eq!(
            (r.late, r.wrong_type, r.bad, r.foreign_replies),
            (3, 1, 1, 1)
        );
    }

    #[test]
    fn the_range_clamps_and_the_filter_lags() {
        let (mut c, _) = core(|k| k.filter_hz = Some(10.0));
        let mut m = arm();
        let mut zs = Vec::new();
        for _ in 0..200 {
            c.next_cycle(&mut m).unwrap();
            c.on_reply(&corr(9.0, MessageType::PathCorrection), pc());
            c.end_cycle(&mut m).unwrap();
            zs.push(m.correction.translation.z);
        }
        let k = 1.0 - (-2.0 * core::f64::consts::PI * 10.0 * 0.004_f64).exp();
        assert!(
            (zs[0] - 0.005 * k).abs() < 1e-12,
            "first-order step: {}",
            zs[0]
        );
        assert!(zs.windows(2).all(|w| w[1] >= w[0]));
        assert!((zs[199] - 0.005).abs() < 1e-6, "settles at the 5 mm range");
        assert_eq!(c.report().clamped, 200);
    }

    #[test]
    fn the_process_command_goes_out_and_the_state_comes_back_from_rapid_variables() {
        let (mut c, mut vars) = core(|k| k.process = Some(CommandSlots::default()));
        let mut m = arm();
        let bytes = c.next_cycle(&mut m).unwrap().to_vec();
        let r = EgmRobot::decode(&bytes[..]).unwrap();
        assert_eq!(
            r.rapid_from_robot.unwrap().dnum,
            [0.0, 0.0, 0.0, 0.0],
            "OFF without a program"
        );
        vars.publish(&ProcessState {
            phase: ProcessPhase::Pressing,
            force: 19.9,
            fault: hal::ProcessFault::None,
        })
        .unwrap();
        c.end_cycle(&mut m).unwrap();
        assert_eq!(
            c.report().log[0].state.unwrap().phase,
            ProcessPhase::Pressing
        );
        vars.write([7.0, 0.0, 0.0]);
        c.next_cycle(&mut m).unwrap();
        c.end_cycle(&mut m).unwrap();
        assert_eq!(c.report().bad_state, 1);
        assert_eq!(c.report().log[1].state, None);
        assert_eq!(c.report().log[0].command.unwrap().mode, ProcessMode::Off);
    }

    #[test]
    fn cycles_silence_and_a_new_session() {
        let (mut c, _) = core(|k| {
            k.cycles = Some(3);
            k.new_session = Some((1, 9000));
        });
        let mut m = arm();
        let mut seq = Vec::new();
        while let Ok(b) = c.next_cycle(&mut m) {
            seq.push(EgmRobot::decode(b).unwrap().header.unwrap().seqno.unwrap());
            c.end_cycle(&mut m).unwrap();
        }
        assert_eq!(seq, [1, 9000, 9001]);
        let (mut c, _) = core(|k| k.silent_from = Some(0));
        assert_eq!(c.next_cycle(&mut m).err(), Some(Irc5End::Silent));
    }
}
