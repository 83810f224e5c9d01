//! A bare UDP echo: the baseline of the turnaround benchmark (`examples/turnaround.rs`). It binds
//! `127.0.0.1:0` (or the address given), prints the address, and sends every datagram back to its
//! source unchanged — one `recvfrom` and one `sendto` per datagram, nothing else.

use std::io::Write as _;
use std::net::UdpSocket;

fn main() -> std::io::Result<()> {
    let addr = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "127.0.0.1:0".to_owned());
    let sock = UdpSocket::bind(&addr)?;
    let mut out = std::io::stdout();
    writeln!(out, "{}", sock.local_addr()?)?;
    out.flush()?;
    let mut buf = vec![0u8; 65536];
    loop {
        let (n, from) = sock.recv_from(&mut buf)?;
        sock.send_to(&buf[..n], from)?;
    }
}
