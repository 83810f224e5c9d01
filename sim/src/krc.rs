//! A simulated KUKA robot controller speaking RSI over real UDP: the client and clock master.
//!
//! It uses the driver's codec for the opposite direction (writes `<Rob>`, parses `<Sen>`) from the
//! same Ethernet config, judges every reply (parses, SENTYPE, IPOC, deadline), keeps the `Delay`
//! counter, applies HOLDON per element, breaks off after `Timeout` late replies, clamps with POSCORR,
//! stops on POSCORRMON and on `Stop`, and moves a [`Mechanism`] (the shared [`World`] in a cell
//! simulation) with the correction it accepted. Fault injection covers what networks and peers do.
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
    rob: Schema,
    sen: Schema,
    cmd_slots: Option<CommandSlots>,
    state_slots: Option<StateSlots>,
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
        let rob = cfg
            .ethernet
            .rob_schema(cfg.precision)
            .map_err(|e| bad(e.to_string()))?;
        let mut sen = cfg
            .ethernet
            .sen_schema(cfg.precision)
            .map_err(|e| bad(e.to_string()))?;
        let cmd_slots = CommandSlots::find(&rob).map_err(bad)?;
        let state_slots = StateSlots::find(&mut sen).map_err(bad)?;
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
            rob,
            sen,
            cmd_slots,
            state_slots,
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
        let mut run = Run::new(self);
        let end = run.go(self, mech);
        run.report.end = end;
        run.report
    }
}

struct Run {
    report: KrcReport,
    rng: ChaCha8Rng,
    rob_frame: Frame,
    sen_frame: Frame,
    rob_buf: Vec<u8>,
    rx_buf: Vec<u8>,
    /// Received values of the RECEIVE elements, by slot (HOLDON state).
    held: Vec<f64>,
    /// The same values as a frame, for decoding `FcState` as the robot program sees it.
    held_frame: Frame,
    total: [f64; 6],
    late_count: u32,
    stop_prev: bool,
    stalled: Vec<Vec<u8>>,
    reordered: Option<Vec<u8>>,
    ipoc_base: u64,
    session_start: u64,
}

impl Run {
    fn new(k: &Krc) -> Self {
        Self {
            report: KrcReport {
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
            },
            rng: ChaCha8Rng::seed_from_u64(k.cfg.seed),
            rob_frame: Frame::new(),
            sen_frame: Frame::new(),
            rob_buf: vec![0; 65536],
            rx_buf: vec![0; 65536],
            held: vec![0.0; k.sen.slots()],
            held_frame: Frame::new(),
            total: [0.0; 6],
            late_count: 0,
            stop_prev: false,
            stalled: Vec::new(),
            reordered: None,
            ipoc_base: k.cfg.ipoc_base,
            session_start: 0,
        }
    }

    fn go(&mut self, k: &Krc, mech: &mut dyn Mechanism) -> KrcEnd {
        let cfg = &k.cfg;
        let rist = k.rob.six("RIst", POSE);
        let rsol = k.rob.six("RSol", POSE);
        let delay_slot = k.rob.slot("Delay", "D");
        let rkorr: [Option<usize>; 6] = POSE.map(|a| k.sen.slot("RKorr", a));
        let stop_slot = k.sen.slot("Stop", "");
        if cfg.mode == CorrectionMode::Absolute {
            // A simulated cell may start with its tool away from the programmed path: that offset is
            // the correction in effect, as if an earlier RSI session had left it there, so a late first
            // reply holds it instead of dropping the tool back onto the path.
            let (actual, programmed) = mech.poses();
            let offset = programmed
                .orientation
                .inverse_transform_vector(&(actual.position - programmed.position));
            let wire0 = wire::offset_to_wire(&offset, &hal::Vector3::zeros());
            for (i, slot) in rkorr.iter().enumerate() {
                if let Some(s) = slot {
                    self.held[*s] = wire0[i];
                }
            }
            self.total = wire0;
        }
        let start = Instant::now();
        let mut n: u64 = 0;
        loop {
            if k.abort.load(Ordering::Relaxed) {
                return KrcEnd::Aborted;
            }
            if cfg.cycles.is_some_and(|c| n >= c) {
                return KrcEnd::Completed;
            }
            if cfg.faults.silent_from.is_some_and(|s| n >= s) {
                return KrcEnd::Silent;
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
            let cycle_start = match cfg.timing {
                Timing::Realtime => start + cfg.period * (n as u32),
                Timing::Lockstep { .. } => Instant::now(),
            };
            if let Timing::Realtime = cfg.timing {
                sleep_until(cycle_start);
            }
            let ipoc = self.ipoc_base + (n - self.session_start) * cfg.ipoc_step;
            let delay = self.late_count;
            self.report.max_delay = self.report.max_delay.max(delay);

            // Build <Rob>.
            let (actual, programmed) = mech.poses();
            if let Some(s) = rist {
                self.rob_frame.set6(s, wire::pose_to_wire(&actual));
            }
            if let Some(s) = rsol {
                self.rob_frame.set6(s, wire::pose_to_wire(&programmed));
            }
            if let Some(s) = delay_slot {
                self.rob_frame.set(s, f64::from(delay));
            }
            // The robot program's process command; a controller running no program sends OFF.
            let command = k.cmd_slots.map(|slots| {
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
            let len = match k.rob.write(&self.rob_frame, &mut self.rob_buf) {
                Ok(len) => len,
                Err(e) => return KrcEnd::Io(format!("cannot encode <Rob>: {e}")),
            };
            let datagram = self.rob_buf[..len].to_vec();

            if let Err(e) = self.send_cycle(k, n, ipoc, datagram) {
                return KrcEnd::Io(e.to_string());
            }

            // Wait for and judge the reply.
            let deadline = match cfg.timing {
                Timing::Realtime => cycle_start + cfg.period,
                Timing::Lockstep { .. } if cfg.ethernet.onlysend => Instant::now() + cfg.period,
                Timing::Lockstep { deadline } => Instant::now() + deadline,
            };
            let good = match self.await_reply(k, ipoc, deadline) {
                Ok(g) => g,
                Err(e) => return KrcEnd::Io(e.to_string()),
            };
            if !good && k.abort.load(Ordering::Relaxed) {
                // Aborted while waiting: the PC side is finished, this cycle is not judged.
                return KrcEnd::Aborted;
            }
            if cfg.ethernet.onlysend {
                // The robot only sends: nothing is judged, nothing is late, nothing is applied.
                self.report.cycles += 1;
                mech.advance(&Correction::default());
                n += 1;
                continue;
            }

            // HOLDON per element, then the correction mode.
            for f in k.sen.elements().iter().flat_map(|e| e.fields()) {
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
            let state = k
                .state_slots
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
            let rk: [f64; 6] = rkorr.map(|s| s.map_or(0.0, |s| self.held[s]));
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
                    ipoc,
                    delay,
                    on_time: good,
                    correction: clamped,
                    clamped: was_clamped,
                    command,
                    state,
                });
            }
            let t_norm = clamped[..3].iter().map(|v| v * v).sum::<f64>().sqrt();
            let r_norm = clamped[3..].iter().map(|v| v * v).sum::<f64>().sqrt();
            if t_norm > wire::m_to_mm(cfg.poscorrmon.translation)
                || r_norm > cfg.poscorrmon.rotation.to_degrees()
            {
                return KrcEnd::PoscorrMon;
            }
            let (translation, rotation) = wire::offset_from_wire(clamped);
            mech.advance(&Correction {
                translation,
                rotation,
                stop: false,
                ..Correction::default()
            });
            n += 1;
            let stop = stop_slot.is_some_and(|s| self.held[s] != 0.0);
            if stop && !self.stop_prev {
                return KrcEnd::Stopped;
            }
            self.stop_prev = stop;
            if self.late_count >= cfg.timeout {
                return KrcEnd::Timeout;
            }
        }
    }

    /// Send this cycle's `<Rob>` through the fault plan.
    fn send_cycle(&mut self, k: &Krc, n: u64, ipoc: u64, datagram: Vec<u8>) -> io::Result<()> {
        let cfg = &k.cfg;
        let f = &cfg.faults;
        if !f.jitter.is_zero() && cfg.timing == Timing::Realtime {
            let j = self.rng.random_range(0..=f.jitter.as_nanos() as u64);
            std::thread::sleep(Duration::from_nanos(j));
        }
        if let Some(sock) = &k.foreign
            && f.foreign.contains(&n)
        {
            let mut fake = self.rob_frame.clone();
            fake.set_ipoc(Ipoc::new(ipoc + 1));
            let len = k
                .rob
                .write(&fake, &mut self.rob_buf)
                .map_err(|e| io::Error::other(e.to_string()))?;
            sock.send_to(&self.rob_buf[..len], cfg.target)?;
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

    /// Receive until a good reply for `ipoc` or the deadline; true for a good one.
    fn await_reply(&mut self, k: &Krc, ipoc: u64, deadline: Instant) -> io::Result<bool> {
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
            if from != k.cfg.target {
                self.report.foreign_replies += 1;
                continue;
            }
            if k.cfg.ethernet.onlysend {
                self.report.unexpected_replies += 1;
                continue;
            }
            if self.rng.random_bool(k.cfg.faults.drop_sen.clamp(0.0, 1.0)) {
                continue;
            }
            match k.sen.parse(&self.rx_buf[..len], &mut self.sen_frame) {
                Err(ParseError::WrongType) => {
                    self.report.wrong_sentype += 1;
                    self.report.last_bad = Some(ParseError::WrongType);
                }
                Err(e) => {
                    self.report.bad += 1;
                    self.report.last_bad = Some(e);
                }
                Ok(()) if self.sen_frame.ipoc().value() != ipoc => {
                    self.report.ipoc_mismatch += 1;
                }
                Ok(()) => match k.state_slots.map(|s| s.decode(&self.sen_frame)) {
                    Some(Err(e)) => {
                        self.report.bad_process += 1;
                        self.report.last_bad_process = Some(e);
                    }
                    _ => return Ok(true),
                },
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
