//! An in-memory CAN bus: for unit tests, for simulations, and for machines without SocketCAN.
//!
//! It behaves like a SocketCAN interface where it matters to the driver: a frame goes to every *other*
//! port whose filter accepts it, in order; a sender does not receive its own frames; receive queues are
//! bounded (frames beyond [`PORT_QUEUE`] are dropped, as a full socket buffer drops them).
//!
//! Besides ports, the bus can carry **responders** ([`Responder`]): peers called synchronously, in the
//! sender's thread, for every frame a port sends. Their answers are queued with a delay the responder
//! chooses. With a [virtual clock](MemBus::with_virtual_clock) a port waiting in
//! [`recv`](CanTransport::recv) advances time to the next due answer or to its timeout instead of
//! sleeping — a request/answer exchange then takes no wall time and is fully deterministic. The virtual
//! clock is for single-threaded use (driver and responders): another thread's frames are not waited for.

use core::time::Duration;
use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

use crate::codec::Base;
use crate::frame::Frame;
use crate::transport::{BusError, BusEvent, CanTransport, Clock, TransportError, filter_accepts};

/// Frames one port can hold before further frames are dropped.
pub const PORT_QUEUE: usize = 4096;

/// A peer on the bus that answers frames synchronously (a simulated device).
pub trait Responder: Send {
    /// Called for every frame a port sends, at bus time `now`. Emit answers with `out(delay, frame)`;
    /// each is delivered to the ports `delay` after `now`.
    fn on_frame(&mut self, frame: &Frame, now: Duration, out: &mut dyn FnMut(Duration, Frame));
}

struct Queued {
    due: Duration,
    event: BusEvent,
}

struct PortSlot {
    id: u64,
    filter: Option<Base>,
    queue: VecDeque<Queued>,
    dropped: u64,
}

#[derive(Default)]
struct State {
    ports: Vec<PortSlot>,
    next_id: u64,
}

struct Inner {
    state: Mutex<State>,
    responders: Mutex<Vec<Box<dyn Responder>>>,
    ready: Condvar,
    clock: Clock,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic while holding the lock leaves plain data behind; carry on with it.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl Inner {
    /// Queue `event` at `due` on every port except `from` whose filter accepts it.
    fn deliver(&self, from: Option<u64>, due: Duration, event: BusEvent) {
        let mut st = lock(&self.state);
        for port in st.ports.iter_mut().filter(|p| Some(p.id) != from) {
            let accepted = match (&event, port.filter) {
                (BusEvent::Frame(f), Some(base)) => filter_accepts(base, f),
                _ => true,
            };
            if !accepted {
                continue;
            }
            if port.queue.len() >= PORT_QUEUE {
                port.dropped += 1;
                continue;
            }
            let at = port
                .queue
                .iter()
                .rposition(|q| q.due <= due)
                .map_or(0, |i| i + 1);
            port.queue.insert(at, Queued { due, event });
        }
        drop(st);
        self.ready.notify_all();
    }
}

/// The bus. Cheap to clone; every clone is the same bus.
#[derive(Clone)]
pub struct MemBus {
    inner: Arc<Inner>,
}

impl Default for MemBus {
    fn default() -> Self {
        Self::new()
    }
}

impl MemBus {
    /// A bus on the real monotonic clock.
    pub fn new() -> Self {
        Self::with_clock(Clock::real())
    }

    /// A bus on a virtual clock (see the module documentation).
    pub fn with_virtual_clock() -> Self {
        Self::with_clock(Clock::virtual_at_zero())
    }

    fn with_clock(clock: Clock) -> Self {
        Self {
            inner: Arc::new(Inner {
                state: Mutex::new(State::default()),
                responders: Mutex::new(Vec::new()),
                ready: Condvar::new(),
                clock,
            }),
        }
    }

    /// A new endpoint that receives everything until it sets a filter.
    pub fn port(&self) -> MemPort {
        let mut st = lock(&self.inner.state);
        let id = st.next_id;
        st.next_id += 1;
        st.ports.push(PortSlot {
            id,
            filter: None,
            queue: VecDeque::new(),
            dropped: 0,
        });
        MemPort {
            inner: Arc::clone(&self.inner),
            id,
            answers: Vec::with_capacity(8),
        }
    }

    /// Put a responder on the bus.
    pub fn attach(&self, responder: impl Responder + 'static) {
        lock(&self.inner.responders).push(Box::new(responder));
    }

    /// Report a controller error to every port (as every socket on an interface sees its error frames).
    pub fn raise_error(&self, error: BusError) {
        let now = self.inner.clock.now();
        self.inner.deliver(None, now, BusEvent::Error(error));
    }

    /// The bus clock.
    pub fn clock(&self) -> Clock {
        self.inner.clock.clone()
    }
}

/// One endpoint of a [`MemBus`].
pub struct MemPort {
    inner: Arc<Inner>,
    id: u64,
    /// The responders' answers to one sent frame (kept: a send allocates nothing).
    answers: Vec<(Duration, Frame)>,
}

impl MemPort {
    /// Frames dropped because this port's queue was full.
    pub fn dropped(&self) -> u64 {
        let st = lock(&self.inner.state);
        st.ports
            .iter()
            .find(|p| p.id == self.id)
            .map_or(0, |p| p.dropped)
    }
}

impl Drop for MemPort {
    fn drop(&mut self) {
        lock(&self.inner.state).ports.retain(|p| p.id != self.id);
    }
}

impl CanTransport for MemPort {
    fn send(&mut self, frame: &Frame) -> Result<(), TransportError> {
        let now = self.inner.clock.now();
        self.inner
            .deliver(Some(self.id), now, BusEvent::Frame(*frame));
        // Responders run one at a time, in the sender's thread, outside the queue lock.
        let mut answers = core::mem::take(&mut self.answers);
        answers.clear();
        {
            let mut responders = lock(&self.inner.responders);
            for r in responders.iter_mut() {
                r.on_frame(frame, now, &mut |delay, f| answers.push((now + delay, f)));
            }
        }
        for &(due, f) in &answers {
            self.inner.deliver(None, due, BusEvent::Frame(f));
        }
        self.answers = answers;
        Ok(())
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<BusEvent>, TransportError> {
        let clock = &self.inner.clock;
        let deadline = clock.now().saturating_add(timeout);
        let mut st = lock(&self.inner.state);
        loop {
            let now = clock.now();
            let port = st
                .ports
                .iter_mut()
                .find(|p| p.id == self.id)
                .ok_or(TransportError::Closed)?;
            let next_due = port.queue.front().map(|q| q.due);
            match next_due {
                Some(due) if due <= now => {
                    return Ok(port.queue.pop_front().map(|q| q.event));
                }
                _ => {}
            }
            if clock.is_virtual() {
                match next_due {
                    Some(due) if due <= deadline => clock.advance_to(due),
                    _ => {
                        clock.advance_to(deadline);
                        return Ok(None);
                    }
                }
                continue;
            }
            if now >= deadline {
                return Ok(None);
            }
            let until = next_due.map_or(deadline, |d| d.min(deadline));
            st = self
                .inner
                .ready
                .wait_timeout(st, until.saturating_sub(now))
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }

    fn accept_only(&mut self, base: Base) -> Result<(), TransportError> {
        let mut st = lock(&self.inner.state);
        let port = st
            .ports
            .iter_mut()
            .find(|p| p.id == self.id)
            .ok_or(TransportError::Closed)?;
        port.filter = Some(base);
        port.queue.retain(|q| match q.event {
            BusEvent::Frame(f) => filter_accepts(base, &f),
            BusEvent::Error(_) => true,
        });
        Ok(())
    }

    fn clock(&self) -> Clock {
        self.inner.clock.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(id: u16) -> Frame {
        Frame::standard(id, &[id as u8]).unwrap()
    }

    fn frame_of(e: Option<BusEvent>) -> Option<Frame> {
        match e {
            Some(BusEvent::Frame(f)) => Some(f),
            _ => None,
        }
    }

    #[test]
    fn frames_reach_other_ports_in_order_but_not_the_sender() {
        let bus = MemBus::new();
        let mut a = bus.port();
        let mut b = bus.port();
        a.send(&f(0x200)).unwrap();
        a.send(&f(0x201)).unwrap();
        assert_eq!(frame_of(b.recv(Duration::ZERO).unwrap()), Some(f(0x200)));
        assert_eq!(frame_of(b.recv(Duration::ZERO).unwrap()), Some(f(0x201)));
        assert_eq!(b.recv(Duration::ZERO).unwrap(), None);
        assert_eq!(a.recv(Duration::ZERO).unwrap(), None);
    }

    #[test]
    fn filter_drops_foreign_extended_and_remote_frames() {
        let bus = MemBus::new();
        let mut a = bus.port();
        let mut b = bus.port();
        b.accept_only(Base::DEFAULT).unwrap();
        a.send(&f(0x310)).unwrap();
        a.send(&Frame::extended(0x200, &[]).unwrap()).unwrap();
        a.send(&Frame::remote(0x200, false, 8).unwrap()).unwrap();
        a.send(&f(0x20F)).unwrap();
        bus.raise_error(BusError::from_raw(BusError::BUSOFF));
        assert_eq!(frame_of(b.recv(Duration::ZERO).unwrap()), Some(f(0x20F)));
        assert!(matches!(
            b.recv(Duration::ZERO).unwrap(),
            Some(BusEvent::Error(BusError { bus_off: true, .. }))
        ));
        assert_eq!(b.recv(Duration::ZERO).unwrap(), None);
    }

    struct Echo;
    impl Responder for Echo {
        fn on_frame(
            &mut self,
            frame: &Frame,
            _now: Duration,
            out: &mut dyn FnMut(Duration, Frame),
        ) {
            out(
                Duration::from_millis(5),
                Frame::standard(frame.id() as u16 + 1, &[]).unwrap(),
            );
            out(
                Duration::ZERO,
                Frame::standard(frame.id() as u16 + 2, &[]).unwrap(),
            );
        }
    }

    #[test]
    fn virtual_clock_jumps_to_due_answers_and_to_timeouts() {
        let bus = MemBus::with_virtual_clock();
        bus.attach(Echo);
        let mut a = bus.port();
        a.send(&Frame::standard(0x100, &[]).unwrap()).unwrap();
        // The undelayed answer first although emitted second.
        assert_eq!(
            frame_of(a.recv(Duration::ZERO).unwrap()).map(|f| f.id()),
            Some(0x102)
        );
        // The delayed one is not there within 1 ms; the clock moves to the timeout.
        assert_eq!(a.recv(Duration::from_millis(1)).unwrap(), None);
        assert_eq!(bus.clock().now(), Duration::from_millis(1));
        assert_eq!(
            frame_of(a.recv(Duration::from_secs(1)).unwrap()).map(|f| f.id()),
            Some(0x101)
        );
        assert_eq!(bus.clock().now(), Duration::from_millis(5));
    }

    #[test]
    fn real_clock_recv_waits_for_another_thread() {
        let bus = MemBus::new();
        let mut a = bus.port();
        let mut b = bus.port();
        let t = std::thread::spawn(move || a.send(&f(0x200)).unwrap());
        let got = b.recv(Duration::from_secs(30)).unwrap();
        t.join().unwrap();
        assert_eq!(frame_of(got), Some(f(0x200)));
    }

    #[test]
    fn full_queue_drops_and_counts() {
        let bus = MemBus::new();
        let mut a = bus.port();
        let b = bus.port();
        for _ in 0..PORT_QUEUE + 3 {
            a.send(&f(0x200)).unwrap();
        }
        assert_eq!(b.dropped(), 3);
    }
}
