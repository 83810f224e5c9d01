//! The KUKA RSI wiring of the application: `forcecell sim` over real loopback UDP (the driver against
//! the simulated controller, or against any external RSI client), and `forcecell rsi-config`.

use std::net::{Ipv4Addr, SocketAddr};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::Duration;

use anyhow::{Context, Result, anyhow, bail};
use controller::{LoopConfig, Tuning};
use hal::{Correction, Cycle, ForceSensor, RobotLink};
use kuka_rsi::{
    CorrectionMode, Diagnostics, EthernetConfig, Limits, LinkConfig, LinkError, PoscorrLimits,
    ProcessChannels, ProcessIo, ProcessSetup, RobotFilter, RobotSetup, RsiLink, Segment,
};
use sim::irc5::Irc5Report;
use sim::krc::{Krc, KrcConfig, KrcEnd, KrcReport, Timing};
use sim::{InProcRobot, InProcSensor, InnerLoopModel, SharedWorld};

use crate::args::{ModeArg, RobotBackend, RsiArgs, RsiConfigArgs};
use crate::recorder::Recorder;
use crate::runner::{RunResult, RunSpec, run_recorded};
use crate::stop::Interruptible;

impl RsiArgs {
    /// One line for the run's header.
    pub fn describe(&self) -> String {
        match (self.external_robot, self.robot) {
            (Some(addr), RobotBackend::Egm) => {
                format!("simulated IRC5 sending to an EGM client on {addr}")
            }
            (Some(addr), _) => format!("KUKA RSI driver listening on {addr} for an external robot"),
            (None, RobotBackend::Inproc) => "in-process robot".to_string(),
            (None, RobotBackend::Egm) => format!(
                "ABB EGM driver (path correction) ↔ simulated IRC5 over loopback UDP ({})",
                if self.realtime {
                    "real time"
                } else {
                    "lockstep"
                }
            ),
            (None, RobotBackend::Rsi) => format!(
                "KUKA RSI driver ↔ simulated KRC over loopback UDP ({})",
                if self.realtime {
                    "real time"
                } else {
                    "lockstep"
                }
            ),
        }
    }
}

/// What the wire did during a run, by robot family.
#[derive(Clone, Debug)]
pub enum WireSummary {
    /// KUKA RSI.
    Rsi {
        /// The driver's counters and latency distribution.
        diagnostics: Diagnostics,
        /// The simulated controller's report (none with an external robot).
        krc: Option<KrcReport>,
    },
    /// ABB EGM.
    Egm {
        /// The driver's counters, the robot's status and the latency distribution.
        diagnostics: abb_egm::Diagnostics,
        /// The simulated controller's report.
        irc5: Option<Irc5Report>,
    },
}

impl WireSummary {
    /// Print a short table.
    pub fn print(&self) {
        match self {
            Self::Rsi { diagnostics, krc } => {
                print_link(diagnostics);
                if let Some(k) = krc {
                    println!(
                        "  simulated KRC: {} cycles, {} good, {} late, max Delay {}, ended {:?}",
                        k.cycles, k.good, k.late, k.max_delay, k.end
                    );
                }
            }
            Self::Egm { diagnostics, irc5 } => {
                crate::egm::print_link(diagnostics);
                if let Some(r) = irc5 {
                    crate::egm::print_irc5(r);
                }
            }
        }
    }
}

/// Say once, when a robot link is bound, that the kernel gives its socket no receive timestamps
/// (`stamps` false): late replies are then measured from the receive call's return, blind to a
/// datagram's wait in the socket.
pub fn say_stamps(stamps: bool, link: &str) {
    if !stamps {
        eprintln!(
            "warning: the kernel refused receive timestamps (SO_TIMESTAMPNS) on the {link} socket: late replies \
             are measured from the receive call's return, blind to the time a datagram waited in the socket"
        );
    }
}

/// Print the RSI link's counters (received, answered, late after arrival, skipped, stale, missed,
/// foreign, malformed, oversized, implausible), its arrival→send and receive→send latencies.
pub fn print_link(d: &Diagnostics) {
    let c = d.counters;
    let l = &d.latency;
    println!(
        "RSI link: {} received, {} answered, {} late after arrival, {} skipped, {} stale, {} missed, {} foreign, {} malformed, {} oversized, {} implausible",
        c.received,
        c.answered,
        c.late,
        c.skipped,
        c.stale,
        c.missed,
        c.foreign,
        c.malformed,
        c.oversized,
        c.implausible
    );
    // `late` judges the time from the datagram's arrival (the kernel's stamp) to the reply's send;
    // `missed` counts the robot's cycles that never arrived (IPOC gaps).
    let a = &d.from_arrival;
    println!(
        "  arrival→send: p50 {:?}, p99 {:?}, p99.9 {:?}, max {:?}",
        a.quantile(0.5),
        a.quantile(0.99),
        a.quantile(0.999),
        a.max()
    );
    if c.unstamped > 0 {
        println!(
            "  note: {} of the replies had no kernel receive stamp: their lateness was measured from the receive call's return",
            c.unstamped
        );
    }
    println!(
        "  receive→send: p50 {:?}, p99 {:?}, p99.9 {:?}, max {:?}",
        l.quantile(0.5),
        l.quantile(0.99),
        l.quantile(0.999),
        l.max()
    );
    // The rest is the send call: on loopback it also delivers to the robot's socket and wakes it.
    let b = &d.before_send;
    if b.count() > 0 {
        println!(
            "  of which before the send call (user space): p50 {:?}, p99 {:?}, p99.9 {:?}, max {:?}",
            b.quantile(0.5),
            b.quantile(0.99),
            b.quantile(0.999),
            b.max()
        );
    }
}

/// Robot-side limits wide enough for a tuning's own loop limits, so the driver never acts before the
/// loop does: the envelope is the loop's `max_offset`, the rate limit its `max_step`, POSCORR 10 % and
/// POSCORRMON 20 % beyond the envelope. (The scenarios work in absolute normal positions around 10 mm,
/// beyond RSI's default ±5 mm.) With orientation following (`[orientation]` in the tuning) the
/// rotation's POSCORR limit is the tuning's `poscorr`, POSCORRMON's 20 % beyond it, and the driver's
/// envelope 90 % of it (the law's own envelope, `max_angle`, faults first); without it, RSI's defaults.
pub fn cell_limits(tuning: &Tuning) -> (Limits, PoscorrLimits, PoscorrLimits) {
    let loop_cfg: &LoopConfig = &tuning.loop_cfg;
    let mut limits = Limits {
        max_translation: loop_cfg.max_offset,
        max_translation_step: loop_cfg.max_step,
        ..Limits::default()
    };
    let mut poscorr = PoscorrLimits {
        translation: loop_cfg.max_offset * 1.1,
        ..PoscorrLimits::default()
    };
    let mut mon = PoscorrLimits {
        translation: loop_cfg.max_offset * 1.2,
        ..PoscorrLimits::MONITOR_DEFAULT
    };
    if let Some(o) = &tuning.orientation {
        poscorr.rotation = o.poscorr;
        mon.rotation = o.poscorr * 1.2;
        limits.max_rotation = 0.9 * o.poscorr;
    }
    (limits, poscorr, mon)
}

/// How long one wait for the robot's first datagram lasts before the stop flag is looked at again.
const FIRST_CONTACT_POLL: Duration = Duration::from_millis(100);

/// Clears a flag when dropped.
pub(crate) struct ClearOnDrop(pub(crate) Arc<AtomicBool>);

impl Drop for ClearOnDrop {
    fn drop(&mut self) {
        self.0.store(false, Ordering::Relaxed);
    }
}

fn period_of(model: &InnerLoopModel) -> Duration {
    Duration::from_secs_f64(model.period)
}

/// The robot half of a simulated cell, ready to run: the world it drives and, over RSI, the bound
/// driver and the simulated controller already sending (or waiting for an external client). The
/// sensor half is chosen separately and handed to [`RobotSide::run`].
pub struct RobotSide {
    spec: RunSpec,
    world: SharedWorld,
    kind: Kind,
    recorder: Option<Recorder>,
}

enum Kind {
    Inproc,
    Simulated {
        link: Box<RsiLink>,
        krc: thread::JoinHandle<KrcReport>,
        abort: Arc<AtomicBool>,
        running: Arc<AtomicBool>,
    },
    SimulatedEgm {
        sim: Box<crate::egm::SimulatedEgm>,
        running: Arc<AtomicBool>,
    },
    External {
        link: Box<RsiLink>,
    },
}

impl RobotSide {
    /// The in-process robot on a fresh world (no wire).
    pub fn inproc(spec: &RunSpec) -> Self {
        Self {
            world: spec.world(),
            spec: spec.clone(),
            kind: Kind::Inproc,
            recorder: None,
        }
    }

    /// The robot the options ask for.
    pub fn start(spec: &RunSpec, args: &RsiArgs) -> Result<Self> {
        if let Some(addr) = args.external_robot {
            if args.robot == RobotBackend::Egm {
                bail!(
                    "--external-robot speaks RSI only so far; an external EGM client is not supported yet"
                );
            }
            return Self::external(
                spec,
                addr,
                args.process_channels,
                args.ethernet_config.as_deref(),
            );
        }
        match args.robot {
            RobotBackend::Inproc if args.realtime => {
                bail!("--realtime needs a robot on a wire (--robot rsi or egm)")
            }
            RobotBackend::Inproc => Ok(Self::inproc(spec)),
            RobotBackend::Rsi => Self::simulated(spec, args.realtime),
            RobotBackend::Egm => {
                let world = spec.world();
                let running = Arc::new(AtomicBool::new(true));
                let sim = crate::egm::start_simulated(
                    spec,
                    &world,
                    args.realtime,
                    FIRST_CONTACT_POLL,
                    running.clone(),
                )?;
                Ok(Self {
                    spec: spec.clone(),
                    world,
                    kind: Kind::SimulatedEgm {
                        sim: Box::new(sim),
                        running,
                    },
                    recorder: None,
                })
            }
        }
    }

    /// The scenario as this robot runs it (an external robot sets the period and the inner loop).
    pub fn spec(&self) -> &RunSpec {
        &self.spec
    }

    /// Hand every cycle's record to `recorder` during [`RobotSide::run`].
    pub fn record_to(&mut self, recorder: Recorder) {
        self.recorder = Some(recorder);
    }

    /// Whether this robot keeps the wall clock (the simulated controller in real time, an external
    /// robot) rather than stepping in lockstep with the loop.
    pub fn is_realtime(&self, args: &RsiArgs) -> bool {
        args.external_robot.is_some() || (args.robot != RobotBackend::Inproc && args.realtime)
    }

    /// The world the robot moves; a sensor backend measures it.
    pub fn world(&self) -> &SharedWorld {
        &self.world
    }

    fn simulated(spec: &RunSpec, realtime: bool) -> Result<Self> {
        let world = spec.world();
        let local = SocketAddr::from((Ipv4Addr::LOCALHOST, 0));
        let mut ethernet = EthernetConfig::forcecell(Ipv4Addr::LOCALHOST, 0, false);
        // A scenario with a robot program runs it on the simulated controller, over the process
        // channels as a robot configured by `forcecell rsi-config` would.
        if spec.scenario.program.is_some() {
            ethernet = ethernet.with_process(ProcessChannels::default());
        }
        let (limits, poscorr, poscorrmon) = cell_limits(&spec.tuning);
        let mut lc = LinkConfig::new(ethernet.clone(), RobotFilter::Any);
        lc.bind = Some(local);
        lc.period = period_of(&spec.plant);
        lc.limits = limits;
        lc.poscorr = poscorr;
        lc.poscorrmon = poscorrmon;
        // Short waits for the first datagram, so a stop or a dead controller thread ends the wait.
        lc.first_contact_timeout = Some(FIRST_CONTACT_POLL);
        // 1 s: lockstep pauses whenever the loop does.
        lc.watchdog_cycles = ((1.0 / spec.plant.period).ceil() as u32).max(25);
        let mut link = RsiLink::bind(lc).context("RSI driver")?;
        say_stamps(link.kernel_stamps(), "RSI");
        let mut kc = KrcConfig::new(ethernet, link.local_addr()?);
        kc.period = period_of(&spec.plant);
        kc.ipoc_step = ((spec.plant.period * 1000.0).round() as u64).max(1);
        kc.timing = if realtime {
            Timing::Realtime
        } else {
            // Lockstep has no real-time meaning: a reply is late only if the host stalled (a loaded
            // machine, a slow emulated guest). Waiting long keeps exactly one datagram per step
            // there too; a shorter wait made the controller move on, the driver answer the newer
            // datagram, and the run end one step short.
            Timing::Lockstep {
                deadline: Duration::from_secs(5),
            }
        };
        // Lockstep: exactly one datagram per step. Real time: the robot keeps its clock whatever the
        // loop misses, so it runs until the loop is done and aborts it.
        // One more than the run's steps: the last cycle is answered with `Stop`.
        kc.cycles = (!realtime).then(|| spec.steps() + 1);
        kc.poscorr = poscorr;
        kc.poscorrmon = poscorrmon;
        let mut krc = Krc::new(kc).context("simulated KUKA controller")?;
        link.set_robot_filter(RobotFilter::Exact(krc.local_addr()?));
        let abort = krc.abort_handle();
        let mut mech: SharedWorld = world.clone();
        let running = Arc::new(AtomicBool::new(true));
        let alive = running.clone();
        let krc = thread::Builder::new()
            .name("sim-krc".into())
            .spawn(move || {
                // Cleared however the thread ends (a panic included), so the driver stops waiting.
                let _alive = ClearOnDrop(alive);
                krc.run(&mut mech)
            })?;
        Ok(Self {
            spec: spec.clone(),
            world,
            kind: Kind::Simulated {
                link: Box::new(link),
                krc,
                abort,
                running,
            },
            recorder: None,
        })
    }

    fn external(
        spec: &RunSpec,
        addr: SocketAddr,
        process: bool,
        ethernet_config: Option<&std::path::Path>,
    ) -> Result<Self> {
        let mut spec = spec.clone();
        if process {
            // The client runs its own robot program: the scenario's is not run on its behalf.
            spec.scenario.program = None;
        }
        // The client is the clock and the inner loop: the world just follows what it reports.
        spec.plant = InnerLoopModel {
            period: 0.004,
            tau: 0.0,
            delay_cycles: 0,
        };
        spec.plant_label = "external".into();
        spec.external = true;
        let world = spec.world();
        let ip = match addr.ip() {
            std::net::IpAddr::V4(ip) => ip,
            std::net::IpAddr::V6(_) => bail!("RSI is IPv4: give an IPv4 ADDR:PORT"),
        };
        let ethernet = match ethernet_config {
            // The robot's own file: its layout both ways. What `run` would refuse is said, and the
            // dry run still answers in that layout (zeros where forcecell has nothing to send).
            Some(p) => {
                let text = std::fs::read_to_string(p)
                    .with_context(|| format!("cannot read Ethernet config {}", p.display()))?;
                let e =
                    EthernetConfig::parse(&text).map_err(|e| anyhow!("{}: {e}", p.display()))?;
                if let Err(why) = e.check_for_control(process) {
                    println!(
                        "warning: `forcecell run` would refuse {}: {why}; the dry run answers in its layout anyway",
                        p.display()
                    );
                }
                e
            }
            None => {
                let e = EthernetConfig::forcecell(ip, addr.port(), false);
                if process {
                    e.with_process(ProcessChannels::default())
                } else {
                    e
                }
            }
        };
        let sentype = ethernet.sentype.clone();
        let (limits, poscorr, poscorrmon) = cell_limits(&spec.tuning);
        let mut lc = LinkConfig::new(ethernet, RobotFilter::Any);
        lc.bind = Some(addr);
        lc.limits = limits;
        lc.poscorr = poscorr;
        lc.poscorrmon = poscorrmon;
        lc.first_contact_timeout = Some(FIRST_CONTACT_POLL);
        let link = RsiLink::bind(lc).context("RSI driver")?;
        println!(
            "listening for an RSI client on {} (SENTYPE {sentype}; `forcecell rsi-config` writes its files)",
            link.local_addr()?
        );
        say_stamps(link.kernel_stamps(), "RSI");
        Ok(Self {
            spec,
            world,
            kind: Kind::External {
                link: Box::new(link),
            },
            recorder: None,
        })
    }

    /// Run the scenario with this robot and `sensor` (which must measure [`RobotSide::world`]).
    pub fn run<S>(
        self,
        sensor: S,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(RunResult, Option<WireSummary>)>
    where
        S: ForceSensor,
        S::Error: Send + Sync + 'static,
    {
        let Self {
            spec,
            world,
            kind,
            recorder,
        } = self;
        match kind {
            Kind::Inproc => {
                let robot = InProcRobot::new(world.clone());
                Ok((
                    run_recorded(&spec, &world, robot, sensor, recorder, progress)?,
                    None,
                ))
            }
            Kind::Simulated {
                mut link,
                krc,
                abort,
                running,
            } => {
                let robot = Interruptible::new(&mut *link, crate::stop::flag())
                    .with_peer(|| running.load(Ordering::Relaxed));
                let result = run_recorded(&spec, &world, robot, sensor, recorder, progress);
                abort.store(true, Ordering::Relaxed);
                let report = krc
                    .join()
                    .map_err(|_| anyhow!("the simulated controller panicked"))?;
                let run = result?;
                if !matches!(
                    report.end,
                    KrcEnd::Completed | KrcEnd::Aborted | KrcEnd::Stopped
                ) {
                    eprintln!("note: the simulated controller ended with {:?}", report.end);
                }
                Ok((
                    run,
                    Some(WireSummary::Rsi {
                        diagnostics: link.diagnostics().clone(),
                        krc: Some(report),
                    }),
                ))
            }
            Kind::SimulatedEgm { mut sim, running } => {
                let robot = Interruptible::new(&mut sim.link, crate::stop::flag())
                    .with_peer(|| running.load(Ordering::Relaxed));
                let result = run_recorded(&spec, &world, robot, sensor, recorder, progress);
                sim.abort.store(true, Ordering::Relaxed);
                let report = sim
                    .irc5
                    .join()
                    .map_err(|_| anyhow!("the simulated IRC5 panicked"))?;
                let run = result?;
                if !matches!(
                    report.end,
                    sim::irc5::Irc5End::Completed | sim::irc5::Irc5End::Aborted
                ) {
                    eprintln!("note: the simulated IRC5 ended with {:?}", report.end);
                }
                Ok((
                    run,
                    Some(WireSummary::Egm {
                        diagnostics: sim.link.diagnostics().clone(),
                        irc5: Some(report),
                    }),
                ))
            }
            Kind::External { mut link } => {
                let robot = Interruptible::new(
                    ExternalRobot {
                        link: &mut link,
                        world: world.clone(),
                        start: spec.scenario.start_position(),
                        origin: None,
                    },
                    crate::stop::flag(),
                );
                let run = run_recorded(&spec, &world, robot, sensor, recorder, progress)?;
                // What the client's first cycles showed that degrades control, at the virtual
                // workpiece's stiffness.
                for w in link.diagnostics().advisories(
                    link.config().period.as_secs_f64(),
                    spec.scenario.environment.k_c,
                ) {
                    println!("{w}");
                }
                Ok((
                    run,
                    Some(WireSummary::Rsi {
                        diagnostics: link.diagnostics().clone(),
                        krc: None,
                    }),
                ))
            }
        }
    }

    /// Run with the world's own sensor model read in process (no sensor wire).
    pub fn run_inproc_sensor(
        self,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(RunResult, Option<WireSummary>)> {
        let sensor = InProcSensor::new(self.world.clone());
        self.run(sensor, progress)
    }
}

/// Run a scenario with the chosen robot backend and the in-process sensor.
pub fn run(
    spec: &RunSpec,
    args: &RsiArgs,
    progress: &mut dyn FnMut(f64),
) -> Result<(RunResult, Option<WireSummary>)> {
    RobotSide::start(spec, args)?.run_inproc_sensor(progress)
}

/// An external RSI client drives a world whose robot follows the reported pose exactly. The virtual
/// workpiece is placed relative to the pose the client reports when its session starts — a real robot's
/// correction starts at zero after `RSI_ON` — so that pose is the scenario's start position: each cycle
/// the world's position is `start + (x − x at the session's first cycle)`, and the simulated sensor
/// measures there.
struct ExternalRobot<'a> {
    link: &'a mut RsiLink,
    world: SharedWorld,
    /// The scenario's start position in the world, m.
    start: f64,
    /// The normal offset the client reported on its session's first cycle, m.
    origin: Option<f64>,
}

impl ExternalRobot<'_> {
    /// Where the world's tool is for a reported normal offset `x` on cycle `c`.
    fn world_position(&mut self, c: &Cycle, x: f64) -> f64 {
        if c.new_session || self.origin.is_none() {
            self.origin = Some(x);
        }
        self.start + (x - self.origin.unwrap_or(x))
    }
}

impl RobotLink for ExternalRobot<'_> {
    type Error = LinkError;

    fn next_cycle(&mut self) -> Result<Cycle, LinkError> {
        let mut c = self.link.next_cycle()?;
        let x = c.tool_offset().z;
        let at = x.is_finite().then(|| self.world_position(&c, x));
        let mut w = sim::world::lock(&self.world);
        // The world keeps the robot's time: the cycles it sent that never arrived pass in the world
        // too (holding the last command), so the truth of cycle `t` is the world at `t`. At most a
        // second is caught up at once (a clock jump is no reason to stall).
        let period = w.period();
        let due = (c.t / period).round();
        if due.is_finite() && due > 0.0 {
            let behind = (due as u64)
                .saturating_sub(w.cycle_index())
                .min((1.0 / period) as u64);
            for _ in 0..behind {
                w.advance(None);
            }
        }
        if let Some(at) = at {
            // The reported rotation from the programmed pose turns the world's tool too (on a curved
            // part, docs/curved-parts.md; the 1-DOF plant has no rotation and ignores it).
            let turned = (c.programmed.orientation.inverse() * c.actual.orientation).scaled_axis();
            let rotation = if turned.iter().all(|v| v.is_finite()) {
                turned
            } else {
                hal::Vector3::zeros()
            };
            w.advance(Some(&Correction {
                rotation,
                ..Correction::along_z(at)
            }));
        }
        // A client that sends no `FcCmd` gets the scenario's program (if it has one) run on its
        // behalf; one that does runs its own.
        if c.process.is_none() {
            c.process = w.process_command();
        }
        Ok(c)
    }

    fn reply(&mut self, correction: &Correction) -> Result<(), LinkError> {
        // The answer first: the world's bookkeeping (a lock) is no part of the turnaround.
        let sent = self.link.reply(correction);
        sim::world::lock(&self.world).process_reply(correction.process);
        sent
    }
}

/// `FORCE_N:LENGTH_MM,...` → segments in SI.
fn parse_segments(text: &str) -> Result<Vec<Segment>> {
    text.split(',')
        .map(|item| {
            let (f, l) = item.trim().split_once(':').ok_or_else(|| {
                anyhow!("--segments: {item:?} is not FORCE_N:LENGTH_MM (e.g. 30:100)")
            })?;
            let force: f64 = f
                .trim()
                .parse()
                .map_err(|_| anyhow!("--segments: force {f:?} is not a number"))?;
            let length_mm: f64 = l
                .trim()
                .parse()
                .map_err(|_| anyhow!("--segments: length {l:?} is not a number"))?;
            Ok(Segment {
                force,
                length: kuka_rsi::wire::mm_to_m(length_mm),
            })
        })
        .collect()
}

/// What `rsi-config` writes for, resolved from its flags over the cell file's values.
#[derive(Clone, Debug, PartialEq)]
pub struct RsiTarget {
    /// The PC's address (IP_NUMBER).
    pub ip: Ipv4Addr,
    /// The robot controller's address.
    pub robot_ip: std::net::IpAddr,
    /// UDP port.
    pub port: u16,
    /// POSCORR and POSCORRMON.
    pub poscorr: PoscorrLimits,
    /// POSCORRMON.
    pub poscorrmon: PoscorrLimits,
    /// `#RELATIVE`.
    pub relative: bool,
    /// `#IPO_FAST` (4 ms).
    pub ipo_fast: bool,
    /// ETHERNET Timeout.
    pub timeout: u32,
    /// With the process channels.
    pub process: bool,
}

/// Resolve the addresses, limits and settings of `rsi-config`: each flag given, else the cell file's
/// value (`--config`), else (for the port, mode, cycle, Timeout and channels only) the default. The
/// PC's and the robot's addresses and POSCORR/POSCORRMON have no default: without them it refuses,
/// in one line naming each missing value.
pub fn rsi_target(a: &RsiConfigArgs) -> Result<RsiTarget> {
    let (cell, rsi) = match &a.config {
        Some(p) => {
            let robot = crate::cell::CellConfig::load(p)?.robot;
            let crate::robot::RobotKind::KukaRsi(rsi) = robot.kind.clone() else {
                bail!(
                    "rsi-config: {} is an ABB EGM cell (`forcecell egm-config` writes its files)",
                    p.display()
                );
            };
            (Some(robot), Some(rsi))
        }
        None => (None, None),
    };
    let cell_ip = match cell.as_ref().map(|r| r.listen.ip()) {
        Some(std::net::IpAddr::V4(ip)) => Some(ip),
        Some(std::net::IpAddr::V6(ip)) => {
            bail!("rsi-config: robot.listen {ip} is IPv6; RSI is IPv4")
        }
        None => None,
    };
    let ip = a.ip.or(cell_ip);
    let robot_ip = a.robot_ip.or(cell.as_ref().map(|r| r.robot_ip));
    // A tuning gives the limits its loop needs: the translation (unless the flags say), and the
    // rotation of an orientation-following tuning (RSI's 5° otherwise).
    let tuning_poscorr = match &a.tuning {
        Some(t) => {
            let t = crate::scenario::load_tuning(t)?;
            let (_, p, m) = cell_limits(&t);
            Some((p, m))
        }
        None => None,
    };
    let tuning_limits = tuning_poscorr.map(|(p, m)| (p.translation * 1e3, m.translation * 1e3));
    let poscorr_mm = a
        .poscorr_mm
        .or(rsi.as_ref().map(|r| r.poscorr_mm))
        .or(tuning_limits.map(|t| t.0));
    let poscorrmon_mm = a
        .poscorrmon_mm
        .or(rsi.as_ref().map(|r| r.poscorrmon_mm))
        .or(tuning_limits.map(|t| t.1));
    let (Some(ip), Some(robot_ip), Some(poscorr_mm), Some(poscorrmon_mm)) =
        (ip, robot_ip, poscorr_mm, poscorrmon_mm)
    else {
        let missing: Vec<&str> = [
            (ip.is_none(), "the PC's address (--ip)"),
            (robot_ip.is_none(), "the robot's address (--robot-ip)"),
            (poscorr_mm.is_none(), "POSCORR (--poscorr-mm)"),
            (poscorrmon_mm.is_none(), "POSCORRMON (--poscorrmon-mm)"),
        ]
        .into_iter()
        .filter_map(|(m, what)| m.then_some(what))
        .collect();
        bail!(
            "rsi-config: missing {}: give the cell file (--config cell.toml) or the flags",
            missing.join(", ")
        );
    };
    if std::net::IpAddr::V4(ip) == robot_ip {
        bail!(
            "rsi-config: the PC's address {ip} (IP_NUMBER, where the robot sends) is the robot's own              address: give the PC's address as the robot sees it (--ip, or robot.listen)"
        );
    }
    if poscorrmon_mm <= poscorr_mm {
        bail!(
            "rsi-config: POSCORRMON {poscorrmon_mm} mm must be above POSCORR {poscorr_mm} mm (the \
             monitor stops the robot beyond what the correction may reach)"
        );
    }
    // The rotation limits: with a cell file its own (what `run` holds the robot to: `poscorr_deg`,
    // `poscorrmon_deg`, RSI's 5°/6° when absent), so the robot and the cell file cannot disagree;
    // without one the tuning's, else RSI's defaults.
    let rotation = match &rsi {
        Some(r) => {
            let (p, m) = r.rotation_limits_deg();
            (p.to_radians(), m.to_radians())
        }
        None => tuning_poscorr.map_or(
            (
                PoscorrLimits::default().rotation,
                PoscorrLimits::MONITOR_DEFAULT.rotation,
            ),
            |t| (t.0.rotation, t.1.rotation),
        ),
    };
    if rotation.1 <= rotation.0 {
        bail!(
            "rsi-config: POSCORRMON's rotation {:.1}° must be above POSCORR's {:.1}°",
            rotation.1.to_degrees(),
            rotation.0.to_degrees()
        );
    }
    let mode = a.mode.or(rsi.as_ref().map(|r| match r.mode {
        crate::cell::ModeName::Absolute => ModeArg::Absolute,
        crate::cell::ModeName::Relative => ModeArg::Relative,
    }));
    Ok(RsiTarget {
        ip,
        robot_ip,
        port: a
            .port
            .or(cell.as_ref().map(|r| r.listen.port()))
            .unwrap_or(49152),
        poscorr: PoscorrLimits {
            translation: poscorr_mm * 1e-3,
            rotation: rotation.0,
        },
        poscorrmon: PoscorrLimits {
            translation: poscorrmon_mm * 1e-3,
            rotation: rotation.1,
        },
        relative: mode == Some(ModeArg::Relative),
        ipo_fast: !(a.ipo12 || cell.as_ref().is_some_and(|r| r.cycle_ms == 12)),
        timeout: a.timeout.or(rsi.as_ref().map(|r| r.timeout)).unwrap_or(100),
        process: !a.no_process && cell.as_ref().is_none_or(|r| r.process),
    })
}

/// The robot-side setup for these options.
pub fn robot_setup(a: &RsiConfigArgs) -> Result<RobotSetup> {
    if a.name.is_empty()
        || !a
            .name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_')
    {
        bail!(
            "--name {:?}: KRL names are ASCII letters, digits and '_'",
            a.name
        );
    }
    let t = rsi_target(a)?;
    let relative = t.relative;
    let mut ethernet = EthernetConfig::forcecell(t.ip, t.port, relative);
    let process = if !t.process {
        None
    } else {
        ethernet = ethernet.with_process(ProcessChannels::default());
        Some(ProcessSetup {
            io: ProcessIo {
                mode_pint: a.pint_mode,
                seg_pint: a.pint_seg,
                force_prea: a.prea_force,
                ramp_prea: a.prea_ramp,
                state_pint: a.pint_state,
                fault_pint: a.pint_fault,
                measured_prea: a.prea_measured,
            },
            segments: parse_segments(&a.segments)?,
            feed: kuka_rsi::wire::mm_to_m(a.feed_mm_s),
            ramp: a.ramp,
            wait_timeout: a.wait_timeout,
            timer: 1,
            interrupt: 21,
            flag: 1,
        })
    };
    let setup = RobotSetup {
        ethernet,
        mode: if relative {
            CorrectionMode::Relative
        } else {
            CorrectionMode::Absolute
        },
        ipo_fast: t.ipo_fast,
        timeout: t.timeout,
        precision: 4,
        poscorr: t.poscorr,
        poscorrmon: t.poscorrmon,
        name: a.name.clone(),
        process,
    };
    setup.validate().map_err(|e| anyhow!("rsi-config: {e}"))?;
    Ok(setup)
}

/// Write the robot-side files; returns their paths and, with the process channels, the
/// `$SEN_PINT`/`$SEN_PREA` mapping the integrator must build in RSI Visual. Everything is validated
/// and rendered first; a file of the same name is refused (all of them named) unless `--force`; every
/// file is written to a temporary name and only when all were written is any renamed over its name,
/// so a failure leaves every earlier file as it was.
pub fn rsi_config(a: &RsiConfigArgs) -> Result<(Vec<PathBuf>, Vec<String>)> {
    let setup = robot_setup(a)?;
    let files = setup.files();
    let paths: Vec<PathBuf> = files.iter().map(|(n, _)| a.out.join(n)).collect();
    if !a.force {
        let existing: Vec<String> = paths
            .iter()
            .filter(|p| std::fs::symlink_metadata(p).is_ok())
            .map(|p| p.display().to_string())
            .collect();
        if !existing.is_empty() {
            bail!(
                "rsi-config: {} already exist(s); nothing was written (--force replaces them)",
                existing.join(", ")
            );
        }
    }
    // Even with --force, only a regular file is replaced: found now, before anything is written.
    for p in &paths {
        if let Ok(m) = std::fs::symlink_metadata(p)
            && !m.is_file()
        {
            bail!(
                "rsi-config: {} is not a regular file; nothing was written",
                p.display()
            );
        }
    }
    let dir = crate::output::OutDir::create(&a.out, "output directory (--out)")?;
    let temps: Vec<PathBuf> = paths.iter().map(|p| crate::output::temp_path(p)).collect();
    let cleanup = |temps: &[PathBuf]| {
        for t in temps {
            let _ = std::fs::remove_file(t);
        }
    };
    for ((_, text), (tmp, path)) in files.iter().zip(temps.iter().zip(&paths)) {
        let written = std::fs::write(tmp, text).and_then(|()| std::fs::File::open(tmp)?.sync_all());
        if let Err(e) = written {
            cleanup(&temps);
            bail!(
                "cannot write {}: {}; nothing was replaced",
                path.display(),
                crate::input::os_error(&e)
            );
        }
    }
    for (i, (tmp, path)) in temps.iter().zip(&paths).enumerate() {
        if let Err(e) = std::fs::rename(tmp, path) {
            cleanup(&temps[i..]);
            bail!(
                "cannot write {}: {}",
                path.display(),
                crate::input::os_error(&e)
            );
        }
    }
    dir.keep();
    let mapping = setup
        .process
        .as_ref()
        .map(|p| p.mapping(&setup.ethernet))
        .unwrap_or_default();
    Ok((paths, mapping))
}
