//! A simulated ATI NETCANOEM board: answers the whole opcode table on any CAN transport (vcan through
//! [`serve`], or synchronously on the in-memory bus as an [`ati_can::Responder`]), with fault injection.
//!
//! Gauges come from a true wrench (a [`WrenchSource`], e.g. the contact plant) through the inverse of the
//! active slot's calibration, plus drift and Gaussian noise, rounded and clamped to `i16` — so an
//! overload really saturates a gauge. The board's codec is the driver's ([`ati_can::codec`]), used in the
//! opposite direction; the spec's golden vectors pin both.

use core::time::Duration;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use ati_can::calibration::CalibrationError;
use ati_can::codec::{op, split};
use ati_can::{
    Answer, Base, BusEvent, Calibration, CanTransport, Converter, Firmware, ForceUnit, Frame,
    Gauges, Request, Responder, Status, TorqueUnit, TransportError,
};
use hal::Wrench;
use rand::SeedableRng;

use crate::world::SharedWorld;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Where the node's wrench (N, N·m, sensor frame) comes from, at node time `t`.
pub trait WrenchSource: Send {
    /// The wrench acting on the sensor now, or `None` when the board should not answer this poll
    /// (a sensor dropout).
    fn wrench(&mut self, t: Duration) -> Option<Wrench>;
}

impl<F: FnMut(Duration) -> Wrench + Send> WrenchSource for F {
    fn wrench(&mut self, t: Duration) -> Option<Wrench> {
        Some(self(t))
    }
}

/// A [`World`](crate::World) as the node's wrench source.
pub struct WorldSource {
    world: SharedWorld,
    measured: bool,
}

impl WorldSource {
    /// The world's sensor model reading (the scenario's noise, bias, drift and dropouts), which the node
    /// then quantises through its calibration.
    pub fn measured(world: SharedWorld) -> Self {
        Self {
            world,
            measured: true,
        }
    }

    /// The plant's true wrench ([`World::true_wrench`](crate::World::true_wrench)), untouched.
    pub fn truth(world: SharedWorld) -> Self {
        Self {
            world,
            measured: false,
        }
    }
}

impl WrenchSource for WorldSource {
    fn wrench(&mut self, _t: Duration) -> Option<Wrench> {
        let mut w = crate::world::lock(&self.world);
        if self.measured {
            w.measure()
        } else {
            Some(w.true_wrench())
        }
    }
}

/// A fault applied to the node's next answer(s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Fault {
    /// No answer at all.
    Drop,
    /// Leave out frame `i` of the answer.
    DropFrame(usize),
    /// Send the first two frames of the answer in reverse order.
    Swap,
    /// Send frame `i` twice in a row.
    DuplicateFrame(usize),
    /// Send the whole answer twice.
    DuplicateAnswer,
    /// The first frame one byte short.
    WrongDlc,
    /// The first frame with this opcode instead of its own (same data).
    WrongOpcode(u8),
    /// Every multi-byte field little-endian.
    WrongByteOrder,
    /// The answer after this delay.
    Late(Duration),
    /// A frame of another base (0x7F0) before the answer.
    Foreign,
    /// An extended frame with the answer's identifier before the answer.
    Extended,
    /// A remote frame with the answer's identifier before the answer.
    Remote,
}

/// The board's settings.
#[derive(Clone, Debug)]
pub struct NodeConfig {
    /// Base identifier.
    pub base: Base,
    /// Firmware reported (≥ 3.7 answers counts per unit, ≥ 3.8 the ADC request).
    pub firmware: Firmware,
    /// Calibration serial number, ASCII.
    pub serial: [u8; 8],
    /// The 16 calibration slots.
    pub slots: [Calibration; 16],
    /// Gaussian gauge noise, counts (standard deviation).
    pub noise_counts: f64,
    /// Gauge drift, counts per second, per gauge.
    pub drift_counts_per_s: [f64; 6],
    /// Seed of the noise.
    pub seed: u64,
    /// Bit `k` set: slot `k` holds no calibration; selecting it keeps the active slot (and echoes that).
    pub missing_slots: u16,
}

/// A plausible Mini45-like calibration: about 0.01 N and 0.2 N·mm per count, with cross-coupling.
pub fn example_calibration() -> Calibration {
    let mut matrix = [[0.0f32; 6]; 6];
    for (i, row) in matrix.iter_mut().enumerate() {
        for (j, c) in row.iter_mut().enumerate() {
            *c = if i == j {
                if i < 3 { 10_000.0 } else { 200.0 }
            } else {
                // Small, asymmetric cross-talk, exactly representable in f32.
                ((i * 7 + j * 3) % 11) as f32 * if i < 3 { 12.5 } else { 0.25 }
                    - if i < 3 { 50.0 } else { 1.0 }
            };
        }
    }
    Calibration {
        matrix,
        counts_per_force: 1_000_000,
        counts_per_torque: 1_000_000,
        force_unit: ForceUnit::N,
        torque_unit: TorqueUnit::Nm,
    }
}

impl Default for NodeConfig {
    /// Firmware 3.8, serial `FT-SIM01`, slot `k` = the example calibration with its matrix scaled by
    /// `1 + k/8` (so a board that fell back to slot 0 reads visibly wrong), no noise, no drift.
    fn default() -> Self {
        let base_cal = example_calibration();
        let slots = core::array::from_fn(|k| {
            let mut c = base_cal;
            let s = 1.0 + k as f32 / 8.0;
            for row in c.matrix.iter_mut() {
                for v in row.iter_mut() {
                    *v *= s;
                }
            }
            c
        });
        Self {
            base: Base::DEFAULT,
            firmware: Firmware {
                major: 3,
                minor: 8,
                build: 1,
            },
            serial: *b"FT-SIM01",
            slots,
            noise_counts: 0.0,
            drift_counts_per_s: [0.0; 6],
            seed: 1,
            missing_slots: 0,
        }
    }
}

/// The simulated board.
pub struct AtiNode {
    cfg: NodeConfig,
    converters: Vec<Converter>,
    active: u8,
    status: u16,
    source: Box<dyn WrenchSource>,
    rng: ChaCha8Rng,
    noise: Option<Normal<f64>>,
    faults: VecDeque<Fault>,
    silent: bool,
    polls: u64,
    requests: u64,
    next_base: Option<u8>,
    next_bitrate: Option<u8>,
    /// Scratch lists of [`AtiNode::handle`].
    answer_buf: Vec<Answer>,
    frame_buf: Vec<Frame>,
}

impl AtiNode {
    /// A board in slot 0 with status 0. Fails when a slot's calibration is unusable or singular.
    pub fn new(
        cfg: NodeConfig,
        source: impl WrenchSource + 'static,
    ) -> Result<Self, CalibrationError> {
        let converters = cfg
            .slots
            .iter()
            .map(|c| {
                let conv = c.converter()?;
                conv.counts_for(&Wrench::default())?;
                Ok(conv)
            })
            .collect::<Result<Vec<_>, CalibrationError>>()?;
        let noise = (cfg.noise_counts > 0.0)
            .then(|| Normal::new(0.0, cfg.noise_counts).ok())
            .flatten();
        Ok(Self {
            rng: ChaCha8Rng::seed_from_u64(cfg.seed),
            cfg,
            converters,
            active: 0,
            status: 0,
            source: Box::new(source),
            noise,
            faults: VecDeque::new(),
            silent: false,
            polls: 0,
            requests: 0,
            next_base: None,
            next_bitrate: None,
            answer_buf: Vec::with_capacity(8),
            frame_buf: Vec::with_capacity(16),
        })
    }

    /// The settings.
    pub fn config(&self) -> &NodeConfig {
        &self.cfg
    }

    /// Set the status word sent with every poll answer.
    pub fn set_status(&mut self, status: u16) {
        self.status = status;
    }

    /// The status word.
    pub fn status(&self) -> Status {
        Status(self.status)
    }

    /// Report another firmware version.
    pub fn set_firmware(&mut self, fw: Firmware) {
        self.cfg.firmware = fw;
    }

    /// Apply `fault` to the next answer (faults queue up, one per answer).
    pub fn inject(&mut self, fault: Fault) {
        self.faults.push_back(fault);
    }

    /// Apply `fault` to each of the next `n` answers.
    pub fn inject_n(&mut self, fault: Fault, n: usize) {
        self.faults.extend(core::iter::repeat_n(fault, n));
    }

    /// Faults injected but not applied yet.
    pub fn pending_faults(&self) -> usize {
        self.faults.len()
    }

    /// Stop answering anything (a disconnected board) or resume.
    pub fn set_silent(&mut self, silent: bool) {
        self.silent = silent;
    }

    /// A watchdog reset: back to calibration slot 0 with the watchdog bit set until a slot is selected.
    pub fn reset(&mut self) {
        self.active = 0;
        self.status |= Status::WATCHDOG_RESET;
    }

    /// The active calibration slot.
    pub fn active_slot(&self) -> u8 {
        self.active
    }

    /// Poll requests answered or faulted so far.
    pub fn polls(&self) -> u64 {
        self.polls
    }

    /// Valid requests received so far.
    pub fn requests(&self) -> u64 {
        self.requests
    }

    /// Base and bit-rate code stored for the next power-up, if set.
    pub fn pending_settings(&self) -> (Option<u8>, Option<u8>) {
        (self.next_base, self.next_bitrate)
    }

    /// The gauges the board would report for `wrench` at time `t` (before faults).
    pub fn gauges_for(&mut self, wrench: &Wrench, t: Duration) -> Gauges {
        let conv = &self.converters[usize::from(self.active)];
        // Singularity was checked in `new`; a zero vector is the safe fallback.
        let exact = conv.counts_for(wrench).unwrap_or([0.0; 6]);
        let mut g = [0i16; 6];
        for (i, out) in g.iter_mut().enumerate() {
            let noise = self.noise.map_or(0.0, |n| n.sample(&mut self.rng));
            let v = exact[i] + self.cfg.drift_counts_per_s[i] * t.as_secs_f64() + noise;
            // A reading the gauge cannot represent is a saturated gauge, as on the board (the spec:
            // ±32767/−32768 marks the sample unusable) — never a plausible 0 N. An injected NaN
            // sample has no sign: it saturates high.
            *out = if v.is_nan() {
                i16::MAX
            } else {
                v.round().clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
            };
        }
        Gauges(g)
    }

    /// The answers to `req` at `now`, pushed onto `out`.
    fn answers(&mut self, req: Request, now: Duration, out: &mut Vec<Answer>) {
        let fw = self.cfg.firmware;
        let cal = self.cfg.slots[usize::from(self.active)];
        match req {
            Request::Poll => {
                self.polls += 1;
                let Some(w) = self.source.wrench(now) else {
                    return;
                };
                let g = self.gauges_for(&w, now);
                let (first, second) = split(&g);
                out.extend([
                    Answer::PollFirst {
                        status: Status(self.status),
                        gauges: first,
                    },
                    Answer::PollSecond { gauges: second },
                ]);
            }
            Request::MatrixRow(r) => {
                let row = cal.matrix[usize::from(r)];
                out.extend((0..3u8).map(|part| Answer::MatrixPart {
                    part,
                    coefficients: [row[usize::from(2 * part)], row[usize::from(2 * part + 1)]],
                }));
            }
            Request::Serial => out.push(Answer::Serial(self.cfg.serial)),
            Request::SelectSlot(s) => {
                if self.cfg.missing_slots & (1 << s) == 0 {
                    self.active = s;
                }
                let s = self.active;
                self.status &= !Status::WATCHDOG_RESET;
                out.push(Answer::SlotEcho(s));
            }
            Request::CountsPerUnit if fw.has_counts_per_unit() => out.push(Answer::Counts {
                per_force: cal.counts_per_force,
                per_torque: cal.counts_per_torque,
            }),
            Request::Units => out.push(Answer::Units {
                force: cal.force_unit.code(),
                torque: cal.torque_unit.code(),
            }),
            Request::AdcVoltage(i) if (fw.major, fw.minor) >= (3, 8) => {
                out.push(Answer::Adc(2500 + u16::from(i)));
            }
            Request::Reset => self.reset(),
            Request::SetBase(b) => self.next_base = Some(b),
            Request::SetBitrate(c) => self.next_bitrate = Some(c),
            Request::Firmware => out.push(Answer::Firmware(fw)),
            Request::CountsPerUnit | Request::AdcVoltage(_) => {}
        }
    }

    /// Handle one frame seen on the bus at node time `now`; emit answers with `out(delay, frame)`.
    /// Frames that are not valid requests for this base are ignored, as the board ignores them.
    pub fn handle(&mut self, frame: &Frame, now: Duration, out: &mut dyn FnMut(Duration, Frame)) {
        let Ok(req) = Request::decode(frame, self.cfg.base) else {
            return;
        };
        self.requests += 1;
        // Both lists are kept between frames: an answer allocates nothing.
        let mut answers = core::mem::take(&mut self.answer_buf);
        answers.clear();
        self.answers(req, now, &mut answers);
        if !(self.silent || answers.is_empty()) {
            let base = self.cfg.base;
            let mut frames = core::mem::take(&mut self.frame_buf);
            frames.clear();
            frames.extend(answers.iter().filter_map(|a| a.encode(base).ok()));
            let mut delay = Duration::ZERO;
            if let Some(fault) = self.faults.pop_front() {
                apply(fault, base, &mut frames, &mut delay);
            }
            for &f in &frames {
                out(delay, f);
            }
            self.frame_buf = frames;
        }
        self.answer_buf = answers;
    }
}

fn swap_fields(f: &Frame) -> Frame {
    let mut d = [0u8; 8];
    let n = f.data().len();
    d[..n].copy_from_slice(f.data());
    let width = match (f.id() & 0xF) as u8 {
        op::POLL | op::POLL_2 | op::ADC => 2,
        0x2..=0x4 | op::COUNTS => 4,
        _ => 1,
    };
    for chunk in d[..n].chunks_mut(width) {
        chunk.reverse();
    }
    if (f.id() & 0xF) as u8 == op::FIRMWARE {
        d.swap(2, 3);
    }
    Frame::standard(f.id() as u16, &d[..n]).unwrap_or(*f)
}

fn apply(fault: Fault, base: Base, frames: &mut Vec<Frame>, delay: &mut Duration) {
    let first_id = frames.first().map_or(base.id(0), |f| f.id() as u16);
    match fault {
        Fault::Drop => frames.clear(),
        Fault::DropFrame(i) if i < frames.len() => {
            frames.remove(i);
        }
        Fault::Swap if frames.len() >= 2 => frames.swap(0, 1),
        Fault::DuplicateFrame(i) if i < frames.len() => {
            let f = frames[i];
            frames.insert(i, f);
        }
        Fault::DuplicateAnswer => {
            let copy = frames.clone();
            frames.extend(copy);
        }
        Fault::WrongDlc => {
            if let Some(f) = frames.first_mut() {
                let n = f.data().len().saturating_sub(1);
                if let Some(g) = Frame::standard(f.id() as u16, &f.data()[..n]) {
                    *f = g;
                }
            }
        }
        Fault::WrongOpcode(opcode) => {
            if let Some(f) = frames.first_mut() {
                let id = (f.id() as u16 & 0x7F0) | u16::from(opcode & 0xF);
                if let Some(g) = Frame::standard(id, f.data()) {
                    *f = g;
                }
            }
        }
        Fault::WrongByteOrder => {
            for f in frames.iter_mut() {
                *f = swap_fields(f);
            }
        }
        Fault::Late(d) => *delay = d,
        Fault::Foreign => {
            if let Some(f) = Frame::standard(0x7F0, &[0xAA; 8]) {
                frames.insert(0, f);
            }
        }
        Fault::Extended => {
            if let Some(f) = Frame::extended(u32::from(first_id), &[0x55; 8]) {
                frames.insert(0, f);
            }
        }
        Fault::Remote => {
            if let Some(f) = Frame::remote(u32::from(first_id), false, 8) {
                frames.insert(0, f);
            }
        }
        // An index beyond the answer, or a swap of a one-frame answer: nothing to do.
        Fault::DropFrame(_) | Fault::Swap | Fault::DuplicateFrame(_) => {}
    }
}

/// A node shared between a transport (or a bus) and the test or application that steers it.
#[derive(Clone)]
pub struct SharedNode(Arc<Mutex<AtiNode>>);

impl SharedNode {
    /// Share `node`.
    pub fn new(node: AtiNode) -> Self {
        Self(Arc::new(Mutex::new(node)))
    }

    /// Lock it to steer it (status, faults, reset …).
    pub fn lock(&self) -> MutexGuard<'_, AtiNode> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Responder for SharedNode {
    fn on_frame(&mut self, frame: &Frame, now: Duration, out: &mut dyn FnMut(Duration, Frame)) {
        self.lock().handle(frame, now, out);
    }
}

/// Run `node` on `transport` (e.g. a SocketCAN interface) until `stop` is set: answer every request,
/// holding late answers back without blocking the others. Returns on a transport error.
pub fn serve<T: CanTransport>(
    node: &SharedNode,
    transport: T,
    stop: &AtomicBool,
) -> Result<(), TransportError> {
    let base = node.lock().config().base;
    serve_responder(&mut node.clone(), base, transport, stop)
}

/// [`serve`] for any [`Responder`] answering on `base` (e.g. a replay of a recorded bus log).
pub fn serve_responder<R: Responder, T: CanTransport>(
    responder: &mut R,
    base: Base,
    mut transport: T,
    stop: &AtomicBool,
) -> Result<(), TransportError> {
    transport.accept_only(base)?;
    let clock = transport.clock();
    let mut pending: VecDeque<(Duration, Frame)> = VecDeque::new();
    while !stop.load(Ordering::Acquire) {
        let now = clock.now();
        while pending.front().is_some_and(|(due, _)| *due <= now) {
            if let Some((_, f)) = pending.pop_front() {
                transport.send(&f)?;
            }
        }
        let wait = pending
            .front()
            .map_or(Duration::from_millis(20), |(due, _)| {
                due.saturating_sub(now)
            });
        if let Some(BusEvent::Frame(f)) = transport.recv(wait)? {
            let t = clock.now();
            responder.on_frame(&f, t, &mut |delay, answer| {
                let due = t + delay;
                let at = pending
                    .iter()
                    .rposition(|(d, _)| *d <= due)
                    .map_or(0, |i| i + 1);
                pending.insert(at, (due, answer));
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ati_can::codec::interleave;

    fn node_with(w: Wrench) -> AtiNode {
        AtiNode::new(NodeConfig::default(), move |_t: Duration| w).unwrap()
    }

    fn collect(node: &mut AtiNode, req: Request) -> Vec<(Duration, Frame)> {
        let mut v = Vec::new();
        let f = req.encode(Base::DEFAULT).unwrap();
        node.handle(&f, Duration::ZERO, &mut |d, f| v.push((d, f)));
        v
    }

    #[test]
    fn poll_answer_reads_back_as_the_true_wrench() {
        let w = Wrench::from_array([12.0, -3.0, 40.0, 0.5, -0.25, 0.1]);
        let mut node = node_with(w);
        let frames = collect(&mut node, Request::Poll);
        assert_eq!(frames.len(), 2);
        let (Ok(Answer::PollFirst { gauges: a, status }), Ok(Answer::PollSecond { gauges: b })) = (
            Answer::decode(&frames[0].1, Base::DEFAULT),
            Answer::decode(&frames[1].1, Base::DEFAULT),
        ) else {
            panic!("{frames:?}");
        };
        assert_eq!(status, Status(0));
        let conv = NodeConfig::default().slots[0].converter().unwrap();
        let back = conv.wrench(&interleave(a, b), &[0.0; 6]);
        for (x, y) in back.to_array().iter().zip(w.to_array()) {
            // Quantisation: well under one count of any axis.
            assert!((x - y).abs() < 0.02, "{x} vs {y}");
        }
    }

    #[test]
    fn overload_saturates_a_gauge() {
        let mut node = node_with(Wrench::from_array([0.0, 0.0, 5000.0, 0.0, 0.0, 0.0]));
        let g = node.gauges_for(
            &Wrench::from_array([0.0, 0.0, 5000.0, 0.0, 0.0, 0.0]),
            Duration::ZERO,
        );
        assert!(g.is_saturated(), "{g:?}");
    }

    #[test]
    fn a_non_finite_reading_is_a_saturated_gauge_not_zero_newtons() {
        let mut node = node_with(Wrench::default());
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let g = node.gauges_for(
                &Wrench::from_array([0.0, 0.0, bad, 0.0, 0.0, 0.0]),
                Duration::ZERO,
            );
            assert!(g.is_saturated(), "{bad}: {g:?}");
        }
    }

    #[test]
    fn old_firmware_does_not_answer_counts_or_adc() {
        let mut node = node_with(Wrench::default());
        assert_eq!(collect(&mut node, Request::CountsPerUnit).len(), 1);
        assert_eq!(collect(&mut node, Request::AdcVoltage(0)).len(), 1);
        node.set_firmware(Firmware {
            major: 3,
            minor: 6,
            build: 0,
        });
        assert!(collect(&mut node, Request::CountsPerUnit).is_empty());
        assert!(collect(&mut node, Request::AdcVoltage(0)).is_empty());
    }

    #[test]
    fn slot_selection_reset_and_settings() {
        let mut node = node_with(Wrench::default());
        let echo = collect(&mut node, Request::SelectSlot(3));
        assert_eq!(echo[0].1.to_string(), "206#03");
        assert_eq!(node.active_slot(), 3);
        assert!(collect(&mut node, Request::Reset).is_empty());
        assert_eq!(node.active_slot(), 0);
        assert!(node.status().watchdog_reset());
        collect(&mut node, Request::SelectSlot(3));
        assert!(!node.status().watchdog_reset());
        collect(&mut node, Request::SetBase(0x21));
        collect(&mut node, Request::SetBitrate(1));
        assert_eq!(node.pending_settings(), (Some(0x21), Some(1)));
    }

    #[test]
    fn faults_shape_the_answer() {
        let mut node = node_with(Wrench::default());
        let ids =
            |v: &[(Duration, Frame)]| v.iter().map(|(_, f)| f.to_string()).collect::<Vec<_>>();
        node.inject(Fault::Swap);
        let v = collect(&mut node, Request::Poll);
        assert!(ids(&v)[0].starts_with("201#") && ids(&v)[1].starts_with("200#"));
        node.inject(Fault::Drop);
        assert!(collect(&mut node, Request::Poll).is_empty());
        node.inject(Fault::DuplicateFrame(0));
        assert_eq!(collect(&mut node, Request::Poll).len(), 3);
        node.inject(Fault::WrongDlc);
        assert_eq!(collect(&mut node, Request::Poll)[0].1.dlc(), 7);
        node.inject(Fault::WrongOpcode(0xA));
        assert_eq!(collect(&mut node, Request::Poll)[0].1.id(), 0x20A);
        node.inject(Fault::Late(Duration::from_millis(7)));
        assert!(
            collect(&mut node, Request::Poll)
                .iter()
                .all(|(d, _)| *d == Duration::from_millis(7))
        );
        node.inject(Fault::Extended);
        assert!(collect(&mut node, Request::Poll)[0].1.is_extended());
        node.inject(Fault::WrongByteOrder);
        let v = collect(&mut node, Request::Firmware);
        assert_eq!(v[0].1.to_string(), "20F#03080100");
        // Faults are used up: the next answer is clean.
        assert_eq!(
            collect(&mut node, Request::Firmware)[0].1.to_string(),
            "20F#03080001"
        );
    }

    #[test]
    fn world_sources_read_the_contact_plant() {
        use crate::{ContactPlant, InnerLoopModel, SensorParams, World};
        // 0.1 mm into a 70 kN/m surface: 7 N.
        let world = World::new(
            ContactPlant::spring(70_000.0, 0.01),
            InnerLoopModel::P0,
            SensorParams::default(),
            0.0101,
        )
        .shared();
        let conv = NodeConfig::default().slots[0].converter().unwrap();
        for source in [
            WorldSource::truth(world.clone()),
            WorldSource::measured(world.clone()),
        ] {
            let mut node = AtiNode::new(NodeConfig::default(), source).unwrap();
            let frames = collect(&mut node, Request::Poll);
            let (Ok(Answer::PollFirst { gauges: a, .. }), Ok(Answer::PollSecond { gauges: b })) = (
                Answer::decode(&frames[0].1, Base::DEFAULT),
                Answer::decode(&frames[1].1, Base::DEFAULT),
            ) else {
                panic!("{frames:?}");
            };
            let fz = conv.wrench(&interleave(a, b), &[0.0; 6]).force.z;
            assert!((fz - 7.0).abs() < 0.02, "{fz}");
        }
    }

    #[test]
    fn ignores_what_is_not_a_request() {
        let mut node = node_with(Wrench::default());
        let mut n = 0;
        for f in [
            Frame::standard(0x200, &[0; 8]).unwrap(),
            Frame::standard(0x300, &[]).unwrap(),
            Frame::extended(0x200, &[]).unwrap(),
            Frame::remote(0x200, false, 0).unwrap(),
        ] {
            node.handle(&f, Duration::ZERO, &mut |_, _| n += 1);
        }
        assert_eq!((n, node.requests()), (0, 0));
    }
}
