//! What the receive call costs on this machine: UDP echoes that differ only in how they receive,
//! answering a client in lockstep, all pinned to one CPU, each timed send → reply.
//!
//! ```text
//! cargo run --release -p forcecell-udp --example receive_echo -- 20000
//! ```
//!
//! * `recvfrom`: the bare echo (`UdpSocket::recv_from`), stamps off;
//! * `recvfrom+timeout 1s`, `… 30s`: the same with a receive timeout set, as the links' watchdog
//!   sets one (the kernel arms a timer whenever the call sleeps, whatever its length);
//! * `Receiver`: this crate's receive (blocking `recvmsg` with the kernel's stamp), without and with
//!   a timeout;
//! * `recvmmsg16`: the links' former receive, `recvmmsg(MSG_WAITFORONE)` of 16 with stamps (nix's
//!   wrapper, headers allocated once), without and with a timeout.
//!
//! Before each timed send the client waits until the echo's thread is asleep (state `S` in
//! `/proc/self/task/TID/stat`), so no round trip starts while another program is still running on
//! the CPU. Prints p50, p99 and p99.9 of each, µs.

use std::io::IoSliceMut;
use std::net::{SocketAddr, UdpSocket};
use std::os::fd::AsRawFd;
use std::sync::Arc;
use std::sync::atomic::{AtomicI32, Ordering};
use std::time::{Duration, Instant};

use nix::sched::{CpuSet, sched_setaffinity};
use nix::sys::socket::{MsgFlags, MultiHeaders, SockaddrStorage, recvmmsg, setsockopt, sockopt};
use nix::sys::time::TimeSpec;
use nix::unistd::Pid;

/// The echoes: name, receive (0 `recv_from`, 1 `Receiver`, 2 `recvmmsg`), receive timeout.
const KINDS: [(&str, u8, Option<u64>); 7] = [
    ("recvfrom", 0, None),
    ("recvfrom+timeout 1s", 0, Some(1)),
    ("recvfrom+timeout 30s", 0, Some(30)),
    ("Receiver", 1, None),
    ("Receiver+timeout 1s", 1, Some(1)),
    ("recvmmsg16", 2, None),
    ("recvmmsg16+timeout 1s", 2, Some(1)),
];

fn tid() -> i32 {
    // The thread's id as the kernel knows it: the last path element of /proc/thread-self.
    std::fs::read_link("/proc/thread-self")
        .ok()
        .and_then(|p| p.file_name()?.to_str()?.parse().ok())
        .unwrap_or(0)
}

fn pin_to_cpu0() {
    let mut cpus = CpuSet::new();
    cpus.set(0).unwrap();
    sched_setaffinity(Pid::from_raw(0), &cpus).expect("pin to CPU 0");
}

fn asleep(tid: i32) -> bool {
    std::fs::read_to_string(format!("/proc/self/task/{tid}/stat"))
        .ok()
        .and_then(|s| s.rfind(')').map(|i| s[i + 2..].starts_with('S')))
        .unwrap_or(true)
}

fn echo(kind: usize, sock: UdpSocket, me: Arc<AtomicI32>) {
    pin_to_cpu0();
    me.store(tid(), Ordering::SeqCst);
    let (_, kind, timeout) = KINDS[kind];
    sock.set_read_timeout(timeout.map(Duration::from_secs))
        .unwrap();
    match kind {
        0 => {
            let mut buf = [0u8; 2049];
            while let Ok((n, from)) = sock.recv_from(&mut buf) {
                if n == 1 {
                    return;
                }
                sock.send_to(&buf[..n], from).unwrap();
            }
        }
        1 => {
            // As the links receive: every datagram offered, answered from the receiver's buffer.
            let mut rx = udp::Receiver::new(&sock, 2048);
            loop {
                let mut end = false;
                let _ = rx.recv_all(&sock, Some(Instant::now()), |bytes, from, _, _| {
                    end |= bytes.len() == 1;
                    sock.send_to(bytes, from).unwrap();
                });
                if end {
                    return;
                }
            }
        }
        _ => {
            // The former receive: buffers, message headers and the I/O vectors' array set up once
            // per call without allocating, as the links had them.
            setsockopt(&sock, sockopt::ReceiveTimestampns, &true).unwrap();
            let mut bufs: [[u8; 2049]; 16] = [[0; 2049]; 16];
            let mut headers =
                MultiHeaders::<SockaddrStorage>::preallocate(16, Some(nix::cmsg_space!(TimeSpec)));
            loop {
                let mut iovs = bufs.each_mut().map(|b| [IoSliceMut::new(&mut b[..])]);
                let Ok(mut res) = recvmmsg(
                    sock.as_raw_fd(),
                    &mut headers,
                    &mut iovs,
                    MsgFlags::MSG_WAITFORONE,
                    None,
                ) else {
                    continue;
                };
                let r = res.next().unwrap();
                let from = r
                    .address
                    .and_then(|a| a.as_sockaddr_in().map(|v| SocketAddr::from(*v)))
                    .unwrap();
                let n = r.bytes;
                if n == 1 {
                    return;
                }
                sock.send_to(&bufs[0][..n], from).unwrap();
            }
        }
    }
}

fn main() {
    let cycles: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(20_000);
    let mut peers = vec![];
    for kind in 0..KINDS.len() {
        let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
        let me = Arc::new(AtomicI32::new(0));
        peers.push((sock.local_addr().unwrap(), me.clone()));
        std::thread::spawn(move || echo(kind, sock, me));
    }
    pin_to_cpu0();
    std::thread::sleep(Duration::from_millis(100));
    let client = UdpSocket::bind("127.0.0.1:0").unwrap();
    let datagram = vec![b'x'; 700];
    let mut reply = vec![0u8; 4096];
    let mut times: Vec<Vec<f64>> = vec![Vec::with_capacity(cycles); KINDS.len()];
    for i in 0..cycles + 2000 {
        for (k, (addr, me)) in peers.iter().enumerate() {
            let t = me.load(Ordering::SeqCst);
            while !asleep(t) {
                std::thread::yield_now();
            }
            let t0 = Instant::now();
            client.send_to(&datagram, addr).unwrap();
            client.recv_from(&mut reply).unwrap();
            if i >= 2000 {
                times[k].push(t0.elapsed().as_secs_f64() * 1e6);
            }
        }
    }
    for (addr, _) in &peers {
        client.send_to(&[1], addr).unwrap();
    }
    println!("{cycles} lockstep round trips each (µs)   p50     p99   p99.9");
    for (k, v) in times.iter_mut().enumerate() {
        v.sort_by(f64::total_cmp);
        let p = |q: f64| v[((v.len() - 1) as f64 * q) as usize];
        println!(
            "{:<34} {:>6.2} {:>7.2} {:>7.2}",
            KINDS[k].0,
            p(0.5),
            p(0.99),
            p(0.999)
        );
    }
}
