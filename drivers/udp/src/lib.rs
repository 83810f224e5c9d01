//! The robot links' UDP receive (KUKA RSI and ABB EGM share it): the datagrams of one cycle, each
//! with its source and the kernel's arrival stamp.
//!
//! **One system call in the steady state.** The robot owns the clock: one datagram arrives per cycle
//! and is answered before the next one comes. [`Receiver::recv_all`] waits for it with one blocking
//! `recvmsg`, which also returns the kernel's arrival stamp (`SO_TIMESTAMPNS`) as a control message.
//! Only when that datagram had already waited in the socket before the call (it arrived before the
//! caller's clock read that preceded the call, or its arrival is unknown) can more be queued behind
//! it, after a stall; they are then read with non-blocking `recvmsg` calls, up to [`BATCH`]
//! in all, so the link can answer the newest. A blocking `recvmmsg(MSG_WAITFORONE)` would drain in
//! the same call but always tries a second, empty read: on a 2-vCPU Firecracker guest a bare echo
//! built on it answered ≈ 0.1 µs slower at p50 than one built on this receive (13.42–13.47 against
//! 13.30–13.39 µs, both with a receive timeout; `examples/receive_echo.rs`), every cycle, to serve a
//! backlog that a cell in step never has.
//!
//! Sans-IO sessions stay in the drivers; this is the thin shell under them, without unsafe code.

use std::io::{self, IoSliceMut};
use std::net::{SocketAddr, UdpSocket};
use std::os::fd::AsRawFd;
use std::time::{Duration, Instant, SystemTime};

use nix::sys::socket::{
    ControlMessageOwned, MsgFlags, RecvMsg, SockaddrStorage, recvmsg, setsockopt, sockopt,
};
use nix::sys::time::TimeSpec;

/// Datagrams read into the buffers at once (a longer backlog after a stall is read in further
/// batches by the same [`Receiver::recv_all`]).
pub const BATCH: usize = 16;

/// One datagram read: its length, its source and the kernel's arrival stamp (`CLOCK_REALTIME`).
type Got = (usize, Option<SocketAddr>, Option<SystemTime>);

/// Receive buffers, allocated once, and the socket's stamping.
pub struct Receiver {
    bufs: [Box<[u8]>; BATCH],
    got: [Got; BATCH],
    /// The monotonic and the wall clock, read together just after the last read of a batch.
    read_at: (Instant, SystemTime),
    /// Room for one `SCM_TIMESTAMPNS` control message (nix fills a `Vec` it does not grow).
    cmsg: Vec<u8>,
    stamped: bool,
    /// The kernel was seen stamping datagrams on arrival ([`arrival_stamping_on`]): only then can a
    /// stamp tell a datagram that woke the call from one that was queued before it.
    on_arrival: bool,
}

impl std::fmt::Debug for Receiver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Receiver")
            .field("max_datagram", &(self.bufs[0].len() - 1))
            .field("stamped", &self.stamped)
            .finish()
    }
}

/// Ask the kernel to stamp every datagram's arrival (`SO_TIMESTAMPNS`, nanoseconds, `CLOCK_REALTIME`).
/// `SO_TIMESTAMPING` would offer hardware stamps too, which no NIC on a robot cell's PC is set up
/// for, at the cost of a flag set and a three-stamp control message; the software receive stamp is
/// the same in both. Returns false where the kernel refuses (the link then measures from the
/// receive call).
fn enable_stamps(sock: &UdpSocket) -> bool {
    setsockopt(sock, sockopt::ReceiveTimestampns, &true).is_ok()
}

/// A kernel stamp (`CLOCK_REALTIME`) on the monotonic clock: `read_at` and `wall` are the two clocks
/// read together just after the receive call returned. `None` for a stamp after `wall` or more than
/// a second before it (the wall clock was stepped in between: no arrival is better than a wrong one).
fn arrival(stamp: SystemTime, wall: SystemTime, read_at: Instant) -> Option<Instant> {
    let waited = wall.duration_since(stamp).ok()?;
    if waited > Duration::from_secs(1) {
        return None;
    }
    read_at.checked_sub(waited)
}

/// A UDP receive error that only means "nothing usable arrived yet" (timeout, signal, or an ICMP
/// port-unreachable echoed back by the kernel).
pub fn is_transient(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock
            | io::ErrorKind::TimedOut
            | io::ErrorKind::Interrupted
            | io::ErrorKind::ConnectionRefused
            | io::ErrorKind::ConnectionReset
    )
}

/// Whether more datagrams may be queued behind one just read: yes when it arrived no later than
/// `since` (the caller's clock read before the receive call: it was already in the socket), or when
/// its arrival is unknown. A datagram that arrived after `since` woke the call or came just before
/// it, after everything queued ahead of it (at worst a datagram behind it is read, and the queue
/// drained, one call later).
fn may_have_backlog(since: Instant, arrived: Option<Instant>) -> bool {
    arrived.is_none_or(|a| a <= since)
}

/// Whether the kernel stamps datagrams when they arrive, checked on a pair of throwaway loopback
/// sockets. The first socket of the system to ask for stamps switches stamping on through deferred
/// work; until that has run, a datagram is stamped when it is read, so a datagram that waited in the
/// socket would look as if it had woken the call, and a backlog would be answered one stale datagram
/// a cycle. Waits for it (a millisecond at a time, at most 0.2 s: it takes microseconds where it is
/// needed at all); false where it never comes, and the receiver then drains after every read.
fn arrival_stamping_on() -> bool {
    let (Ok(rx), Ok(tx)) = (
        UdpSocket::bind("127.0.0.1:0"),
        UdpSocket::bind("127.0.0.1:0"),
    ) else {
        return false;
    };
    let Ok(to) = rx.local_addr() else {
        return false;
    };
    if !enable_stamps(&rx)
        || rx
            .set_read_timeout(Some(Duration::from_millis(50)))
            .is_err()
    {
        return false;
    }
    let mut buf = [0u8; 8];
    let mut cmsg = nix::cmsg_space!(TimeSpec);
    for _ in 0..200 {
        if tx.send_to(&[1], to).is_err() {
            return false;
        }
        let before_read = SystemTime::now();
        let mut iov = [IoSliceMut::new(&mut buf)];
        let Ok(r) = recvmsg::<SockaddrStorage>(
            rx.as_raw_fd(),
            &mut iov,
            Some(&mut cmsg),
            MsgFlags::empty(),
        ) else {
            return false;
        };
        // Stamped before the read began: on arrival.
        if stamp_of(&r).is_some_and(|s| s < before_read) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    false
}

/// The kernel's arrival stamp that came with a read, if any (a truncated control message,
/// `MSG_CTRUNC`, reads as none).
fn stamp_of(r: &RecvMsg<'_, '_, SockaddrStorage>) -> Option<SystemTime> {
    r.cmsgs().ok().and_then(|mut cm| {
        cm.find_map(|m| match m {
            ControlMessageOwned::ScmTimestampns(ts) => system_time(&ts),
            _ => None,
        })
    })
}

fn system_time(ts: &TimeSpec) -> Option<SystemTime> {
    let secs = u64::try_from(ts.tv_sec()).ok()?;
    let nanos = u32::try_from(ts.tv_nsec()).ok()?;
    SystemTime::UNIX_EPOCH.checked_add(Duration::new(secs, nanos))
}

impl Receiver {
    /// Buffers for datagrams of up to `max_datagram` bytes, and the kernel's stamps switched on for
    /// `sock` where it allows ([`stamped`](Self::stamped)).
    pub fn new(sock: &UdpSocket, max_datagram: usize) -> Self {
        let stamped = enable_stamps(sock);
        Self {
            // One byte more than the largest accepted datagram: a longer one is cut there and still
            // reads as oversized.
            bufs: core::array::from_fn(|_| vec![0; max_datagram + 1].into_boxed_slice()),
            got: [(0, None, None); BATCH],
            read_at: (Instant::now(), SystemTime::now()),
            cmsg: nix::cmsg_space!(TimeSpec),
            stamped,
            on_arrival: stamped && arrival_stamping_on(),
        }
    }

    /// True when the kernel stamps each datagram's arrival (`SO_TIMESTAMPNS` accepted).
    pub fn stamped(&self) -> bool {
        self.stamped
    }

    /// Read what the robot sent and hand each datagram to `offer` (bytes cut at `max_datagram + 1`,
    /// source, arrival on the monotonic clock where stamped, and when it was read), oldest first:
    /// with `waiting_since` (the caller's clock read before the call) the first read blocks up to the
    /// socket's timeout; with `None` nothing blocks. Only where there may be a backlog (the first
    /// datagram arrived before `waiting_since`, or its arrival is unknown, or nothing waited) is the
    /// socket read further, without waiting, batch after batch until it is empty. Returns how
    /// many were offered: 0 on a timeout or an empty socket (a transient error, [`is_transient`]);
    /// any other error as it is.
    pub fn recv_all(
        &mut self,
        sock: &UdpSocket,
        waiting_since: Option<Instant>,
        mut offer: impl FnMut(&[u8], SocketAddr, Option<Instant>, Instant),
    ) -> io::Result<usize> {
        let mut waiting_since = waiting_since;
        let mut total = 0;
        loop {
            let (n, read_at) = match self.recv(sock, waiting_since) {
                Ok(r) => r,
                Err(e) if is_transient(&e) => return Ok(total),
                Err(e) => return Err(e),
            };
            for k in 0..n {
                if let (bytes, Some(from), arrived) = self.datagram(k) {
                    offer(bytes, from, arrived, read_at);
                }
            }
            total += n;
            if n < BATCH {
                return Ok(total);
            }
            waiting_since = None;
        }
    }

    /// Read the next datagram — `waiting_since` given: blocking up to the socket's timeout, the
    /// instant being the caller's clock read before the call; `None`: not blocking at all — and,
    /// when it may have company ([`may_have_backlog`]), whatever else is queued behind it, up to
    /// [`BATCH`] in all, without waiting. Returns how many were read ([`datagram`](Self::datagram)
    /// 0 to n−1, oldest first) and when (the monotonic clock, read once just after the reads: no
    /// other clock is read in the steady state); the first read's error as it is (a timeout,
    /// `WouldBlock` when not waiting and nothing is there).
    fn recv(
        &mut self,
        sock: &UdpSocket,
        waiting_since: Option<Instant>,
    ) -> io::Result<(usize, Instant)> {
        let flags = match waiting_since {
            Some(_) => MsgFlags::empty(),
            None => MsgFlags::MSG_DONTWAIT,
        };
        self.read_one(sock, 0, flags)?;
        // Both clocks together (vDSO: no system call): the stamps are on the wall clock.
        self.read_at = (Instant::now(), SystemTime::now());
        let mut n = 1;
        let may_have_company = |since| !self.on_arrival || may_have_backlog(since, self.arrival(0));
        if waiting_since.is_none_or(may_have_company) {
            // A failure here (nothing more: WouldBlock) ends the batch; a lasting one shows on the
            // next call's first read.
            while n < BATCH && self.read_one(sock, n, MsgFlags::MSG_DONTWAIT).is_ok() {
                n += 1;
            }
            if n > 1 {
                self.read_at = (Instant::now(), SystemTime::now());
            }
        }
        Ok((n, self.read_at.0))
    }

    /// Datagram `k` of the last [`recv`](Self::recv): its bytes (cut at `max_datagram + 1`), source
    /// and arrival on the monotonic clock (from the kernel's stamp; `None` without one).
    fn datagram(&self, k: usize) -> (&[u8], Option<SocketAddr>, Option<Instant>) {
        let (len, from, _) = self.got[k];
        (
            &self.bufs[k][..len.min(self.bufs[k].len())],
            from,
            self.arrival(k),
        )
    }

    fn arrival(&self, k: usize) -> Option<Instant> {
        let (at, wall) = self.read_at;
        self.got[k].2.and_then(|stamp| arrival(stamp, wall, at))
    }

    fn read_one(&mut self, sock: &UdpSocket, k: usize, flags: MsgFlags) -> io::Result<()> {
        let mut iov = [IoSliceMut::new(&mut self.bufs[k][..])];
        let r = recvmsg::<SockaddrStorage>(sock.as_raw_fd(), &mut iov, Some(&mut self.cmsg), flags)
            .map_err(io::Error::from)?;
        let from = r.address.and_then(|a| {
            a.as_sockaddr_in()
                .map(|v4| SocketAddr::from(*v4))
                .or_else(|| a.as_sockaddr_in6().map(|v6| SocketAddr::from(*v6)))
        });
        self.got[k] = (r.bytes, from, stamp_of(&r));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair() -> (UdpSocket, UdpSocket) {
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        sock.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        (sock, UdpSocket::bind("127.0.0.1:0").unwrap())
    }

    fn wait(rx: &mut Receiver, sock: &UdpSocket) -> usize {
        rx.recv(sock, Some(Instant::now())).unwrap().0
    }

    /// A receiver that relies on its stamps: `Receiver::new` waited for the kernel to stamp on
    /// arrival (the first socket to ask switches it on through deferred work).
    fn stamping(sock: &UdpSocket, max_datagram: usize) -> Receiver {
        let rx = Receiver::new(sock, max_datagram);
        assert!(
            rx.on_arrival,
            "the kernel never stamped a datagram on arrival"
        );
        rx
    }

    /// The kernel's stamp is the datagram's arrival: after the peer's clock read before its `send`,
    /// and before the one after it (both `CLOCK_REALTIME`, the clock `SO_TIMESTAMPNS` stamps with);
    /// on the monotonic clock, before the read's return.
    #[test]
    fn the_socket_returns_the_kernel_arrival_stamp() {
        let (sock, peer) = pair();
        let mut rx = stamping(&sock, 1024);
        assert!(rx.stamped());
        for k in 0..3u8 {
            let before = SystemTime::now();
            peer.send_to(&[k; 40], sock.local_addr().unwrap()).unwrap();
            let after = SystemTime::now();
            let (n, read_at) = rx.recv(&sock, Some(Instant::now())).unwrap();
            assert_eq!(n, 1);
            let stamp = rx.got[0].2.expect("a kernel stamp");
            assert!(
                before <= stamp && stamp <= after,
                "{before:?} <= {stamp:?} <= {after:?}"
            );
            let (bytes, from, arrived) = rx.datagram(0);
            let peer_addr = Some(peer.local_addr().unwrap());
            assert_eq!((bytes, from), (&[k; 40][..], peer_addr));
            assert!(arrived.expect("an arrival") <= read_at);
        }
    }

    /// A receiver on a socket whose stamps are off reads no arrival (the link then measures from
    /// the receive call) and drains after every read.
    #[test]
    fn without_stamps_a_datagram_reads_unstamped() {
        let (sock, peer) = pair();
        let mut rx = Receiver::new(&sock, 1024);
        setsockopt(&sock, sockopt::ReceiveTimestampns, &false).unwrap();
        rx.stamped = false;
        peer.send_to(&[1; 40], sock.local_addr().unwrap()).unwrap();
        peer.send_to(&[2; 40], sock.local_addr().unwrap()).unwrap();
        std::thread::sleep(Duration::from_millis(1));
        // Even with `since` before both: no arrival known, so the queue is drained.
        let since = Instant::now() - Duration::from_secs(1);
        assert_eq!(rx.recv(&sock, Some(since)).unwrap().0, 2);
        assert_eq!(rx.datagram(0).2, None);
        assert_eq!(rx.datagram(1).0, &[2; 40][..]);
    }

    /// Datagrams queued before the call (a stall) are all read, oldest first, each with its
    /// arrival, up to BATCH a call; the rest on the next call.
    #[test]
    fn a_backlog_is_read_whole_oldest_first() {
        let (sock, peer) = pair();
        let mut rx = stamping(&sock, 1024);
        let to = sock.local_addr().unwrap();
        for k in 0..(BATCH + 4) as u8 {
            peer.send_to(&[k; 8], to).unwrap();
        }
        std::thread::sleep(Duration::from_millis(1));
        assert_eq!(wait(&mut rx, &sock), BATCH);
        for k in 0..BATCH {
            let (bytes, _, arrived) = rx.datagram(k);
            assert_eq!(bytes, &[k as u8; 8][..]);
            assert!(arrived.is_some(), "datagram {k} with its arrival");
        }
        assert_eq!(rx.recv(&sock, None).unwrap().0, 4);
        assert_eq!(rx.datagram(3).0, &[BATCH as u8 + 3; 8][..]);
        let e = rx.recv(&sock, None).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::WouldBlock, "{e}");
        assert!(is_transient(&e));
    }

    /// A datagram that arrived after the caller's clock read is taken as the one that woke the
    /// call and read alone; what is queued behind it is read by the next call, which drains.
    #[test]
    fn a_datagram_that_woke_the_call_is_read_alone() {
        let (sock, peer) = pair();
        let mut rx = stamping(&sock, 64);
        let to = sock.local_addr().unwrap();
        let since = Instant::now();
        for k in 1..=3u8 {
            peer.send_to(&[k; 8], to).unwrap();
        }
        assert_eq!(rx.recv(&sock, Some(since)).unwrap().0, 1);
        assert_eq!(rx.datagram(0).0, &[1; 8][..]);
        assert_eq!(wait(&mut rx, &sock), 2, "queued before this call: drained");
        assert_eq!(rx.datagram(1).0, &[3; 8][..]);
    }

    /// A datagram longer than `max_datagram` is cut one byte past it, so it still reads as too long.
    #[test]
    fn an_oversized_datagram_reads_one_byte_too_long() {
        let (sock, peer) = pair();
        let mut rx = Receiver::new(&sock, 16);
        peer.send_to(&[7; 100], sock.local_addr().unwrap()).unwrap();
        assert_eq!(wait(&mut rx, &sock), 1);
        assert_eq!(rx.datagram(0).0.len(), 17);
    }

    #[test]
    fn a_wait_times_out_as_a_transient_error() {
        let (sock, _peer) = pair();
        sock.set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        let mut rx = Receiver::new(&sock, 64);
        let e = rx.recv(&sock, Some(Instant::now())).unwrap_err();
        assert!(is_transient(&e), "{e}");
    }

    #[test]
    fn only_a_datagram_that_waited_in_the_socket_may_have_company() {
        let t = Instant::now();
        let us = Duration::from_micros;
        assert!(
            may_have_backlog(t, Some(t - us(5))),
            "queued before the call"
        );
        assert!(may_have_backlog(t, Some(t)));
        assert!(!may_have_backlog(t, Some(t + us(5))), "woke the call");
        assert!(may_have_backlog(t, None), "arrival unknown");
    }

    #[test]
    fn a_stamp_becomes_an_arrival_on_the_monotonic_clock_or_none() {
        let (wall, now) = (SystemTime::now(), Instant::now());
        let ms = Duration::from_millis;
        assert_eq!(arrival(wall - ms(3), wall, now), Some(now - ms(3)));
        assert_eq!(arrival(wall, wall, now), Some(now));
        assert_eq!(arrival(wall + ms(1), wall, now), None, "after the read");
        assert_eq!(arrival(wall - ms(1500), wall, now), None, "a stepped clock");
    }

    /// The check's word is the kernel's behaviour: once it says stamps are taken on arrival, a
    /// datagram queued before a read carries a stamp from before that read began.
    #[test]
    fn the_arrival_check_agrees_with_the_stamps() {
        let (sock, peer) = pair();
        let mut rx = stamping(&sock, 64);
        peer.send_to(&[1; 8], sock.local_addr().unwrap()).unwrap();
        std::thread::sleep(Duration::from_millis(1));
        let before_read = SystemTime::now();
        assert_eq!(wait(&mut rx, &sock), 1);
        assert!(rx.got[0].2.expect("a kernel stamp") < before_read);
    }

    #[test]
    fn a_receiver_can_move_to_another_thread() {
        fn is_send<T: Send>() {}
        is_send::<Receiver>();
    }
}
