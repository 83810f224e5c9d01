//! A simulated KUKA robot controller speaking RSI over real UDP: the client and clock master.
//!
//! It uses the driver's codec for the opposite direction (writes `<Rob>`, parses `<Sen>`) from the
//! same Ethernet config, judges every reply (parses, SENTYPE, IPOC, deadline), keeps the `Delay`
//! counter, applies HOLDON per element, breaks off after `Timeout` late replies, clamps with POSCORR,
//! stops on POSCORRMON and on `Stop`, and moves a [`Mechanism`] (the shared [`World`](crate::World) in a cell
//! simulation) with the correction it accepted. Fault injection covers what networks and peers do.
//!
//! The decisions live in [`KrcCore`], which does no I/O and reads no clock (unit-tested without sockets);
//! [`Krc`] is its shell: the socket, the timing and the fault plan. With the process channels in the config
//! it sends the [`Mechanism`]'s `FcCmd` every cycle and hands it every cycle's `FcState`.
//!
//! Timing is either **real time** (one `<Rob>` every period, a reply is on time when it arrives before
//! the next one is due) or **lockstep** (the next `<Rob>` right after a good reply, or after a wall-clock
//! deadline when none came), which runs a cell faster than real time with the same protocol.

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use hal::{Correction, Pose, ProcessCommand, ProcessState};
use kuka_rsi::codec::{Frame, Ipoc, Schema};
use kuka_rsi::{
    CommandSlots, CorrectionMode, EthernetConfig, ParseError, PoscorrLimits, ProcessError,
    StateSlots, wire,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::world::{SharedWorld, lock};

/// What the robot's motion looks like to the controller.
pub trait Mechanism {
    /// Measured and programmed tool pose now.
    fn poses(&mut self) -> (Pose, Pose);
    /// Apply the total correction accepted this cycle (SI, tool frame, after POSCORR) and advance
    /// one period.
    fn advance(&mut self, correction: &Correction);
    /// The robot program's process command for the cycle about to be sent (`FcCmd`), if it runs one.
    /// Sent only when the Ethernet config declares the `FcCmd` elements.
    fn process_command(&mut self) -> Option<ProcessCommand> {
        None
    }
    /// The process state the PC sent in its reply to the last cycle (`FcState`), when the config
    /// declares it.
    fn process_state(&mut self, _state: ProcessState) {}
}

impl Mechanism for SharedWorld {
    fn poses(&mut self) -> (Pose, Pose) {
        let c = lock(self).cycle();
        (c.actual, c.programmed)
    }

    fn advance(&mut self, correction: &Correction) {
        lock(self).advance(Some(correction));
    }

    fn process_command(&mut self) -> Option<ProcessCommand> {
        lock(self).process_command()
    }

    fn process_state(&mut self, state: ProcessState) {
        lock(self).process_reply(state);
    }
}

/// A stiff arm: the measured pose is the programmed pose plus the correction of the previous cycle.
#[derive(Clone, Debug)]
pub struct RigidArm {
    /// The programmed pose.
    pub programmed: Pose,
    /// The correction last applied.
    pub correction: Correction,
}

impl RigidArm {
    /// An arm at `programmed` with no correction.
    pub fn new(programmed: Pose) -> Self {
        Self {
            programmed,
            correction: Correction::default(),
        }
    }
}

impl Mechanism for RigidArm {
    fn poses(&mut self) -> (Pose, Pose) {
        let p = self.programmed;
        let q = p.orientation * hal::UnitQuaternion::from_scaled_axis(self.correction.rotation);
        let actual = Pose {
            position: p.position + p.orientation * self.correction.translation,
            orientation: q,
        };
        (actual, p)
    }

    fn advance(&mut self, correction: &Correction) {
        self.correction = *correction;
    }
}

/// When the next `<Rob>` goes out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Timing {
    /// Every period on the wall clock; a reply is late when it has not arrived when the next
    /// datagram is due.
    Realtime,
    /// Right after a good reply; a reply that has not arrived within `deadline` is late.
    Lockstep {
        /// Wall-clock wait for a reply.
        deadline: Duration,
    },
}

/// How late replies add up towards `Timeout` (the manual does not say; both are offered).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Counting {
    /// Reset by every good reply.
    #[default]
    Consecutive,
    /// Never reset within a session.
    Cumulative,
}

/// A bad datagram the controller can be told to send.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Garbage {
    /// Not XML.
    Malformed,
    /// A well-formed `<Rob>` padded to this many bytes.
    Oversized(usize),
    /// A `<Rob>` with a non-ASCII byte.
    NonAscii,
    /// The first half of a `<Rob>`.
    Truncated,
}

/// Faults to inject. Probabilities are per cycle, drawn from a seeded generator.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Faults {
    /// Extra random delay before each send, up to this (real time only).
    pub jitter: Duration,
    /// Probability that a `<Rob>` is lost on the way to the PC.
    pub drop_rob: f64,
    /// Probability that a `<Sen>` is lost on the way back.
    pub drop_sen: f64,
    /// Probability that a `<Rob>` arrives twice.
    pub duplicate: f64,
    /// Probability that a `<Rob>` is held back and arrives after the next one.
    pub reorder: f64,
    /// `(cycle, n)`: the network holds the datagrams of `n` cycles from `cycle` on, then delivers
    /// them in one burst together with the current one.
    pub stall: Option<(u64, u64)>,
    /// Bad datagrams sent just before the good one of a cycle.
    pub garbage: Vec<(u64, Garbage)>,
    /// Cycles at which a valid-looking `<Rob>` also arrives from another source.
    pub foreign: Vec<u64>,
    /// From this cycle on the controller sends nothing (RSI ended without goodbye).
    pub silent_from: Option<u64>,
    /// `(cycle, base)`: a new RSI session starts here with IPOC `base` (correction reset to zero).
    pub new_session: Option<(u64, u64)>,
}

/// The simulated controller's settings.
#[derive(Clone, Debug, PartialEq)]
pub struct KrcConfig {
    /// The Ethernet config (same file as the driver's).
    pub ethernet: EthernetConfig,
    /// Where the PC listens (a loopback address).
    pub target: SocketAddr,
    /// Where the controller binds (default `127.0.0.1:0`).
    pub bind: SocketAddr,
    /// Real time or lockstep.
    pub timing: Timing,
    /// Interpolation cycle.
    pub period: Duration,
    /// IPOC of the first cycle.
    pub ipoc_base: u64,
    /// IPOC step per cycle (period in ms for RSI 3; 1 for RSI 2.x).
    pub ipoc_step: u64,
    /// ETHERNET `Timeout`: late replies tolerated; reaching it breaks off.
    pub timeout: u32,
    /// How late replies add up.
    pub counting: Counting,
    /// `#ABSOLUTE` or `#RELATIVE`.
    pub mode: CorrectionMode,
    /// POSCORR: the total correction is clamped per axis to these.
    pub poscorr: PoscorrLimits,
    /// POSCORRMON: RSI stops when the overall correction exceeds these (norms).
    pub poscorrmon: PoscorrLimits,
    /// ETHERNET `Precision` (decimals sent).
    pub precision: u8,
    /// End after this many cycles (`None`: until stopped, silent or broken off).
    pub cycles: Option<u64>,
    /// Faults.
    pub faults: Faults,
    /// Seed of the fault generator.
    pub seed: u64,
    /// Keep a per-cycle log in the report.
    pub log: bool,
}

impl KrcConfig {
    /// Lockstep (1 s deadline) at 4 ms against `target`, Timeout 100 consecutive, absolute,
    /// default POSCORR (5 mm, 5°) and POSCORRMON (6 mm, 6°), precision 4.
    pub fn new(ethernet: EthernetConfig, target: SocketAddr) -> Self {
        Self {
            ethernet,
            target,
            bind: SocketAddr::from(([127, 0, 0, 1], 0)),
            timing: Timing::Lockstep {
                deadline: Duration::from_secs(1),
            },
            period: Duration::from_millis(4),
            ipoc_base: 1_000_000,
            ipoc_step: 4,
            timeout: 100,
            counting: Counting::Consecutive,
            mode: CorrectionMode::Absolute,
            poscorr: PoscorrLimits::default(),
            poscorrmon: PoscorrLimits::MONITOR_DEFAULT,
            precision: 4,
            cycles: None,
            faults: Faults::default(),
            seed: 1,
            log: false,
        }
    }
}

/// Why the controller stopped.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum KrcEnd {
    /// The configured number of cycles ran.
    Completed,
    /// The PC raised `Stop`: `RSI_MOVECORR` ended cleanly.
    Stopped,
    /// `Timeout` late replies: KSS29002 RSITimeout.
    Timeout,
    /// POSCORRMON tripped.
    PoscorrMon,
    /// The controller went silent (fault injection).
    Silent,
    /// Aborted from outside.
    Aborted,
    /// A socket error.
    Io(String),
}

/// One cycle as the controller saw it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KrcCycle {
    /// IPOC sent.
    pub ipoc: u64,
    /// `Delay` sent.
    pub delay: u32,
    /// A good, matching reply arrived in time.
    pub on_time: bool,
    /// The total correction applied after POSCORR, `[X Y Z A B C]` mm and degrees.
    pub correction: [f64; 6],
    /// POSCORR clamped something.
    pub clamped: bool,
    /// The `FcCmd` sent (when the config declares it).
    pub command: Option<ProcessCommand>,
    /// The `FcState` in effect after this cycle's reply, HOLDON applied (when the config declares it).
    pub state: Option<ProcessState>,
}

/// What happened.
#[derive(Clone, Debug, PartialEq)]
pub struct KrcReport {
    /// Why it ended.
    pub end: KrcEnd,
    /// Cycles run.
    pub cycles: u64,
    /// Good replies in time.
    pub good: u64,
    /// Late or missing replies.
    pub late: u64,
    /// Replies that did not parse (other than SENTYPE).
    pub bad: u64,
    /// Replies with the wrong `Type`.
    pub wrong_sentype: u64,
    /// Replies whose `FcState` broke the contract (a State or Fault code it does not define); counted
    /// as bad replies, not applied.
    pub bad_process: u64,
    /// The last such `FcState` error.
    pub last_bad_process: Option<ProcessError>,
    /// Replies with an IPOC other than the cycle's.
    pub ipoc_mismatch: u64,
    /// Replies from a source other than the PC's address.
    pub foreign_replies: u64,
    /// Replies received although the config says ONLYSEND.
    pub unexpected_replies: u64,
    /// Largest `Delay` sent.
    pub max_delay: u32,
    /// Cycles in which POSCORR clamped.
    pub clamped: u64,
    /// Per-cycle log (when asked for).
    pub log: Vec<KrcCycle>,
    /// The last parse error of a bad reply.
    pub last_bad: Option<ParseError>,
}

/// The simulated controller.
pub struct Krc {
    cfg: KrcConfig,
    sock: UdpSocket,
    foreign: Option<UdpSocket>,
    abort: Arc<AtomicBool>,
}

const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];

impl Krc {
    /// Bind the controller's socket.
    pub fn new(cfg: KrcConfig) -> io::Result<Self> {
        let bad = |e: String| io::Error::new(io::ErrorKind::InvalidInput, e);
        if !cfg.target.ip().is_loopback() || !cfg.bind.ip().is_loopback() {
            return Err(bad(
                "the simulated controller only talks on loopback addresses".into(),
            ));
        }
        // Check the config once here, so that `run` cannot fail on it.
        KrcCore::new(cfg.clone()).map_err(bad)?;
        let sock = UdpSocket::bind(cfg.bind)?;
        let foreign = if cfg.faults.foreign.is_empty() {
            None
        } else {
            Some(UdpSocket::bind(SocketAddr::new(cfg.bind.ip(), 0))?)
        };
        Ok(Self {
            cfg,
            sock,
            foreign,
            abort: Arc::new(AtomicBool::new(false)),
        })
    }

    /// The controller's own address (what a driver's robot filter must accept).
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.sock.local_addr()
    }

    /// The address foreign datagrams come from, when the fault plan has any.
    pub fn foreign_addr(&self) -> Option<SocketAddr> {
        self.foreign.as_ref().and_then(|s| s.local_addr().ok())
    }

    /// A flag that aborts [`Krc::run`] at the next cycle when set.
    pub fn abort_handle(&self) -> Arc<AtomicBool> {
        self.abort.clone()
    }

    /// Run one RSI session (or several, with injected new sessions) until it ends.
    pub fn run(&mut self, mech: &mut dyn Mechanism) -> KrcReport {
        let core = match KrcCore::new(self.cfg.clone()) {
            Ok(c) => c,
            Err(e) => {
                let mut r = KrcReport::empty();
                r.end = KrcEnd::Io(e);
                return r;
            }
        };
        let mut run = Run {
            core,
            rng: ChaCha8Rng::seed_from_u64(self.cfg.seed),
            rx_buf: vec![0; 65536],
            stalled: Vec::new(),
            reordered: None,
        };
        let end = run.go(self, mech);
        let mut report = run.core.into_report();
        report.end = end;
        report
    }
}

impl KrcReport {
    fn empty() -> Self {
        Self {
            end: KrcEnd::Completed,
            cycles: 0,
            good: 0,
            late: 0,
            bad: 0,
            wrong_sentype: 0,
            bad_process: 0,
            last_bad_process: None,
            ipoc_mismatch: 0,
            foreign_replies: 0,
            unexpected_replies: 0,
            max_delay: 0,
            clamped: 0,
            log: Vec::new(),
            last_bad: None,
        }
    }
}

/// What [`KrcCore::on_reply`] made of one datagram.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReplyVerdict {
    /// A good reply to the current cycle: it will be applied.
    Good,
    /// From a source other than the PC's address.
    Foreign,
    /// The config says ONLYSEND: no reply was expected.
    Unexpected,
    /// The root's `Type` is not SENTYPE.
    WrongSentype,
    /// Does not parse as `<Sen>`.
    Bad,
    /// Parses, but answers another IPOC.
    IpocMismatch,
    /// Parses, but its `FcState` breaks the contract.
    BadProcess,
    /// The current cycle already has its good reply, or none is awaited.
    Ignored,
}

struct CoreSlots {
    rist: Option<[usize; 6]>,
    rsol: Option<[usize; 6]>,
    delay: Option<usize>,
    rkorr: [Option<usize>; 6],
    stop: Option<usize>,
    cmd: Option<CommandSlots>,
    state: Option<StateSlots>,
}

/// The current cycle: what was sent.
#[derive(Clone, Copy)]
struct Sent {
    ipoc: u64,
    delay: u32,
    command: Option<ProcessCommand>,
    good: bool,
}

/// The simulated controller's decisions without I/O: it writes each cycle's `<Rob>`, judges the
/// replies it is given (source, parse, SENTYPE, IPOC, `FcState`), and at the end of each cycle
/// applies HOLDON, counts late replies towards `Timeout`, clamps with POSCORR, checks POSCORRMON and
/// `Stop`, and moves the [`Mechanism`]. It reads no clock and owns no socket: the shell ([`Krc`])
/// decides when a cycle starts and when its reply window closes ([`KrcCore::reply_deadline`]), and
/// carries the datagrams through the fault plan.
///
/// One cycle: [`next_cycle`](Self::next_cycle) → send its bytes → [`on_reply`](Self::on_reply) for
/// each datagram received until a good one or the deadline → [`end_cycle`](Self::end_cycle).
pub struct KrcCore {
    cfg: KrcConfig,
    rob: Schema,
    sen: Schema,
    slots: CoreSlots,
    report: KrcReport,
    rob_frame: Frame,
    sen_frame: Frame,
    rob_buf: Vec<u8>,
    /// Received values of the RECEIVE elements, by slot (HOLDON state).
    held: Vec<f64>,
    /// The same values as a frame, for decoding `FcState` as the robot program sees it.
    held_frame: Frame,
    total: [f64; 6],
    late_count: u32,
    stop_prev: bool,
    ipoc_base: u64,
    session_start: u64,
    n: u64,
    started: bool,
    sent: Option<Sent>,
}

impl KrcCore {
    /// Derive the schemas and process channels from the config.
    pub fn new(cfg: KrcConfig) -> Result<Self, String> {
        let rob = cfg
            .ethernet
            .rob_schema(cfg.precision)
            .map_err(|e| e.to_string())?;
        let mut sen = cfg
            .ethernet
            .sen_schema(cfg.precision)
            .map_err(|e| e.to_string())?;
        let slots = CoreSlots {
            rist: rob.six("RIst", POSE),
            rsol: rob.six("RSol", POSE),
            delay: rob.slot("Delay", "D"),
            rkorr: POSE.map(|a| sen.slot("RKorr", a)),
            stop: sen.slot("Stop", ""),
            cmd: CommandSlots::find(&rob)?,
            state: StateSlots::find(&mut sen)?,
        };
        Ok(Self {
            held: vec![0.0; sen.slots()],
            rob,
            sen,
            slots,
            report: KrcReport::empty(),
            rob_frame: Frame::new(),
            sen_frame: Frame::new(),
            rob_buf: vec![0; 65536],
            held_frame: Frame::new(),
            total: [0.0; 6],
            late_count: 0,
            stop_prev: false,
            ipoc_base: cfg.ipoc_base,
            session_start: 0,
            n: 0,
            started: false,
            sent: None,
            cfg,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &KrcConfig {
        &self.cfg
    }

    /// The `<Rob>` schema.
    pub fn rob_schema(&self) -> &Schema {
        &self.rob
    }

    /// The `<Rob>` frame of the current cycle.
    pub fn rob_frame(&self) -> &Frame {
        &self.rob_frame
    }

    /// Cycles begun so far (the index of the current one).
    pub fn cycle_index(&self) -> u64 {
        self.n
    }

    /// The report so far.
    pub fn report(&self) -> &KrcReport {
        &self.report
    }

    /// The report (its `end` is the shell's to set).
    pub fn into_report(self) -> KrcReport {
        self.report
    }

    /// When the reply window of a cycle begun at `cycle_start` and sent at `sent_at` closes:
    /// real time, the next period; lockstep, the configured deadline after sending (one period when
    /// the robot only sends).
    pub fn reply_deadline(&self, cycle_start: Instant, sent_at: Instant) -> Instant {
        match self.cfg.timing {
            Timing::Realtime => cycle_start + self.cfg.period,
            Timing::Lockstep { .. } if self.cfg.ethernet.onlysend => sent_at + self.cfg.period,
            Timing::Lockstep { deadline } => sent_at + deadline,
        }
    }

    /// Begin the next cycle and write its `<Rob>`; `Err` when the run ends before it (the cycle
    /// count ran out, or the fault plan makes the controller fall silent).
    pub fn next_cycle(&mut self, mech: &mut dyn Mechanism) -> Result<&[u8], KrcEnd> {
        let cfg = &self.cfg;
        if !self.started {
            self.started = true;
            if cfg.mode == CorrectionMode::Absolute {
                // A simulated cell may start with its tool away from the programmed path: that offset
                // is the correction in effect, as if an earlier RSI session had left it there, so a late
                // first reply holds it instead of dropping the tool back onto the path.
                let (actual, programmed) = mech.poses();
                let offset = programmed
                    .orientation
                    .inverse_transform_vector(&(actual.position - programmed.position));
                let wire0 = wire::offset_to_wire(&offset, &hal::Vector3::zeros());
                for (i, slot) in self.slots.rkorr.iter().enumerate() {
                    if let Some(s) = slot {
                        self.held[*s] = wire0[i];
                    }
                }
                self.total = wire0;
            }
        }
        let n = self.n;
        if cfg.cycles.is_some_and(|c| n >= c) {
            return Err(KrcEnd::Completed);
        }
        if cfg.faults.silent_from.is_some_and(|s| n >= s) {
            return Err(KrcEnd::Silent);
        }
        if let Some((at, base)) = cfg.faults.new_session
            && at == n
        {
            // RSI_OFF … RSI_ON: a new IPOC base, the correction and the counters start again.
            self.ipoc_base = base;
            self.session_start = n;
            self.total = [0.0; 6];
            self.held.iter_mut().for_each(|v| *v = 0.0);
            self.late_count = 0;
            self.stop_prev = false;
        }
        let ipoc = self.ipoc_base + (n - self.session_start) * cfg.ipoc_step;
        let delay = self.late_count;
        self.report.max_delay = self.report.max_delay.max(delay);
        let (actual, programmed) = mech.poses();
        if let Some(s) = self.slots.rist {
            self.rob_frame.set6(s, wire::pose_to_wire(&actual));
        }
        if let Some(s) = self.slots.rsol {
            self.rob_frame.set6(s, wire::pose_to_wire(&programmed));
        }
        if let Some(s) = self.slots.delay {
            self.rob_frame.set(s, f64::from(delay));
        }
        // The robot program's process command; a controller running no program sends OFF.
        let command = self.slots.cmd.map(|slots| {
            let c = mech.process_command().unwrap_or(ProcessCommand {
                mode: hal::ProcessMode::Off,
                force: 0.0,
                ramp: 0.0,
                segment: 0,
            });
            slots.encode(&c, &mut self.rob_frame);
            c
        });
        self.rob_frame.set_ipoc(Ipoc::new(ipoc));
        let len = self
            .rob
            .write(&self.rob_frame, &mut self.rob_buf)
            .map_err(|e| KrcEnd::Io(format!("cannot encode <Rob>: {e}")))?;
        self.sent = Some(Sent {
            ipoc,
            delay,
            command,
            good: false,
        });
        Ok(&self.rob_buf[..len])
    }

    /// Judge one datagram received from `from` during the current cycle.
    pub fn on_reply(&mut self, bytes: &[u8], from: SocketAddr) -> ReplyVerdict {
        if from != self.cfg.target {
            self.report.foreign_replies += 1;
            return ReplyVerdict::Foreign;
        }
        if self.cfg.ethernet.onlysend {
            self.report.unexpected_replies += 1;
            return ReplyVerdict::Unexpected;
        }
        let Some(sent) = self.sent.as_mut().filter(|s| !s.good) else {
            return ReplyVerdict::Ignored;
        };
        match self.sen.parse(bytes, &mut self.sen_frame) {
            Err(ParseError::WrongType) => {
                self.report.wrong_sentype += 1;
                self.report.last_bad = Some(ParseError::WrongType);
                ReplyVerdict::WrongSentype
            }
            Err(e) => {
                self.report.bad += 1;
                self.report.last_bad = Some(e);
                ReplyVerdict::Bad
            }
            Ok(()) if self.sen_frame.ipoc().value() != sent.ipoc => {
                self.report.ipoc_mismatch += 1;
                ReplyVerdict::IpocMismatch
            }
            Ok(()) => match self.slots.state.map(|s| s.decode(&self.sen_frame)) {
                Some(Err(e)) => {
                    self.report.bad_process += 1;
                    self.report.last_bad_process = Some(e);
                    ReplyVerdict::BadProcess
                }
                _ => {
                    sent.good = true;
                    ReplyVerdict::Good
                }
            },
        }
    }

    /// End the current cycle: apply the good reply (or HOLDON and a late count without one), clamp,
    /// monitor and move `mech`. `Err` when RSI stops (Stop, POSCORRMON, Timeout).
    pub fn end_cycle(&mut self, mech: &mut dyn Mechanism) -> Result<(), KrcEnd> {
        let Some(sent) = self.sent.take() else {
            return Ok(());
        };
        let cfg = &self.cfg;
        let good = sent.good;
        if cfg.ethernet.onlysend {
            // The robot only sends: nothing is judged, nothing is late, nothing is applied.
            self.report.cycles += 1;
            mech.advance(&Correction::default());
            self.n += 1;
            return Ok(());
        }

        // HOLDON per element, then the correction mode.
        for f in self.sen.elements().iter().flat_map(|e| e.fields()) {
            if let Some(s) = f.slot {
                if good {
                    self.held[s] = self.sen_frame.get(s);
                } else if !f.holdon {
                    self.held[s] = 0.0;
                }
                self.held_frame.set(s, self.held[s]);
            }
        }
        // FcState as the robot program reads it (HOLDON applied). Only replies whose FcState
        // decoded were accepted as good, so the held values always decode.
        let state = self
            .slots
            .state
            .and_then(|slots| slots.decode(&self.held_frame).ok());
        if let Some(st) = state {
            mech.process_state(st);
        }
        if good {
            self.report.good += 1;
            if cfg.counting == Counting::Consecutive {
                self.late_count = 0;
            }
        } else {
            self.report.late += 1;
            self.late_count += 1;
        }
        let rk: [f64; 6] = self.slots.rkorr.map(|s| s.map_or(0.0, |s| self.held[s]));
        let wanted = match cfg.mode {
            CorrectionMode::Absolute => rk,
            CorrectionMode::Relative => core::array::from_fn(|i| self.total[i] + rk[i]),
        };
        let lim_t = wire::m_to_mm(cfg.poscorr.translation);
        let lim_r = cfg.poscorr.rotation.to_degrees();
        let clamped: [f64; 6] = core::array::from_fn(|i| {
            let l = if i < 3 { lim_t } else { lim_r };
            wanted[i].clamp(-l, l)
        });
        let was_clamped = clamped != wanted;
        self.report.clamped += u64::from(was_clamped);
        self.total = clamped;
        self.report.cycles += 1;
        if cfg.log {
            self.report.log.push(KrcCycle {
                ipoc: sent.ipoc,
                delay: sent.delay,
                on_time: good,
                correction: clamped,
                clamped: was_clamped,
                command: sent.command,
                state,
            });
        }
        let t_norm = clamped[..3].iter().map(|v| v * v).sum::<f64>().sqrt();
        let r_norm = clamped[3..].iter().map(|v| v * v).sum::<f64>().sqrt();
        if t_norm > wire::m_to_mm(cfg.poscorrmon.translation)
            || r_norm > cfg.poscorrmon.rotation.to_degrees()
        {
            return Err(KrcEnd::PoscorrMon);
        }
        let (translation, rotation) = wire::offset_from_wire(clamped);
        mech.advance(&Correction {
            translation,
            rotation,
            stop: false,
            ..Correction::default()
        });
        self.n += 1;
        let stop = self.slots.stop.is_some_and(|s| self.held[s] != 0.0);
        if stop && !self.stop_prev {
            return Err(KrcEnd::Stopped);
        }
        self.stop_prev = stop;
        if self.late_count >= cfg.timeout {
            return Err(KrcEnd::Timeout);
        }
        Ok(())
    }
}

/// The socket shell of one run: timing, the fault plan, sending and receiving.
struct Run {
    core: KrcCore,
    rng: ChaCha8Rng,
    rx_buf: Vec<u8>,
    stalled: Vec<Vec<u8>>,
    reordered: Option<Vec<u8>>,
}

impl Run {
    fn go(&mut self, k: &Krc, mech: &mut dyn Mechanism) -> KrcEnd {
        let cfg = &k.cfg;
        let start = Instant::now();
        loop {
            if k.abort.load(Ordering::Relaxed) {
                return KrcEnd::Aborted;
            }
            let n = self.core.cycle_index();
            let cycle_start = match cfg.timing {
                Timing::Realtime => start + cfg.period * (n as u32),
                Timing::Lockstep { .. } => Instant::now(),
            };
            if let Timing::Realtime = cfg.timing {
                sleep_until(cycle_start);
            }
            let datagram = match self.core.next_cycle(mech) {
                Ok(d) => d.to_vec(),
                Err(end) => return end,
            };
            if let Err(e) = self.send_cycle(k, n, datagram) {
                return KrcEnd::Io(e.to_string());
            }
            let deadline = self.core.reply_deadline(cycle_start, Instant::now());
            let good = match self.await_reply(k, deadline) {
                Ok(g) => g,
                Err(e) => return KrcEnd::Io(e.to_string()),
            };
            if !good && k.abort.load(Ordering::Relaxed) {
                // Aborted while waiting: the PC side is finished, this cycle is not judged.
                return KrcEnd::Aborted;
            }
            if let Err(end) = self.core.end_cycle(mech) {
                return end;
            }
        }
    }

    /// Send this cycle's `<Rob>` through the fault plan.
    fn send_cycle(&mut self, k: &Krc, n: u64, datagram: Vec<u8>) -> io::Result<()> {
        let cfg = &k.cfg;
        let f = &cfg.faults;
        if !f.jitter.is_zero() && cfg.timing == Timing::Realtime {
            let j = self.rng.random_range(0..=f.jitter.as_nanos() as u64);
            std::thread::sleep(Duration::from_nanos(j));
        }
        if let Some(sock) = &k.foreign
            && f.foreign.contains(&n)
        {
            let mut fake = self.core.rob_frame().clone();
            fake.set_ipoc(Ipoc::new(fake.ipoc().value() + 1));
            let mut buf = vec![0u8; 65536];
            let len = self
                .core
                .rob_schema()
                .write(&fake, &mut buf)
                .map_err(|e| io::Error::other(e.to_string()))?;
            sock.send_to(&buf[..len], cfg.target)?;
        }
        for (_, g) in f.garbage.iter().filter(|(at, _)| *at == n) {
            let bytes = match *g {
                Garbage::Malformed => b"<Rob Type=\"KUKA\"><RIst X=\"1\"".to_vec(),
                Garbage::Truncated => datagram[..datagram.len() / 2].to_vec(),
                Garbage::NonAscii => {
                    let mut d = datagram.clone();
                    let at = d.len() / 3;
                    d[at] = 0xC3;
                    d
                }
                Garbage::Oversized(size) => {
                    let mut d = datagram.clone();
                    let pad = size.saturating_sub(d.len());
                    let at = d.len() - "</Rob>".len();
                    d.splice(at..at, core::iter::repeat_n(b' ', pad));
                    d
                }
            };
            k.sock.send_to(&bytes, cfg.target)?;
        }
        if let Some((at, len)) = f.stall
            && n >= at
            && n < at + len
        {
            self.stalled.push(datagram);
            return Ok(());
        }
        for d in self.stalled.drain(..) {
            k.sock.send_to(&d, cfg.target)?;
        }
        if self.rng.random_bool(f.drop_rob.clamp(0.0, 1.0)) {
            return Ok(());
        }
        if self.rng.random_bool(f.reorder.clamp(0.0, 1.0)) {
            if let Some(old) = self.reordered.replace(datagram) {
                k.sock.send_to(&old, cfg.target)?;
            }
            return Ok(());
        }
        k.sock.send_to(&datagram, cfg.target)?;
        if let Some(old) = self.reordered.take() {
            k.sock.send_to(&old, cfg.target)?;
        }
        if self.rng.random_bool(f.duplicate.clamp(0.0, 1.0)) {
            k.sock.send_to(&datagram, cfg.target)?;
        }
        Ok(())
    }

    /// Receive until a good reply for the current cycle or the deadline; true for a good one.
    fn await_reply(&mut self, k: &Krc, deadline: Instant) -> io::Result<bool> {
        loop {
            let now = Instant::now();
            if now >= deadline {
                return Ok(false);
            }
            k.sock.set_read_timeout(Some(deadline - now))?;
            let (len, from) = match k.sock.recv_from(&mut self.rx_buf) {
                Ok(r) => r,
                Err(e) if kuka_rsi::link::is_transient(&e) => {
                    continue;
                }
                Err(e) => return Err(e),
            };
            // A reply lost on the way back never reaches the controller's judgement.
            if from == k.cfg.target
                && !k.cfg.ethernet.onlysend
                && self.rng.random_bool(k.cfg.faults.drop_sen.clamp(0.0, 1.0))
            {
                continue;
            }
            if self.core.on_reply(&self.rx_buf[..len], from) == ReplyVerdict::Good {
                return Ok(true);
            }
        }
    }
}

fn sleep_until(t: Instant) {
    let now = Instant::now();
    if t > now {
        std::thread::sleep(t - now);
    }
}

#[cfg(test)]
mod tests {
    //! The controller's core without sockets or clocks.
    use super::*;
    use kuka_rsi::ProcessChannels;

    fn pc() -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], 49152))
    }

    fn core(process: bool, tweak: impl FnOnce(&mut KrcConfig)) -> KrcCore {
        let mut eth = EthernetConfig::forcecell([127, 0, 0, 1].into(), 49152, false);
        if process {
            eth = eth.with_process(ProcessChannels::default());
        }
        let mut cfg = KrcConfig::new(eth, pc());
        cfg.log = true;
        tweak(&mut cfg);
        KrcCore::new(cfg).unwrap()
    }

    fn arm() -> RigidArm {
        RigidArm::new(Pose::from_position(hal::Vector3::new(0.5, 0.0, 0.3)))
    }

    /// The `<Sen>` a PC would send for `ipoc`.
    fn sen(ipoc: &str, z: &str, stop: u8, state: Option<&str>) -> Vec<u8> {
        let fc = state.map_or(String::new(), |s| format!("<FcState {s}/>"));
        format!(
            "<Sen Type=\"ImFree\"><RKorr X=\"0\" Y=\"0\" Z=\"{z}\" A=\"0\" B=\"0\" C=\"0\"/><Stop>{stop}</Stop>{fc}<IPOC>{ipoc}</IPOC></Sen>"
        )
        .into_bytes()
    }

    fn ipoc_of(rob: &[u8]) -> String {
        let t = core::str::from_utf8(rob).unwrap();
        t[t.find("<IPOC>").unwrap() + 6..t.find("</IPOC>").unwrap()].to_owned()
    }

    #[test]
    fn a_good_reply_is_applied_and_logged() {
        let mut c = core(false, |_| {});
        let mut m = arm();
        let rob = c.next_cycle(&mut m).unwrap().to_vec();
        let ipoc = ipoc_of(&rob);
        assert_eq!(ipoc, "1000000");
        assert_eq!(
            c.on_reply(&sen(&ipoc, "1.5", 0, None), pc()),
            ReplyVerdict::Good
        );
        assert_eq!(
            c.on_reply(&sen(&ipoc, "1.5", 0, None), pc()),
            ReplyVerdict::Ignored
        );
        c.end_cycle(&mut m).unwrap();
        assert!((m.correction.translation.z - 0.0015).abs() < 1e-12);
        let r = c.report();
        assert_eq!((r.cycles, r.good, r.late), (1, 1, 0));
        assert!(r.log[0].on_time);
    }

    #[test]
    fn bad_replies_are_judged_and_late_ones_reach_timeout() {
        let mut c = core(false, |k| k.timeout = 3);
        let mut m = arm();
        let verdicts = [
            (sen("1", "0", 0, None), pc(), ReplyVerdict::IpocMismatch),
            (
                b"<Sen Type=\"Other\"><IPOC>1</IPOC></Sen>".to_vec(),
                pc(),
                ReplyVerdict::WrongSentype,
            ),
            (b"garbage".to_vec(), pc(), ReplyVerdict::Bad),
            (
                sen("1", "0", 0, None),
                SocketAddr::from(([127, 0, 0, 1], 1)),
                ReplyVerdict::Foreign,
            ),
        ];
        let mut end = Ok(());
        for (bytes, from, v) in verdicts.iter().take(3) {
            c.next_cycle(&mut m).unwrap();
            assert_eq!(c.on_reply(bytes, *from), *v);
            assert_eq!(
                c.on_reply(&verdicts[3].0, verdicts[3].1),
                ReplyVerdict::Foreign
            );
            end = c.end_cycle(&mut m);
        }
        assert_eq!(end, Err(KrcEnd::Timeout));
        let r = c.report();
        assert_eq!(
            (
                r.late,
                r.ipoc_mismatch,
                r.wrong_sentype,
                r.bad,
                r.foreign_replies
            ),
            (3, 1, 1, 1, 3)
        );
        assert_eq!(r.log.iter().map(|l| l.delay).collect::<Vec<_>>(), [0, 1, 2]);
    }

    #[test]
    fn poscorr_clamps_and_stop_ends_on_its_rising_edge() {
        let mut c = core(false, |_| {});
        let mut m = arm();
        let ipoc = ipoc_of(c.next_cycle(&mut m).unwrap());
        c.on_reply(&sen(&ipoc, "9.0", 0, None), pc());
        c.end_cycle(&mut m).unwrap();
        assert!(c.report().log[0].clamped);
        assert_eq!(c.report().log[0].correction[2], 5.0);
        let ipoc = ipoc_of(c.next_cycle(&mut m).unwrap());
        c.on_reply(&sen(&ipoc, "0", 1, None), pc());
        assert_eq!(c.end_cycle(&mut m), Err(KrcEnd::Stopped));
    }

    #[test]
    fn fc_state_is_held_on_a_late_reply_and_checked() {
        let mut c = core(true, |_| {});
        let mut m = arm();
        let rob = c.next_cycle(&mut m).unwrap().to_vec();
        let text = String::from_utf8(rob.clone()).unwrap();
        assert!(
            text.contains("<FcCmd Mode=\"0\" F=\"0.0000\" Ramp=\"0.0000\" Seg=\"0\"/>"),
            "{text}"
        );
        let ipoc = ipoc_of(&rob);
        let bad = sen(&ipoc, "0", 0, Some("State=\"7\" F=\"1.00\" Fault=\"0\""));
        assert_eq!(c.on_reply(&bad, pc()), ReplyVerdict::BadProcess);
        let good = sen(&ipoc, "0", 0, Some("State=\"3\" F=\"19.98\" Fault=\"0\""));
        assert_eq!(c.on_reply(&good, pc()), ReplyVerdict::Good);
        c.end_cycle(&mut m).unwrap();
        c.next_cycle(&mut m).unwrap();
        c.end_cycle(&mut m).unwrap(); // no reply: late, FcState held (HOLDON 1)
        let log = &c.report().log;
        assert_eq!(log[0].state.unwrap().phase, hal::ProcessPhase::Pressing);
        assert!(!log[1].on_time);
        assert_eq!(log[1].state, log[0].state);
        assert_eq!(c.report().bad_process, 1);
    }

    #[test]
    fn cycles_and_silence_end_the_run() {
        let mut c = core(false, |k| k.cycles = Some(1));
        let mut m = arm();
        let ipoc = ipoc_of(c.next_cycle(&mut m).unwrap());
        c.on_reply(&sen(&ipoc, "0", 0, None), pc());
        c.end_cycle(&mut m).unwrap();
        assert_eq!(c.next_cycle(&mut m).err(), Some(KrcEnd::Completed));
        let mut c = core(false, |k| k.faults.silent_from = Some(0));
        assert_eq!(c.next_cycle(&mut m).err(), Some(KrcEnd::Silent));
    }
}
