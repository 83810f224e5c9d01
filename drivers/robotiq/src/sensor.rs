//! [`Ft300`]: start-up (listen first, then Modbus), a background thread reading the raw stream, the HAL's
//! non-blocking `read`, and the host-side zero.

use core::time::Duration;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Instant;

use hal::{ForceSensor, Sample, Wrench};
use tokio_serial::SerialPort;

/// A raw serial port as the reader uses it.
type RawPort = Box<dyn SerialPort>;

use crate::codec::{BAUD, Counts, Identity, SLAVE};
use crate::error::RobotiqError;
use crate::link::{Counters, Health, LinkConfig, LinkState, RawReader};
use crate::modbus::{self, Startup};

/// Driver settings.
#[derive(Clone, Debug, PartialEq)]
pub struct Config {
    /// The serial device (configuration: the driver never scans ports).
    pub port: PathBuf,
    /// Modbus slave address.
    pub slave: u8,
    /// Limit of one Modbus exchange.
    pub modbus_timeout: Duration,
    /// How long to listen for a stream that is already running before talking Modbus.
    pub listen: Duration,
    /// Limit of one raw read: the longest the reader blocks when no byte comes (health is re-evaluated
    /// at least this often).
    pub poll: Duration,
    /// Stream limits.
    pub link: LinkConfig,
    /// Send the stop bytes when the driver is dropped.
    pub stop_on_drop: bool,
}

impl Config {
    /// Defaults for the sensor on `port`.
    pub fn new(port: impl Into<PathBuf>) -> Self {
        Self {
            port: port.into(),
            slave: SLAVE,
            modbus_timeout: Duration::from_millis(300),
            listen: Duration::from_millis(60),
            poll: Duration::from_millis(5),
            link: LinkConfig::default(),
            stop_on_drop: true,
        }
    }

    /// Check the values.
    pub fn validate(&self) -> Result<(), RobotiqError> {
        self.link.validate()?;
        if self.slave == 0 || self.slave > 247 {
            return Err(RobotiqError::Config(format!(
                "slave address {} is outside 1..=247",
                self.slave
            )));
        }
        if self.poll.is_zero() || self.modbus_timeout.is_zero() {
            return Err(RobotiqError::Config(
                "poll and modbus_timeout must be positive".into(),
            ));
        }
        Ok(())
    }
}

/// How a zero is taken.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZeroConfig {
    /// Samples averaged.
    pub samples: usize,
    /// Largest allowed spread (max − min) of any force channel over the window, N.
    pub max_force_spread: f64,
    /// Largest allowed spread of any torque channel, N·m.
    pub max_torque_spread: f64,
    /// Give up after this long.
    pub timeout: Duration,
}

impl Default for ZeroConfig {
    fn default() -> Self {
        Self {
            samples: 50,
            max_force_spread: 1.0,
            max_torque_spread: 0.05,
            timeout: Duration::from_secs(2),
        }
    }
}

/// Average `raw` (newest frames without zero) into a zero, or refuse when they spread too much.
pub fn zero_from(raw: &[Counts], cfg: &ZeroConfig) -> Result<Wrench, RobotiqError> {
    if raw.is_empty() {
        return Err(RobotiqError::ZeroTimeout {
            got: 0,
            wanted: cfg.samples,
        });
    }
    let mut lo = [f64::INFINITY; 6];
    let mut hi = [f64::NEG_INFINITY; 6];
    let mut sum = [0.0; 6];
    for c in raw {
        for (i, v) in c.to_wrench().to_array().into_iter().enumerate() {
            lo[i] = lo[i].min(v);
            hi[i] = hi[i].max(v);
            sum[i] += v;
        }
    }
    let spread: Vec<f64> = (0..6).map(|i| hi[i] - lo[i]).collect();
    let force_spread = spread[..3].iter().copied().fold(0.0, f64::max);
    let torque_spread = spread[3..].iter().copied().fold(0.0, f64::max);
    if force_spread > cfg.max_force_spread || torque_spread > cfg.max_torque_spread {
        return Err(RobotiqError::Moving {
            force_spread,
            torque_spread,
        });
    }
    Ok(Wrench::from_array(sum.map(|s| s / raw.len() as f64)))
}

struct Shared {
    state: Mutex<LinkState>,
    frame: Condvar,
    stop: AtomicBool,
    io_error: Mutex<Option<String>>,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, LinkState> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

fn open_raw(path: &Path, poll: Duration) -> Result<RawPort, RobotiqError> {
    tokio_serial::new(path.to_string_lossy(), BAUD)
        .timeout(poll)
        .open()
        .map_err(|e| RobotiqError::io(format!("opening {}", path.display()), e.into()))
}

/// The FT 300 over a serial port, read in the background. See the module documentation.
pub struct Ft300 {
    shared: Arc<Shared>,
    epoch: Instant,
    startup: Startup,
    thread: Option<JoinHandle<()>>,
}

impl Ft300 {
    /// Start the sensor on `cfg.port`: listen for a stream already running (recognised without any
    /// Modbus exchange); otherwise read the identity and the wrench registers and write register 410;
    /// then read the raw stream in a background thread.
    pub fn open(cfg: Config) -> Result<Self, RobotiqError> {
        cfg.validate()?;
        let epoch = Instant::now();
        let mut reader = RawReader::new(open_raw(&cfg.port, cfg.poll)?);
        let mut state = LinkState::new(cfg.link, epoch.elapsed());
        // Listen first: a sensor may be streaming since power-up, and Modbus requests would only add
        // noise to its stream.
        let listen_until = epoch + cfg.listen;
        while Instant::now() < listen_until && state.seq() < 2 {
            let bytes = reader
                .poll()
                .map_err(|e| RobotiqError::io("listening for a running stream", e))?;
            let now = epoch.elapsed();
            state.on_bytes(bytes, now);
        }
        let startup = if state.seq() >= 2 {
            Startup {
                identity: None,
                wrench: None,
            }
        } else {
            drop(reader);
            let (id, w) = modbus::startup(&cfg.port, cfg.slave, cfg.modbus_timeout, true)?;
            reader = RawReader::new(open_raw(&cfg.port, cfg.poll)?);
            state = LinkState::new(cfg.link, epoch.elapsed());
            Startup {
                identity: Some(id),
                wrench: Some(w),
            }
        };
        let shared = Arc::new(Shared {
            state: Mutex::new(state),
            frame: Condvar::new(),
            stop: AtomicBool::new(false),
            io_error: Mutex::new(None),
        });
        let thread = {
            let shared = Arc::clone(&shared);
            let stop_on_drop = cfg.stop_on_drop;
            std::thread::Builder::new()
                .name("ft300-reader".into())
                .spawn(move || reader_loop(reader, &shared, epoch, stop_on_drop))
                .map_err(|e| RobotiqError::io("spawning the reader thread", e))?
        };
        Ok(Self {
            shared,
            epoch,
            startup,
            thread: Some(thread),
        })
    }

    /// What the start-up learned (no identity when the sensor was found streaming).
    pub fn startup(&self) -> &Startup {
        &self.startup
    }

    /// The background thread's pthread (to give it a real-time priority), while it runs.
    pub fn reader_thread(&self) -> Option<std::os::unix::thread::RawPthread> {
        use std::os::unix::thread::JoinHandleExt;
        self.thread.as_ref().map(JoinHandleExt::as_pthread_t)
    }

    /// The identity, when the start-up read it.
    pub fn identity(&self) -> Option<&Identity> {
        self.startup.identity.as_ref()
    }

    /// The health now.
    pub fn health(&self) -> Health {
        self.shared.lock().health_at(self.epoch.elapsed())
    }

    /// The counters.
    pub fn counters(&self) -> Counters {
        self.shared.lock().counters()
    }

    /// The I/O error that ended the reader, if one did.
    pub fn reader_error(&self) -> Option<String> {
        self.shared
            .io_error
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// The host-side zero now in use.
    pub fn bias(&self) -> Wrench {
        self.shared.lock().bias()
    }

    /// Average the next `cfg.samples` frames into the host-side zero. Refused (and the old zero kept)
    /// when the wrench spreads more than allowed over the window — the tool moves or touches something —
    /// or when the frames do not come in time.
    pub fn zero(&self, cfg: ZeroConfig) -> Result<Wrench, RobotiqError> {
        let deadline = Instant::now() + cfg.timeout;
        let mut raw = Vec::with_capacity(cfg.samples);
        let mut guard = self.shared.lock();
        let mut seen = guard.seq();
        while raw.len() < cfg.samples {
            let now = Instant::now();
            if now >= deadline {
                return Err(RobotiqError::ZeroTimeout {
                    got: raw.len(),
                    wanted: cfg.samples,
                });
            }
            guard = self
                .shared
                .frame
                .wait_timeout(guard, deadline - now)
                .unwrap_or_else(|p| p.into_inner())
                .0;
            if let Some((c, seq)) = guard.latest_counts()
                && seq > seen
            {
                seen = seq;
                raw.push(c);
            }
        }
        let bias = zero_from(&raw, &cfg)?;
        guard.set_bias(bias);
        Ok(bias)
    }
}

fn reader_loop(
    mut reader: RawReader<RawPort>,
    shared: &Shared,
    epoch: Instant,
    stop_on_drop: bool,
) {
    while !shared.stop.load(Ordering::Acquire) {
        match reader.poll() {
            Ok(bytes) => {
                let now = epoch.elapsed();
                let mut st = shared.lock();
                let frames = st.on_bytes(bytes, now);
                st.observe(now);
                drop(st);
                if frames > 0 {
                    shared.frame.notify_all();
                }
            }
            Err(e) => {
                *shared.io_error.lock().unwrap_or_else(|p| p.into_inner()) = Some(e.to_string());
                return;
            }
        }
    }
    if stop_on_drop {
        // Best effort: the port may be gone already.
        let _ = modbus::send_stop(reader.port_mut());
    }
}

impl ForceSensor for Ft300 {
    type Error = RobotiqError;

    fn read(&mut self) -> Result<Sample, RobotiqError> {
        let now = self.epoch.elapsed();
        let st = self.shared.lock();
        st.sample_at(now)
    }
}

impl Drop for Ft300 {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Listen on `path` for `listen`: true when at least two valid frames arrive (the sensor is streaming).
/// Nothing is written to the port.
pub fn stream_running(path: &Path, listen: Duration) -> Result<bool, RobotiqError> {
    let mut reader = RawReader::new(open_raw(path, Duration::from_millis(5))?);
    let epoch = Instant::now();
    let mut state = LinkState::new(LinkConfig::default(), Duration::ZERO);
    while epoch.elapsed() < listen && state.seq() < 2 {
        let bytes = reader
            .poll()
            .map_err(|e| RobotiqError::io("listening for a running stream", e))?;
        state.on_bytes(bytes, epoch.elapsed());
    }
    Ok(state.seq() >= 2)
}

/// Send the stop bytes on `path` (a sensor that streams goes back to Modbus).
pub fn stop_stream(path: &Path) -> Result<(), RobotiqError> {
    let mut port = open_raw(path, Duration::from_millis(5))?;
    modbus::send_stop(&mut port).map_err(|e| RobotiqError::io("sending the stop bytes", e))
}

/// The FT 300 in lockstep with a simulation that owns the clock: on each `read`, when the next 10 ms
/// frame is due in simulated time, `trigger` asks the device for one frame and the read waits (bounded
/// by `wait`, wall-clock) until it has come through the port and the decoder. Samples are stamped and
/// aged in simulated time. The port, decoder and health are those of [`Ft300`].
pub struct Lockstep<R, C, T> {
    reader: RawReader<R>,
    state: LinkState,
    clock: C,
    trigger: T,
    period: Duration,
    next_due: Duration,
    wait: Duration,
}

impl<R, C, T> Lockstep<R, C, T>
where
    R: std::io::Read,
    C: FnMut() -> Duration,
    T: FnMut(),
{
    /// A lockstep sensor reading `port` (already streaming), with simulated time from `clock`.
    pub fn new(port: R, link: LinkConfig, period: Duration, mut clock: C, trigger: T) -> Self {
        let now = clock();
        Self {
            reader: RawReader::new(port),
            state: LinkState::new(link, now),
            clock,
            trigger,
            period,
            next_due: now,
            wait: Duration::from_secs(2),
        }
    }

    /// The counters.
    pub fn counters(&self) -> Counters {
        self.state.counters()
    }

    /// The health at the simulation's present.
    pub fn health(&mut self) -> Health {
        let now = (self.clock)();
        self.state.health_at(now)
    }

    /// Average the next `cfg.samples` frames into the zero (simulated time does not move meanwhile).
    pub fn zero(&mut self, cfg: ZeroConfig) -> Result<Wrench, RobotiqError> {
        let mut raw = Vec::with_capacity(cfg.samples);
        while raw.len() < cfg.samples {
            let seq = self.state.seq();
            self.pull()?;
            match self.state.latest_counts() {
                Some((c, s)) if s > seq => raw.push(c),
                _ => {
                    return Err(RobotiqError::ZeroTimeout {
                        got: raw.len(),
                        wanted: cfg.samples,
                    });
                }
            }
        }
        let bias = zero_from(&raw, &cfg)?;
        self.state.set_bias(bias);
        Ok(bias)
    }

    /// Ask for one frame and read until it has been decoded or `wait` has passed.
    fn pull(&mut self) -> Result<(), RobotiqError> {
        let now = (self.clock)();
        let seq = self.state.seq();
        (self.trigger)();
        let deadline = Instant::now() + self.wait;
        while self.state.seq() == seq && Instant::now() < deadline {
            let bytes = self
                .reader
                .poll()
                .map_err(|e| RobotiqError::io("reading the stream", e))?;
            self.state.on_bytes(bytes, now);
        }
        self.state.observe(now);
        Ok(())
    }
}

impl<R, C, T> ForceSensor for Lockstep<R, C, T>
where
    R: std::io::Read,
    C: FnMut() -> Duration,
    T: FnMut(),
{
    type Error = RobotiqError;

    fn read(&mut self) -> Result<Sample, RobotiqError> {
        let now = (self.clock)();
        if now >= self.next_due {
            self.pull()?;
            while self.next_due <= now {
                self.next_due += self.period;
            }
        }
        self.state.sample_at(now)
    }
}

/// Open `path` for raw stream reading (for [`Lockstep`]).
pub fn open_stream_port(path: &Path) -> Result<impl std::io::Read + Send, RobotiqError> {
    open_raw(path, Duration::from_millis(5))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_averages_a_still_window_and_refuses_a_moving_one() {
        let still: Vec<Counts> = (0..10)
            .map(|i| Counts([100 + i % 2, 0, -200, 10, 0, 0]))
            .collect();
        let z = zero_from(&still, &ZeroConfig::default()).unwrap();
        assert!((z.force.x - 1.005).abs() < 1e-9, "{z:?}");
        assert!((z.force.z + 2.0).abs() < 1e-9);
        let moving: Vec<Counts> = (0..10).map(|i| Counts([0, 0, i * 50, 0, 0, 0])).collect();
        assert!(matches!(
            zero_from(&moving, &ZeroConfig::default()),
            Err(RobotiqError::Moving { force_spread, .. }) if (force_spread - 4.5).abs() < 1e-9
        ));
    }

    #[test]
    fn config_is_checked() {
        assert!(Config::new("/dev/ttyUSB0").validate().is_ok());
        let mut c = Config::new("/dev/ttyUSB0");
        c.slave = 0;
        assert!(matches!(c.validate(), Err(RobotiqError::Config(_))));
    }
}
