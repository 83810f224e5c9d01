//! What one control cycle of the whole cell costs on the wire: forcecell's real loop (the RSI driver
//! on a loopback UDP socket, a force sensor, the control law, the recorder) answering a lockstep robot
//! stand-in, side by side with a bare UDP echo answered from the same CPU.
//!
//! ```text
//! cargo build --release --example cell_latency
//! target/release/examples/cell_latency --cell run --sensor robotiq --cycles 50000 --loop-cpu 0 --other-cpu 1
//! target/release/examples/cell_latency --cell external --cycles 50000 --loop-cpu 0 --other-cpu 1
//! target/release/examples/cell_latency --cell egm --cycles 50000 --loop-cpu 0 --other-cpu 1 --standin-cpu 0
//! target/release/examples/cell_latency --cell run --cycles 50000 --loop-cpu 0 --other-cpu 0   # all on one CPU
//! ```
//!
//! * `--cell run`: [`forcecell::cell::run_cell_recorded`] as `forcecell run` calls it — the RSI link
//!   bound from a cell file (tuning `robust-100hz`), the sensor, the MCAP recorder thread.
//! * `--cell external`: `forcecell sim --external-robot` — [`forcecell::rsi::RobotSide`] on
//!   `paper-fig9` with tuning `robust`, recorded, the world following the pose the stand-in reports.
//! * `--cell egm`: the same loop as `--cell run` (tuning `robust-100hz`, the recorder) with the ABB EGM
//!   driver ([`abb_egm::EgmLink`]) in place of RSI; the stand-in is then the simulated IRC5's sans-IO
//!   core ([`sim::irc5::Irc5Core`]): it writes `EgmRobot`, judges the `EgmSensorPathCorr` and moves
//!   the spring world, each cycle sending the same `EgmRobot` to the echo and to forcecell.
//! * `--cell egm-driver`: the EGM driver alone (no law, no sensor, no recorder): the link decodes
//!   each `EgmRobot`, runs its session and answers a fixed correction — the driver's own turnaround.
//! * `--cell none`: the echo alone.
//! * `--sensor inproc` (the world's sensor model read in the cycle), `robotiq` (the FT 300 driver
//!   reading a simulated FT 300 that streams at 100 Hz on a pseudo-terminal, as on a cell) or, with
//!   `--cell external`, `ati` (the ATI driver against the simulated node on the in-memory bus, the
//!   command's default).
//!
//! The stand-in is a robot in `#ABSOLUTE` mode with an ideal position loop: it sends `<Rob>` with a
//! fresh IPOC (4 per cycle) and the tool where the last `<Sen>` put it, waits for the answer, and —
//! for `--cell run` — moves the spring world the sensor measures. Each cycle it sends the same
//! datagram to the echo first (`--no-echo` leaves it out), then to forcecell, and times each send →
//! reply on the wall clock. `--period-us P` waits P µs between cycles (a real robot's 4000); default
//! 0: lockstep.
//!
//! `--realtime` (`--cell run`) applies `run`'s real-time settings (the cell file's `[realtime]` defaults:
//! `SCHED_FIFO` 80, memory locked, the stack touched; [`forcecell::rt::Realtime`]) to the loop's thread
//! exactly as `run` applies them, and the same to the echo, so the echo stays the bar of what this
//! machine gives a minimal program under the same settings. `--standin-priority P` runs the robot
//! stand-in at `SCHED_FIFO` P in every condition (it plays a robot controller, which has hardware of
//! its own). With a period, the replies later than the period (the robot's cycle: RSI counts them
//! against its `Timeout`) are counted for the echo and for forcecell (`late`).
//!
//! `--echo-times` has the echo time its own receive→send as the links do (the receive call's return
//! to the send call's return), printed after forcecell's: what this machine gives a program that
//! does nothing but answer. Off by default: it adds two clock reads to the echo's cycle.
//!
//! `--spin-us N` (`--cell run`) sets the RSI link's `spin`: it polls for the datagram from N µs
//! before it is due until N µs after (`robot.spin_us` in a cell file).
//!
//! `--recorder-sched idle` runs the recorder's writer thread under `SCHED_IDLE` (`chrt --idle`),
//! `--recorder-sched nice` at nice 19 (`renice`): on a CPU it shares with the loop it then yields to
//! the loop as soon as a datagram wakes it.
//!
//! `--loop-cpu C` pins forcecell's loop thread and the echo to CPU C; `--other-cpu D` pins every other
//! thread (the stand-in, the recorder, the sensor's reader and the simulated sensor) to D;
//! `--standin-cpu S` then moves the stand-in to S (the loop's CPU: lockstep on one CPU, no
//! cross-CPU wake-up in the round trip). Prints the
//! stand-in's round trips (p50, p99, p99.9, max, µs) of the echo and of forcecell and their ratio,
//! and the driver's own receive→send distribution.

use std::net::{Ipv4Addr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use hal::Correction;
use kuka_rsi::{EthernetConfig, Frame, Ipoc, Latency, RsiLink};
use nix::sched::{CpuSet, sched_setaffinity};
use nix::unistd::Pid;
use sim::{ContactPlant, InProcSensor, InnerLoopModel, SensorParams, SharedWorld, World};

const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];
const AXES: [&str; 6] = ["A1", "A2", "A3", "A4", "A5", "A6"];

#[derive(Clone, Debug)]
struct Opts {
    cell: String,
    sensor: String,
    cycles: usize,
    warmup: usize,
    period: Duration,
    loop_cpu: Option<usize>,
    other_cpu: Option<usize>,
    standin_cpu: Option<usize>,
    echo: bool,
    record: bool,
    recorder_sched: Option<String>,
    realtime: bool,
    standin_priority: u8,
    spin_us: u64,
    settle: bool,
    echo_times: bool,
}

fn parse_opts() -> Result<Opts> {
    let mut o = Opts {
        cell: "run".into(),
        sensor: String::new(),
        cycles: 20_000,
        warmup: 2_000,
        period: Duration::ZERO,
        loop_cpu: None,
        other_cpu: None,
        standin_cpu: None,
        echo: true,
        record: true,
        recorder_sched: None,
        realtime: false,
        standin_priority: 0,
        spin_us: 0,
        settle: false,
        echo_times: false,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut val = || args.next().ok_or_else(|| anyhow!("{a} needs a value"));
        match a.as_str() {
            "--cell" => o.cell = val()?,
            "--sensor" => o.sensor = val()?,
            "--cycles" => o.cycles = val()?.parse()?,
            "--warmup" => o.warmup = val()?.parse()?,
            "--period-us" => o.period = Duration::from_micros(val()?.parse()?),
            "--loop-cpu" => o.loop_cpu = Some(val()?.parse()?),
            "--other-cpu" => o.other_cpu = Some(val()?.parse()?),
            "--standin-cpu" => o.standin_cpu = Some(val()?.parse()?),
            "--no-echo" => o.echo = false,
            "--spin-us" => o.spin_us = val()?.parse()?,
            "--no-record" => o.record = false,
            "--recorder-sched" => o.recorder_sched = Some(val()?),
            "--realtime" => o.realtime = true,
            "--standin-priority" => o.standin_priority = val()?.parse()?,
            "--settle" => o.settle = true,
            "--echo-times" => o.echo_times = true,
            _ => bail!("unknown option {a} (see the file's documentation)"),
        }
    }
    if o.sensor.is_empty() {
        o.sensor = if o.cell == "external" {
            "ati"
        } else {
            "inproc"
        }
        .into();
    }
    Ok(o)
}

/// Pin the calling thread (and the threads it spawns from now on) to `cpu`.
fn pin(cpu: Option<usize>) -> Result<()> {
    if let Some(cpu) = cpu {
        let mut set = CpuSet::new();
        set.set(cpu)?;
        sched_setaffinity(Pid::from_raw(0), &set)?;
    }
    Ok(())
}

fn percentiles(t: &mut [u32]) -> [f64; 4] {
    t.sort_unstable();
    let p = |q: f64| f64::from(t[((t.len() as f64 - 1.0) * q).round() as usize]) / 1000.0;
    [p(0.5), p(0.99), p(0.999), p(1.0)]
}

/// The robot stand-in's world for `--cell run`: a spring 1 mm from the tool's start, the tool where
/// each answer puts it.
fn spring_world() -> SharedWorld {
    World::new(
        ContactPlant::spring(70_000.0, 0.001),
        InnerLoopModel::P0,
        SensorParams::default(),
        0.0,
    )
    .shared()
}

struct Standin {
    sock: UdpSocket,
    rob: kuka_rsi::Schema,
    sen: kuka_rsi::Schema,
    frame: Frame,
    rist: [usize; 6],
    rsol: [usize; 6],
    rkorr_z: usize,
    stop: usize,
    sen_frame: Frame,
}

impl Standin {
    fn new() -> Result<Self> {
        let eth = EthernetConfig::forcecell(Ipv4Addr::LOCALHOST, 0, false);
        let rob = eth.rob_schema(4).map_err(|e| anyhow!("{e}"))?;
        let sen = eth.sen_schema(4).map_err(|e| anyhow!("{e}"))?;
        let mut frame = Frame::new();
        let rist = rob.six("RIst", POSE).context("RIst")?;
        let rsol = rob.six("RSol", POSE).context("RSol")?;
        for t in ["AIPos", "ASPos"] {
            frame.set6(
                rob.six(t, AXES).context("axes")?,
                [0.0, -90.0, 90.0, 0.0, 90.0, 0.0],
            );
        }
        frame.set(rob.slot("Delay", "D").context("Delay")?, 0.0);
        let sock = UdpSocket::bind("127.0.0.1:0")?;
        sock.set_read_timeout(Some(Duration::from_secs(2)))?;
        Ok(Self {
            sock,
            rkorr_z: sen.slot("RKorr", "Z").context("RKorr")?,
            stop: sen.slot("Stop", "").context("Stop")?,
            rob,
            sen,
            frame,
            rist,
            rsol,
            sen_frame: Frame::new(),
        })
    }

    /// Write the `<Rob>` of cycle `k` with the tool `z_mm` off its path.
    fn rob(&mut self, k: usize, z_mm: f64, out: &mut [u8]) -> Result<usize> {
        let path = [500.0, 0.0, 300.0, 0.0, 0.0, 0.0];
        let mut actual = path;
        actual[2] += z_mm;
        self.frame.set6(self.rsol, path);
        self.frame.set6(self.rist, actual);
        self.frame.set_ipoc(Ipoc::new(1_000_000 + 4 * k as u64));
        Ok(self.rob.write(&self.frame, out)?)
    }

    /// The answer's `RKorr.Z` (mm) and `Stop`.
    fn answer(&mut self, bytes: &[u8]) -> Result<(f64, bool)> {
        self.sen.parse(bytes, &mut self.sen_frame)?;
        Ok((
            self.sen_frame.get(self.rkorr_z),
            self.sen_frame.get(self.stop) != 0.0,
        ))
    }
}

/// `--settle`: before each timed send the stand-in waits until forcecell's loop thread and the echo
/// thread are both asleep (state `S` in `/proc/self/task/TID/stat`), yielding its CPU meanwhile, so
/// neither round trip starts while the other's program is still finishing its cycle on the CPU they
/// share: the work a program does after its reply (forcecell's record, the echo's return to its
/// receive call) is then not charged to the next round trip, as it is not on a cell whose robot is
/// another machine. Threads are found by name (`loop`, `echo`).
struct Settle {
    stats: Vec<std::fs::File>,
    buf: [u8; 512],
    waits: u64,
}

impl Settle {
    /// Watch the threads named `loop` and `echo`, `want` of them (a thread names itself once it runs:
    /// wait up to 2 s for them).
    fn new(on: bool, want: usize) -> Result<Self> {
        let mut stats = Vec::new();
        if on {
            for _ in 0..200 {
                stats.clear();
                for e in std::fs::read_dir("/proc/self/task")? {
                    let dir = e?.path();
                    let name = std::fs::read_to_string(dir.join("comm")).unwrap_or_default();
                    if matches!(name.trim(), "loop" | "echo") {
                        stats.push(std::fs::File::open(dir.join("stat"))?);
                    }
                }
                if stats.len() >= want {
                    break;
                }
                thread::sleep(Duration::from_millis(10));
            }
            if stats.len() < want {
                bail!(
                    "--settle: found {} of the {want} threads named loop or echo",
                    stats.len()
                );
            }
        }
        Ok(Self {
            stats,
            buf: [0; 512],
            waits: 0,
        })
    }

    /// Yield until every watched thread is asleep (at most 100 000 yields: a thread that never
    /// sleeps is not waited for forever).
    fn wait(&mut self) {
        use std::os::unix::fs::FileExt;
        for _ in 0..100_000 {
            let mut running = false;
            for f in &self.stats {
                let n = f.read_at(&mut self.buf, 0).unwrap_or(0);
                let line = &self.buf[..n];
                // The state follows the command name's closing parenthesis and a space.
                if let Some(p) = line.iter().rposition(|&b| b == b')') {
                    running |= line.get(p + 2) == Some(&b'R');
                }
            }
            if !running {
                return;
            }
            self.waits += 1;
            thread::yield_now();
        }
    }
}

struct Times {
    echo: Vec<u32>,
    cell: Vec<u32>,
}

/// Drive the cell at `cell` (and the echo at `echo`) until `cycles` after the warm-up are timed or
/// the cell says `Stop`; `world`: the spring to move with each answer.
fn stand_in(
    o: &Opts,
    echo: Option<SocketAddr>,
    cell: Option<SocketAddr>,
    world: Option<SharedWorld>,
) -> Result<Times> {
    let mut s = Standin::new()?;
    let mut settle = Settle::new(
        o.settle,
        usize::from(echo.is_some()) + usize::from(cell.is_some()),
    )?;
    let mut out = [0u8; 2048];
    let mut inp = [0u8; 4096];
    let mut times = Times {
        echo: Vec::with_capacity(o.cycles),
        cell: Vec::with_capacity(o.cycles),
    };
    let mut z_mm = 0.0;
    let mut next = Instant::now();
    for k in 0..o.warmup + o.cycles {
        if !o.period.is_zero() {
            next += o.period;
            while Instant::now() < next {
                thread::sleep(next - Instant::now());
            }
        }
        let n = s.rob(k, z_mm, &mut out)?;
        // On the wall clock the echo answers half a period after the cell: each round trip follows
        // the same idle time (the one that follows the other would find the kernel's paths warm).
        let echo_first = o.period.is_zero();
        let timed = k >= o.warmup;
        if !echo_first {
            settle.wait();
            let stop = cell_round(
                &mut s,
                &out[..n],
                &mut inp,
                cell,
                world.as_ref(),
                timed,
                &mut times.cell,
                &mut z_mm,
            )?;
            if stop {
                break;
            }
            let half = next + o.period / 2;
            while Instant::now() < half {
                thread::sleep(half - Instant::now());
            }
        }
        if let Some(addr) = echo {
            settle.wait();
            let t0 = Instant::now();
            s.sock.send_to(&out[..n], addr)?;
            s.sock.recv_from(&mut inp)?;
            let dt = t0.elapsed();
            if timed {
                times
                    .echo
                    .push(u32::try_from(dt.as_nanos()).unwrap_or(u32::MAX));
            }
        }
        if echo_first && o.settle {
            settle.wait();
        }
        if echo_first
            && cell_round(
                &mut s,
                &out[..n],
                &mut inp,
                cell,
                world.as_ref(),
                timed,
                &mut times.cell,
                &mut z_mm,
            )?
        {
            break;
        }
    }
    if o.settle {
        eprintln!(
            "settle: {} yields waiting for a thread to sleep",
            settle.waits
        );
    }
    Ok(times)
}

/// One round trip to the cell at `cell` (if any): times it into `times` when `timed`, takes the
/// correction into `z_mm` and moves `world`. True when the answer says `Stop`.
#[allow(clippy::too_many_arguments)]
fn cell_round(
    s: &mut Standin,
    datagram: &[u8],
    inp: &mut [u8],
    cell: Option<SocketAddr>,
    world: Option<&SharedWorld>,
    timed: bool,
    times: &mut Vec<u32>,
    z_mm: &mut f64,
) -> Result<bool> {
    let Some(addr) = cell else { return Ok(false) };
    let t0 = Instant::now();
    s.sock.send_to(datagram, addr)?;
    let (m, _) = s.sock.recv_from(inp).context("no answer from the cell")?;
    let dt = t0.elapsed();
    if timed {
        times.push(u32::try_from(dt.as_nanos()).unwrap_or(u32::MAX));
    }
    let (z, stop) = s.answer(&inp[..m])?;
    *z_mm = z;
    if let Some(w) = world {
        sim::world::lock(w).advance(Some(&Correction::along_z(z * 1e-3)));
    }
    Ok(stop)
}

/// The robot stand-in of `--cell egm`: the simulated IRC5's core on a lockstep socket, timing each
/// send → reply to the echo (first, as [`stand_in`] does in lockstep) and to the cell.
fn stand_in_egm(
    o: &Opts,
    echo: Option<SocketAddr>,
    cell: SocketAddr,
    mut world: SharedWorld,
) -> Result<Times> {
    let sock = UdpSocket::bind("127.0.0.1:0")?;
    sock.set_read_timeout(Some(Duration::from_secs(2)))?;
    let mut cfg = sim::irc5::Irc5Config::new(cell);
    cfg.range = abb_egm::CorrectionRange { translation: 0.01 };
    let mut core = sim::irc5::Irc5Core::new(cfg, sim::irc5::RapidVariables::default())
        .map_err(|e| anyhow!(e))?;
    let mut inp = [0u8; 4096];
    let mut settle = Settle::new(o.settle, usize::from(echo.is_some()) + 1)?;
    let mut times = Times {
        echo: Vec::with_capacity(o.cycles),
        cell: Vec::with_capacity(o.cycles),
    };
    let mut next = Instant::now();
    for k in 0..o.warmup + o.cycles {
        if !o.period.is_zero() {
            next += o.period;
            while Instant::now() < next {
                thread::sleep(next - Instant::now());
            }
        }
        let timed = k >= o.warmup;
        let out = core
            .next_cycle(&mut world)
            .map_err(|e| anyhow!("the simulated IRC5 ended: {e:?}"))?;
        if let Some(addr) = echo {
            settle.wait();
            let t0 = Instant::now();
            sock.send_to(out, addr)?;
            sock.recv_from(&mut inp)?;
            if timed {
                times
                    .echo
                    .push(u32::try_from(t0.elapsed().as_nanos()).unwrap_or(u32::MAX));
            }
        }
        settle.wait();
        let t0 = Instant::now();
        sock.send_to(out, cell)?;
        let (m, from) = sock
            .recv_from(&mut inp)
            .context("no answer from the cell")?;
        let dt = t0.elapsed();
        if timed {
            times
                .cell
                .push(u32::try_from(dt.as_nanos()).unwrap_or(u32::MAX));
        }
        let verdict = core.on_reply(&inp[..m], from);
        if verdict != sim::irc5::Verdict::Good {
            bail!("cycle {k}: the cell's answer is {verdict:?}");
        }
        core.end_cycle(&mut world)
            .map_err(|e| anyhow!("the simulated IRC5 ended: {e:?}"))?;
    }
    Ok(times)
}

/// The bare echo: `recv_from`, `send_to` (a 200 ms receive timeout, to notice the end; the links'
/// watchdog sleeps with one too). With `times`, it also times its own receive→send as the links
/// do (from the receive call's return to the send call's return; two clock reads a datagram).
fn echo_server(sock: UdpSocket, done: Arc<AtomicBool>, times: Option<Arc<Mutex<Vec<u32>>>>) {
    let mut buf = vec![0u8; 65536];
    let mut own = Vec::with_capacity(if times.is_some() { 1 << 20 } else { 0 });
    sock.set_read_timeout(Some(Duration::from_millis(200))).ok();
    while !done.load(Ordering::Relaxed) {
        if let Ok((n, from)) = sock.recv_from(&mut buf) {
            let got = times.as_ref().map(|_| Instant::now());
            let _ = sock.send_to(&buf[..n], from);
            if let Some(t) = got
                && own.len() < own.capacity()
            {
                own.push(u32::try_from(t.elapsed().as_nanos()).unwrap_or(u32::MAX));
            }
        }
    }
    if let Some(t) = times {
        *t.lock().unwrap() = own;
    }
}

/// Give this process's threads named `recorder` the scheduling `how` asks for, through `chrt` or
/// `renice` (util-linux).
fn resched_recorder(how: &str) -> Result<()> {
    let mut found = 0;
    for task in std::fs::read_dir("/proc/self/task")? {
        let task = task?.path();
        if std::fs::read_to_string(task.join("comm"))?.trim() != "recorder" {
            continue;
        }
        let tid = task
            .file_name()
            .context("tid")?
            .to_string_lossy()
            .into_owned();
        let status = match how {
            "idle" => std::process::Command::new("chrt")
                .args(["--idle", "-p", "0", &tid])
                .status()?,
            "nice" => std::process::Command::new("renice")
                .args(["-n", "19", "-p", &tid])
                .stdout(std::process::Stdio::null())
                .status()?,
            _ => bail!("--recorder-sched {how}: idle or nice"),
        };
        if !status.success() {
            bail!("could not reschedule the recorder thread {tid}");
        }
        found += 1;
    }
    if found == 0 {
        bail!("--recorder-sched: no recorder thread");
    }
    Ok(())
}

fn free_port() -> Result<SocketAddr> {
    Ok(UdpSocket::bind("127.0.0.1:0")?.local_addr()?)
}

const CELL: &str = r#"
tuning = "robust-100hz"
record = "unused"

[robot]
listen = "127.0.0.1:49152"
robot_ip = "127.0.0.1"

[sensor]
kind = "robotiq"
port = "unused"
"#;

/// The sensor of `--cell run`, measuring `world`.
enum RunSensor {
    Inproc(InProcSensor),
    // The simulated device lives as long as the driver reads it.
    Robotiq(
        Box<robotiq::Ft300>,
        #[allow(dead_code)] sim::ft300::SimFt300,
    ),
}

impl hal::ForceSensor for RunSensor {
    type Error = hal::ErrorKind;
    fn read(&mut self) -> Result<hal::Sample, Self::Error> {
        match self {
            Self::Inproc(s) => s.read(),
            Self::Robotiq(s, _) => s.read().map_err(|e| hal::Error::kind(&e)),
        }
    }
}

impl RunSensor {
    fn open(kind: &str, world: &SharedWorld) -> Result<Self> {
        Ok(match kind {
            "inproc" => Self::Inproc(InProcSensor::new(world.clone())),
            "robotiq" => {
                let device = sim::ft300::SimFt300::spawn(
                    sim::ft300::Ft300Config {
                        noise_force: 0.0,
                        noise_torque: 0.0,
                        streaming_at_start: true,
                        ..sim::ft300::Ft300Config::default()
                    },
                    sim::ati_node::WorldSource::measured(world.clone()),
                )?;
                let ft = robotiq::Ft300::open(robotiq::Config::new(device.path()))?;
                Self::Robotiq(Box::new(ft), device)
            }
            k => bail!("--sensor {k}: inproc or robotiq with --cell run"),
        })
    }
}

/// The driver's receive→send distribution and, where it keeps one, the part before the send call.
type DriverLatency = (Latency, Option<Latency>);

/// The cell's own receive→send distribution, µs.
fn driver_line(l: &Latency) -> String {
    let us = |d: Duration| d.as_secs_f64() * 1e6;
    format!(
        "p50 {:.0}, p99 {:.0}, p99.9 {:.0}, max {:.1} (1 µs buckets, upper edges; {} replies)",
        us(l.quantile(0.5)),
        us(l.quantile(0.99)),
        us(l.quantile(0.999)),
        us(l.max()),
        l.count()
    )
}

fn main() -> Result<()> {
    let o = parse_opts()?;
    // Everything but the loop and the echo is spawned from here on the other CPU.
    pin(o.other_cpu)?;
    let dir = std::env::temp_dir().join(format!("cell_latency-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let done = Arc::new(AtomicBool::new(false));
    let echo_own: Option<Arc<Mutex<Vec<u32>>>> = o.echo_times.then(Arc::default);
    let mut echo_thread = None;
    let echo = if o.echo {
        let sock = UdpSocket::bind("127.0.0.1:0")?;
        let addr = sock.local_addr()?;
        let (d, cpu, rt, own) = (done.clone(), o.loop_cpu, o.realtime, echo_own.clone());
        echo_thread = Some(thread::Builder::new().name("echo".into()).spawn(move || {
            pin(cpu).expect("pin the echo");
            if rt {
                let applied = forcecell::rt::Realtime::default().apply_to_cycle_thread();
                for r in applied.refusals() {
                    eprintln!("warning: echo: {r}");
                }
            }
            echo_server(sock, d, own);
        })?);
        Some(addr)
    } else {
        None
    };
    let driver: Arc<Mutex<Option<DriverLatency>>> = Arc::default();
    let (cell_addr, world, looping) =
        match o.cell.as_str() {
            "none" => (None, None, None),
            "run" => {
                let cfg = forcecell::cell::CellConfig::from_toml(CELL, "cell.toml")?;
                let tuning = cfg.tuning()?;
                let mut lc = cfg.link_config(&tuning)?;
                // The stand-in may pause between warm-up and timing (a slow machine): 1 s watchdog.
                lc.watchdog_cycles = 250;
                // The cell file must name a real port; the benchmark lets the OS choose a free one.
                lc.bind = Some(SocketAddr::from((Ipv4Addr::LOCALHOST, 0)));
                // `--spin-us`: the link's `spin` (robot.spin_us of a cell file).
                lc.spin = Duration::from_micros(o.spin_us);
                let mut link = RsiLink::bind(lc)?;
                let addr = link.local_addr()?;
                let world = spring_world();
                let sensor = RunSensor::open(&o.sensor, &world)?;
                let recorder = if o.record {
                    let (tx, rec) = forcecell::recorder::start(
                        &dir.join("run.mcap"),
                        forcecell::recorder::RecorderOptions::default(),
                        None,
                    )?;
                    Some((tx, rec))
                } else {
                    None
                };
                let (cpu, driver, rt) = (o.loop_cpu, driver.clone(), o.realtime);
                let h = thread::Builder::new().name("loop".into()).spawn(
                    move || -> Result<String> {
                        pin(cpu)?;
                        if rt {
                            // As `run` does on its cycle's thread before the first cycle.
                            let applied =
                                forcecell::rt::Realtime::default().apply_to_cycle_thread();
                            println!("loop: {applied}");
                            for r in applied.refusals() {
                                eprintln!("warning: {r}");
                            }
                        }
                        let stop = AtomicBool::new(false);
                        let (tx, rec) = recorder.map_or((None, None), |(t, r)| (Some(t), Some(r)));
                        let out = forcecell::cell::run_cell_recorded(
                            &cfg, &tuning, &mut link, sensor, &stop, tx,
                        )?;
                        let d = link.diagnostics();
                        *driver.lock().unwrap() =
                            Some((d.latency.clone(), Some(d.before_send.clone())));
                        let recorded = rec.map(|r| r.finish(Vec::new())).transpose()?;
                        Ok(format!(
                            "{}; {} cycles, {} sensor faults, {} limited; recorded {}",
                            out.ended,
                            out.stats.cycles,
                            out.stats.sensor_faults,
                            out.stats.limited,
                            recorded.map_or("nothing".into(), |r| r.to_string())
                        ))
                    },
                )?;
                (Some(addr), Some(world), Some(h))
            }
            "external" => {
                let addr = free_port()?;
                let mut spec = forcecell::runner::RunSpec::new(
                    forcecell::scenario::Scenario::load("paper-fig9")?,
                    None,
                    Some("robust"),
                )?;
                // Long enough for every cycle the stand-in sends; it ends the run.
                spec.scenario.duration = (o.warmup + o.cycles + 10) as f64 * 0.004;
                let args = forcecell::args::RsiArgs {
                    external_robot: Some(addr),
                    ..forcecell::args::RsiArgs::default()
                };
                let (o2, driver) = (o.clone(), driver.clone());
                let mcap = dir.join("external.mcap");
                let h = thread::Builder::new().name("loop".into()).spawn(
                    move || -> Result<String> {
                        let mut robot = forcecell::rsi::RobotSide::start(&spec, &args)?;
                        let recording = if o2.record {
                            let (tx, rec) = forcecell::runner::start_recording(
                                robot.spec(),
                                &mcap,
                                true,
                                None,
                            )?;
                            robot.record_to(tx);
                            Some(rec)
                        } else {
                            None
                        };
                        // The simulated sensor's threads (if any) are spawned by the run: pin only now.
                        pin(o2.loop_cpu)?;
                        let (run, wire) = match o2.sensor.as_str() {
                            "inproc" => robot.run_inproc_sensor(&mut |_| {})?,
                            "robotiq" => forcecell::robotiq::run_sim_with(robot, &mut |_| {})?,
                            "ati" => forcecell::ati::run_sim_with(robot, None, &mut |_| {})?,
                            k => bail!("--sensor {k}: inproc, robotiq or ati with --cell external"),
                        };
                        if let Some(forcecell::rsi::WireSummary::Rsi { diagnostics: d, .. }) = &wire
                        {
                            *driver.lock().unwrap() =
                                Some((d.latency.clone(), Some(d.before_send.clone())));
                        }
                        let recorded = recording.map(|r| r.finish(run.rows.clone())).transpose()?;
                        Ok(format!(
                            "{} rows, ended early: {:?}; recorded {}",
                            run.rows.len(),
                            run.ended_early,
                            recorded.map_or("nothing".into(), |r| r.to_string())
                        ))
                    },
                )?;
                // The link binds in the thread: let it.
                thread::sleep(Duration::from_millis(300));
                (Some(addr), None, Some(h))
            }
            "egm" | "egm-driver" => {
                let driver_only = o.cell == "egm-driver";
                let cfg = forcecell::cell::CellConfig::from_toml(CELL, "cell.toml")?;
                let tuning = cfg.tuning()?;
                let (limits, range) = forcecell::egm::cell_limits(&tuning.loop_cfg);
                let mut lc = abb_egm::LinkConfig::new(
                    SocketAddr::from((Ipv4Addr::LOCALHOST, 0)),
                    abb_egm::RobotFilter::Ip(Ipv4Addr::LOCALHOST.into()),
                );
                lc.limits = limits;
                lc.range = range;
                // As for `run`: a 1 s watchdog, the stand-in may pause between warm-up and timing.
                lc.watchdog_cycles = 250;
                lc.session_jump = 250;
                let mut link = abb_egm::EgmLink::bind(lc)?;
                let addr = link.local_addr()?;
                let world = spring_world();
                let sensor = RunSensor::open(&o.sensor, &world)?;
                let recorder = if o.record && !driver_only {
                    Some(forcecell::recorder::start(
                        &dir.join("egm.mcap"),
                        forcecell::recorder::RecorderOptions::default(),
                        None,
                    )?)
                } else {
                    None
                };
                let (cpu, driver) = (o.loop_cpu, driver.clone());
                let h = thread::Builder::new().name("loop".into()).spawn(
                    move || -> Result<String> {
                        pin(cpu)?;
                        if driver_only {
                            // The driver alone: decode, session, a fixed correction encoded.
                            use hal::RobotLink as _;
                            let mut n = 0u64;
                            let end = loop {
                                match link.next_cycle() {
                                    Ok(_) => {
                                        link.reply(&Correction::along_z(0.0))?;
                                        n += 1;
                                    }
                                    Err(e) => break e,
                                }
                            };
                            *driver.lock().unwrap() =
                                Some((link.diagnostics().latency.clone(), None));
                            drop(sensor);
                            return Ok(format!("the EGM driver alone: {n} cycles, ended: {end}"));
                        }
                        let stop = AtomicBool::new(false);
                        let (tx, rec) = recorder.map_or((None, None), |(t, r)| (Some(t), Some(r)));
                        let out = forcecell::cell::run_cell_recorded(
                            &cfg, &tuning, &mut link, sensor, &stop, tx,
                        )?;
                        *driver.lock().unwrap() = Some((link.diagnostics().latency.clone(), None));
                        let recorded = rec.map(|r| r.finish(Vec::new())).transpose()?;
                        Ok(format!(
                            "{}; {} cycles, {} sensor faults, {} limited; recorded {}",
                            out.ended,
                            out.stats.cycles,
                            out.stats.sensor_faults,
                            out.stats.limited,
                            recorded.map_or("nothing".into(), |r| r.to_string())
                        ))
                    },
                )?;
                (Some(addr), Some(world), Some(h))
            }
            c => bail!("--cell {c}: run, egm, egm-driver, external or none"),
        };
    if let Some(how) = &o.recorder_sched {
        // The writer thread exists once the cell started.
        thread::sleep(Duration::from_millis(200));
        resched_recorder(how)?;
    }
    pin(o.standin_cpu)?;
    if o.standin_priority > 0 {
        let applied = forcecell::rt::Realtime {
            priority: o.standin_priority,
            sensor_priority: 0,
            cpu: None,
            lock_memory: false,
        }
        .apply_to_cycle_thread();
        for r in applied.refusals() {
            eprintln!("warning: stand-in: {r}");
        }
    }
    let mut times = if o.cell.starts_with("egm") {
        let (cell, world) = cell_addr.zip(world).context("the EGM cell")?;
        stand_in_egm(&o, echo, cell, world)?
    } else {
        stand_in(&o, echo, cell_addr, world)?
    };
    done.store(true, Ordering::Relaxed);
    if let Some(h) = looping {
        let ended = h.join().map_err(|_| anyhow!("the loop panicked"))??;
        println!("cell: {ended}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    println!(
        "{} cell, {} sensor, {} cycles timed after {} warm-up, {}; loop CPU {:?}, stand-in {:?}, others {:?}",
        o.cell,
        o.sensor,
        o.cycles,
        o.warmup,
        if o.period.is_zero() {
            "lockstep".to_string()
        } else {
            format!("every {:?}", o.period)
        },
        o.loop_cpu,
        o.standin_cpu.or(o.other_cpu),
        o.other_cpu
    );
    println!(
        "{:<34} {:>8} {:>8} {:>8} {:>8}",
        "round trip (µs)", "p50", "p99", "p99.9", "max"
    );
    let mut rows = Vec::new();
    for (name, t) in [
        ("bare UDP echo", &mut times.echo),
        ("forcecell", &mut times.cell),
    ] {
        if t.is_empty() {
            continue;
        }
        let r = percentiles(t);
        println!(
            "{name:<34} {:>8.1} {:>8.1} {:>8.1} {:>8.1}",
            r[0], r[1], r[2], r[3]
        );
        rows.push(r);
    }
    if !o.period.is_zero() {
        let limit = u32::try_from(o.period.as_nanos()).unwrap_or(u32::MAX);
        let late = |t: &[u32]| t.iter().filter(|&&v| v > limit).count();
        println!(
            "late (reply after more than {:?}): echo {} of {}, forcecell {} of {}",
            o.period,
            late(&times.echo),
            times.echo.len(),
            late(&times.cell),
            times.cell.len()
        );
    }
    if let [e, f] = rows[..] {
        println!(
            "{:<34} {:>8.2} {:>8.2} {:>8.2} {:>8.2}",
            "ratio forcecell/echo",
            f[0] / e[0],
            f[1] / e[1],
            f[2] / e[2],
            f[3] / e[3]
        );
    }
    if let Some((l, b)) = driver.lock().unwrap().as_ref() {
        println!("forcecell's own receive→send, µs: {}", driver_line(l));
        if let Some(b) = b {
            println!("  of which before the send call, µs: {}", driver_line(b));
        }
    }
    if let (Some(own), Some(h)) = (echo_own, echo_thread) {
        done.store(true, Ordering::Relaxed);
        h.join().map_err(|_| anyhow!("the echo panicked"))?;
        let mut v = std::mem::take(&mut *own.lock().unwrap());
        if !v.is_empty() {
            let [p50, p99, p999, max] = percentiles(&mut v);
            println!(
                "the echo's own receive→send, µs: p50 {p50:.1}, p99 {p99:.1}, p99.9 {p999:.1}, max {max:.1} ({} replies)",
                v.len()
            );
        }
    }
    Ok(())
}
