//! The two ways to use the driver as a [`hal::ForceSensor`]:
//!
//! * [`AtiSensor`] — real time: a background thread polls at a fixed rate; `read` hands over the newest
//!   sample and never waits for the bus (the HAL contract).
//! * [`Lockstep`] — simulation: `read` performs exactly one request/answer exchange, bounded by the
//!   per-request deadline, then returns the newest sample. Against a simulated node attached to the
//!   in-memory bus ([`crate::mem::MemBus::attach`]) the node answers in the caller's thread, so the sample
//!   reflects the simulated world *now* and a faster-than-real-time loop stays deterministic. This
//!   deliberately waits for the bus inside `read`: use it only where the caller owns the clock.

use core::time::Duration;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;

use hal::{ForceSensor, Sample};

use crate::codec::{Gauges, Request, Status};
use crate::driver::{BiasConfig, Counters, DeviceInfo, Driver, Health, View};
use crate::error::{AtiError, BiasError};
use crate::transport::{CanTransport, Clock, TransportError};

/// What the poller publishes after every step.
#[derive(Clone, Copy, Debug)]
struct Snapshot {
    view: View,
    counters: Counters,
    info: Option<DeviceInfo>,
    status: Status,
    raw: Option<Gauges>,
    bias: [f64; 6],
    bias_outcome: Option<Result<[f64; 6], BiasError>>,
    transport_errors: u64,
}

struct Shared {
    snapshot: Mutex<Snapshot>,
    bias_request: Mutex<Option<BiasConfig>>,
    bias_done: Condvar,
    stop: AtomicBool,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// A driver polling in a background thread. Dropping it stops the thread.
pub struct AtiSensor {
    shared: Arc<Shared>,
    clock: Clock,
    thread: Option<JoinHandle<()>>,
}

fn snapshot_of<T: CanTransport>(d: &Driver<T>, transport_errors: u64) -> Snapshot {
    Snapshot {
        view: d.view(),
        counters: d.counters(),
        info: d.info().copied(),
        status: d.status(),
        raw: d.raw_gauges(),
        bias: d.bias(),
        bias_outcome: None,
        transport_errors,
    }
}

impl AtiSensor {
    /// Start polling at `rate_hz` in a new thread (start-up runs first, in the same thread, one request
    /// per tick). Refused when one poll exchange cannot fit in a period at the configured bit rate, or
    /// when the transport runs on a virtual clock.
    pub fn spawn<T: CanTransport + Send + 'static>(
        driver: Driver<T>,
        rate_hz: f64,
    ) -> Result<Self, AtiError> {
        if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= 10_000.0) {
            return Err(AtiError::Config(format!(
                "poll rate {rate_hz} Hz is outside (0, 10 000]"
            )));
        }
        let period = Duration::from_secs_f64(1.0 / rate_hz);
        let deadline = driver.config().deadline(Request::Poll);
        if deadline > period {
            return Err(AtiError::Config(format!(
                "polling at {rate_hz} Hz leaves {period:?} per exchange, but one poll may take {deadline:?} at {} bit/s: lower the rate or raise the bit rate",
                driver.config().bitrate
            )));
        }
        let clock = driver.clock();
        if clock.is_virtual() {
            return Err(AtiError::Config(
                "background polling needs a transport on the real clock; use Lockstep on a virtual clock".into(),
            ));
        }
        let shared = Arc::new(Shared {
            snapshot: Mutex::new(snapshot_of(&driver, 0)),
            bias_request: Mutex::new(None),
            bias_done: Condvar::new(),
            stop: AtomicBool::new(false),
        });
        let worker = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("ati-can-poll".into())
            .spawn(move || poll_loop(driver, period, &worker))
            .map_err(|e| AtiError::Config(format!("cannot start the polling thread: {e}")))?;
        Ok(Self {
            shared,
            clock,
            thread: Some(thread),
        })
    }

    fn snapshot(&self) -> Snapshot {
        *lock(&self.shared.snapshot)
    }

    /// The background thread's pthread (to give it a real-time priority), while it runs.
    pub fn reader_thread(&self) -> Option<std::os::unix::thread::RawPthread> {
        use std::os::unix::thread::JoinHandleExt;
        self.thread.as_ref().map(JoinHandleExt::as_pthread_t)
    }

    /// Health now.
    pub fn health(&self) -> Health {
        self.snapshot().view.health_at(self.clock.now())
    }

    /// Counters so far.
    pub fn counters(&self) -> Counters {
        self.snapshot().counters
    }

    /// Transport errors the poller carried on through.
    pub fn transport_errors(&self) -> u64 {
        self.snapshot().transport_errors
    }

    /// What start-up read, once finished.
    pub fn info(&self) -> Option<DeviceInfo> {
        self.snapshot().info
    }

    /// The newest status word.
    pub fn status(&self) -> Status {
        self.snapshot().status
    }

    /// The raw gauges of the newest good sample.
    pub fn raw_gauges(&self) -> Option<Gauges> {
        self.snapshot().raw
    }

    /// The bias in use, counts.
    pub fn bias(&self) -> [f64; 6] {
        self.snapshot().bias
    }

    /// Take a bias over the next `cfg.window` samples, waiting at most `timeout` for the poller
    /// (this waits; it is not for the control path).
    pub fn tare(&self, cfg: BiasConfig, timeout: Duration) -> Result<[f64; 6], AtiError> {
        lock(&self.shared.snapshot).bias_outcome = None;
        *lock(&self.shared.bias_request) = Some(cfg);
        let guard = lock(&self.shared.snapshot);
        let (mut guard, _) = self
            .shared
            .bias_done
            .wait_timeout_while(guard, timeout, |s| s.bias_outcome.is_none())
            .unwrap_or_else(|e| e.into_inner());
        match guard.bias_outcome.take() {
            Some(r) => r.map_err(AtiError::from),
            None => Err(AtiError::Timeout),
        }
    }

    /// Stop the poller and wait for it.
    pub fn stop(mut self) {
        self.halt();
    }

    fn halt(&mut self) {
        self.shared.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            // A panicked poller has nothing more to say; its last snapshot stays.
            let _ = t.join();
        }
    }
}

impl core::fmt::Debug for AtiSensor {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let s = self.snapshot();
        f.debug_struct("AtiSensor")
            .field("health", &s.view.health_at(self.clock.now()))
            .field("counters", &s.counters)
            .finish_non_exhaustive()
    }
}

impl Drop for AtiSensor {
    fn drop(&mut self) {
        self.halt();
    }
}

fn poll_loop<T: CanTransport>(mut driver: Driver<T>, period: Duration, shared: &Shared) {
    let clock = driver.clock();
    let mut next = clock.now();
    let mut transport_errors = 0;
    while !shared.stop.load(Ordering::Acquire) {
        let mut refused = None;
        if let Some(cfg) = lock(&shared.bias_request).take() {
            refused = driver.begin_bias(cfg).err();
        }
        let mut lost = false;
        match driver.step() {
            Ok(_) => {}
            Err(AtiError::Transport(TransportError::Closed)) => lost = true,
            Err(_) => transport_errors += 1,
        }
        let mut snap = snapshot_of(&driver, transport_errors);
        if lost {
            snap.view.health = Health::LinkLost;
        }
        snap.bias_outcome = refused.map(Err).or_else(|| driver.take_bias_outcome());
        let has_outcome = snap.bias_outcome.is_some();
        {
            let mut s = lock(&shared.snapshot);
            // Keep an outcome nobody has collected yet.
            if snap.bias_outcome.is_none() {
                snap.bias_outcome = s.bias_outcome;
            }
            *s = snap;
        }
        if has_outcome {
            shared.bias_done.notify_all();
        }
        if lost {
            return;
        }
        next += period;
        let now = clock.now();
        if next > now {
            std::thread::sleep(next - now);
        } else if now - next > period {
            // Fell behind by more than a period (a stall): resume the grid from now, no burst.
            next = now;
        }
    }
}

impl ForceSensor for AtiSensor {
    type Error = AtiError;

    /// The newest sample the poller holds. Never waits for the bus.
    fn read(&mut self) -> Result<Sample, AtiError> {
        self.snapshot().view.sample_at(self.clock.now())
    }
}

/// The driver as a [`ForceSensor`] whose `read` performs one exchange first (see the module docs).
pub struct Lockstep<T>(pub Driver<T>);

impl<T: CanTransport> Lockstep<T> {
    /// The driver.
    pub fn driver(&mut self) -> &mut Driver<T> {
        &mut self.0
    }
}

impl<T: CanTransport> ForceSensor for Lockstep<T> {
    type Error = AtiError;

    /// One exchange (a poll, or a start-up step while starting), then the newest sample.
    fn read(&mut self) -> Result<Sample, AtiError> {
        self.0.step()?;
        self.0.read()
    }
}
