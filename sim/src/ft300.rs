//! A simulated Robotiq FT 300 on a real serial device: a pseudo-terminal pair whose slave path is what a
//! driver opens.
//!
//! Inside, the "firmware" multiplexes the one wire between two personalities, as the real sensor does:
//! * **Modbus**: bytes from the driver go, over a second internal pseudo-terminal pair, to a real
//!   tokio-modbus RTU server (slave 9) that answers the registers of the spec (wrench 180..=185,
//!   accelerometer 190..=192, firmware 500..=502, serial 510..=513, year 514) and takes the write of
//!   0x0200 to register 410;
//! * **stream**: after that write has been answered, 16-byte frames at 100 Hz (or one per
//!   [`SimFt300::emit`] in [`Pace::Manual`]) from a [`WrenchSource`], with noise and the device's
//!   quantisation (0.01 N, 0.001 N·m). About ten 0xFF bytes in a row stop the stream.
//!
//! Faults ([`StreamFault`]) apply to the next frames sent.

use core::time::Duration;
use std::collections::VecDeque;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;

use hal::Wrench;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use robotiq::codec::{
    Counts, Identity, REG_ACCEL, REG_FIRMWARE, REG_SERIAL, REG_STREAM, REG_WRENCH, REG_YEAR, SLAVE,
    STOP_BYTE, STREAM_START, encode_frame,
};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{Notify, mpsc};
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};
use tokio_serial::{SerialPort, SerialStream};

use crate::ati_node::WrenchSource;

/// 0xFF bytes in a row that stop the stream.
pub const STOP_RUN: usize = 10;

/// When frames are sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pace {
    /// Every `period` of wall-clock time, like the device.
    Realtime,
    /// Only when [`SimFt300::emit`] asks (a simulation that owns the clock).
    Manual,
}

/// Settings of the simulated sensor.
#[derive(Clone, Debug)]
pub struct Ft300Config {
    /// Identity registers.
    pub identity: Identity,
    /// Standard deviation of the force noise, N.
    pub noise_force: f64,
    /// Standard deviation of the torque noise, N·m.
    pub noise_torque: f64,
    /// Seed of the noise.
    pub seed: u64,
    /// Streaming from the start (a sensor left streaming at power-up).
    pub streaming_at_start: bool,
    /// Frame period in [`Pace::Realtime`].
    pub period: Duration,
    /// When frames are sent.
    pub pace: Pace,
    /// Also make this path a symbolic link to the device (removed again when the sensor stops).
    pub link: Option<PathBuf>,
}

/// The identity of the simulated sensor: firmware `FTS-3.1.0`, serial registers
/// `0x4654 0x5333 0x3030 0x3432`, which the vendor's host driver reads as `FTS-875704368`
/// ([`Identity::serial_text`]), 2021.
pub fn example_identity() -> Identity {
    Identity {
        firmware: *b"FTS\x03\x01\x00",
        serial: Identity::serial_bytes(*b"FTS", b'3', 875_704_368),
        year: 2021,
    }
}

/// Bits one byte takes on the FT 300's line: start, 8 data, stop (8N1).
pub const BITS_PER_BYTE: u32 = 10;

/// The time `bytes` take on a serial line at `baud` bit/s, [`BITS_PER_BYTE`] each.
pub fn wire_time(bytes: usize, baud: u32) -> Duration {
    Duration::from_nanos(bytes as u64 * u64::from(BITS_PER_BYTE) * 1_000_000_000 / u64::from(baud))
}

/// Modbus RTU's end-of-frame silence: 3.5 character times (the slave knows the request ended only
/// after it).
pub fn frame_gap(baud: u32) -> Duration {
    Duration::from_nanos(35 * u64::from(BITS_PER_BYTE) * 100_000_000 / u64::from(baud))
}

/// The RTU bytes of a request to the sensor and of its answer (`ok`: the normal response, else an
/// exception: address, function, code, CRC).
pub fn rtu_sizes(req: &Request<'_>, ok: bool) -> (usize, usize) {
    let request = match req {
        Request::ReadHoldingRegisters(..) | Request::WriteSingleRegister(..) => 8,
        Request::WriteMultipleRegisters(_, words) => 9 + 2 * words.len(),
        _ => 8,
    };
    let reply = match req {
        _ if !ok => 5,
        Request::ReadHoldingRegisters(_, n) => 5 + 2 * usize::from(*n),
        _ => 8,
    };
    (request, reply)
}

/// How long after a request's first byte the simulated sensor's answer has fully left it, at
/// `baud`: the request's bytes, the end-of-frame silence, the answer's bytes. A pseudo-terminal
/// moves bytes at once; the simulated sensor holds each answer back until this time, so a master
/// polls it no faster than the wire allows (at 19 200 bit/s, reading the six wrench registers takes
/// 8 + 17 bytes, 13.0 ms, plus 1.8 ms of silence: at most 67 polls a second).
pub fn exchange_time(request_bytes: usize, reply_bytes: usize, baud: u32) -> Duration {
    wire_time(request_bytes + reply_bytes, baud) + frame_gap(baud)
}

impl Default for Ft300Config {
    fn default() -> Self {
        Self {
            identity: example_identity(),
            noise_force: 0.02,
            noise_torque: 0.0005,
            seed: 300,
            streaming_at_start: false,
            period: Duration::from_millis(10),
            pace: Pace::Realtime,
            link: None,
        }
    }
}

/// A fault applied to the stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StreamFault {
    /// The next frame with a wrong CRC: its Fz high byte is flipped after the CRC was computed, so a
    /// driver that used it anyway would read a wildly different Fz.
    BadCrc,
    /// The next frame with the header bytes `0x20 0x4E` in its payload (Fx and Fy read 200.00 N):
    /// a valid frame a decoder must not split.
    HeaderInPayload,
    /// The next frame sent with this many bytes missing from its middle.
    DropBytes(usize),
    /// No byte for this long, then the stream goes on.
    Stall(Duration),
    /// This many random bytes (headers among them) before the next frame.
    Garbage(usize),
}

/// What the simulated sensor has done.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Ft300Stats {
    /// Frames sent (including broken ones).
    pub frames: u64,
    /// Modbus requests the server answered.
    pub modbus_requests: u64,
    /// Writes that started the stream.
    pub starts: u64,
    /// Times the stop bytes stopped the stream.
    pub stops: u64,
    /// Streaming now.
    pub streaming: bool,
    /// Faults applied.
    pub faults: u64,
}

struct Ctl {
    faults: VecDeque<StreamFault>,
    stats: Ft300Stats,
    start_requested: bool,
    source: Box<dyn WrenchSource>,
    last: Wrench,
    noise: (Option<Normal<f64>>, Option<Normal<f64>>),
    rng: ChaCha8Rng,
    t0: std::time::Instant,
    identity: Identity,
}

impl Ctl {
    /// The wrench now, with noise, quantised.
    fn counts(&mut self) -> Counts {
        let t = self.t0.elapsed();
        // A dropout or a non-finite model value: the device has no such thing, it repeats its last value.
        if let Some(w) = self.source.wrench(t)
            && w.is_finite()
        {
            self.last = w;
        }
        let mut a = self.last.to_array();
        for (i, v) in a.iter_mut().enumerate() {
            let n = if i < 3 { self.noise.0 } else { self.noise.1 };
            *v += n.map_or(0.0, |n| n.sample(&mut self.rng));
        }
        // Out of range: the device saturates at its i16 limits.
        Counts::from_wrench(&Wrench::from_array(a)).unwrap_or_else(|_| {
            let mut c = [0i16; 6];
            for (i, v) in a.iter().enumerate() {
                let s = if i < 3 { 100.0 } else { 1000.0 };
                c[i] = (v * s).clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16;
            }
            Counts(c)
        })
    }

    fn register(&mut self, addr: u16, wrench: &Counts) -> Option<u16> {
        let fw = self.identity.firmware_registers();
        let sn = self.identity.serial_registers();
        Some(match addr {
            a if (REG_WRENCH..REG_WRENCH + 6).contains(&a) => {
                wrench.to_registers()[usize::from(a - REG_WRENCH)]
            }
            a if (REG_ACCEL..REG_ACCEL + 3).contains(&a) => {
                // Upright, at rest: −1 g on z, in 1/1000 g.
                [0u16, 0, (-1000i16) as u16][usize::from(a - REG_ACCEL)]
            }
            REG_STREAM => 0,
            a if (REG_FIRMWARE..REG_FIRMWARE + 3).contains(&a) => fw[usize::from(a - REG_FIRMWARE)],
            a if (REG_SERIAL..REG_SERIAL + 4).contains(&a) => sn[usize::from(a - REG_SERIAL)],
            REG_YEAR => self.identity.year,
            _ => return None,
        })
    }
}

struct Control {
    ctl: Mutex<Ctl>,
    stop: AtomicBool,
    wake: Notify,
}

impl Control {
    fn lock(&self) -> MutexGuard<'_, Ctl> {
        self.ctl.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// The Modbus personality: a tokio-modbus service over the sensor's registers.
#[derive(Clone)]
struct Registers(Arc<Control>);

impl tokio_modbus::server::Service for Registers {
    type Request = SlaveRequest<'static>;
    type Response = Option<Response>;
    type Exception = ExceptionCode;
    type Future = std::pin::Pin<
        Box<dyn std::future::Future<Output = Result<Option<Response>, ExceptionCode>> + Send>,
    >;

    fn call(&self, req: SlaveRequest<'static>) -> Self::Future {
        if req.slave != SLAVE {
            // Another slave on the bus: silence.
            return Box::pin(std::future::ready(Ok(None)));
        }
        let mut c = self.0.lock();
        c.stats.modbus_requests += 1;
        let result = match req.request {
            Request::ReadHoldingRegisters(addr, n) => {
                let wrench = c.counts();
                let regs: Option<Vec<u16>> = (0..n)
                    .map(|i| addr.checked_add(i).and_then(|a| c.register(a, &wrench)))
                    .collect();
                match regs {
                    Some(r) if n > 0 => Ok(Some(Response::ReadHoldingRegisters(r))),
                    _ => Err(ExceptionCode::IllegalDataAddress),
                }
            }
            Request::WriteMultipleRegisters(addr, ref words) => {
                if addr == REG_STREAM && words.as_ref() == [STREAM_START] {
                    c.start_requested = true;
                    Ok(Some(Response::WriteMultipleRegisters(addr, 1)))
                } else if addr == REG_STREAM {
                    Err(ExceptionCode::IllegalDataValue)
                } else {
                    Err(ExceptionCode::IllegalDataAddress)
                }
            }
            Request::WriteSingleRegister(addr, _) => {
                if addr == REG_STREAM {
                    // The manual documents FC03 and FC16 only, and starts the stream with FC16;
                    // a device answers an undocumented function with exception 01.
                    Err(ExceptionCode::IllegalFunction)
                } else {
                    Err(ExceptionCode::IllegalDataAddress)
                }
            }
            _ => Err(ExceptionCode::IllegalFunction),
        };
        // The answer leaves when the wire would have carried the request and the answer.
        let (rq, rp) = rtu_sizes(&req.request, result.is_ok());
        let due = exchange_time(rq, rp, robotiq::codec::BAUD);
        drop(c);
        Box::pin(async move {
            tokio::time::sleep(due).await;
            result
        })
    }
}

/// A simulated FT 300 serving on a pseudo-terminal. Stops when dropped.
pub struct SimFt300 {
    path: PathBuf,
    link: Option<PathBuf>,
    control: Arc<Control>,
    emit: mpsc::UnboundedSender<()>,
    thread: Option<JoinHandle<io::Result<()>>>,
}

impl SimFt300 {
    /// Create the pseudo-terminals and start serving, wrench from `source`.
    pub fn spawn(cfg: Ft300Config, source: impl WrenchSource + 'static) -> io::Result<Self> {
        let noise = (
            (cfg.noise_force > 0.0)
                .then(|| Normal::new(0.0, cfg.noise_force).ok())
                .flatten(),
            (cfg.noise_torque > 0.0)
                .then(|| Normal::new(0.0, cfg.noise_torque).ok())
                .flatten(),
        );
        let control = Arc::new(Control {
            ctl: Mutex::new(Ctl {
                faults: VecDeque::new(),
                stats: Ft300Stats::default(),
                start_requested: false,
                source: Box::new(source),
                last: Wrench::default(),
                noise,
                rng: ChaCha8Rng::seed_from_u64(cfg.seed),
                t0: std::time::Instant::now(),
                identity: cfg.identity.clone(),
            }),
            stop: AtomicBool::new(false),
            wake: Notify::new(),
        });
        let (emit, emit_rx) = mpsc::unbounded_channel();
        let (path_tx, path_rx) = std::sync::mpsc::channel();
        let thread = {
            let control = Arc::clone(&control);
            let cfg = cfg.clone();
            std::thread::Builder::new()
                .name("sim-ft300".into())
                .spawn(move || {
                    let rt = tokio::runtime::Builder::new_current_thread()
                        .enable_all()
                        .build()?;
                    rt.block_on(device(cfg, control, emit_rx, path_tx))
                })?
        };
        let path = match path_rx.recv() {
            Ok(Ok(p)) => p,
            Ok(Err(e)) => return Err(e),
            Err(_) => {
                let e = thread
                    .join()
                    .map_err(|_| io::Error::other("the simulated FT 300 thread panicked"))?
                    .err()
                    .unwrap_or_else(|| io::Error::other("the simulated FT 300 did not start"));
                return Err(e);
            }
        };
        let link = match cfg.link {
            Some(l) => {
                if l.symlink_metadata()
                    .is_ok_and(|m| m.file_type().is_symlink())
                {
                    std::fs::remove_file(&l)?;
                }
                std::os::unix::fs::symlink(&path, &l)?;
                Some(l)
            }
            None => None,
        };
        Ok(Self {
            path,
            link,
            control,
            emit,
            thread: Some(thread),
        })
    }

    /// The device a driver opens (the slave side of the pseudo-terminal).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The symbolic link, when one was asked for.
    pub fn link(&self) -> Option<&Path> {
        self.link.as_deref()
    }

    /// Apply `fault` to the stream (queued: faults apply one after another).
    pub fn inject(&self, fault: StreamFault) {
        self.control.lock().faults.push_back(fault);
    }

    /// Faults still queued.
    pub fn pending_faults(&self) -> usize {
        self.control.lock().faults.len()
    }

    /// What it has done.
    pub fn stats(&self) -> Ft300Stats {
        self.control.lock().stats
    }

    /// In [`Pace::Manual`]: send one frame now (when streaming), from the source's wrench now.
    pub fn emit(&self) {
        let _ = self.emit.send(());
    }

    /// Stop serving and report how it ended.
    pub fn stop(mut self) -> io::Result<()> {
        self.shutdown()
    }

    fn shutdown(&mut self) -> io::Result<()> {
        self.control.stop.store(true, Ordering::Release);
        self.control.wake.notify_one();
        if let Some(l) = self.link.take() {
            let _ = std::fs::remove_file(l);
        }
        match self.thread.take() {
            Some(t) => t
                .join()
                .map_err(|_| io::Error::other("the simulated FT 300 thread panicked"))?,
            None => Ok(()),
        }
    }
}

impl Drop for SimFt300 {
    fn drop(&mut self) {
        let _ = self.shutdown();
    }
}

/// Garbage for [`StreamFault::Garbage`]: random bytes with headers among them.
fn garbage(rng: &mut ChaCha8Rng, n: usize) -> Vec<u8> {
    (0..n)
        .map(|_| match rng.random_range(0..8u8) {
            0 => 0x20,
            1 => 0x4E,
            _ => rng.random(),
        })
        .collect()
}

/// The bytes of the next frame, faults applied; `None` for a stall of that length.
fn next_bytes(c: &mut Ctl) -> Result<Vec<u8>, Duration> {
    let counts = c.counts();
    let fault = c.faults.pop_front();
    if fault.is_some() {
        c.stats.faults += 1;
    }
    let mut out = Vec::with_capacity(32);
    match fault {
        None => out.extend_from_slice(&encode_frame(counts)),
        Some(StreamFault::BadCrc) => {
            let mut f = encode_frame(counts);
            f[7] ^= 0x40;
            out.extend_from_slice(&f);
        }
        Some(StreamFault::HeaderInPayload) => {
            let mut k = counts;
            let hidden = i16::from_le_bytes([0x20, 0x4E]);
            k.0[0] = hidden;
            k.0[1] = hidden;
            out.extend_from_slice(&encode_frame(k));
        }
        Some(StreamFault::DropBytes(n)) => {
            let f = encode_frame(counts);
            let n = n.min(14);
            out.extend_from_slice(&f[..2]);
            out.extend_from_slice(&f[2 + n..]);
        }
        Some(StreamFault::Stall(d)) => return Err(d),
        Some(StreamFault::Garbage(n)) => {
            out.extend(garbage(&mut c.rng, n));
            out.extend_from_slice(&encode_frame(counts));
        }
    }
    c.stats.frames += 1;
    Ok(out)
}

async fn device(
    cfg: Ft300Config,
    control: Arc<Control>,
    mut emit_rx: mpsc::UnboundedReceiver<()>,
    path_tx: std::sync::mpsc::Sender<io::Result<PathBuf>>,
) -> io::Result<()> {
    let made = (|| -> io::Result<_> {
        let (outer, outer_slave) = SerialStream::pair().map_err(io::Error::from)?;
        let (inner_server, inner) = SerialStream::pair().map_err(io::Error::from)?;
        let path = outer_slave
            .name()
            .ok_or_else(|| io::Error::other("the pseudo-terminal has no name"))?;
        Ok((outer, outer_slave, inner_server, inner, PathBuf::from(path)))
    })();
    let (mut outer, _outer_slave_held, inner_server, mut inner, path) = match made {
        Ok(v) => v,
        Err(e) => {
            let _ = path_tx.send(Err(io::Error::new(e.kind(), e.to_string())));
            return Err(e);
        }
    };
    let _ = path_tx.send(Ok(path));
    let server = tokio::spawn(
        tokio_modbus::server::rtu::Server::new(inner_server)
            .serve_forever(Registers(Arc::clone(&control))),
    );
    let mut streaming = cfg.streaming_at_start;
    control.lock().stats.streaming = streaming;
    let mut ff_run = 0usize;
    let mut swallow_ff = false;
    let mut tick = tokio::time::interval(cfg.period);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Burst);
    let mut stall_until: Option<tokio::time::Instant> = None;
    let mut from_driver = [0u8; 512];
    let mut from_server = [0u8; 512];
    let realtime = cfg.pace == Pace::Realtime;
    let result = loop {
        if control.stop.load(Ordering::Acquire) {
            break Ok(());
        }
        tokio::select! {
            () = control.wake.notified() => {}
            r = outer.read(&mut from_driver) => {
                let n = match r {
                    Ok(0) => continue,
                    Ok(n) => n,
                    // The driver side closed (EIO on a pty master): wait for the next opener.
                    Err(e) if e.raw_os_error() == Some(5) => {
                        tokio::time::sleep(Duration::from_millis(2)).await;
                        continue;
                    }
                    Err(e) => break Err(e),
                };
                let mut forward = Vec::with_capacity(n);
                for &b in &from_driver[..n] {
                    if streaming {
                        // In stream mode the sensor only listens for the stop bytes.
                        if b == STOP_BYTE {
                            ff_run += 1;
                            if ff_run >= STOP_RUN {
                                streaming = false;
                                swallow_ff = true;
                                ff_run = 0;
                                let mut c = control.lock();
                                c.stats.stops += 1;
                                c.stats.streaming = false;
                            }
                        } else {
                            ff_run = 0;
                        }
                    } else if swallow_ff && b == STOP_BYTE {
                        // The rest of the stop bytes.
                    } else {
                        swallow_ff = false;
                        forward.push(b);
                    }
                }
                if !forward.is_empty() {
                    inner.write_all(&forward).await?;
                }
            }
            r = inner.read(&mut from_server) => {
                let n = r?;
                outer.write_all(&from_server[..n]).await?;
                let mut c = control.lock();
                if c.start_requested {
                    c.start_requested = false;
                    c.stats.starts += 1;
                    c.stats.streaming = true;
                    streaming = true;
                    tick.reset();
                }
            }
            _ = tick.tick(), if realtime && streaming => {
                if stall_until.is_some_and(|t| tokio::time::Instant::now() < t) {
                    continue;
                }
                stall_until = None;
                let bytes = next_bytes(&mut control.lock());
                match bytes {
                    Ok(b) => outer.write_all(&b).await?,
                    Err(d) => stall_until = Some(tokio::time::Instant::now() + d),
                }
            }
            e = emit_rx.recv(), if !realtime => {
                if e.is_none() {
                    break Ok(());
                }
                if streaming {
                    let bytes = next_bytes(&mut control.lock());
                    if let Ok(b) = bytes {
                        outer.write_all(&b).await?;
                    }
                }
            }
        }
    };
    server.abort();
    result
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The simulator's own pacing: each answer is held for its bytes' time on a 19 200 bit/s line,
    /// 10 bits a byte, so a register poll is bounded by the wire's arithmetic (no clock read here).
    #[test]
    fn an_answer_takes_its_bytes_time_on_the_wire() {
        let baud = robotiq::codec::BAUD;
        // One byte: 10 bits at 19 200 bit/s.
        assert_eq!(wire_time(1, baud), Duration::from_nanos(520_833));
        assert_eq!(frame_gap(baud), Duration::from_nanos(1_822_916));
        // Reading the six wrench registers: an 8-byte request, a 5 + 12 = 17-byte answer.
        let poll = Request::ReadHoldingRegisters(REG_WRENCH, 6);
        assert_eq!(rtu_sizes(&poll, true), (8, 17));
        let t = exchange_time(8, 17, baud);
        assert_eq!(t, wire_time(25, baud) + frame_gap(baud));
        // 25 bytes alone allow 76.8 polls a second; with the silence, 67.4.
        let rate = 1.0 / t.as_secs_f64();
        assert!(rate < 1.0 / wire_time(25, baud).as_secs_f64());
        assert!((67.0..68.0).contains(&rate), "{rate}");
        // The stream start, as FC16 (9 + 2 bytes, 8 back) or refused FC06 (8, exception 5 back).
        let start = Request::WriteMultipleRegisters(REG_STREAM, vec![STREAM_START].into());
        assert_eq!(rtu_sizes(&start, true), (11, 8));
        let fc6 = Request::WriteSingleRegister(REG_STREAM, STREAM_START);
        assert_eq!(rtu_sizes(&fc6, false), (8, 5));
    }

    #[test]
    fn faults_shape_the_bytes() {
        let cfg = Ft300Config {
            noise_force: 0.0,
            noise_torque: 0.0,
            ..Ft300Config::default()
        };
        let mut c = Ctl {
            faults: VecDeque::from([
                StreamFault::BadCrc,
                StreamFault::DropBytes(3),
                StreamFault::Garbage(7),
                StreamFault::Stall(Duration::from_millis(50)),
                StreamFault::HeaderInPayload,
            ]),
            stats: Ft300Stats::default(),
            start_requested: false,
            source: Box::new(|_t: Duration| Wrench::from_array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])),
            last: Wrench::default(),
            noise: (None, None),
            rng: ChaCha8Rng::seed_from_u64(cfg.seed),
            t0: std::time::Instant::now(),
            identity: cfg.identity.clone(),
        };
        let good = encode_frame(Counts([100, 200, 300, 100, 200, 300]));
        let bad = next_bytes(&mut c).unwrap();
        assert_eq!(bad.len(), 16);
        assert_ne!(bad, good.to_vec());
        assert_eq!(next_bytes(&mut c).unwrap().len(), 13);
        let g = next_bytes(&mut c).unwrap();
        assert_eq!(&g[7..], &good[..]);
        assert_eq!(next_bytes(&mut c), Err(Duration::from_millis(50)));
        let h = next_bytes(&mut c).unwrap();
        assert_eq!(&h[2..6], &[0x20, 0x4E, 0x20, 0x4E]);
        assert_eq!(next_bytes(&mut c).unwrap(), good.to_vec());
        assert_eq!(c.stats.faults, 5);
    }
}
