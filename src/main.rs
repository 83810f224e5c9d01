//! `forcecell` — simulate a polishing cell, or deploy the controller on a real one.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Result;
use clap::{Args, Parser, Subcommand};
use forcecell::plot;
use forcecell::runner::RunSpec;
use forcecell::scenario::Scenario;
use indicatif::{ProgressBar, ProgressStyle};

#[derive(Parser)]
#[command(
    name = "forcecell",
    version,
    about = "Adaptive force control for robotic polishing cells",
    propagate_version = true
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the controller on a real cell from a config file (KUKA RSI + ATI CAN): record and plot.
    Run(RunArgs),
    /// Check a cell file before the first robot cycle: addresses, limits, the robot's files, the
    /// sensor and its tool model, the real-time permissions. Exit 0: ready.
    Check(CheckArgs),
    /// Fit the tool's weight and the sensor bias from static poses the robot holds (for the cell file's [gravity]).
    Calibrate(CalibrateArgs),
    /// Simulate a cell: run a scenario, print a summary, write DIR/NAME.csv and DIR/NAME.png.
    Sim(SimArgs),
    /// Write the robot-side KUKA RSI files (Ethernet config XML, KRL template) for this configuration.
    RsiConfig(forcecell::args::RsiConfigArgs),
    /// Write the ABB controller's side of EGM path correction: the UDPUC entry, the external-motion
    /// settings and a RAPID module (none of it has met a real IRC5).
    EgmConfig(forcecell::args::EgmConfigArgs),
    /// Plot a recorded trace (MCAP or CSV written by `sim` or `run`) to PNG and print its metrics.
    Plot(PlotArgs),
    /// Export an MCAP recording as a CSV trace (the columns `sim` and `run` write).
    Export(ExportArgs),
    /// What a recorded pass did to the part: removal depth and dwell along the path, the 2-D map, its
    /// uniformity; writes NAME-removal.mcap and NAME-removal.png beside the recording.
    Removal(RemovalArgs),
    /// Judge a tuning (damping ratio, delay margin) or propose impedance parameters for a stiffness range
    /// and the robot's loop.
    Tune(TuneArgs),
    /// Run the B scenarios on P1 and P2 with the robust and the paper's tuning (or the tunings given): one table, plots in OUT.
    BenchScenarios(BenchArgs),
    /// Run a simulated sensor alone: an ATI node on a CAN interface, or a Robotiq FT 300 on a
    /// pseudo-terminal.
    #[command(subcommand)]
    SimSensor(SimSensorKind),
    /// Talk to a force/torque sensor: identity, readings, bias.
    #[command(subcommand)]
    Sensor(SensorKind),
}

#[derive(Subcommand)]
enum SimSensorKind {
    /// ATI NETCANOEM node on a SocketCAN interface.
    Ati(SimSensorArgs),
    /// Robotiq FT 300 on a new pseudo-terminal: prints the device path to connect to.
    Robotiq(RobotiqSimArgs),
}

#[derive(Subcommand)]
enum SensorKind {
    /// ATI NETCANOEM over CAN.
    Ati(SensorArgs),
    /// Robotiq FT 300 over a serial port (Modbus RTU, then the 100 Hz stream).
    Robotiq(RobotiqSensorArgs),
}

#[derive(Args)]
struct RobotiqSimArgs {
    /// Also make PATH a symbolic link to the device (removed at exit).
    #[arg(long)]
    link: Option<PathBuf>,
    /// Constant Fz the sensor reports, N (within the FT 300's ±300 N range).
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true, value_parser = forcecell::args::ft300_force_n)]
    fz: f64,
    /// Force noise, N (standard deviation; torque noise is a hundredth of it in N·m).
    #[arg(long, default_value_t = 0.02, allow_negative_numbers = true, value_parser = forcecell::args::noise_n)]
    noise: f64,
    /// Stream from the start, like a sensor left streaming at power-up.
    #[arg(long)]
    streaming: bool,
    /// Stop after this many seconds (default: run until interrupted).
    #[arg(long, allow_negative_numbers = true, value_parser = forcecell::args::serve_seconds)]
    seconds: Option<f64>,
}

#[derive(Args)]
struct RobotiqSensorArgs {
    /// The serial device (e.g. /dev/ttyUSB0, or the path `sim-sensor robotiq` printed). Never scanned for.
    #[arg(long)]
    port: PathBuf,
    #[command(subcommand)]
    action: RobotiqCommand,
}

#[derive(Subcommand)]
enum RobotiqCommand {
    /// Identity (firmware, serial number, year) and the wrench registers, over Modbus.
    Info,
    /// Start the stream and print readings (N, N·m, zero removed), ten per second.
    Read {
        /// Lines to print.
        #[arg(long, default_value_t = 20)]
        count: u32,
        /// Take a zero first (hold the sensor still, unloaded).
        #[arg(long)]
        zero: bool,
    },
    /// Take a host-side zero over 50 frames and print it (refused while the wrench moves).
    Zero,
}

/// Which sensor on which CAN interface (shared by `sim-sensor ati` and `sensor ati`).
#[derive(Args)]
struct CanSensorArgs {
    /// CAN interface, e.g. can0 or vcan0.
    #[arg(long)]
    can: String,
    /// Base identifier (ids BASE<<4 | opcode).
    #[arg(long, default_value = "0x20", value_parser = forcecell::ati::parse_base)]
    base: ati_can::Base,
}

#[derive(Args)]
struct SimSensorArgs {
    #[command(flatten)]
    bus: CanSensorArgs,
    /// Constant Fz the node reports, N.
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true, value_parser = forcecell::args::sensor_force_n)]
    fz: f64,
    /// Gauge noise, counts (standard deviation).
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true, value_parser = forcecell::args::noise_counts)]
    noise: f64,
    /// Stop after this many seconds (default: run until interrupted).
    #[arg(long, allow_negative_numbers = true, value_parser = forcecell::args::serve_seconds)]
    seconds: Option<f64>,
    /// Answer from a recorded candump `-L` log (`sensor ati --can-log`, a cell's `record`) instead of
    /// a constant wrench: each request gets the log's next answer to it, after the recorded delay.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["fz", "noise"])]
    replay: Option<PathBuf>,
}

#[derive(Args)]
struct SensorArgs {
    #[command(flatten)]
    bus: CanSensorArgs,
    /// Bus bit rate, bit/s (sets the per-request deadline).
    #[arg(long, default_value_t = 1_000_000)]
    bitrate: u32,
    /// Calibration slot to select.
    #[arg(long, default_value_t = 0)]
    slot: u8,
    /// The board's turnaround allowance added to each request's wire time, µs (raise it on a loaded
    /// host or a virtual interface).
    #[arg(long, default_value_t = 300, allow_negative_numbers = true, value_parser = forcecell::args::turnaround_us)]
    turnaround_us: u64,
    /// Log every CAN frame sent and received to FILE in candump `-L` format (for can-utils).
    #[arg(long, value_name = "FILE")]
    can_log: Option<PathBuf>,
    #[command(subcommand)]
    action: SensorCommand,
}

#[derive(Subcommand)]
enum SensorCommand {
    /// Identity and calibration (firmware, serial, slot, matrix, counts per unit, units, status).
    Info,
    /// A stream of readings (N, N·m, bias removed), ten per second (one per poll below 10 Hz).
    Read {
        /// Lines to print.
        #[arg(long, default_value_t = 20)]
        count: u32,
        /// Poll rate, Hz.
        #[arg(long, default_value_t = 500.0, allow_negative_numbers = true, value_parser = forcecell::args::poll_rate_hz)]
        rate: f64,
        /// Take a bias first (hold the sensor still, unloaded).
        #[arg(long)]
        tare: bool,
    },
    /// Take a bias over 200 samples and print it (refused while saturated, in error or moving).
    Tare,
}

#[derive(Args)]
struct TuneArgs {
    /// Softest expected surface, N/m.
    #[arg(long, default_value_t = 10_000.0, allow_negative_numbers = true, value_parser = forcecell::args::stiffness_n_per_m)]
    k_min: f64,
    /// Stiffest expected surface, N/m.
    #[arg(long, default_value_t = 500_000.0, allow_negative_numbers = true, value_parser = forcecell::args::stiffness_n_per_m)]
    k_max: f64,
    /// The robot's loop by plant name (p0, p1, p2); --period/--lag/--delay override its values.
    #[arg(long, default_value = "p2", value_parser = ["p0", "p1", "p2"])]
    plant: String,
    /// Control period, s.
    #[arg(long, allow_negative_numbers = true, value_parser = forcecell::args::period_s)]
    period: Option<f64>,
    /// Position-loop lag, s.
    #[arg(long, allow_negative_numbers = true, value_parser = forcecell::args::lag_s)]
    lag: Option<f64>,
    /// Pure delay, s.
    #[arg(long, allow_negative_numbers = true, value_parser = forcecell::args::lag_s)]
    delay: Option<f64>,
    /// A tuning to judge (built-in name or TOML file); without it, parameters are proposed.
    #[arg(long)]
    tuning: Option<String>,
    /// Force set-point of a proposal, N.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true, value_parser = forcecell::args::set_point_n)]
    f_r: f64,
}

#[derive(Args)]
struct BenchArgs {
    /// Only scenarios whose name starts with one of these (e.g. b01 b05).
    only: Vec<String>,
    /// Output directory for the CSVs and plots.
    #[arg(long, default_value = "out/bench")]
    out: PathBuf,
    /// Tunings to run, built-in names or TOML files (repeat the flag; default: robust and paper).
    #[arg(long = "tuning", value_name = "TUNING")]
    tunings: Vec<String>,
    /// Exit with status 1 when a tuning other than the paper's misses a target.
    #[arg(long)]
    check: bool,
}

/// Where `--live` listens by default: loopback only.
const LIVE_DEFAULT: &str = "127.0.0.1:8765";

#[derive(Args)]
struct RunArgs {
    /// The cell configuration (TOML; see docs/deploying.md).
    #[arg(long, short)]
    config: PathBuf,
    /// Serve the run live over the Foxglove WebSocket protocol on ADDR (default 127.0.0.1:8765).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = LIVE_DEFAULT)]
    live: Option<std::net::SocketAddr>,
}

#[derive(Args)]
struct CheckArgs {
    /// The cell configuration (TOML), as for `run`.
    #[arg(long, short)]
    config: PathBuf,
}

#[derive(Args)]
struct CalibrateArgs {
    /// The cell configuration (TOML), as for `run`.
    #[arg(long, short)]
    config: PathBuf,
    /// Static orientations to collect.
    #[arg(long, default_value_t = 8)]
    poses: usize,
}

#[derive(Args)]
struct ExportArgs {
    /// The recording, MCAP.
    mcap: PathBuf,
    /// Write a CSV trace (the only export so far).
    #[arg(long, required = true)]
    csv: bool,
    /// The CSV to write (default: the recording's path with .csv).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Args)]
struct RemovalArgs {
    /// The recordings (MCAP from `sim` or `run`; each must carry the robot's poses).
    #[arg(required = true)]
    mcap: Vec<PathBuf>,
    /// Also draw the maps side by side into this PNG (one colour scale) and print a table of the
    /// figures, one row per recording.
    #[arg(long, value_name = "PNG")]
    compare: Option<PathBuf>,
    /// Where the `[removal]` table is (pad, tool speed, Preston's coefficient): a built-in scenario's
    /// name, or a scenario or cell TOML file.
    #[arg(long)]
    config: String,
    /// Output directory (default: the recording's).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Args)]
struct PlotArgs {
    /// The trace: an MCAP recording or a CSV.
    csv: PathBuf,
    /// The PNG to write (default: the CSV's path with .png).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Args)]
struct SimArgs {
    /// Built-in scenario name or a scenario TOML file.
    #[arg(long, short, default_value = "paper-fig9")]
    scenario: String,
    /// Robot inner loop: p0 (ideal), p1 (1 kHz, 10 ms lag, 4 ms delay), p2 (RSI-like 4 ms, 12 ms delay).
    #[arg(long, value_parser = ["p0", "p1", "p2"])]
    plant: Option<String>,
    /// Built-in tuning name or a tuning TOML file (default: the scenario's; with `--external-robot`,
    /// `robust` in place of `paper` or `impedance`: a real robot's 4 or 12 ms cycle is no place for them).
    #[arg(long)]
    tuning: Option<String>,
    /// Output directory.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// List the built-in scenarios and tunings, then exit.
    #[arg(long)]
    list: bool,
    /// Exit with status 1 when a scenario target is missed.
    #[arg(long)]
    check: bool,
    /// Force sensor: `ati` (the ATI CAN driver against a simulated node, in lockstep), `robotiq` (the FT 300
    /// driver against a simulated sensor over a pseudo-terminal, one frame per 10 ms of simulated time)
    /// or `inproc` (the world's sensor model read directly, no wire).
    #[arg(long, default_value = "ati", value_parser = ["ati", "robotiq", "inproc"])]
    sensor: String,
    /// Run the ATI sensor over this SocketCAN interface (e.g. vcan0) instead of the in-memory bus.
    #[arg(long)]
    can: Option<String>,
    /// Serve the run live over the Foxglove WebSocket protocol on ADDR (default 127.0.0.1:8765); the
    /// simulated controller then runs on the wall clock (--realtime).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = LIVE_DEFAULT)]
    live: Option<std::net::SocketAddr>,
    /// With `--live`: when the scenario ends (its files written), keep serving the live view until
    /// Ctrl-C (SIGINT) or SIGTERM.
    #[arg(long, requires = "live")]
    hold: bool,
    #[command(flatten)]
    robot: forcecell::args::RsiArgs,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Sim(a) => sim(a),
        Command::RsiConfig(a) => forcecell::rsi::rsi_config(&a).map(|(files, mapping)| {
            for f in files {
                println!("wrote {}", f.display());
            }
            for line in mapping {
                println!("{line}");
            }
            ExitCode::SUCCESS
        }),
        Command::EgmConfig(a) => forcecell::egm::egm_config(&a).map(|files| {
            for f in files {
                println!("wrote {}", f.display());
            }
            ExitCode::SUCCESS
        }),
        Command::Plot(a) => plot_trace(a),
        Command::Export(a) => export(a),
        Command::Removal(a) => removal(a),
        Command::Run(a) => forcecell::cell::run(&a.config, a.live).map(ExitCode::from),
        Command::Check(a) => forcecell::check::check(&a.config).map(|findings| {
            for f in &findings {
                println!("{f}");
            }
            let failed = findings
                .iter()
                .filter(|f| f.verdict == forcecell::check::Verdict::Fail)
                .count();
            if failed == 0 {
                println!("ready");
                ExitCode::SUCCESS
            } else {
                println!("not ready: {failed} problem(s) above");
                ExitCode::from(forcecell::stop::CHECK_FAILED)
            }
        }),
        Command::Calibrate(a) => {
            forcecell::cell::calibrate(&a.config, a.poses).map(|()| ExitCode::SUCCESS)
        }
        Command::Tune(a) => tune(a),
        Command::BenchScenarios(a) => bench_scenarios(a),
        Command::SimSensor(SimSensorKind::Ati(a)) if a.replay.is_some() => {
            forcecell::ati::sim_sensor_replay(
                &a.bus.can,
                a.bus.base,
                a.replay.as_deref().unwrap_or(std::path::Path::new("")),
                a.seconds,
            )
            .map(|()| ExitCode::SUCCESS)
        }
        Command::SimSensor(SimSensorKind::Ati(a)) => forcecell::ati::sim_sensor(
            &a.bus.can,
            a.bus.base,
            hal::Wrench::from_array([0.0, 0.0, a.fz, 0.0, 0.0, 0.0]),
            a.noise,
            a.seconds,
        )
        .map(|()| ExitCode::SUCCESS),
        Command::SimSensor(SimSensorKind::Robotiq(a)) => forcecell::robotiq::sim_sensor(
            a.link,
            hal::Wrench::from_array([0.0, 0.0, a.fz, 0.0, 0.0, 0.0]),
            a.noise,
            a.streaming,
            a.seconds,
        )
        .map(|()| ExitCode::SUCCESS),
        Command::Sensor(SensorKind::Ati(a)) => sensor(a),
        Command::Sensor(SensorKind::Robotiq(a)) => {
            let action = match a.action {
                RobotiqCommand::Info => forcecell::robotiq::SensorAction::Info,
                RobotiqCommand::Zero => forcecell::robotiq::SensorAction::Zero,
                RobotiqCommand::Read { count, zero } => {
                    forcecell::robotiq::SensorAction::Read { count, zero }
                }
            };
            forcecell::robotiq::sensor(&a.port, action).map(|()| ExitCode::SUCCESS)
        }
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(forcecell::stop::ERROR)
        }
    }
}

fn sim(mut a: SimArgs) -> Result<ExitCode> {
    if a.list {
        list()?;
        return Ok(ExitCode::SUCCESS);
    }
    let scenario = Scenario::load(&a.scenario)?;
    // A real robot's 4 or 12 ms cycle is no place for the paper's law or a fixed impedance: a dry run
    // keeps the scenario's tuning unless it is one of those (a curved part keeps its following).
    let tuning = match (&a.tuning, a.robot.external_robot) {
        (Some(t), _) => Some(t.as_str()),
        (None, Some(_))
            if !scenario.tuning_named
                || ["paper", "impedance"].contains(&scenario.tuning.as_str()) =>
        {
            Some("robust")
        }
        (None, _) => None,
    };
    let spec = RunSpec::new(scenario, a.plant.as_deref(), tuning)?;
    if a.sensor != "ati" && a.can.is_some() {
        anyhow::bail!("--can needs --sensor ati");
    }
    if let Some(iface) = &a.can {
        // The interface is a device: checked with the options, before anything is written.
        drop(ati_can::SocketCanTransport::open(iface)?);
    }
    // SIGINT/SIGTERM end the run early, not the process: the trace, plot and summary are written.
    forcecell::stop::install()?;
    println!(
        "forcecell sim: {} — {}",
        spec.scenario.name, spec.scenario.description
    );
    println!(
        "plant {} (period {} ms, lag {} ms, delay {} ms) · tuning {}{} · {} steps",
        spec.plant_label,
        spec.plant.period * 1e3,
        spec.plant.tau * 1e3,
        spec.plant.delay() * 1e3,
        spec.tuning.name,
        if tuning.is_none() && !spec.scenario.tuning_named {
            " (the scenario names none: the shipped default)"
        } else {
            ""
        },
        spec.steps()
    );
    if let (Some(client), forcecell::args::RobotBackend::Egm) =
        (a.robot.external_robot, a.robot.robot)
    {
        if a.robot.process_channels || a.robot.ethernet_config.is_some() {
            anyhow::bail!(
                "--process-channels and --ethernet-config are RSI options; with --robot egm the scenario's program runs on the simulated IRC5"
            );
        }
        let code = forcecell::egm::dry_run(&spec, client, a.robot.sensor_link.as_deref())?;
        return Ok(ExitCode::from(code));
    }
    if a.robot.sensor_link.is_some() {
        anyhow::bail!("--sensor-link is the EGM dry run's (--external-robot with --robot egm)");
    }
    let sensor = &spec.scenario.sensor;
    if sensor.bandwidth > 0.0 {
        println!(
            "sensor filtered at {} Hz: its force {:.2} ms older than the position it comes with",
            sensor.bandwidth,
            sensor.delay() * 1e3
        );
    }
    let mut bar = DelayedBar::new(Duration::from_millis(300));
    println!(
        "sensor: {}",
        match (a.sensor.as_str(), a.can.as_deref()) {
            ("inproc", _) => "in-process sensor model".to_string(),
            ("robotiq", _) =>
                "Robotiq FT 300 driver ↔ simulated sensor on a pseudo-terminal (100 Hz, lockstep)"
                    .to_string(),
            (_, None) => "ATI driver ↔ simulated node, in-memory CAN bus".to_string(),
            (_, Some(iface)) => format!("ATI driver ↔ simulated node on {iface}"),
        }
    );
    println!("robot: {}", a.robot.describe());
    let live = match a.live {
        Some(addr) => {
            if a.robot.robot != forcecell::args::RobotBackend::Inproc {
                a.robot.realtime = true;
            }
            let server = forcecell::live::LiveServer::bind(addr)?;
            println!(
                "live view: ws://{} (Foxglove: Open connection → Foxglove WebSocket)",
                server.local_addr()
            );
            Some(server)
        }
        None => None,
    };
    let mut robot = forcecell::rsi::RobotSide::start(&spec, &a.robot)?;
    // Every option, device and address checked: only now is the output directory created (and
    // removed again if still empty when the run fails); each output is written under a temporary
    // name and renamed when complete, so an earlier run's files survive a failed one.
    let out_dir = forcecell::output::OutDir::create(&a.out, "output directory (--out)")?;
    let mcap = a.out.join(format!("{}.mcap", spec.file_stem()));
    // Another run's results of the same name are replaced: said before the run, not found after it.
    let earlier: Vec<String> = ["mcap", "csv", "png"]
        .iter()
        .map(|ext| mcap.with_extension(ext))
        .chain(std::iter::once(
            a.out.join(format!("{}-pass.png", spec.file_stem())),
        ))
        .filter(|p| p.is_file())
        .map(|p| p.display().to_string())
        .collect();
    if !earlier.is_empty() {
        println!(
            "replacing an earlier run's {} (--out another directory keeps them)",
            earlier.join(", ")
        );
    }
    let (tx, recording) = forcecell::runner::start_recording(
        &spec,
        &mcap,
        robot.is_realtime(&a.robot),
        live.as_ref().map(forcecell::live::LiveServer::sink),
    )?;
    robot.record_to(tx);
    let (run, wire) = match a.sensor.as_str() {
        "inproc" => robot.run_inproc_sensor(&mut |frac| bar.update(frac))?,
        "robotiq" => forcecell::robotiq::run_sim_with(robot, &mut |frac| bar.update(frac))?,
        _ => forcecell::ati::run_sim_with(robot, a.can.as_deref(), &mut |frac| bar.update(frac))?,
    };
    bar.finish();
    if let Some(w) = &wire {
        w.print();
    }
    let recorded = recording.finish(run.rows.clone())?;
    out_dir.keep();
    let code = ExitCode::from(forcecell::report::sim(&spec, &run, &a.out, a.check)?);
    println!("recorded {recorded}");
    if let (Some(cfg), Some(_), None) = (
        &spec.scenario.removal,
        &spec.scenario.program,
        a.robot.external_robot,
    ) {
        match forcecell::removal::run(&mcap, cfg, None) {
            Ok(o) => println!("{}", forcecell::removal::report(&o)),
            Err(e) => eprintln!("removal map not written: {e:#}"),
        }
    }
    if let (Some(server), true) = (&live, a.hold) {
        // Every file is written: only the live view is left, until the operator ends it. A stop
        // asked during the run ends the command now.
        if !forcecell::stop::requested() {
            println!(
                "holding the live view on ws://{} (Ctrl-C ends)",
                server.local_addr()
            );
            while !forcecell::stop::requested() {
                std::thread::sleep(Duration::from_millis(50));
            }
            println!("live view closed");
        }
    }
    Ok(code)
}

fn tune(a: TuneArgs) -> Result<ExitCode> {
    let mut model = forcecell::tune::loop_of_plant(&a.plant)?;
    model.period = a.period.unwrap_or(model.period);
    model.lag = a.lag.unwrap_or(model.lag);
    model.delay = a.delay.unwrap_or(model.delay);
    let req = forcecell::tune::TuneRequest {
        k_min: a.k_min,
        k_max: a.k_max,
        model,
        tuning: a.tuning,
        f_r: a.f_r,
    };
    let (text, safe) = forcecell::tune::report(&req)?;
    println!("{text}");
    Ok(if safe {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

fn bench_scenarios(a: BenchArgs) -> Result<ExitCode> {
    let mut opts = forcecell::bench::BenchOptions {
        only: a.only,
        ..Default::default()
    };
    if !a.tunings.is_empty() {
        opts.tunings = a.tunings;
    }
    println!("bench-scenarios {}", forcecell::bench::WIRES);
    let prov = forcecell::bench::provenance(&opts);
    let rows = forcecell::bench::run(&opts, &a.out, &mut |label| eprintln!("running {label}"))?;
    print!("{}", forcecell::bench::table(&rows));
    let summary = forcecell::bench::write_summary(&a.out, prov, &rows)?;
    println!("plots and traces in {}", a.out.display());
    println!("summary {}", summary.display());
    let missed = rows.iter().any(|r| r.tuning != "paper" && !r.pass);
    Ok(if a.check && missed {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}

fn sensor(a: SensorArgs) -> Result<ExitCode> {
    let cfg = ati_can::Config {
        base: a.bus.base,
        bitrate: a.bitrate,
        slot: a.slot,
        turnaround: Duration::from_micros(a.turnaround_us),
        ..ati_can::Config::default()
    };
    let action = match a.action {
        SensorCommand::Info => forcecell::ati::SensorAction::Info,
        SensorCommand::Tare => forcecell::ati::SensorAction::Tare,
        SensorCommand::Read { count, rate, tare } => {
            forcecell::ati::SensorAction::Read { count, rate, tare }
        }
    };
    forcecell::ati::sensor(&a.bus.can, cfg, action, a.can_log.as_deref())?;
    Ok(ExitCode::SUCCESS)
}

fn export(a: ExportArgs) -> Result<ExitCode> {
    // The output is checked before anything is read or written: a CSV by its name, never the input.
    let csv = a
        .out
        .clone()
        .unwrap_or_else(|| a.mcap.with_extension("csv"));
    forcecell::output::require_extension(&csv, &["csv"], "a CSV export")?;
    forcecell::output::refuse_input(&csv, &a.mcap)?;
    let (rows, truncated) = forcecell::recorder::load_trace(&a.mcap)?;
    if let Some(why) = truncated {
        eprintln!(
            "note: {} ends early ({why}): exported up to its last complete record",
            a.mcap.display()
        );
    }
    forcecell::output::write_csv(&csv, &rows)?;
    println!("wrote {} ({} rows)", csv.display(), rows.len());
    Ok(ExitCode::SUCCESS)
}

fn removal(a: RemovalArgs) -> Result<ExitCode> {
    let cfg = forcecell::removal::load_config(&a.config)?;
    if let Some(png) = &a.compare {
        forcecell::output::require_extension(png, &["png"], "a plot")?;
        for m in &a.mcap {
            forcecell::output::refuse_input(png, m)?;
        }
    }
    let mut done = Vec::new();
    for m in &a.mcap {
        let o = forcecell::removal::run(m, &cfg, a.out.as_deref())?;
        println!("{}", forcecell::removal::report(&o));
        done.push((forcecell::removal::label(m), o));
    }
    if let Some(png) = &a.compare {
        print!("{}", forcecell::removal::table(&done));
        let maps: Vec<(&str, &scenario::removal::Removal)> =
            done.iter().map(|(l, o)| (l.as_str(), &o.removal)).collect();
        forcecell::plot::write_removal_png(png, &maps)?;
        println!("wrote {}", png.display());
    }
    Ok(ExitCode::SUCCESS)
}

fn plot_trace(a: PlotArgs) -> Result<ExitCode> {
    // The output is checked before anything is read or written: a PNG by its name, never the input.
    let png = a.out.clone().unwrap_or_else(|| a.csv.with_extension("png"));
    forcecell::output::require_extension(&png, &["png"], "a plot")?;
    forcecell::output::refuse_input(&png, &a.csv)?;
    let (rows, truncated) = forcecell::recorder::load_trace(&a.csv)?;
    if let Some(why) = truncated {
        eprintln!(
            "note: {} ends early ({why}): plotted up to its last complete record",
            a.csv.display()
        );
    }
    if rows.is_empty() {
        anyhow::bail!("{}: the trace has no rows", a.csv.display());
    }
    let m = forcecell::metrics::Metrics::compute(&rows, 0.0, f64::INFINITY);
    println!(
        "{} rows, {:.3} s: peak {:.2} N, settle {} s, steady-state error {:.4} N, RMS {:.4} N, {} contact losses",
        rows.len(),
        rows.last().map_or(0.0, |r| r.t),
        m.peak_force,
        m.settle_time,
        m.ss_error,
        m.rms_error,
        m.contact_losses
    );
    let title = a
        .csv
        .file_stem()
        .map_or("trace".into(), |s| s.to_string_lossy().into_owned());
    plot::write_png(&png, &title, &rows)?;
    println!("wrote {}", png.display());
    Ok(ExitCode::SUCCESS)
}

fn list() -> Result<()> {
    println!("built-in scenarios:");
    for s in Scenario::builtins()? {
        println!(
            "  {:<22} {:>5} s  {:<3} {:<10} {}",
            s.name,
            s.duration,
            s.plant.label(),
            s.tuning,
            s.description
        );
    }
    println!("built-in tunings:");
    for n in forcecell::scenario::builtin_tuning_names() {
        let t = forcecell::scenario::load_tuning(n)?;
        println!("  {:<22} {}", t.name, t.description);
    }
    Ok(())
}

/// A progress bar that appears only when a run takes more than a moment (and stderr is a terminal).
struct DelayedBar {
    start: Instant,
    delay: Duration,
    bar: Option<ProgressBar>,
}

impl DelayedBar {
    fn new(delay: Duration) -> Self {
        Self {
            start: Instant::now(),
            delay,
            bar: None,
        }
    }

    fn update(&mut self, frac: f64) {
        if self.bar.is_none() && self.start.elapsed() >= self.delay && frac < 1.0 {
            let b = ProgressBar::new(1000);
            b.set_style(
                ProgressStyle::with_template("{bar:40} {percent:>3}% simulated, eta {eta}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            self.bar = Some(b);
        }
        if let Some(b) = &self.bar {
            b.set_position((frac * 1000.0) as u64);
        }
    }

    fn finish(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}
