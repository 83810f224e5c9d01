//! The driver: start-up, polling, pairing answers with requests, health, bias.
//!
//! [`Driver::step`] performs **exactly one** request/answer exchange (or, after an abandoned request,
//! one bounded quiet wait) and never waits longer than one per-request deadline. Everything else — the
//! background poller ([`crate::AtiSensor`]), the lockstep adaptor ([`crate::Lockstep`]), the blocking
//! [`Driver::start`] — is a loop over `step`.
//!
//! # Pairing answers with requests
//! CAN answers carry no request tag, so the driver keeps one: every request gets a new generation and
//! only frames that arrive inside that request's window (after it was sent, before its deadline) can
//! complete it. When a request is abandoned (no answer, a malformed or out-of-sequence frame), the driver
//! sends nothing until a *late window* of three deadlines after that request has passed; frames arriving
//! meanwhile are counted as stray and dropped. Frames already queued when a request is sent are dropped
//! the same way. So a late answer is never paired with a newer request, as long as the board answers
//! within three deadlines or not at all.

use core::time::Duration;

use hal::{Sample, Wrench};

use crate::calibration::{
    Calibration, Converter, ForceUnit, LEGACY_COUNTS_PER_UNIT, TorqueUnit, plausible_coefficient,
    plausible_counts,
};
use crate::codec::{Answer, Base, CodecError, Firmware, Gauges, Request, Status, interleave};
use crate::error::{AtiError, BiasError, StartupProblem};
use crate::transport::{BusError, BusEvent, CanTransport, Clock};

/// Frames [`Driver`] drains in one go once a wait is over.
const DISCARD_BURST: u32 = 256;

/// Driver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// The board's base identifier.
    pub base: Base,
    /// Bus bit rate, bit/s: sets the per-request deadline.
    pub bitrate: u32,
    /// Calibration slot to select, 0..=15.
    pub slot: u8,
    /// Allowance for the board's own turnaround, added to the wire time (not published by ATI).
    pub turnaround: Duration,
    /// A sample older than this is stale.
    pub stale_after: Duration,
    /// Polls in a row without a valid answer before the health becomes [`Health::Timeout`].
    pub timeout_after: u32,
    /// Good samples in a row needed to leave a fault state (hysteresis).
    pub recover_after: u32,
    /// Attempts per start-up request.
    pub attempts: u32,
    /// Largest plausible change of a gauge between two answers, counts. A larger jump drops the answer
    /// as implausible (it catches byte-swapped answers, which no single-frame check can). `None`: off.
    pub max_gauge_step: Option<u16>,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            base: Base::DEFAULT,
            bitrate: 1_000_000,
            slot: 0,
            turnaround: Duration::from_micros(300),
            stale_after: Duration::from_millis(10),
            timeout_after: 3,
            recover_after: 3,
            attempts: 3,
            max_gauge_step: None,
        }
    }
}

/// Bits of a classic standard data frame with `dlc` bytes, without stuffing.
fn frame_bits(dlc: u8) -> u64 {
    47 + 8 * u64::from(dlc)
}

impl Config {
    /// Time on the wire of `req` and its answer, with worst-case bit stuffing (×1.2).
    pub fn wire_time(&self, req: Request) -> Duration {
        let bits = frame_bits(req.data_len())
            + req
                .answer_layout()
                .iter()
                .map(|&(_, d)| frame_bits(d))
                .sum::<u64>();
        Duration::from_nanos(bits * 1_200_000_000 / u64::from(self.bitrate.max(1)))
    }

    /// How long the driver waits for the answer to `req`: twice the wire time plus the turnaround.
    pub fn deadline(&self, req: Request) -> Duration {
        self.wire_time(req) * 2 + self.turnaround
    }

    /// The longest turnaround allowance accepted (every wait on the sensor ends).
    pub const MAX_WAIT: Duration = Duration::from_secs(10);

    /// Checks the values.
    pub fn validate(&self) -> Result<(), AtiError> {
        let bad = |m: String| Err(AtiError::Config(m));
        if self.bitrate < 10_000 || self.bitrate > 1_000_000 {
            return bad(format!(
                "bit rate {} bit/s is outside 10 k..1 M",
                self.bitrate
            ));
        }
        if self.slot > 15 {
            return bad(format!("calibration slot {} is outside 0..=15", self.slot));
        }
        if self.timeout_after == 0 || self.recover_after == 0 || self.attempts == 0 {
            return bad("timeout_after, recover_after and attempts must be at least 1".into());
        }
        if self.stale_after.is_zero() {
            return bad("stale_after must be positive".into());
        }
        if self.turnaround > Self::MAX_WAIT {
            return bad(format!(
                "turnaround {:?} is above {:?}: a CAN board answers within milliseconds (a slow virtual interface within seconds), and every request waits this long before it times out",
                self.turnaround,
                Self::MAX_WAIT
            ));
        }
        Ok(())
    }
}

/// The driver's view of the sensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Health {
    /// Start-up is running (or restarting after a watchdog reset or a bus restart).
    Waiting,
    /// Samples are good and fresh.
    Ok,
    /// Samples are good but the newest is older than the staleness limit.
    Stale,
    /// Several polls in a row got no valid answer.
    Timeout,
    /// The status word reports a critical error.
    DeviceError(Status),
    /// A gauge is saturated.
    Saturated,
    /// The CAN controller is bus-off.
    BusOff,
    /// The transport is closed.
    LinkLost,
}

/// What the driver has counted since it was created.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Requests sent.
    pub requests: u64,
    /// Good samples produced.
    pub samples: u64,
    /// Requests whose answer did not arrive in time.
    pub timeouts: u64,
    /// Frames of this base that failed to decode (wrong length, opcode without an answer, reserved
    /// status bits).
    pub malformed: u64,
    /// Answers whose frames came in the wrong order, duplicated or with an unexpected opcode.
    pub sequence_errors: u64,
    /// Frames of this base that arrived outside any request's window (late answers, duplicates).
    pub stray: u64,
    /// Frames of other bases, extended or remote frames that reached the driver.
    pub foreign: u64,
    /// Answers withheld because the status word had a critical bit.
    pub device_errors: u64,
    /// Answers withheld because a gauge was saturated.
    pub saturated: u64,
    /// Answers dropped because a gauge jumped more than `max_gauge_step`.
    pub implausible: u64,
    /// Watchdog resets seen in the status word.
    pub watchdog_resets: u64,
    /// Completed start-ups.
    pub startups: u64,
    /// Start-up passes that failed and started over.
    pub startup_failures: u64,
    /// Slot echoes that did not match.
    pub echo_mismatches: u64,
    /// Controller error reports received.
    pub bus_errors: u64,
    /// Times the controller went bus-off.
    pub bus_off: u64,
    /// Waits in the late window after an abandoned request.
    pub quiet_waits: u64,
}

/// What the start-up read from the board.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeviceInfo {
    /// Firmware version.
    pub firmware: Firmware,
    /// ASCII calibration serial number, when the board answered.
    pub serial: Option<[u8; 8]>,
    /// The active calibration slot (echo-checked).
    pub slot: u8,
    /// Matrix, counts per unit and units.
    pub calibration: Calibration,
    /// True when the counts per unit are the 1 000 000 fallback of old firmware.
    pub counts_assumed: bool,
    /// True when the board did not report units and N / N·m were assumed.
    pub units_assumed: bool,
}

impl DeviceInfo {
    /// The serial number as text (non-printable bytes dropped).
    pub fn serial_text(&self) -> Option<String> {
        self.serial.map(|s| {
            s.iter()
                .filter(|b| b.is_ascii_graphic() || **b == b' ')
                .map(|&b| char::from(b))
                .collect::<String>()
                .trim()
                .to_owned()
        })
    }
}

/// How a bias is taken.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BiasConfig {
    /// Samples averaged.
    pub window: u32,
    /// Largest allowed spread (max − min) of any gauge over the window, counts.
    pub max_spread: u16,
}

impl Default for BiasConfig {
    fn default() -> Self {
        Self {
            window: 100,
            max_spread: 200,
        }
    }
}

/// What one [`Driver::step`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// A poll produced a good sample with this sequence number.
    Sample(u64),
    /// A poll answer arrived but was withheld (critical status, saturation, implausible jump).
    Withheld,
    /// The request got no usable answer (timeout, malformed, out of sequence).
    NoAnswer,
    /// A start-up request was answered; start-up continues.
    StartupProgress,
    /// Start-up finished.
    Started,
    /// A start-up pass failed and starts over.
    StartupFailed(StartupProblem),
    /// A watchdog reset was seen: start-up runs again.
    Restarting,
    /// Waited in the late window of an abandoned request; nothing was sent.
    Quiet,
    /// The controller is bus-off; nothing was sent.
    BusOff,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Step {
    Firmware,
    Serial,
    Slot,
    Matrix(u8),
    Counts,
    Units,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Startup(Step),
    Running,
    BusOff,
}

/// The newest good sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Latest {
    pub wrench: Wrench,
    pub gauges: Gauges,
    pub seq: u64,
    pub stamp: Duration,
}

#[derive(Clone, Copy, Debug, Default)]
struct Partial {
    firmware: Option<Firmware>,
    serial: Option<[u8; 8]>,
    matrix: [[f32; 6]; 6],
    counts: Option<(u32, u32)>,
    counts_assumed: bool,
    units: Option<(ForceUnit, TorqueUnit)>,
}

#[derive(Clone, Copy, Debug)]
struct BiasJob {
    cfg: BiasConfig,
    n: u32,
    sum: [f64; 6],
    min: [i16; 6],
    max: [i16; 6],
}

/// The result of one exchange.
enum Reply {
    /// All frames of the answer, in layout order.
    Answer([Option<Answer>; 3]),
    /// Abandoned: no answer in time, or a bad frame.
    Abandoned,
    BusOff,
}

/// The state [`Driver::read`] and the background sensor derive a sample or an error from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct View {
    pub health: Health,
    pub latest: Option<Latest>,
    pub problem: Option<StartupProblem>,
    pub stale_after: Duration,
}

impl View {
    pub fn health_at(&self, now: Duration) -> Health {
        match (self.health, self.latest) {
            (Health::Ok, Some(l)) if now.saturating_sub(l.stamp) > self.stale_after => {
                Health::Stale
            }
            (h, _) => h,
        }
    }

    pub fn sample_at(&self, now: Duration) -> Result<Sample, AtiError> {
        match self.health {
            Health::Ok => {}
            Health::Waiting | Health::Stale => {
                return Err(AtiError::NotReady {
                    problem: self.problem,
                });
            }
            Health::Timeout => return Err(AtiError::Timeout),
            Health::DeviceError(s) => return Err(AtiError::DeviceFault(s)),
            Health::Saturated => return Err(AtiError::Saturated),
            Health::BusOff => return Err(AtiError::BusOff),
            Health::LinkLost => return Err(AtiError::LinkLost),
        }
        let Some(l) = self.latest else {
            return Err(AtiError::NotReady { problem: None });
        };
        let age = now.saturating_sub(l.stamp);
        if age > self.stale_after {
            return Err(AtiError::Stale { age });
        }
        Ok(Sample {
            wrench: l.wrench,
            seq: l.seq,
            age,
        })
    }
}

/// The ATI NETCANOEM driver over one transport. See the module documentation.
pub struct Driver<T> {
    transport: T,
    cfg: Config,
    clock: Clock,
    phase: Phase,
    attempt: u32,
    partial: Partial,
    info: Option<DeviceInfo>,
    converter: Option<Converter>,
    problem: Option<StartupProblem>,
    generation: u64,
    polls: u64,
    quiet_until: Option<Duration>,
    health: Health,
    good_streak: u32,
    fail_streak: u32,
    status: Status,
    last_gauges: Option<Gauges>,
    latest: Option<Latest>,
    bias: [f64; 6],
    bias_job: Option<BiasJob>,
    bias_outcome: Option<Result<[f64; 6], BiasError>>,
    counters: Counters,
}

impl<T: CanTransport> Driver<T> {
    /// A driver that has not talked to the board yet. Sets the transport's filter to the base.
    pub fn new(mut transport: T, cfg: Config) -> Result<Self, AtiError> {
        cfg.validate()?;
        transport.accept_only(cfg.base)?;
        let clock = transport.clock();
        Ok(Self {
            transport,
            cfg,
            clock,
            phase: Phase::Startup(Step::Firmware),
            attempt: 0,
            partial: Partial::default(),
            info: None,
            converter: None,
            problem: None,
            generation: 0,
            polls: 0,
            quiet_until: None,
            health: Health::Waiting,
            good_streak: 0,
            fail_streak: 0,
            status: Status(0),
            last_gauges: None,
            latest: None,
            bias: [0.0; 6],
            bias_job: None,
            bias_outcome: None,
            counters: Counters::default(),
        })
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// The clock samples are stamped with.
    pub fn clock(&self) -> Clock {
        self.clock.clone()
    }

    /// Health now (including staleness of the newest sample).
    pub fn health(&self) -> Health {
        self.view().health_at(self.clock.now())
    }

    /// Counters so far.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// What start-up read, once it has finished.
    pub fn info(&self) -> Option<&DeviceInfo> {
        self.info.as_ref()
    }

    /// The status word of the newest poll answer.
    pub fn status(&self) -> Status {
        self.status
    }

    /// The raw gauges of the newest good sample.
    pub fn raw_gauges(&self) -> Option<Gauges> {
        self.latest.map(|l| l.gauges)
    }

    /// The generation of the newest request (increases with every request sent).
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// The current bias, counts per gauge.
    pub fn bias(&self) -> [f64; 6] {
        self.bias
    }

    /// Set the bias (counts per gauge). It applies at once: the newest sample is converted again
    /// from its raw gauges, so no read after this returns a wrench with the old bias.
    pub fn set_bias(&mut self, bias: [f64; 6]) {
        self.bias = bias;
        if let (Some(l), Some(conv)) = (self.latest.as_mut(), self.converter) {
            l.wrench = conv.wrench(&l.gauges, &self.bias);
        }
    }

    /// Give the transport back.
    pub fn into_transport(self) -> T {
        self.transport
    }

    pub(crate) fn view(&self) -> View {
        View {
            health: self.health,
            latest: self.latest,
            problem: self.problem,
            stale_after: self.cfg.stale_after,
        }
    }

    /// The newest sample, from what the driver holds: never touches the bus.
    pub fn read(&self) -> Result<Sample, AtiError> {
        self.view().sample_at(self.clock.now())
    }

    /// The newest good sample whatever the health (for diagnostics and tests; control code uses
    /// [`read`](Self::read), which withholds it in a fault state).
    pub fn last_sample(&self) -> Option<Sample> {
        let now = self.clock.now();
        self.latest.map(|l| Sample {
            wrench: l.wrench,
            seq: l.seq,
            age: now.saturating_sub(l.stamp),
        })
    }

    /// Run start-up to the end: steps until it completes or one full pass fails (then that pass's
    /// problem is returned). Bounded by about `attempts × deadline` per start-up request.
    pub fn start(&mut self) -> Result<DeviceInfo, AtiError> {
        loop {
            match self.step()? {
                Outcome::Started => break,
                Outcome::StartupFailed(p) => return Err(AtiError::Startup(p)),
                Outcome::BusOff => return Err(AtiError::BusOff),
                _ if self.phase == Phase::Running => break,
                _ => {}
            }
        }
        self.info.ok_or(AtiError::NotReady { problem: None })
    }

    /// One exchange: a start-up request or a poll (or a bounded quiet wait after an abandoned request,
    /// or a bounded wait for a restart while bus-off). Never waits longer than one deadline.
    pub fn step(&mut self) -> Result<Outcome, AtiError> {
        if self.phase == Phase::BusOff {
            return self.wait_for_restart();
        }
        if let Some(q) = self.quiet_until {
            let now = self.clock.now();
            if now < q {
                self.counters.quiet_waits += 1;
                let until = q.min(now + self.cfg.deadline(Request::Poll));
                self.discard_until(until)?;
                return Ok(if self.phase == Phase::BusOff {
                    Outcome::BusOff
                } else {
                    Outcome::Quiet
                });
            }
            self.quiet_until = None;
        }
        match self.phase {
            Phase::Running => self.poll(),
            Phase::Startup(step) => self.startup_step(step),
            Phase::BusOff => Ok(Outcome::BusOff),
        }
    }

    /// Start taking a bias over the next `cfg.window` good samples. Refused unless the newest answer
    /// was a good sample: health Ok, or Stale (a driver stepped late, as a command's lock-step driver
    /// is after a pause; the window takes fresh samples only, and a missing one refuses it).
    pub fn begin_bias(&mut self, cfg: BiasConfig) -> Result<(), BiasError> {
        if cfg.window == 0 {
            return Err(BiasError::EmptyWindow);
        }
        if self.bias_job.is_some() {
            return Err(BiasError::Busy);
        }
        match self.health() {
            Health::Ok | Health::Stale => {}
            Health::Saturated => return Err(BiasError::Saturated),
            Health::DeviceError(s) => return Err(BiasError::DeviceFault(s)),
            _ => return Err(BiasError::NotReady),
        }
        self.bias_outcome = None;
        self.bias_job = Some(BiasJob {
            cfg,
            n: 0,
            sum: [0.0; 6],
            min: [i16::MAX; 6],
            max: [i16::MIN; 6],
        });
        Ok(())
    }

    /// The result of the last bias, once (None while it is running or when none was asked for).
    pub fn take_bias_outcome(&mut self) -> Option<Result<[f64; 6], BiasError>> {
        self.bias_outcome.take()
    }

    /// Take a bias now: [`begin_bias`](Self::begin_bias), then step until it completes or is refused.
    pub fn tare(&mut self, cfg: BiasConfig) -> Result<[f64; 6], AtiError> {
        self.begin_bias(cfg)?;
        loop {
            self.step()?;
            if let Some(r) = self.take_bias_outcome() {
                return r.map_err(AtiError::from);
            }
        }
    }

    fn finish_bias(&mut self, r: Result<[f64; 6], BiasError>) {
        if let Ok(b) = r {
            self.set_bias(b);
        }
        self.bias_job = None;
        self.bias_outcome = Some(r);
    }

    fn feed_bias(&mut self, gauges: &Gauges) {
        let Some(job) = self.bias_job.as_mut() else {
            return;
        };
        for i in 0..6 {
            let g = gauges.0[i];
            job.sum[i] += f64::from(g);
            job.min[i] = job.min[i].min(g);
            job.max[i] = job.max[i].max(g);
        }
        job.n += 1;
        if job.n < job.cfg.window {
            return;
        }
        let job = *job;
        for gauge in 0..6 {
            let spread = (i32::from(job.max[gauge]) - i32::from(job.min[gauge])) as u32;
            if spread > u32::from(job.cfg.max_spread) {
                return self.finish_bias(Err(BiasError::Moving {
                    gauge,
                    spread,
                    allowed: job.cfg.max_spread,
                }));
            }
        }
        self.finish_bias(Ok(job.sum.map(|s| s / f64::from(job.n))));
    }

    fn fail_bias(&mut self, e: BiasError) {
        if self.bias_job.is_some() {
            self.finish_bias(Err(e));
        }
    }

    // ---- the exchange -------------------------------------------------------------------------

    fn on_bus_error(&mut self, e: BusError) {
        self.counters.bus_errors += 1;
        if e.bus_off {
            self.counters.bus_off += 1;
            self.phase = Phase::BusOff;
            self.health = Health::BusOff;
            self.fail_bias(BiasError::NotReady);
        } else if e.restarted && self.phase == Phase::BusOff {
            self.restart();
        }
    }

    /// Drop everything that arrives until `until` (bus time), counting it. Stops early after a burst
    /// of [`DISCARD_BURST`] frames past `until`, so a flooded bus cannot hold the caller.
    fn discard_until(&mut self, until: Duration) -> Result<(), AtiError> {
        let mut burst = 0;
        loop {
            let wait = until.saturating_sub(self.clock.now());
            if wait.is_zero() {
                burst += 1;
                if burst > DISCARD_BURST {
                    return Ok(());
                }
            }
            match self.transport.recv(wait)? {
                // A transport may wake early (rounding, signals): only the clock says the wait is over.
                None if self.clock.now() < until => {}
                None => return Ok(()),
                Some(BusEvent::Error(e)) => self.on_bus_error(e),
                Some(BusEvent::Frame(f)) => match self.cfg.base.opcode_of(&f) {
                    Ok(_) => self.counters.stray += 1,
                    Err(_) => self.counters.foreign += 1,
                },
            }
        }
    }

    fn abandon(&mut self, sent: Duration, req: Request) -> Reply {
        self.quiet_until = Some(sent + self.cfg.deadline(req) * 3);
        Reply::Abandoned
    }

    fn exchange(&mut self, req: Request) -> Result<Reply, AtiError> {
        // Anything already queued belongs to an older generation.
        let now = self.clock.now();
        self.discard_until(now)?;
        if self.phase == Phase::BusOff {
            return Ok(Reply::BusOff);
        }
        let frame = req.encode(self.cfg.base)?;
        self.generation += 1;
        self.transport.send(&frame)?;
        self.counters.requests += 1;
        if req == Request::Poll {
            self.polls += 1;
        }
        let sent = self.clock.now();
        let deadline = sent + self.cfg.deadline(req);
        let layout = req.answer_layout();
        let mut got: [Option<Answer>; 3] = [None; 3];
        let mut n = 0;
        loop {
            // Past the deadline the wait is zero: what already sits in the queue still counts (a
            // descheduled driver must not call an answer it has received a timeout).
            let wait = deadline.saturating_sub(self.clock.now());
            let event = self.transport.recv(wait)?;
            let frame = match event {
                // Woke early: wait on until the deadline.
                None if self.clock.now() < deadline => continue,
                None => {
                    self.counters.timeouts += 1;
                    return Ok(self.abandon(sent, req));
                }
                Some(BusEvent::Error(e)) => {
                    self.on_bus_error(e);
                    if self.phase == Phase::BusOff {
                        return Ok(Reply::BusOff);
                    }
                    continue;
                }
                Some(BusEvent::Frame(f)) => f,
            };
            match Answer::decode(&frame, self.cfg.base) {
                Err(
                    CodecError::Foreign { .. }
                    | CodecError::Extended { .. }
                    | CodecError::Remote { .. },
                ) => self.counters.foreign += 1,
                Err(_) => {
                    self.counters.malformed += 1;
                    return Ok(self.abandon(sent, req));
                }
                Ok(a) => {
                    let reserved = matches!(a, Answer::PollFirst { status, .. } if status.0 & Status::RESERVED != 0);
                    if reserved {
                        self.counters.malformed += 1;
                        return Ok(self.abandon(sent, req));
                    }
                    if layout.get(n).map(|&(op, _)| op) != Some(a.opcode()) {
                        self.counters.sequence_errors += 1;
                        return Ok(self.abandon(sent, req));
                    }
                    got[n] = Some(a);
                    n += 1;
                    if n == layout.len() {
                        return Ok(Reply::Answer(got));
                    }
                }
            }
        }
    }

    fn wait_for_restart(&mut self) -> Result<Outcome, AtiError> {
        let until = self.clock.now() + self.cfg.deadline(Request::Poll);
        self.discard_until(until)?;
        Ok(if self.phase == Phase::BusOff {
            Outcome::BusOff
        } else {
            Outcome::Restarting
        })
    }

    // ---- polling ------------------------------------------------------------------------------

    fn no_valid_answer(&mut self) {
        self.good_streak = 0;
        self.fail_streak = self.fail_streak.saturating_add(1);
        if self.fail_streak >= self.cfg.timeout_after && self.health != Health::Waiting {
            self.health = Health::Timeout;
        }
        self.fail_bias(BiasError::NoAnswer);
    }

    fn poll(&mut self) -> Result<Outcome, AtiError> {
        let answer = match self.exchange(Request::Poll)? {
            Reply::BusOff => return Ok(Outcome::BusOff),
            Reply::Abandoned => {
                self.no_valid_answer();
                return Ok(Outcome::NoAnswer);
            }
            Reply::Answer(a) => a,
        };
        let stamp = self.clock.now();
        let seq = self.polls;
        let (
            Some(Answer::PollFirst {
                status,
                gauges: first,
            }),
            Some(Answer::PollSecond { gauges: second }),
        ) = (answer[0], answer[1])
        else {
            // The layout check in `exchange` makes this unreachable; treat it as a bad answer anyway.
            self.counters.sequence_errors += 1;
            self.no_valid_answer();
            return Ok(Outcome::NoAnswer);
        };
        let gauges = interleave(first, second);
        self.status = status;
        if status.watchdog_reset() {
            self.counters.watchdog_resets += 1;
            self.restart();
            return Ok(Outcome::Restarting);
        }
        let jumped = match (self.cfg.max_gauge_step, self.last_gauges) {
            (Some(max), Some(prev)) => prev
                .0
                .iter()
                .zip(gauges.0)
                .any(|(&p, g)| (i32::from(p) - i32::from(g)).unsigned_abs() > u32::from(max)),
            _ => false,
        };
        self.last_gauges = Some(gauges);
        if jumped {
            self.counters.implausible += 1;
            self.no_valid_answer();
            return Ok(Outcome::NoAnswer);
        }
        let withheld = if status.is_critical() {
            self.counters.device_errors += 1;
            self.fail_bias(BiasError::DeviceFault(status));
            Some(Health::DeviceError(status))
        } else if gauges.is_saturated() {
            self.counters.saturated += 1;
            self.fail_bias(BiasError::Saturated);
            Some(Health::Saturated)
        } else {
            None
        };
        self.fail_streak = 0;
        if let Some(h) = withheld {
            self.good_streak = 0;
            self.health = h;
            return Ok(Outcome::Withheld);
        }
        let Some(conv) = self.converter else {
            // Running without a converter cannot happen (start-up sets it); restart to be safe.
            self.restart();
            return Ok(Outcome::Restarting);
        };
        self.latest = Some(Latest {
            wrench: conv.wrench(&gauges, &self.bias),
            gauges,
            seq,
            stamp,
        });
        self.counters.samples += 1;
        self.good_streak = self.good_streak.saturating_add(1);
        if self.health == Health::Waiting || self.good_streak >= self.cfg.recover_after {
            self.health = Health::Ok;
        }
        self.feed_bias(&gauges);
        Ok(Outcome::Sample(seq))
    }

    /// Forget the running state and run start-up again (watchdog reset, bus restart). The bias stays:
    /// it lives on the raw gauges, which a board reset does not move.
    fn restart(&mut self) {
        self.phase = Phase::Startup(Step::Firmware);
        self.attempt = 0;
        self.partial = Partial::default();
        self.health = Health::Waiting;
        self.latest = None;
        self.last_gauges = None;
        self.good_streak = 0;
        self.fail_streak = 0;
        self.fail_bias(BiasError::NotReady);
    }

    // ---- start-up -----------------------------------------------------------------------------

    fn request_of(&self, step: Step) -> Request {
        match step {
            Step::Firmware => Request::Firmware,
            Step::Serial => Request::Serial,
            Step::Slot => Request::SelectSlot(self.cfg.slot),
            Step::Matrix(row) => Request::MatrixRow(row),
            Step::Counts => Request::CountsPerUnit,
            Step::Units => Request::Units,
        }
    }

    fn advance(&mut self, next: Step) -> Outcome {
        self.phase = Phase::Startup(next);
        self.attempt = 0;
        Outcome::StartupProgress
    }

    fn startup_failed(&mut self, p: StartupProblem) -> Outcome {
        self.counters.startup_failures += 1;
        self.problem = Some(p);
        self.phase = Phase::Startup(Step::Firmware);
        self.attempt = 0;
        self.partial = Partial::default();
        Outcome::StartupFailed(p)
    }

    fn startup_step(&mut self, step: Step) -> Result<Outcome, AtiError> {
        let req = self.request_of(step);
        let answer = match self.exchange(req)? {
            Reply::BusOff => return Ok(Outcome::BusOff),
            Reply::Answer(a) => a,
            Reply::Abandoned => return Ok(self.startup_no_answer(step)),
        };
        Ok(match (step, answer[0]) {
            (Step::Firmware, Some(Answer::Firmware(fw))) => {
                self.partial.firmware = Some(fw);
                self.advance(Step::Serial)
            }
            (Step::Serial, Some(Answer::Serial(s))) => {
                self.partial.serial = Some(s);
                self.advance(Step::Slot)
            }
            (Step::Slot, Some(Answer::SlotEcho(echoed))) => {
                if echoed == self.cfg.slot {
                    self.advance(Step::Matrix(0))
                } else {
                    self.counters.echo_mismatches += 1;
                    self.attempt += 1;
                    if self.attempt >= self.cfg.attempts {
                        self.startup_failed(StartupProblem::SlotEcho {
                            requested: self.cfg.slot,
                            echoed,
                        })
                    } else {
                        Outcome::NoAnswer
                    }
                }
            }
            (Step::Matrix(row), _) => {
                let mut coeffs = [0.0f32; 6];
                for (part, a) in answer.iter().enumerate() {
                    if let Some(Answer::MatrixPart { coefficients, .. }) = a {
                        coeffs[2 * part] = coefficients[0];
                        coeffs[2 * part + 1] = coefficients[1];
                    }
                }
                if !coeffs.iter().all(|&c| plausible_coefficient(c)) {
                    // Corrupted or byte-swapped: ask for the row again.
                    self.counters.malformed += 1;
                    return Ok(self.startup_no_answer(step));
                }
                self.partial.matrix[usize::from(row)] = coeffs;
                if row < 5 {
                    self.advance(Step::Matrix(row + 1))
                } else {
                    self.advance(Step::Counts)
                }
            }
            (
                Step::Counts,
                Some(Answer::Counts {
                    per_force,
                    per_torque,
                }),
            ) if !(plausible_counts(per_force) && plausible_counts(per_torque)) => {
                // Corrupted or byte-swapped: ask again.
                self.counters.malformed += 1;
                self.startup_no_answer(step)
            }
            (
                Step::Counts,
                Some(Answer::Counts {
                    per_force,
                    per_torque,
                }),
            ) => {
                self.partial.counts = Some((per_force, per_torque));
                self.advance(Step::Units)
            }
            (Step::Units, Some(Answer::Units { force, torque })) => {
                match (ForceUnit::from_code(force), TorqueUnit::from_code(torque)) {
                    (Some(f), Some(t)) => {
                        self.partial.units = Some((f, t));
                        self.finish_startup()
                    }
                    _ => self.startup_failed(StartupProblem::UnitCode { force, torque }),
                }
            }
            // `exchange` checked the opcodes against the request's layout: nothing else can arrive.
            _ => self.startup_no_answer(step),
        })
    }

    fn startup_no_answer(&mut self, step: Step) -> Outcome {
        self.attempt += 1;
        let old_firmware = self
            .partial
            .firmware
            .is_some_and(|fw| !fw.has_counts_per_unit());
        match step {
            Step::Counts if old_firmware => {
                self.partial.counts = Some((LEGACY_COUNTS_PER_UNIT, LEGACY_COUNTS_PER_UNIT));
                self.partial.counts_assumed = true;
                self.advance(Step::Units)
            }
            _ if self.attempt < self.cfg.attempts => Outcome::NoAnswer,
            Step::Serial => self.advance(Step::Slot),
            Step::Units => self.finish_startup(),
            Step::Firmware => self.startup_failed(StartupProblem::NoAnswer {
                step: "firmware (0xF)",
            }),
            Step::Slot => self.startup_failed(StartupProblem::NoAnswer {
                step: "select calibration slot (0x6)",
            }),
            Step::Matrix(_) => self.startup_failed(StartupProblem::NoAnswer {
                step: "calibration matrix (0x2)",
            }),
            Step::Counts => self.startup_failed(StartupProblem::NoAnswer {
                step: "counts per unit (0x7)",
            }),
        }
    }

    fn finish_startup(&mut self) -> Outcome {
        let p = self.partial;
        let (Some(firmware), Some((cpf, cpt))) = (p.firmware, p.counts) else {
            return self.startup_failed(StartupProblem::NoAnswer {
                step: "firmware (0xF)",
            });
        };
        let (force_unit, torque_unit) = p.units.unwrap_or((ForceUnit::N, TorqueUnit::Nm));
        let calibration = Calibration {
            matrix: p.matrix,
            counts_per_force: cpf,
            counts_per_torque: cpt,
            force_unit,
            torque_unit,
        };
        let converter = match calibration.converter() {
            Ok(c) => c,
            Err(e) => return self.startup_failed(StartupProblem::Calibration(e)),
        };
        self.converter = Some(converter);
        self.info = Some(DeviceInfo {
            firmware,
            serial: p.serial,
            slot: self.cfg.slot,
            calibration,
            counts_assumed: p.counts_assumed,
            units_assumed: p.units.is_none(),
        });
        self.problem = None;
        self.phase = Phase::Running;
        self.health = Health::Waiting;
        self.counters.startups += 1;
        Outcome::Started
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deadline_follows_the_bit_rate() {
        let mut cfg = Config {
            bitrate: 250_000,
            turnaround: Duration::ZERO,
            ..Config::default()
        };
        // 253 bits × 1.2 at 250 kbit/s = 1.2144 ms on the wire (the spec's ≈ 1.0–1.2 ms).
        assert_eq!(
            cfg.wire_time(Request::Poll),
            Duration::from_nanos(1_214_400)
        );
        assert_eq!(cfg.deadline(Request::Poll), Duration::from_nanos(2_428_800));
        cfg.bitrate = 1_000_000;
        assert_eq!(cfg.wire_time(Request::Poll), Duration::from_nanos(303_600));
        // A matrix row: 55 + 3 × 111 bits.
        assert_eq!(
            cfg.wire_time(Request::MatrixRow(0)),
            Duration::from_nanos(465_600)
        );
    }

    #[test]
    fn invalid_configs_are_refused_with_a_reason() {
        let bad = [
            Config {
                bitrate: 5_000,
                ..Config::default()
            },
            Config {
                slot: 16,
                ..Config::default()
            },
            Config {
                attempts: 0,
                ..Config::default()
            },
            Config {
                stale_after: Duration::ZERO,
                ..Config::default()
            },
        ];
        for cfg in bad {
            let e = cfg.validate().unwrap_err();
            assert!(matches!(e, AtiError::Config(_)), "{e}");
        }
        assert!(Config::default().validate().is_ok());
    }

    #[test]
    fn view_gates_samples_by_health_and_age() {
        let latest = Latest {
            wrench: Wrench::from_array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
            gauges: Gauges::default(),
            seq: 7,
            stamp: Duration::from_millis(100),
        };
        let mut v = View {
            health: Health::Ok,
            latest: Some(latest),
            problem: None,
            stale_after: Duration::from_millis(10),
        };
        let s = v.sample_at(Duration::from_millis(105)).unwrap();
        assert_eq!((s.seq, s.age), (7, Duration::from_millis(5)));
        assert!(matches!(
            v.sample_at(Duration::from_millis(111)),
            Err(AtiError::Stale { .. })
        ));
        assert_eq!(v.health_at(Duration::from_millis(111)), Health::Stale);
        v.health = Health::Saturated;
        assert!(matches!(
            v.sample_at(Duration::from_millis(101)),
            Err(AtiError::Saturated)
        ));
    }
}
