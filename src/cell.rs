//! `forcecell run`: the controller on a real cell, wired from one TOML file — the robot link (KUKA RSI,
//! or ABB EGM path correction with `kind = "abb-egm"`: [`crate::robot`]), the ATI sensor polled over
//! SocketCAN, gravity compensation, a tuning — recorded to MCAP (CSV exported) and plotted.
//!
//! ```toml
//! tuning = "robust"                 # built-in name or a tuning file
//! duration = 60.0                   # s of robot time; omit to run until the robot stops sending
//! record = "recordings"             # record/run-<unix time>.mcap, streamed (+ .csv, .png exported from it; .candump.log: CAN traffic)
//!
//! [robot]
//! listen = "192.168.1.100:49152"    # IP_NUMBER:PORT of the robot's Ethernet config
//! robot_ip = "192.168.1.10"         # datagrams from anywhere else are dropped and counted
//! ethernet_config = "forcecell_rsi.xml"   # optional: the robot's file (default: `forcecell rsi-config`'s layout)
//! mode = "absolute"                 # or "relative"
//! cycle_ms = 4                      # 4 (#IPO_FAST) or 12 (#IPO)
//! watchdog_cycles = 25
//! poscorr_mm = 5.0                  # the robot's POSCORR translation limit …
//! poscorrmon_mm = 6.0               # … and POSCORRMON's
//! # poscorr_deg = 15.0              # rotation limits (RSI's 5°/6° if absent): an orientation-following
//! # poscorrmon_deg = 18.0           # tuning ([orientation]) needs them at or above its own
//! max_speed = 3.0                   # m/s: a pose jump faster than this is a counted fault
//!
//! [sensor]
//! kind = "ati"
//! can = "can0"
//! base = 0x20
//! bitrate = 1000000
//! slot = 0
//! poll_hz = 1000.0
//! tare = true                       # bias at start: the tool must be in free air and still
//! turnaround_us = 300               # optional: the board's answer allowance per request
//! # or: kind = "robotiq", port = "/dev/ttyUSB0", slave = 9, zero = true (Robotiq FT 300)
//!
//! [gravity]                         # optional: the tool model (least-squares fit, controller::gravity)
//! signed_mass = 2.0                 # kg, sign as fitted
//! mass_moment = [0.0, 0.0, 0.16]    # m'·c, kg·m
//! force_bias = [0.0, 0.0, 0.0]      # N
//! torque_bias = [0.0, 0.0, 0.0]     # N·m
//! mount_rotation = [0.0, 0.0, 0.0]  # sensor frame in the flange frame, rotation vector, rad
//! max_age = 0.012                   # s: older orientations make the sample invalid (the loop holds)
//! ```

use std::net::{IpAddr, SocketAddr};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::{Context, Result, anyhow, bail};
use controller::gravity::{Compensator, GravityModel};
use controller::run::{End, RobotSession, RunLimits, Sink};
use controller::{ControlLoop, LoopStats, Tuning};
use hal::{ForceSensor, RobotLink, UnitQuaternion, Vector3};
use kuka_rsi::{CorrectionMode, EthernetConfig, Limits, LinkConfig, PoscorrLimits, RobotFilter};
use serde::Deserialize;

use crate::provenance::Provenance;
use crate::record::Row;
use crate::recorder::{Record, Recorder, RecorderOptions};
use crate::scenario::load_tuning;

pub use crate::robot::{MAX_TIMEOUT, RobotConfig};

/// Correction mode by name.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModeName {
    /// `#ABSOLUTE`.
    #[default]
    Absolute,
    /// `#RELATIVE`.
    Relative,
}

/// The force sensor of a cell.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum SensorConfig {
    /// An ATI NETCANOEM board (or Schunk FTM/FTN-CAN) on SocketCAN.
    Ati {
        /// CAN interface.
        can: String,
        /// Base identifier (7 bits).
        #[serde(default = "default_base")]
        base: u8,
        /// Bus bit rate, bit/s.
        #[serde(default = "default_bitrate")]
        bitrate: u32,
        /// Calibration slot.
        #[serde(default)]
        slot: u8,
        /// Poll rate, Hz.
        #[serde(default = "default_poll")]
        poll_hz: f64,
        /// Take a bias at start (tool in free air, still).
        #[serde(default)]
        tare: bool,
        /// The board's turnaround allowance per request, µs (raise it on a virtual interface).
        #[serde(default = "default_turnaround_us")]
        turnaround_us: u64,
    },
    /// A Robotiq FT 300 (or FT 150) on a serial port: Modbus RTU start-up, then its 100 Hz stream.
    Robotiq {
        /// The serial device (never scanned for: this is the port).
        port: PathBuf,
        /// Modbus slave address.
        #[serde(default = "default_slave")]
        slave: u8,
        /// Take a host-side zero at start (tool in free air, still).
        #[serde(default)]
        zero: bool,
    },
}

fn default_slave() -> u8 {
    robotiq::codec::SLAVE
}

impl SensorConfig {
    /// Check the values of whichever sensor this is.
    pub fn validate(&self) -> Result<()> {
        match self {
            Self::Ati {
                base,
                poll_hz,
                slot,
                ..
            } => {
                if *base > 0x7F {
                    bail!("sensor.base must be a 7-bit identifier (0..=0x7F), got {base:#x}");
                }
                if *slot > 15 {
                    bail!("sensor.slot must be 0..=15, got {slot}");
                }
                let (lo, hi) = POLL_HZ;
                if !(poll_hz.is_finite() && (lo..=hi).contains(poll_hz)) {
                    bail!(
                        "sensor.poll_hz must be {lo}..={hi} Hz, got {poll_hz}: the driver polls at most 10 kHz, and below 1 Hz every sample is stale before the next"
                    );
                }
            }
            Self::Robotiq { port, slave, .. } => {
                if port.as_os_str().is_empty() {
                    bail!("sensor.port must name the serial device");
                }
                if !(1..=247).contains(slave) {
                    bail!("sensor.slave must be 1..=247, got {slave}");
                }
            }
        }
        Ok(())
    }

    /// Start this sensor (taking a bias or zero at start when configured). The one place the app turns a
    /// sensor kind into a running driver.
    /// With `can_log`, a CAN sensor's traffic is logged there in candump `-L` format.
    pub fn open(&self, zero_at_start: bool, can_log: Option<&Path>) -> Result<CellSensor> {
        match self {
            Self::Ati {
                can,
                base,
                bitrate,
                slot,
                poll_hz,
                turnaround_us,
                ..
            } => {
                let base = ati_can::Base::new(*base)
                    .ok_or_else(|| anyhow!("sensor.base must be 0..=0x7F, got {base:#x}"))?;
                let ati_cfg = ati_can::Config {
                    base,
                    bitrate: *bitrate,
                    slot: *slot,
                    turnaround: Duration::from_micros(*turnaround_us),
                    // A sample is stale after three missed polls (never sooner than the driver's
                    // default): at a low poll rate every sample would otherwise read as stale, and the
                    // loop would hold until its `max_hold` ends the run.
                    stale_after: ati_can::Config::default()
                        .stale_after
                        .max(Duration::from_secs_f64(3.0 / poll_hz)),
                    ..ati_can::Config::default()
                };
                ati_cfg.validate().map_err(|e| anyhow!("sensor: {e}"))?;
                let transport = crate::candump::open_logged(can, can_log)?;
                let mut driver = ati_can::Driver::new(transport, ati_cfg)?;
                let info = driver
                    .start()
                    .with_context(|| format!("ATI sensor at base {base} on {can}"))?;
                println!("sensor: {}", crate::ati::describe(&info));
                if zero_at_start {
                    // The bias needs samples: start-up ends before the first poll.
                    crate::ati::first_sample(&mut driver)?;
                    let bias = crate::ati::tare(&mut driver).context(
                        "bias at start (sensor.tare = true; the tool must be in free air and still)",
                    )?;
                    println!("bias taken (counts): {bias:.1?}");
                }
                Ok(CellSensor::Ati(ati_can::AtiSensor::spawn(
                    driver, *poll_hz,
                )?))
            }
            Self::Robotiq { port, slave, .. } => {
                let cfg = robotiq::Config {
                    slave: *slave,
                    ..robotiq::Config::new(port)
                };
                let ft = robotiq::Ft300::open(cfg)
                    .with_context(|| format!("Robotiq FT 300 on {}", port.display()))?;
                match ft.identity() {
                    Some(id) => println!(
                        "sensor: Robotiq {} serial {} ({})",
                        id.firmware_text(),
                        id.serial_text(),
                        id.year
                    ),
                    None => println!("sensor: Robotiq FT 300, found streaming (identity not read)"),
                }
                // Start-up ends at the 410 write: the first frame follows within a frame or two.
                // The loop must not begin (and hold, and fault) before it, however fast the robot's
                // first cycles come: wait for it, bounded.
                let t0 = std::time::Instant::now();
                while ft.health() == robotiq::Health::Waiting && t0.elapsed() < FIRST_FRAME_WAIT {
                    std::thread::sleep(Duration::from_millis(2));
                }
                if ft.health() == robotiq::Health::Waiting {
                    eprintln!(
                        "warning: the FT 300 sent no frame within {} ms of its start-up",
                        FIRST_FRAME_WAIT.as_millis()
                    );
                }
                if zero_at_start {
                    let bias = ft.zero(crate::robotiq::zero_config())?;
                    println!("zero taken (N, N·m): {:.3?}", bias.to_array());
                }
                Ok(CellSensor::Robotiq(Box::new(ft)))
            }
        }
    }

    /// True when the cell file asks for a bias/zero at start.
    pub fn zero_at_start(&self) -> bool {
        match self {
            Self::Ati { tare, .. } => *tare,
            Self::Robotiq { zero, .. } => *zero,
        }
    }
}

/// A running cell sensor, whichever kind.
pub enum CellSensor {
    /// ATI over CAN, polled in the background.
    Ati(ati_can::AtiSensor),
    /// Robotiq FT 300, its stream read in the background.
    Robotiq(Box<robotiq::Ft300>),
}

/// What a sensor says of itself, read by its driver at start-up (the ATI board's serial and firmware
/// queries, the FT 300's identity registers): [`UNKNOWN`] where the sensor could not say.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SensorIdentity {
    /// The serial number as the sensor reports it.
    pub serial: String,
    /// The firmware version as the sensor reports it.
    pub firmware: String,
}

/// What a recording says of a sensor's serial or firmware it could not read.
pub const UNKNOWN: &str = "unknown";

impl SensorIdentity {
    /// Nothing known.
    pub fn unknown() -> Self {
        Self {
            serial: UNKNOWN.into(),
            firmware: UNKNOWN.into(),
        }
    }
}

impl CellSensor {
    /// The sensor's identity, as its driver read it when it started.
    pub fn identity(&self) -> SensorIdentity {
        let known = |s: String| {
            if s.trim().is_empty() || s == "UNKNOWN" {
                UNKNOWN.to_string()
            } else {
                s
            }
        };
        match self {
            Self::Ati(s) => match s.info() {
                Some(info) => SensorIdentity {
                    serial: known(info.serial_text().unwrap_or_default()),
                    firmware: known(info.firmware.to_string()),
                },
                None => SensorIdentity::unknown(),
            },
            // Found streaming, the FT 300 is not asked (that would stop its stream).
            Self::Robotiq(s) => match s.identity() {
                Some(id) => SensorIdentity {
                    serial: known(id.serial_text()),
                    firmware: known(id.firmware_text()),
                },
                None => SensorIdentity::unknown(),
            },
        }
    }

    /// The sensor's background reader thread (to give it its real-time priority), while it runs.
    pub fn reader_thread(&self) -> Option<std::os::unix::thread::RawPthread> {
        match self {
            Self::Ati(s) => s.reader_thread(),
            Self::Robotiq(s) => s.reader_thread(),
        }
    }
}

/// The error of a [`CellSensor`].
#[derive(Debug)]
pub enum CellSensorError {
    /// From the ATI driver.
    Ati(ati_can::AtiError),
    /// From the Robotiq driver.
    Robotiq(robotiq::RobotiqError),
}

impl std::fmt::Display for CellSensorError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Ati(e) => write!(f, "ATI: {e}"),
            Self::Robotiq(e) => write!(f, "Robotiq: {e}"),
        }
    }
}

impl std::error::Error for CellSensorError {}

impl hal::Error for CellSensorError {
    fn kind(&self) -> hal::ErrorKind {
        match self {
            Self::Ati(e) => e.kind(),
            Self::Robotiq(e) => e.kind(),
        }
    }
}

impl ForceSensor for CellSensor {
    type Error = CellSensorError;

    fn read(&mut self) -> Result<hal::Sample, CellSensorError> {
        match self {
            Self::Ati(s) => s.read().map_err(CellSensorError::Ati),
            Self::Robotiq(s) => s.read().map_err(CellSensorError::Robotiq),
        }
    }
}

/// How long opening an FT 300 waits for its first frame after start-up (ten frames of 10 ms).
const FIRST_FRAME_WAIT: Duration = Duration::from_millis(100);

/// The poll rates a cell's ATI sensor accepts, Hz (as `sensor ati read --rate`).
pub const POLL_HZ: (f64, f64) = (1.0, 10_000.0);
/// The longest a robot may stay silent before a run ends, s (`watchdog_cycles` × the cycle).
pub const MAX_WATCHDOG_S: f64 = 10.0;

fn default_base() -> u8 {
    0x20
}
fn default_bitrate() -> u32 {
    1_000_000
}
fn default_poll() -> f64 {
    1000.0
}
fn default_turnaround_us() -> u64 {
    300
}

/// The tool model for gravity compensation.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GravityConfig {
    /// Signed tool mass, kg.
    pub signed_mass: f64,
    /// `m'·c`, kg·m.
    pub mass_moment: [f64; 3],
    /// Force bias, N.
    #[serde(default)]
    pub force_bias: [f64; 3],
    /// Torque bias, N·m.
    #[serde(default)]
    pub torque_bias: [f64; 3],
    /// Sensor frame in the flange frame, rotation vector, rad.
    #[serde(default)]
    pub mount_rotation: [f64; 3],
    /// Oldest usable orientation, s.
    #[serde(default = "default_max_age")]
    pub max_age: f64,
}

fn default_max_age() -> f64 {
    0.012
}

/// A cell configuration file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CellConfig {
    /// Tuning: built-in name or file.
    pub tuning: String,
    /// Robot time to run, s; `None`: until the robot stops sending.
    #[serde(default)]
    pub duration: Option<f64>,
    /// Where recordings go.
    #[serde(default = "default_record")]
    pub record: PathBuf,
    /// The robot.
    pub robot: RobotConfig,
    /// The sensor.
    pub sensor: SensorConfig,
    /// The tool model; without it nothing is subtracted.
    #[serde(default)]
    pub gravity: Option<GravityConfig>,
    /// Real-time settings of the cycle (on by default: `SCHED_FIFO`, memory locked).
    #[serde(default)]
    pub realtime: crate::rt::Realtime,
    /// The removal model: `run` maps each recording with it at the end (`NAME-removal.png` beside
    /// it), and `forcecell removal` takes it for this cell's recordings.
    #[serde(default)]
    pub removal: Option<::scenario::removal::RemovalConfig>,
}

fn default_record() -> PathBuf {
    PathBuf::from("recordings")
}

impl CellConfig {
    /// Parse and validate a cell file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::input::read_text(path, "cell config", crate::input::MAX_CONFIG)?;
        Self::from_toml(&text, &path.display().to_string())
    }

    /// Parse and validate TOML text; `origin` names it in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self> {
        let c: Self = toml::from_str(text)
            .map_err(|e| anyhow!("{origin}: {}", crate::scenario::one_line(&e.to_string())))?;
        c.validate()
            .with_context(|| format!("{origin}: invalid cell config"))?;
        Ok(c)
    }

    fn validate(&self) -> Result<()> {
        self.realtime.validate().map_err(|e| anyhow!(e))?;
        if let Some(r) = &self.removal {
            r.validate().map_err(|e| anyhow!(e))?;
        }
        let r = &self.robot;
        r.validate()?;
        let cycle = f64::from(r.cycle_ms) * 1e-3;
        if let Some(d) = self.duration {
            if !(d.is_finite() && d > 0.0) {
                bail!("duration must be > 0 s, got {d}");
            }
            let max = crate::scenario::MAX_STEPS as f64 * cycle;
            if d > max {
                bail!(
                    "duration {d} s is more than {max} s: at most {} cycles of {} ms are recorded in a run (omit duration to run until the robot ends its session)",
                    crate::scenario::MAX_STEPS,
                    r.cycle_ms
                );
            }
        }
        self.sensor.validate()?;
        if let Some(g) = &self.gravity {
            let all = [g.signed_mass, g.max_age]
                .into_iter()
                .chain(g.mass_moment)
                .chain(g.force_bias)
                .chain(g.torque_bias)
                .chain(g.mount_rotation);
            if all.clone().any(|v| !v.is_finite()) || g.max_age <= 0.0 {
                bail!("gravity: every value must be finite and max_age > 0");
            }
        }
        Ok(())
    }

    /// The tuning, validated.
    pub fn tuning(&self) -> Result<Tuning> {
        load_tuning(&self.tuning)
    }

    /// The compensator: the tool model, or nothing to subtract.
    pub fn compensator(&self) -> Compensator {
        match &self.gravity {
            Some(g) => Compensator {
                model: GravityModel {
                    signed_mass: g.signed_mass,
                    mass_moment: Vector3::from(g.mass_moment),
                    force_bias: Vector3::from(g.force_bias),
                    torque_bias: Vector3::from(g.torque_bias),
                },
                mount: UnitQuaternion::from_scaled_axis(Vector3::from(g.mount_rotation)),
                max_age: g.max_age,
            },
            None => Compensator {
                model: GravityModel {
                    signed_mass: 0.0,
                    mass_moment: Vector3::zeros(),
                    force_bias: Vector3::zeros(),
                    torque_bias: Vector3::zeros(),
                },
                mount: UnitQuaternion::identity(),
                max_age: f64::INFINITY,
            },
        }
    }

    /// The RSI link's configuration ([`rsi_link_config`]); an error for another robot kind.
    pub fn link_config(&self, tuning: &Tuning) -> Result<LinkConfig> {
        rsi_link_config(&self.robot, tuning)
    }

    /// The robot link's configuration, whichever kind, checked (the robot's files read).
    pub fn robot_spec(&self, tuning: &Tuning) -> Result<crate::robot::RobotSpec> {
        self.robot.spec(tuning)
    }
}

/// The RSI link's configuration: the robot's limits from the file, the driver's envelope inside them
/// (90 % of POSCORR, and never beyond the tuning's own envelope), the rate limit of the tuning.
pub fn rsi_link_config(r: &RobotConfig, tuning: &Tuning) -> Result<LinkConfig> {
    let Some(o) = r.rsi() else {
        bail!(
            "robot: kind = \"{}\" has no RSI link configuration",
            r.kind_name()
        );
    };
    let relative = o.mode == ModeName::Relative;
    let ethernet = match &o.ethernet_config {
        Some(p) => {
            let text = crate::input::read_text(p, "Ethernet config", crate::input::MAX_CONFIG)?;
            EthernetConfig::parse(&text).map_err(|e| anyhow!("{}: {e}", p.display()))?
        }
        None => {
            let IpAddr::V4(ip) = r.listen.ip() else {
                bail!("robot.listen must be an IPv4 address (RSI is IPv4)");
            };
            let e = EthernetConfig::forcecell(ip, r.listen.port(), relative);
            if r.process {
                e.with_process(kuka_rsi::ProcessChannels::default())
            } else {
                e
            }
        }
    };
    // Before anything moves: a configuration the force control cannot work through is refused.
    ethernet
        .check_for_control(r.process)
        .map_err(|e| match &o.ethernet_config {
            Some(p) => anyhow!("{}: {e}", p.display()),
            None => anyhow!("{e}"),
        })?;
    let turn_channels = tuning
        .orientation
        .map(|_| rotation_channels_missing(&ethernet))
        .unwrap_or_default();
    let mut lc = LinkConfig::new(ethernet, RobotFilter::Ip(r.robot_ip));
    lc.bind = Some(r.listen);
    lc.period = Duration::from_millis(u64::from(r.cycle_ms));
    lc.watchdog_cycles = r.watchdog_cycles;
    lc.max_speed = r.max_speed;
    lc.mode = if relative {
        CorrectionMode::Relative
    } else {
        CorrectionMode::Absolute
    };
    let (rot_deg, rotmon_deg) = o.rotation_limits_deg();
    lc.poscorr = PoscorrLimits {
        translation: o.poscorr_mm * 1e-3,
        rotation: rot_deg.to_radians(),
    };
    lc.poscorrmon = PoscorrLimits {
        translation: o.poscorrmon_mm * 1e-3,
        rotation: rotmon_deg.to_radians(),
    };
    // Short waits for the first datagram, so a stop ends the wait (the loop waits again).
    lc.first_contact_timeout = Some(Duration::from_millis(100));
    // Checked 0..=a quarter cycle by the robot section's validation.
    lc.spin = Duration::from_micros(u64::try_from(o.spin_us).unwrap_or(0));
    lc.limits = Limits {
        max_translation: (0.9 * lc.poscorr.translation).min(tuning.loop_cfg.max_offset),
        max_translation_step: tuning.loop_cfg.max_step,
        ..Limits::default()
    };
    if let Some(turn) = &tuning.orientation {
        orientation_fits(
            &turn_channels,
            turn,
            &mut lc.limits,
            lc.poscorr,
            lc.period,
            &tuning.name,
        )?;
    }
    lc.validate().map_err(|e| anyhow!("robot: {e}"))?;
    Ok(lc)
}

/// The rotational correction channels (`RKorr.A`, `.B`, `.C`) the Ethernet config's RECEIVE lacks.
fn rotation_channels_missing(ethernet: &EthernetConfig) -> Vec<&'static str> {
    ["A", "B", "C"]
        .into_iter()
        .filter(|a| {
            !ethernet
                .receive
                .iter()
                .any(|e| e.tag == format!("RKorr.{a}"))
        })
        .collect()
}

/// An orientation-following tuning on an RSI robot: the Ethernet config carries the rotational
/// correction, the robot's POSCORR rotation limit holds the tuning's (so the law, not the robot's
/// silent clamp, limits each axis), and the law's envelope `max_angle` lies inside the driver's
/// (90 % of the robot's limit) so the law faults first; the driver's rate limit then lets the law's
/// fastest turn through (`max_rate` per cycle, 10 % margin).
fn orientation_fits(
    missing: &[&str],
    o: &controller::OrientationParams,
    limits: &mut Limits,
    poscorr: PoscorrLimits,
    period: Duration,
    tuning: &str,
) -> Result<()> {
    if !missing.is_empty() {
        bail!(
            "tuning {tuning} turns the tool (orientation following) and the Ethernet config's \
             RECEIVE has no RKorr.{}: add the rotational correction channels wired to POSCORR \
             (`forcecell rsi-config` writes them)",
            missing.join(", RKorr.")
        );
    }
    let deg = |r: f64| r.to_degrees();
    if o.poscorr > poscorr.rotation + 1e-9 {
        bail!(
            "tuning {tuning}'s orientation.poscorr is {:.1}° and the robot's POSCORR rotation limit \
             is {:.1}° (robot.poscorr_deg): set robot.poscorr_deg to the robot's real limit (raise it \
             on the robot with `forcecell rsi-config --config`) or lower orientation.poscorr",
            deg(o.poscorr),
            deg(poscorr.rotation)
        );
    }
    limits.max_rotation = 0.9 * poscorr.rotation;
    if o.max_angle >= limits.max_rotation {
        bail!(
            "tuning {tuning}'s orientation.max_angle {:.1}° must lie inside the driver's rotation \
             envelope {:.1}° (90 % of robot.poscorr_deg {:.1}°), so the law faults before the robot \
             clamps: raise POSCORR's rotation on the robot and robot.poscorr_deg, or lower max_angle",
            deg(o.max_angle),
            deg(limits.max_rotation),
            deg(poscorr.rotation)
        );
    }
    limits.max_rotation_step = limits
        .max_rotation_step
        .max(1.1 * o.max_rate * period.as_secs_f64());
    Ok(())
}

/// How a cell run ended and what it recorded.
#[derive(Debug)]
pub struct CellOutcome {
    /// One row per answered cycle (no truth columns on a real cell).
    pub rows: Vec<Row>,
    /// Loop counters.
    pub stats: LoopStats,
    /// Why it ended.
    pub ended: String,
    /// Whether `Stop` was sent.
    pub stopped: bool,
    /// `sent`, or `not sent` and the real reason (for the end message).
    pub stop_note: String,
    /// The law's last contact-stiffness estimate, N/m (for the link's advisories).
    pub kc_hat: Option<f64>,
    /// The robot's own late-reply count at the end (RSI: `Delay`).
    pub late: u32,
    /// Which way it ended.
    pub end: CellEnd,
    /// The re-zeros of the sensor between passes and the refusals (`[loop.process] rezero`), the
    /// first [`REZERO_LOG`] of them.
    pub rezeros: Vec<controller::RezeroEvent>,
    /// Re-zero decisions beyond those.
    pub rezeros_more: u64,
}

/// How many re-zero decisions a cell run keeps for its summary (kept without allocating in the
/// cycle; the recording has every one).
pub const REZERO_LOG: usize = 256;

/// Which way a cell run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CellEnd {
    /// The configured duration was done (or the robot ended its program: a run without a duration).
    Done,
    /// The operator's stop flag (SIGINT, SIGTERM).
    Stopped,
    /// The robot ended it before the end: its link failed (it fell silent past its watchdog, or with
    /// the process still on), or its program aborted.
    EndedEarly,
    /// A fault of the loop's guard ended it (force limit, correction limit, contact lost, a hold too
    /// long, a failed sensor): backed off, returned to the path.
    Fault,
}

impl CellEnd {
    /// The process exit status for this end ([`crate::stop`]).
    pub fn exit_status(self) -> u8 {
        match self {
            Self::Done => crate::stop::OK,
            Self::Stopped => crate::stop::INTERRUPTED,
            Self::EndedEarly => crate::stop::ENDED_EARLY,
            Self::Fault => crate::stop::FAULT,
        }
    }
}

/// Run the controller on `robot` and `sensor` until `duration` of robot time has passed, `stop` is set,
/// or the robot link ends; then, if the link still stands, end the correction motion with `Stop`.
/// Gravity compensation from `cfg` is applied between the two.
pub fn run_cell<R, S>(
    cfg: &CellConfig,
    tuning: &Tuning,
    robot: R,
    sensor: S,
    stop: &AtomicBool,
) -> Result<CellOutcome>
where
    R: RobotLink,
    S: ForceSensor,
    R::Error: Send + Sync + 'static,
    S::Error: Send + Sync + 'static,
{
    run_cell_recorded(cfg, tuning, robot, sensor, stop, None)
}

/// [`run_cell`] with every cycle's record (raw and compensated wrench, state, diagnostics) handed to
/// `recorder` instead of collected: the cycle then neither allocates nor writes, and
/// [`CellOutcome::rows`] stays empty (the recording holds the trace).
pub fn run_cell_recorded<R, S>(
    cfg: &CellConfig,
    tuning: &Tuning,
    robot: R,
    sensor: S,
    stop: &AtomicBool,
    recorder: Option<Recorder>,
) -> Result<CellOutcome>
where
    R: RobotLink,
    S: ForceSensor,
    R::Error: Send + Sync + 'static,
    S::Error: Send + Sync + 'static,
{
    // The tuning's whole law: along the normal, with orientation following when it has [orientation].
    let law = tuning.cell_law().map_err(|e| anyhow!(e))?;
    let mut lp = ControlLoop::with_law(robot, sensor, law, tuning.loop_config())
        .with_gravity(cfg.compensator());
    let mut sink = RecordSink::new(recorder).with_status(cfg.robot.late_budget());
    let limits = RunLimits {
        duration: cfg.duration,
        stop: Some(stop),
        // Without a duration the robot's program decides: its link falling silent is the end.
        robot_session: if cfg.duration.is_none() {
            RobotSession::Robot
        } else {
            RobotSession::Run
        },
        ..RunLimits::default()
    };
    let o = controller::run::run(&mut lp, limits, &mut sink);
    sink.end_status();
    let session = cfg.robot.session_name();
    let (ended, end) = match &o.end {
        End::Done | End::Program(None) => (
            format!("{} s of robot time done", sink.last_t),
            CellEnd::Done,
        ),
        End::Stopped(None) => ("stopped by the operator".to_string(), CellEnd::Stopped),
        End::Stopped(Some(e)) => (format!("stopped by the operator: {e}"), CellEnd::Stopped),
        // The robot owns the session (no duration): whether it ended RSI or fell silent is told by
        // what its program last commanded over the process channels.
        End::RobotEnded(e) => match sink.last_phase {
            Some(hal::ProcessPhase::Off) => (
                format!(
                    "the robot ended {session}: the process was off when its program stopped sending ({e})"
                ),
                CellEnd::Done,
            ),
            Some(phase) => (
                format!(
                    "the robot fell silent with the process still in {phase:?} (no orderly {session} end): {e}"
                ),
                CellEnd::EndedEarly,
            ),
            None => (
                format!(
                    "the robot stopped sending: the end of its {session} session, or a lost link — without process channels the two look alike ({e})"
                ),
                CellEnd::Done,
            ),
        },
        End::Fault(e) => (format!("the loop ended: {e}"), CellEnd::Fault),
        End::LinkLost(e) => (format!("the loop ended: {e}"), CellEnd::EndedEarly),
        End::Program(Some(why)) => (why.clone(), CellEnd::EndedEarly),
    };
    Ok(CellOutcome {
        rows: sink.rows,
        stats: lp.stats(),
        ended,
        stopped: o.stopped(),
        stop_note: o.stop_note(),
        kc_hat: sink.kc_hat,
        late: sink.late,
        end,
        rezeros: sink.rezeros,
        rezeros_more: sink.rezeros_more,
    })
}

/// The sink of a cell run: every cycle's [`Record`] to the recorder, or (without one) its [`Row`]
/// collected.
struct RecordSink {
    recorder: Option<Recorder>,
    rows: Vec<Row>,
    last_t: f64,
    /// The law's last finite contact-stiffness estimate, N/m.
    kc_hat: Option<f64>,
    /// The process phase last reported to the robot program (`None`: no process channels).
    last_phase: Option<hal::ProcessPhase>,
    /// The status line while the cell runs (printed on its own thread).
    status: Option<crate::status::Printer>,
    /// The robot's own late-reply count last seen.
    late: u32,
    /// Re-zero decisions, room for [`REZERO_LOG`] made before the run (no allocation in the cycle).
    rezeros: Vec<controller::RezeroEvent>,
    rezeros_more: u64,
}

impl RecordSink {
    fn new(recorder: Option<Recorder>) -> Self {
        Self {
            recorder,
            rows: Vec::new(),
            last_t: 0.0,
            kc_hat: None,
            last_phase: None,
            status: None,
            late: 0,
            rezeros: Vec::with_capacity(REZERO_LOG),
            rezeros_more: 0,
        }
    }

    /// Say what the cell does while it runs ([`crate::status::Printer`]); late replies counted
    /// against `budget`. Without a thread for it, the run goes on silent.
    fn with_status(mut self, budget: Option<u32>) -> Self {
        self.status = crate::status::Printer::spawn(budget).ok();
        self
    }

    fn show(&mut self, r: &controller::CycleReport) {
        self.late = r.cycle.late_replies;
        if let Some(p) = &mut self.status {
            p.offer(r);
        }
    }

    /// Print what the status line has queued and end it.
    fn end_status(&mut self) {
        if let Some(p) = &mut self.status {
            p.finish();
        }
    }
}

impl Sink for RecordSink {
    fn record(&mut self, r: &controller::CycleReport) -> bool {
        self.last_t = r.cycle.t;
        self.show(r);
        if r.out.kc_hat.is_finite() && r.out.kc_hat > 0.0 {
            self.kc_hat = Some(r.out.kc_hat);
        }
        if r.cycle.process.is_some() {
            self.last_phase = Some(r.command.process.phase);
        }
        if let Some(e) = r.rezero {
            if self.rezeros.len() < self.rezeros.capacity() {
                self.rezeros.push(e);
            } else {
                self.rezeros_more += 1;
            }
        }
        match &mut self.recorder {
            Some(tx) => {
                tx.push(Record::from_report(r, r.set_point));
            }
            None => self.rows.push(Row::from_report(r, r.set_point)),
        }
        true
    }
}

/// Start the configured sensor (optionally taking a bias) and bind the robot link, whichever kind
/// ([`crate::robot::RobotSpec::open`]).
/// With `can_log`, the sensor's CAN traffic is logged there in candump `-L` format.
fn open_devices(
    cfg: &CellConfig,
    tuning: &Tuning,
    zero_at_start: bool,
    can_log: Option<&Path>,
) -> Result<(crate::robot::CellRobot, CellSensor)> {
    let spec = cfg.robot_spec(tuning)?;
    let sensor = cfg.sensor.open(zero_at_start, can_log)?;
    let link = spec.open()?;
    Ok((link, sensor))
}

/// `forcecell run --config FILE [--live ADDR]`: check the recording directory, start the sensor, bind
/// the robot link, run, record (MCAP, then the CSV and PNG exported from it). With `live`, the run is
/// also served over the Foxglove WebSocket protocol there. Returns the exit status
/// ([`CellEnd::exit_status`]).
pub fn run(path: &Path, live: Option<SocketAddr>) -> Result<u8> {
    let cfg = CellConfig::load(path)?;
    let tuning = cfg.tuning()?;
    // Every value checked (the robot's files read) before the recording directory is created.
    cfg.robot_spec(&tuning)?;
    let live = match live {
        Some(addr) => {
            let server = crate::live::LiveServer::bind(addr)?;
            println!("live view: ws://{}", server.local_addr());
            Some(server)
        }
        None => None,
    };
    // Before anything moves: a recording that cannot be written is found now, not after the run.
    let dir = crate::output::OutDir::create(&cfg.record, "recording directory")?;
    let csv = reserve_recording(&cfg.record)?;
    let stem = csv.with_extension("");
    crate::stop::install()?;
    // A CAN sensor's traffic is logged beside the recording; a serial sensor has no CAN.
    let can_log =
        matches!(cfg.sensor, SensorConfig::Ati { .. }).then(|| stem.with_extension("candump.log"));
    let (mut link, sensor) = match open_devices(
        &cfg,
        &tuning,
        cfg.sensor.zero_at_start(),
        can_log.as_deref(),
    ) {
        Ok(d) => d,
        Err(e) => {
            let _ = std::fs::remove_file(&csv);
            if let Some(log) = &can_log {
                let _ = std::fs::remove_file(log);
            }
            return Err(e);
        }
    };
    println!(
        "listening on {} for the robot at {} ({}, {} ms cycle, tuning {}); start {} on the robot now, Ctrl-C (or SIGTERM) ends with a clean Stop",
        link.local_addr().map_or(cfg.robot.listen, |a| a),
        cfg.robot.robot_ip,
        cfg.robot.kind_name(),
        cfg.robot.cycle_ms,
        tuning.name,
        match cfg.robot.kind {
            crate::robot::RobotKind::KukaRsi(_) => "RSI",
            crate::robot::RobotKind::AbbEgm(_) => "the RAPID program (EGMActMove)",
        }
    );
    link.say_stamps();
    let mcap = stem.with_extension("mcap");
    // The cell file as the input rule reads it (a regular file, capped), once: hashed and attached.
    let cell = crate::input::read(path, "cell config", crate::input::MAX_CONFIG).ok();
    let mut prov = provenance("run", &cfg, path, cell.as_deref(), &tuning);
    prov.identify_sensor(&sensor.identity());
    let (tx, recording) = crate::recorder::start(
        &mcap,
        recording_options(cell, &tuning, &prov),
        live.as_ref().map(crate::live::LiveServer::sink),
    )?;
    let stop = crate::stop::flag();
    // While it waits: what arrives and is not the robot's cycle, a line per kind, rate-limited.
    let robot = crate::stop::Interruptible::new(&mut link, stop).while_waiting(|l| {
        for line in l.rejection_lines() {
            eprintln!("{line}");
        }
    });
    dir.keep();
    // The cycle runs on this thread: its real-time settings now, before the first cycle.
    let mut applied = cfg.realtime.apply_to_cycle_thread();
    if let Some(reader) = sensor.reader_thread() {
        applied.sensor_priority = cfg.realtime.apply_to_sensor_thread(reader);
    }
    println!("{applied}");
    for r in applied.refusals() {
        eprintln!("warning: {r}");
    }
    let out = run_cell_recorded(&cfg, &tuning, robot, sensor, stop, Some(tx))?;
    let late = match cfg.robot.late_budget() {
        Some(budget) => format!("robot late replies {} of {budget}", out.late),
        None => "the robot reports no late replies".to_string(),
    };
    println!(
        "{}; {} cycles, {} sensor faults, {} limited; {late}; Stop {}",
        out.ended, out.stats.cycles, out.stats.sensor_faults, out.stats.limited, out.stop_note
    );
    for line in crate::report::rezeros(&out.rezeros, out.rezeros_more) {
        println!("{line}");
    }
    // What the first cycles showed that degrades control, at the stiffness the law estimated (the
    // paper's 50 kN/m when it estimated none).
    link.print_diagnostics(
        f64::from(cfg.robot.cycle_ms) * 1e-3,
        out.kc_hat.unwrap_or(50e3),
    );
    let recorded = recording.finish(Vec::new())?;
    println!("recorded {recorded}");
    // What the run did to the part, when the cell file describes the pad and the process
    // (`[removal]`): the map beside the recording. A run that made none (no contact, no poses) says
    // why; the run's own status is not changed by it.
    if let Some(r) = &cfg.removal {
        match crate::removal::run(&mcap, r, None) {
            Ok(o) => println!("{}", crate::removal::report(&o)),
            Err(e) => eprintln!("removal map not written: {e:#}"),
        }
    }
    prov.finish(&out.ended, out.stopped, out.stats.cycles);
    let summary = stem.with_extension("json");
    crate::output::replace(&summary, |tmp| {
        let text = serde_json::to_string_pretty(&prov)?;
        std::fs::write(tmp, text + "\n")?;
        Ok(())
    })?;
    println!("summary {}", summary.display());
    if let Some(log) = &can_log {
        println!("CAN traffic logged to {} (candump -L)", log.display());
    }
    export_recording(&mcap)?;
    Ok(out.end.exit_status())
}

/// A cell run's provenance: where it came from (the cell file and its hash, the tuning, the robot and
/// the sensor), started now.
fn provenance(
    command: &str,
    cfg: &CellConfig,
    cell_file: &Path,
    cell: Option<&[u8]>,
    tuning: &Tuning,
) -> Provenance {
    let mut p = Provenance::start(command, &cell_file.display().to_string(), cell);
    p.tuning = tuning.name.clone();
    p.robot = cfg.robot.describe();
    p.sensor = match &cfg.sensor {
        SensorConfig::Ati { can, base, .. } => format!("ATI NETCANOEM at base {base:#x} on {can}"),
        SensorConfig::Robotiq { port, slave, .. } => {
            format!("Robotiq FT 300 on {} (slave {slave})", port.display())
        }
    };
    p
}

/// A cell run's recording: the cell file and the tuning attached, its provenance as metadata
/// (`forcecell.run`).
fn recording_options(
    cell: Option<Vec<u8>>,
    tuning: &Tuning,
    provenance: &Provenance,
) -> RecorderOptions {
    let mut attachments = Vec::new();
    if let Some(text) = cell {
        attachments.push(("cell.toml".to_string(), "application/toml".into(), text));
    }
    if let Ok(text) = toml::to_string(tuning) {
        attachments.push((
            format!("tuning-{}.toml", tuning.name),
            "application/toml".into(),
            text.into_bytes(),
        ));
    }
    RecorderOptions {
        attachments,
        metadata: vec![("forcecell.run".into(), provenance.metadata())],
        ..RecorderOptions::default()
    }
}

/// The CSV and PNG of a run, exported from its recording.
fn export_recording(mcap: &Path) -> Result<()> {
    let (rows, truncated) = crate::recorder::load_trace(mcap)?;
    if let Some(why) = truncated {
        println!("note: the recording ends early ({why})");
    }
    let csv = mcap.with_extension("csv");
    if rows.is_empty() {
        // The CSV reserved before the run holds only its header.
        let _ = std::fs::remove_file(&csv);
        println!("nothing to record: no cycle was answered");
        return Ok(());
    }
    let png = mcap.with_extension("png");
    crate::output::write_csv(&csv, &rows)?;
    let title = mcap
        .file_stem()
        .map_or("run".into(), |s| s.to_string_lossy().into_owned());
    crate::plot::write_png(&png, &format!("forcecell {title}"), &rows)?;
    println!("wrote {} and {}", csv.display(), png.display());
    Ok(())
}

/// `forcecell calibrate --config FILE --poses N`: while the robot's program holds the tool still in free
/// air in N orientations (answered with zero corrections), fit the tool model and print the `[gravity]`
/// section for the cell file.
pub fn calibrate(path: &Path, poses: usize) -> Result<()> {
    if !(3..=64).contains(&poses) {
        bail!("--poses must be 3..=64 (the fit needs at least 3 orientations), got {poses}");
    }
    let cfg = CellConfig::load(path)?;
    let tuning = cfg.tuning()?;
    let (link, sensor) = open_devices(&cfg, &tuning, false, None)?;
    let dir = crate::output::OutDir::create(&cfg.record, "recording directory")?;
    let stamp = crate::provenance::file_stamp(std::time::SystemTime::now());
    let mcap = cfg.record.join(format!("calibrate-{stamp}.mcap"));
    let cell = crate::input::read(path, "cell config", crate::input::MAX_CONFIG).ok();
    let mut prov = provenance("calibrate", &cfg, path, cell.as_deref(), &tuning);
    prov.identify_sensor(&sensor.identity());
    let (tx, recording) =
        crate::recorder::start(&mcap, recording_options(cell, &tuning, &prov), None)?;
    dir.keep();
    let mount = cfg
        .gravity
        .as_ref()
        .map_or(UnitQuaternion::identity(), |g| {
            UnitQuaternion::from_scaled_axis(Vector3::from(g.mount_rotation))
        });
    println!(
        "listening on {} for the robot at {}: run a program that holds the tool still (≥ 0.5 s, in free air) in {poses} orientations at least 10° apart, turning about two axes",
        cfg.robot.listen, cfg.robot.robot_ip
    );
    crate::stop::install()?;
    let mut sink = RecordSink::new(Some(tx));
    let mut on_pose = |n| println!("pose {n} of {poses}");
    let collecting = controller::calibration::Collecting::new(
        link,
        sensor,
        mount,
        poses,
        controller::calibration::CollectorConfig::default(),
        &mut on_pose,
    );
    let c = controller::calibration::calibrate(
        collecting,
        RunLimits {
            stop: Some(crate::stop::flag()),
            ..RunLimits::default()
        },
        &mut sink,
    )
    .map_err(|e| anyhow!("{e}"));
    drop(sink);
    println!("recorded {}", recording.finish(Vec::new())?);
    let c = c?;
    let m = c.model;
    println!(
        "fitted over {} poses: mass {:.4} kg, worst force residual {:.3} N\n",
        c.poses.len(),
        m.mass(),
        c.worst_force_residual
    );
    print!("{}", gravity_section(&m, mount));
    Ok(())
}

/// The `[gravity]` section of a cell file for a fitted model.
pub fn gravity_section(m: &GravityModel, mount: UnitQuaternion<f64>) -> String {
    let v = |a: &Vector3<f64>| format!("[{:.6}, {:.6}, {:.6}]", a.x, a.y, a.z);
    format!(
        "[gravity]\nsigned_mass = {:.6}\nmass_moment = {}\nforce_bias = {}\ntorque_bias = {}\nmount_rotation = {}\nmax_age = {}\n",
        m.signed_mass,
        v(&m.mass_moment),
        v(&m.force_bias),
        v(&m.torque_bias),
        v(&mount.scaled_axis()),
        default_max_age()
    )
}

/// Create `dir` and reserve a new file in it for this run's trace (`run-<unix time>.csv`, or
/// `run-<unix time>-N.csv` when a run of the same second has one), proven writable by writing the CSV
/// header to it. An unwritable or full directory is an error here, before the robot is started.
pub fn reserve_recording(dir: &Path) -> Result<PathBuf> {
    use std::io::Write;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("recording directory {}: cannot create it", dir.display()))?;
    let stamp = crate::provenance::file_stamp(std::time::SystemTime::now());
    for n in 0..1000 {
        let name = if n == 0 {
            format!("run-{stamp}.csv")
        } else {
            format!("run-{stamp}-{n}.csv")
        };
        let path = dir.join(name);
        let mut f = match std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => {
                bail!(
                    "recording directory {} is not writable ({}): fix it or set `record` in the cell file before starting the robot",
                    dir.display(),
                    os_error(&e)
                )
            }
        };
        let probe = writeln!(f, "{}", crate::record::HEADER).and_then(|()| f.sync_all());
        if let Err(e) = probe {
            drop(f);
            let _ = std::fs::remove_file(&path);
            bail!(
                "recording directory {} cannot take the trace ({}): free space or set `record` in the cell file before starting the robot",
                dir.display(),
                os_error(&e)
            );
        }
        return Ok(path);
    }
    bail!(
        "recording directory {}: 1000 recordings of this second exist already",
        dir.display()
    )
}

/// An I/O error's text without the "(os error N)" suffix (the kind is in the words already).
fn os_error(e: &std::io::Error) -> String {
    let t = e.to_string();
    match t.find(" (os error") {
        Some(i) => t[..i].to_string(),
        None => t,
    }
}
