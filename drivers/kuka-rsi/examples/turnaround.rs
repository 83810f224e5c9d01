//! Turnaround of forcecell's RSI link against a bare UDP echo, measured by one lockstep client.
//!
//! ```text
//! cargo build --release -p forcecell-kuka-rsi --examples
//! taskset -c 0 target/release/examples/turnaround 100000
//! ```
//! The client starts `udp_echo` and `rsi_answer` (siblings of its own executable; they inherit the
//! CPU pinning) as their own processes, then sends the same `<Rob>` — with
//! `<FcCmd Mode="1" F="20.0000" Ramp="0.5000" Seg="3"/>` and a fresh IPOC — to the echo and to
//! forcecell in turn, one at a time, and times each send → reply on the wall clock. The forcecell
//! reply must carry the cycle's IPOC and an `FcState`. Prints p50, p99, p99.9 and max of both and the
//! ratios forcecell/echo.
//!
//! `turnaround CYCLES [ECHO_ADDR FORCECELL_ADDR]`: with addresses, use servers already running
//! (e.g. one under `strace -c`); `-` skips one.

use std::io::{BufRead as _, BufReader};
use std::net::{SocketAddr, UdpSocket};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use kuka_rsi::{CommandSlots, EthernetConfig, Frame, Ipoc, ProcessChannels};

const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];
const AXES: [&str; 6] = ["A1", "A2", "A3", "A4", "A5", "A6"];

fn spawn(name: &str) -> Result<(Child, SocketAddr), Box<dyn std::error::Error>> {
    let exe = std::env::current_exe()?.with_file_name(name);
    let mut child = Command::new(&exe)
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start {}: {e}", exe.display()))?;
    let mut line = String::new();
    BufReader::new(child.stdout.take().ok_or("no stdout")?).read_line(&mut line)?;
    Ok((child, line.trim().parse()?))
}

fn pct(sorted: &[u32], p: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    f64::from(sorted[i]) / 1000.0
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let cycles: usize = args.get(1).map_or(Ok(100_000), |s| s.parse())?;
    let mut children = Vec::new();
    let mut target =
        |k: usize, name: &str| -> Result<Option<SocketAddr>, Box<dyn std::error::Error>> {
            match args.get(k).map(String::as_str) {
                Some("-") => Ok(None),
                Some(a) => Ok(Some(a.parse()?)),
                None => {
                    let (c, a) = spawn(name)?;
                    children.push(c);
                    Ok(Some(a))
                }
            }
        };
    let echo = target(2, "udp_echo")?;
    let fc = target(3, "rsi_answer")?;

    let eth = EthernetConfig::forcecell([127, 0, 0, 1].into(), 0, false)
        .with_process(ProcessChannels::default());
    let rob = eth.rob_schema(4)?;
    let cmd = CommandSlots::find(&rob)?.ok_or("no FcCmd")?;
    let mut frame = Frame::new();
    frame.set6(
        rob.six("RIst", POSE).ok_or("RIst")?,
        [445.0, 0.0, 890.0, 180.0, 0.0, 180.0],
    );
    frame.set6(
        rob.six("RSol", POSE).ok_or("RSol")?,
        [445.0, 0.0, 890.0, 180.0, 0.0, 180.0],
    );
    for t in ["AIPos", "ASPos"] {
        frame.set6(
            rob.six(t, AXES).ok_or("axes")?,
            [0.0, -90.0, 90.0, 0.0, 90.0, 0.0],
        );
    }
    frame.set(rob.slot("Delay", "D").ok_or("Delay")?, 0.0);
    cmd.encode(
        &hal::ProcessCommand {
            mode: hal::ProcessMode::Press,
            force: 20.0,
            ramp: 0.5,
            segment: 3,
        },
        &mut frame,
    );

    let sock = UdpSocket::bind("127.0.0.1:0")?;
    sock.set_read_timeout(Some(Duration::from_secs(5)))?;
    let mut out = [0u8; 2048];
    let mut inp = [0u8; 4096];
    let warmup = 2000;
    let mut t_echo = Vec::with_capacity(cycles);
    let mut t_fc = Vec::with_capacity(cycles);
    let mut bad = 0u64;
    for k in 0..warmup + cycles {
        frame.set_ipoc(Ipoc::new(1_000_000 + 4 * k as u64));
        let n = rob.write(&frame, &mut out)?;
        for (addr, times, is_fc) in [(echo, &mut t_echo, false), (fc, &mut t_fc, true)] {
            let Some(addr) = addr else { continue };
            let t0 = Instant::now();
            sock.send_to(&out[..n], addr)?;
            let (m, _) = sock.recv_from(&mut inp)?;
            let dt = t0.elapsed();
            if k >= warmup {
                times.push(u32::try_from(dt.as_nanos()).unwrap_or(u32::MAX));
            }
            if is_fc {
                let reply = &inp[..m];
                let ipoc = frame.ipoc().digits();
                let ok = reply.windows(8).any(|w| w == b"<FcState")
                    && reply.windows(ipoc.len()).any(|w| w == ipoc);
                bad += u64::from(!ok);
            }
        }
    }
    for mut c in children {
        let _ = c.kill();
        let _ = c.wait();
    }
    println!("lockstep round trips, {cycles} cycles each, interleaved (µs):");
    println!(
        "{:<28} {:>8} {:>8} {:>8} {:>8}",
        "", "p50", "p99", "p99.9", "max"
    );
    let mut rows = Vec::new();
    for (name, t) in [
        ("bare UDP echo", &mut t_echo),
        ("forcecell RSI + FcCmd/FcState", &mut t_fc),
    ] {
        if t.is_empty() {
            continue;
        }
        t.sort_unstable();
        let r = [pct(t, 0.5), pct(t, 0.99), pct(t, 0.999), pct(t, 1.0)];
        println!(
            "{name:<28} {:>8.1} {:>8.1} {:>8.1} {:>8.1}",
            r[0], r[1], r[2], r[3]
        );
        rows.push(r);
    }
    if let [e, f] = rows[..] {
        println!(
            "{:<28} {:>8.2} {:>8.2} {:>8.2} {:>8.2}",
            "ratio forcecell/echo",
            f[0] / e[0],
            f[1] / e[1],
            f[2] / e[2],
            f[3] / e[3]
        );
    }
    if bad > 0 {
        return Err(format!("{bad} forcecell replies without FcState or with a wrong IPOC").into());
    }
    Ok(())
}
