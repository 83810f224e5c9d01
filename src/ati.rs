//! The ATI NETCANOEM sensor in the application: the default force sensor of `forcecell sim` (the driver
//! talking to a simulated node over the in-memory bus, or over a SocketCAN interface), the simulated node
//! on its own (`forcecell sim-sensor ati`) and a real sensor's tools (`forcecell sensor ati`).

use core::time::Duration;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result, anyhow, bail};
use ati_can::{
    AtiSensor, Base, BiasConfig, CanTransport, Config, DeviceInfo, Driver, Health, Lockstep,
    MemBus, SocketCanTransport,
};
use hal::Wrench;
use sim::ati_node::{AtiNode, NodeConfig, SharedNode, WorldSource, serve};

use crate::rsi::{RobotSide, WireSummary};
use crate::runner::{RunResult, RunSpec};

/// Parse a base identifier written as `0x20`, `20h` or decimal.
pub fn parse_base(s: &str) -> Result<Base, String> {
    let v = if let Some(hex) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        u8::from_str_radix(hex, 16)
    } else {
        s.parse::<u8>()
    }
    .map_err(|e| format!("base {s:?}: {e}"))?;
    Base::new(v).ok_or_else(|| format!("base {s} is above 0x7F"))
}

/// Driver settings for a simulated sensor on `can` (`None`: the in-memory bus).
fn sim_driver_config(base: Base, can: Option<&str>) -> Config {
    Config {
        base,
        // vcan has no bit rate, only scheduling (and a slow guest under User-Mode Linux): allow 20 ms
        // per answer there. Lockstep does not care about the period, only about getting the answer.
        turnaround: if can.is_some() {
            Duration::from_millis(20)
        } else {
            Config::default().turnaround
        },
        ..Config::default()
    }
}

/// Run a scenario with the in-process robot and the ATI driver in lockstep with a simulated node that
/// reads the world's sensor model: over the in-memory bus (virtual clock, deterministic) or, with `can`,
/// over that SocketCAN interface (the node answers from its own socket in a thread).
pub fn run_sim(
    spec: &RunSpec,
    can: Option<&str>,
    progress: &mut dyn FnMut(f64),
) -> Result<RunResult> {
    run_sim_with(RobotSide::inproc(spec), can, progress).map(|(run, _)| run)
}

/// [`run_sim`] with any robot side (the in-process robot, RSI over loopback, an external RSI client).
pub fn run_sim_with(
    robot: RobotSide,
    can: Option<&str>,
    progress: &mut dyn FnMut(f64),
) -> Result<(RunResult, Option<WireSummary>)> {
    let world = robot.world().clone();
    let base = Base::DEFAULT;
    let node = SharedNode::new(
        AtiNode::new(
            NodeConfig {
                base,
                ..NodeConfig::default()
            },
            WorldSource::measured(world.clone()),
        )
        .map_err(|e| anyhow!("simulated ATI node: {e}"))?,
    );
    let cfg = sim_driver_config(base, can);
    match can {
        None => {
            let bus = MemBus::with_virtual_clock();
            bus.attach(node);
            let mut driver = Driver::new(bus.port(), cfg)?;
            driver
                .start()
                .context("ATI start-up on the in-memory bus")?;
            robot.run(Lockstep(driver), progress)
        }
        Some(iface) => {
            let stop = Arc::new(AtomicBool::new(false));
            let node_port = SocketCanTransport::open(iface)?;
            let serving = {
                let stop = Arc::clone(&stop);
                std::thread::spawn(move || serve(&node, node_port, &stop))
            };
            let result = (|| {
                let mut driver = Driver::new(SocketCanTransport::open(iface)?, cfg)?;
                driver
                    .start()
                    .with_context(|| format!("ATI start-up on {iface}"))?;
                robot.run(Lockstep(driver), progress)
            })();
            stop.store(true, Ordering::Release);
            serving
                .join()
                .map_err(|_| anyhow!("the simulated ATI node thread panicked"))?
                .with_context(|| format!("simulated ATI node on {iface}"))?;
            result
        }
    }
}

/// `forcecell sim-sensor ati`: the simulated node alone on `iface`, answering with a constant wrench plus
/// noise until `seconds` have passed (forever when `None`).
pub fn sim_sensor(
    iface: &str,
    base: Base,
    wrench: Wrench,
    noise_counts: f64,
    seconds: Option<f64>,
) -> Result<()> {
    let node = SharedNode::new(
        AtiNode::new(
            NodeConfig {
                base,
                noise_counts,
                ..NodeConfig::default()
            },
            move |_t: Duration| wrench,
        )
        .map_err(|e| anyhow!("simulated ATI node: {e}"))?,
    );
    let transport = SocketCanTransport::open(iface)?;
    let stop = stop_after(seconds)?;
    println!(
        "simulated ATI NETCANOEM node on {iface}, base {base} (ids 0x{:03X}..=0x{:03X}), Fz {} N; Ctrl-C ends it",
        base.id(0),
        base.id(0xF),
        wrench.force.z
    );
    serve(&node, transport, &stop).with_context(|| format!("serving on {iface}"))?;
    let n = node.lock();
    println!("answered {} requests ({} polls)", n.requests(), n.polls());
    Ok(())
}

/// A flag that a thread sets after `seconds` (never when `None`).
fn stop_after(seconds: Option<f64>) -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    if let Some(s) = seconds {
        if !(s.is_finite() && s > 0.0) {
            bail!("--seconds must be positive, got {s}");
        }
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || {
            std::thread::sleep(Duration::from_secs_f64(s));
            stop.store(true, Ordering::Release);
        });
    }
    Ok(stop)
}

/// `forcecell sim-sensor ati --replay LOG`: answer the driver on `iface` from a recorded candump log
/// (see [`crate::candump::Replay`]) until `seconds` have passed (forever when `None`).
pub fn sim_sensor_replay(
    iface: &str,
    base: Base,
    log: &std::path::Path,
    seconds: Option<f64>,
) -> Result<()> {
    let records = crate::candump::read_log(log)?;
    let mut replay = crate::candump::Replay::from_log(&records, base)
        .with_context(|| format!("{}", log.display()))?;
    let transport = SocketCanTransport::open(iface)?;
    let stop = stop_after(seconds)?;
    println!(
        "replaying {} on {iface}, base {base}: {} recorded polls, answered as the driver asks; Ctrl-C ends it",
        log.display(),
        replay.recorded_polls
    );
    sim::ati_node::serve_responder(&mut replay, base, transport, &stop)
        .with_context(|| format!("serving on {iface}"))?;
    println!(
        "answered {} of {} recorded polls{}{}",
        replay.replayed_polls,
        replay.recorded_polls,
        if replay.past_end > 0 {
            format!(
                "; {} polls after the log's end went unanswered",
                replay.past_end
            )
        } else {
            String::new()
        },
        if replay.unknown > 0 {
            format!(
                "; {} requests the log never saw went unanswered",
                replay.unknown
            )
        } else {
            String::new()
        }
    );
    Ok(())
}

/// What `forcecell sensor ati` does.
#[derive(Clone, Copy, Debug)]
pub enum SensorAction {
    /// Identity and calibration.
    Info,
    /// A stream of readings.
    Read {
        /// Lines to print.
        count: u32,
        /// Poll rate, Hz.
        rate: f64,
        /// Take a bias first.
        tare: bool,
    },
    /// Take a bias and print it.
    Tare,
}

fn print_info(info: &DeviceInfo) {
    println!("firmware        {}", info.firmware);
    println!(
        "serial          {}",
        info.serial_text().unwrap_or_else(|| "(no answer)".into())
    );
    println!("calibration     slot {}", info.slot);
    let c = &info.calibration;
    println!(
        "counts per unit force {}{}, torque {}",
        c.counts_per_force,
        if info.counts_assumed {
            " (assumed: firmware < 3.7)"
        } else {
            ""
        },
        c.counts_per_torque
    );
    println!(
        "units           {:?}, {:?}{}",
        c.force_unit,
        c.torque_unit,
        if info.units_assumed {
            " (assumed: no answer)"
        } else {
            ""
        }
    );
    println!("matrix (rows Fx Fy Fz Tx Ty Tz, columns sg0..sg5):");
    for row in &c.matrix {
        let cells: Vec<String> = row.iter().map(|v| format!("{v:>12.4}")).collect();
        println!("  {}", cells.join(" "));
    }
}

/// Poll until the driver has its first sample (start-up ends before the first poll), at most
/// `POLLS` polls, each bounded by the request deadline. `Err` says why no sample came.
pub fn first_sample<T: CanTransport>(driver: &mut Driver<T>) -> Result<()> {
    if !poll_until(driver, |h| h != Health::Waiting)? {
        bail!(
            "the sensor answered start-up but no poll in {POLLS} (check the bus and the turnaround)"
        );
    }
    Ok(())
}

/// How many polls [`first_sample`] and a tare's retry wait for a sample.
const POLLS: usize = 20;

/// Step the driver until `done(health)`, at most [`POLLS`] polls; whether it got there.
fn poll_until<T: CanTransport>(
    driver: &mut Driver<T>,
    done: impl Fn(Health) -> bool,
) -> Result<bool> {
    for _ in 0..POLLS {
        if done(driver.health()) {
            return Ok(true);
        }
        driver.step()?;
    }
    Ok(done(driver.health()))
}

/// One line naming a sensor: firmware, serial, calibration slot, units.
pub fn describe(info: &DeviceInfo) -> String {
    format!(
        "ATI firmware {}, serial {}, calibration slot {}, units {:?}/{:?}",
        info.firmware,
        info.serial_text().unwrap_or_else(|| "(no answer)".into()),
        info.slot,
        info.calibration.force_unit,
        info.calibration.torque_unit
    )
}

/// The bias window used by `sensor ati tare` and `run`'s start-up tare.
pub fn bias_config() -> BiasConfig {
    BiasConfig {
        window: 200,
        max_spread: 400,
    }
}

/// How many windows [`tare`] takes before a bus that keeps losing samples refuses the bias.
pub const TARE_WINDOWS: u32 = 3;

/// Take the bias over [`bias_config`]'s window. A window that missed a sample (one poll unanswered:
/// a bus hiccup) is taken again, up to [`TARE_WINDOWS`] windows, each retry said on stderr; a moving
/// or saturated tool, a sensor fault or a sensor gone are refused at once, as the driver says.
pub fn tare<T: CanTransport>(driver: &mut Driver<T>) -> Result<[f64; 6]> {
    let mut window = 1;
    loop {
        match driver.tare(bias_config()) {
            Ok(bias) => return Ok(bias),
            Err(ati_can::AtiError::Bias(ati_can::BiasError::NoAnswer)) if window < TARE_WINDOWS => {
                window += 1;
                eprintln!(
                    "bias: a sample was missing in the window; taking it again ({window} of {TARE_WINDOWS})"
                );
                // The driver's health may have left Ok on the miss: a bias starts on a good sample.
                if !poll_until(driver, |h| h == Health::Ok)? {
                    bail!(
                        "bias refused: no good sample in {POLLS} polls after a missed one (health {:?})",
                        driver.health()
                    );
                }
            }
            Err(ati_can::AtiError::Bias(ati_can::BiasError::NoAnswer)) => {
                bail!(
                    "bias refused: samples were missing in each of {TARE_WINDOWS} windows of {} (check the bus and the turnaround)",
                    bias_config().window
                )
            }
            Err(e) => return Err(e.into()),
        }
    }
}

/// `forcecell sensor ati`: talk to a real sensor (or the simulated node) on `iface`.
/// With `can_log`, every frame sent and received is logged there in candump `-L` format.
pub fn sensor(
    iface: &str,
    mut cfg: Config,
    action: SensorAction,
    can_log: Option<&std::path::Path>,
) -> Result<()> {
    if let SensorAction::Read { rate, .. } = action
        && rate.is_finite()
        && rate > 0.0
    {
        // A sample is stale after three missed polls.
        cfg.stale_after = cfg.stale_after.max(Duration::from_secs_f64(3.0 / rate));
    }
    let transport = crate::candump::open_logged(iface, can_log)?;
    let mut driver = Driver::new(transport, cfg)?;
    let info = driver
        .start()
        .with_context(|| format!("ATI sensor at base {} on {iface}", cfg.base))?;
    // Start-up ends before the first poll: get a sample (or the reason there is none).
    if let Err(e) = first_sample(&mut driver)
        && !matches!(action, SensorAction::Info)
    {
        return Err(e);
    }
    match action {
        SensorAction::Info => {
            print_info(&info);
            println!("status          {}", driver.status());
            println!("health          {:?}", driver.health());
            Ok(())
        }
        SensorAction::Tare => {
            let bias = tare(&mut driver)?;
            println!("bias (counts, sg0..sg5): {bias:.1?}");
            println!(
                "the bias lives in this process only; `sensor ati read --tare` takes it again"
            );
            Ok(())
        }
        SensorAction::Read { count, rate, tare } => {
            if tare {
                let bias = self::tare(&mut driver)?;
                println!("bias (counts): {bias:.1?}");
            }
            stream(driver, count, rate)
        }
    }
}

fn stream<T: CanTransport + Send + 'static>(
    driver: Driver<T>,
    count: u32,
    rate: f64,
) -> Result<()> {
    let mut sensor = AtiSensor::spawn(driver, rate)?;
    let every = crate::readout::reading_interval(rate);
    crate::readout::print_readings(&mut sensor, count, every, AtiSensor::health);
    let c = sensor.counters();
    println!(
        "{} samples, {} timeouts, {} malformed, {} out of sequence, {} device errors, {} saturated",
        c.samples, c.timeouts, c.malformed, c.sequence_errors, c.device_errors, c.saturated
    );
    if sensor.health() == Health::BusOff {
        bail!("the CAN controller is bus-off");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runner::run_inproc;
    use crate::scenario::Scenario;

    /// The default sensor path (driver ↔ node over the in-memory bus, lockstep) measures what the
    /// in-process sensor measures, up to the ATI count quantisation (0.01 N with the node's calibration).
    #[test]
    fn the_ati_path_matches_the_in_process_sensor() {
        let spec = RunSpec::new(Scenario::load("paper-fig9").unwrap(), None, None).unwrap();
        let ati = run_sim(&spec, None, &mut |_| {}).unwrap();
        let inproc = run_inproc(&spec, &mut |_| {}).unwrap();
        assert_eq!(ati.rows.len(), inproc.rows.len());
        assert_eq!(ati.stats.sensor_faults, 0);
        assert!(ati.ended_early.is_none());
        let worst = ati
            .rows
            .iter()
            .zip(&inproc.rows)
            .map(|(a, b)| (a.f - b.f).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.05, "largest difference {worst} N");
        assert!((ati.metrics.ss_error - inproc.metrics.ss_error).abs() < 0.01);
    }

    #[test]
    fn base_parsing() {
        assert_eq!(parse_base("0x20"), Ok(Base::DEFAULT));
        assert_eq!(parse_base("32"), Ok(Base::DEFAULT));
        assert!(parse_base("0x80").unwrap_err().contains("above"));
        assert!(parse_base("zz").is_err());
    }
}
