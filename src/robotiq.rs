//! The Robotiq FT 300 in the application: `forcecell sim --sensor robotiq` (the driver against a simulated
//! sensor over a pseudo-terminal, in lockstep with the plant), the simulated sensor on its own
//! (`forcecell sim-sensor robotiq`) and a real sensor's tools (`forcecell sensor robotiq`).

use core::time::Duration;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use hal::Wrench;
use robotiq::codec::SLAVE;
use robotiq::sensor::{open_stream_port, stop_stream, stream_running};
use robotiq::{Config, Ft300, Health, LinkConfig, Lockstep, ZeroConfig};
use sim::ati_node::WorldSource;
use sim::ft300::{Ft300Config, Pace, SimFt300};

use crate::rsi::{RobotSide, WireSummary};
use crate::runner::{RunResult, RunSpec};

/// The FT 300's frame period.
pub const PERIOD: Duration = Duration::from_millis(10);

/// Run a scenario with the in-process robot and the FT 300 driver reading a simulated sensor over a
/// pseudo-terminal: Modbus start-up (identity, wrench registers, the 410 write) through tokio-modbus on
/// both ends, then the raw stream, one frame per 10 ms of simulated time from the world's sensor model.
pub fn run_sim(spec: &RunSpec, progress: &mut dyn FnMut(f64)) -> Result<RunResult> {
    run_sim_with(RobotSide::inproc(spec), progress).map(|(run, _)| run)
}

/// [`run_sim`] with any robot side.
pub fn run_sim_with(
    robot: RobotSide,
    progress: &mut dyn FnMut(f64),
) -> Result<(RunResult, Option<WireSummary>)> {
    let world = robot.world().clone();
    // The world's sensor model supplies the noise; the device adds its quantisation.
    let device = Arc::new(
        SimFt300::spawn(
            Ft300Config {
                noise_force: 0.0,
                noise_torque: 0.0,
                pace: Pace::Manual,
                ..Ft300Config::default()
            },
            WorldSource::measured(world.clone()),
        )
        .context("simulated FT 300")?,
    );
    let path = device.path().to_owned();
    let (id, _) = robotiq::modbus::startup(&path, SLAVE, Duration::from_millis(500), true)
        .with_context(|| format!("FT 300 start-up on {}", path.display()))?;
    let port = open_stream_port(&path)?;
    let clock_world = world.clone();
    let trigger = Arc::clone(&device);
    let sensor = Lockstep::new(
        port,
        LinkConfig::default(),
        PERIOD,
        move || Duration::from_secs_f64(sim::world::lock(&clock_world).time().max(0.0)),
        move || trigger.emit(),
    );
    eprintln!(
        "FT 300 {} (serial {}) on {}",
        id.firmware_text(),
        id.serial_text(),
        path.display()
    );
    robot.run(sensor, progress)
}

/// `forcecell sim-sensor robotiq`: the simulated FT 300 alone, streaming a constant wrench plus noise at
/// 100 Hz after the 410 write (or from the start), until `seconds` have passed or Ctrl-C.
pub fn sim_sensor(
    link: Option<PathBuf>,
    wrench: Wrench,
    noise: f64,
    streaming: bool,
    seconds: Option<f64>,
) -> Result<()> {
    if let Some(s) = seconds
        && !(s.is_finite() && s > 0.0)
    {
        bail!("--seconds must be positive, got {s}");
    }
    if !(noise.is_finite() && noise >= 0.0) {
        bail!("--noise must be ≥ 0 N, got {noise}");
    }
    let device = SimFt300::spawn(
        Ft300Config {
            noise_force: noise,
            noise_torque: noise / 100.0,
            streaming_at_start: streaming,
            link,
            ..Ft300Config::default()
        },
        move |_t: Duration| wrench,
    )
    .context("simulated FT 300")?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::Release))
            .context("cannot install the Ctrl-C handler")?;
    }
    // The path alone on the first line, for scripts.
    println!("{}", device.link().unwrap_or(device.path()).display());
    eprintln!(
        "simulated Robotiq FT 300 on {} (Modbus RTU slave {SLAVE}, 19200 8N1; registers 180..185, 190..192, 410, 500..502, 510..513, 514), Fz {} N{}; Ctrl-C ends it",
        device.path().display(),
        wrench.force.z,
        if streaming {
            ", streaming from the start"
        } else {
            ""
        }
    );
    let t0 = Instant::now();
    while !stop.load(Ordering::Acquire) && seconds.is_none_or(|s| t0.elapsed().as_secs_f64() < s) {
        std::thread::sleep(Duration::from_millis(20));
    }
    let s = device.stats();
    device.stop().context("simulated FT 300")?;
    eprintln!(
        "answered {} Modbus requests; {} stream starts, {} stops, {} frames",
        s.modbus_requests, s.starts, s.stops, s.frames
    );
    Ok(())
}

/// What `forcecell sensor robotiq` does.
#[derive(Clone, Copy, Debug)]
pub enum SensorAction {
    /// Identity and the wrench registers (Modbus only; a running stream is stopped first).
    Info,
    /// A stream of readings.
    Read {
        /// Lines to print.
        count: u32,
        /// Zero first.
        zero: bool,
    },
    /// Take a host-side zero and print it.
    Zero,
}

/// The zero window used by `sensor robotiq zero` and `run`'s start-up zero: 50 frames (0.5 s).
pub fn zero_config() -> ZeroConfig {
    ZeroConfig::default()
}

/// `forcecell sensor robotiq --port PATH`.
pub fn sensor(port: &Path, action: SensorAction) -> Result<()> {
    match action {
        SensorAction::Info => info(port),
        SensorAction::Zero => {
            let ft = open(port)?;
            let bias = ft.zero(zero_config())?;
            let b = bias.to_array();
            println!(
                "zero (N, N·m): Fx {:.3} Fy {:.3} Fz {:.3} Mx {:.4} My {:.4} Mz {:.4}",
                b[0], b[1], b[2], b[3], b[4], b[5]
            );
            println!(
                "the zero lives in this process only (the FT 300 has no zero command); `sensor robotiq read --zero` takes it again"
            );
            Ok(())
        }
        SensorAction::Read { count, zero } => {
            let ft = open(port)?;
            if zero {
                let b = ft.zero(zero_config())?;
                println!("zero (N): {:.3?}", &b.to_array()[..3]);
            }
            stream(ft, count)
        }
    }
}

fn open(port: &Path) -> Result<Ft300> {
    let ft =
        Ft300::open(Config::new(port)).with_context(|| format!("FT 300 on {}", port.display()))?;
    match ft.identity() {
        Some(id) => eprintln!(
            "FT 300 {} serial {} ({}), stream started",
            id.firmware_text(),
            id.serial_text(),
            id.year
        ),
        None => eprintln!("FT 300 already streaming: identity not read (no Modbus exchange)"),
    }
    // Start-up ends at the 410 write: wait (bounded) for the first frame.
    let t0 = Instant::now();
    while ft.health() == Health::Waiting && t0.elapsed() < Duration::from_millis(200) {
        std::thread::sleep(Duration::from_millis(2));
    }
    Ok(ft)
}

fn info(port: &Path) -> Result<()> {
    let was_streaming = stream_running(port, Duration::from_millis(60))?;
    if was_streaming {
        println!("stream           running at start: stopped it (0xFF × 50) to read the registers");
        stop_stream(port)?;
        std::thread::sleep(Duration::from_millis(60));
    }
    let (id, w) = robotiq::modbus::startup(port, SLAVE, Duration::from_millis(300), false)
        .with_context(|| format!("FT 300 on {}", port.display()))?;
    println!("firmware         {}", id.firmware_text());
    println!("serial           {}", id.serial_text());
    println!("production year  {}", id.year);
    let a = w.to_wrench().to_array();
    println!(
        "wrench (180..185) Fx {:.2} Fy {:.2} Fz {:.2} N, Mx {:.3} My {:.3} Mz {:.3} N·m",
        a[0], a[1], a[2], a[3], a[4], a[5]
    );
    Ok(())
}

fn stream(mut ft: Ft300, count: u32) -> Result<()> {
    // The FT 300 streams at 100 Hz.
    let secs = crate::readout::print_readings(
        &mut ft,
        count,
        crate::readout::reading_interval(100.0),
        Ft300::health,
    )
    .as_secs_f64();
    let c = ft.counters();
    println!(
        "{} frames ({:.1} Hz), {} CRC errors ({:.2} %), {} bytes skipped, {} stale, {} lost",
        c.frames,
        c.frames as f64 / secs.max(1e-9),
        c.crc_errors,
        c.crc_error_rate() * 100.0,
        c.skipped,
        c.stale_events,
        c.lost_events
    );
    if let Some(e) = ft.reader_error() {
        bail!("the stream reader stopped: {e}");
    }
    Ok(())
}
