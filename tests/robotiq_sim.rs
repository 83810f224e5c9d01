//! A Robotiq FT 300 cell in simulation: the driver reads a simulated sensor over a real pseudo-terminal
//! (Modbus start-up through tokio-modbus, then the 100 Hz stream, one frame per 10 ms of simulated time)
//! while the robust law holds B1 on the RSI-like plant P2.

use forcecell::runner::RunSpec;
use forcecell::scenario::Scenario;

fn b1_on_p2(tuning: &str) -> forcecell::runner::RunResult {
    let spec = RunSpec::new(
        Scenario::load("b01-approach").unwrap(),
        Some("p2"),
        Some(tuning),
    )
    .unwrap();
    forcecell::robotiq::run_sim(&spec, &mut |_| {}).unwrap()
}

#[test]
fn a_robotiq_cell_holds_b1_on_p2_with_the_100_hz_tuning() {
    let spec = RunSpec::new(
        Scenario::load("b01-approach").unwrap(),
        Some("p2"),
        Some("robust-100hz"),
    )
    .unwrap();
    let run = b1_on_p2("robust-100hz");
    assert!(run.ended_early.is_none(), "{:?}", run.ended_early);
    assert_eq!(run.stats.sensor_faults, 0);
    let verdicts = run.verdicts(&spec.scenario.targets);
    assert!(!verdicts.is_empty());
    for v in &verdicts {
        assert!(
            v.pass,
            "{} = {} misses its target",
            v.target.metric, v.value
        );
    }
    // The force the loop saw came through the wire: 0.01 N quantisation, so the last value is a
    // multiple of it (the in-process model's is not).
    let f = run.rows.last().unwrap().f;
    assert!(((f * 100.0).round() - f * 100.0).abs() < 1e-6, "{f}");
}

/// Why the tuning changed: with the 1 kHz-sensor gain, every 10 ms frame is corrected by 2.5 commands,
/// and the approach overshoots more than with the slower gain.
#[test]
fn the_1_khz_gain_overshoots_more_with_a_100_hz_sensor() {
    let fast = b1_on_p2("robust");
    let slow = b1_on_p2("robust-100hz");
    assert!(
        fast.metrics.overshoot_pct > slow.metrics.overshoot_pct,
        "robust {} %, robust-100hz {} %",
        fast.metrics.overshoot_pct,
        slow.metrics.overshoot_pct
    );
}

fn cell_file(port: &str, extra: &str) -> String {
    format!(
        r#"
tuning = "robust-100hz"

[robot]
listen = "127.0.0.1:49152"
robot_ip = "127.0.0.1"

[sensor]
kind = "robotiq"
port = "{port}"
{extra}
"#
    )
}

/// `[sensor] kind = "robotiq"` in a cell file opens the FT 300 driver on that port (here: the simulated
/// sensor's pseudo-terminal), zeroes it when asked, and reads through the cell's sensor type.
#[test]
fn a_cell_file_with_a_robotiq_sensor_opens_and_reads_it() {
    use hal::ForceSensor;
    use sim::ft300::{Ft300Config, SimFt300};
    let device = SimFt300::spawn(
        Ft300Config {
            noise_force: 0.0,
            noise_torque: 0.0,
            ..Ft300Config::default()
        },
        |_t: core::time::Duration| hal::Wrench::from_array([0.0, 0.0, 8.0, 0.0, 0.0, 0.0]),
    )
    .unwrap();
    let path = device.path().display().to_string();
    let cfg = forcecell::cell::CellConfig::from_toml(&cell_file(&path, "zero = true"), "cell.toml")
        .unwrap();
    assert!(cfg.sensor.zero_at_start());
    let mut sensor = cfg.sensor.open(true, None).unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    let sample = loop {
        if let Ok(s) = sensor.read() {
            break s;
        }
        assert!(std::time::Instant::now() < deadline, "no sample");
        std::thread::sleep(std::time::Duration::from_millis(2));
    };
    assert!(sample.wrench.force.z.abs() < 1e-9, "zeroed: {sample:?}");
    assert_eq!(device.stats().starts, 1);
    // Its identity, as the start-up read it, for the run's provenance.
    let id = sensor.identity();
    assert_eq!(id.serial, "FTS-875704368");
    assert_eq!(id.firmware, "FTS-3.1.0");
}

/// A sensor found streaming is not asked for its identity (that would stop its stream): the
/// provenance says `unknown`, plainly.
#[test]
fn a_robotiq_sensor_found_streaming_has_an_unknown_identity() {
    use sim::ft300::{Ft300Config, SimFt300};
    let device = SimFt300::spawn(
        Ft300Config {
            streaming_at_start: true,
            ..Ft300Config::default()
        },
        |_t: core::time::Duration| hal::Wrench::from_array([0.0, 0.0, 8.0, 0.0, 0.0, 0.0]),
    )
    .unwrap();
    let path = device.path().display().to_string();
    let cfg = forcecell::cell::CellConfig::from_toml(&cell_file(&path, ""), "cell.toml").unwrap();
    let sensor = cfg.sensor.open(false, None).unwrap();
    assert_eq!(
        sensor.identity(),
        forcecell::cell::SensorIdentity::unknown()
    );
    assert_eq!(sensor.identity().serial, "unknown");
}

#[test]
fn a_robotiq_cell_file_with_bad_values_is_refused() {
    let bad_slave = cell_file("/dev/ttyUSB0", "slave = 0");
    let e = forcecell::cell::CellConfig::from_toml(&bad_slave, "cell.toml").unwrap_err();
    assert!(format!("{e:#}").contains("slave"), "{e:#}");
    let no_port = cell_file("", "");
    let e = forcecell::cell::CellConfig::from_toml(&no_port, "cell.toml").unwrap_err();
    assert!(format!("{e:#}").contains("port"), "{e:#}");
    let unknown = cell_file("/dev/ttyUSB0", "can = \"can0\"");
    assert!(forcecell::cell::CellConfig::from_toml(&unknown, "cell.toml").is_err());
}
