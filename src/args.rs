//! The command line's argument types shared by the binary, the benches and the tests, and its numbers,
//! bounded where they are parsed: each parser accepts only what the physical
//! quantity can be, and says why in its error (clap prints it as `error: invalid value … for '--flag'`).

use std::net::{Ipv4Addr, SocketAddr};
use std::path::PathBuf;

use clap::{Args, ValueEnum};

/// Which robot backend `forcecell sim` drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RobotBackend {
    /// The KUKA RSI driver over loopback UDP against the simulated KUKA controller.
    Rsi,
    /// The ABB EGM driver (path correction) over loopback UDP against the simulated IRC5.
    Egm,
    /// The in-process robot (no wire).
    Inproc,
}

/// `forcecell sim` options for the robot side.
#[derive(Args, Clone, Debug)]
pub struct RsiArgs {
    /// Robot backend.
    #[arg(long, value_enum, default_value = "rsi")]
    pub robot: RobotBackend,
    /// Run the simulated controller on the wall clock (one datagram per period) instead of lockstep.
    #[arg(long)]
    pub realtime: bool,
    /// The dry run. RSI: start no simulated controller, listen on ADDR:PORT for any RSI client (a real
    /// KRC, another simulator); the simulated sensor computes force from the pose that client reports.
    /// With `--robot egm`: play the simulated IRC5 for an EGM client listening on ADDR:PORT (e.g.
    /// `forcecell run` with a `kind = "abb-egm"` cell file), with a simulated FT 300 for its sensor.
    #[arg(long, value_name = "ADDR:PORT")]
    pub external_robot: Option<SocketAddr>,
    /// With `--external-robot`: the client runs its own robot program over the process channels
    /// (sends `FcCmd`, reads `FcState`, as `forcecell rsi-config` configures a robot by default); the
    /// run lasts until it ends its session. Without it the client sends plain `<Rob>` datagrams and
    /// gets the scenario's own course (its program, if it has one, run on the client's behalf).
    #[arg(long, requires = "external_robot")]
    pub process_channels: bool,
    /// With `--external-robot`: the Ethernet configuration the client (robot) uses; the dry run reads
    /// what it says the robot sends and answers in its layout (default: `forcecell rsi-config`'s).
    #[arg(long, value_name = "FILE", requires = "external_robot")]
    pub ethernet_config: Option<std::path::PathBuf>,
    /// With `--external-robot` and `--robot egm`: where the simulated FT 300 that measures the virtual
    /// workpiece is linked (the client's `[sensor] port`); default: the pseudo-terminal's own path,
    /// printed.
    #[arg(long, value_name = "PATH", requires = "external_robot")]
    pub sensor_link: Option<std::path::PathBuf>,
}

/// The default wire: the RSI driver against the simulated KUKA controller over loopback UDP, in lockstep.
impl Default for RsiArgs {
    fn default() -> Self {
        Self {
            robot: RobotBackend::Rsi,
            realtime: false,
            external_robot: None,
            process_channels: false,
            ethernet_config: None,
            sensor_link: None,
        }
    }
}

/// Correction mode on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// `RSI_ON(#ABSOLUTE)`, HOLDON 1 (recommended).
    Absolute,
    /// `RSI_ON(#RELATIVE)`, HOLDON 0.
    Relative,
}

/// `forcecell rsi-config` options.
#[derive(Args, Clone, Debug)]
pub struct RsiConfigArgs {
    /// The PC's address as the robot sees it (IP_NUMBER).
    #[arg(long, default_value = "192.168.1.10")]
    pub ip: Ipv4Addr,
    /// UDP port (PORT).
    #[arg(long, default_value_t = 49152, allow_negative_numbers = true, value_parser = robot_port)]
    pub port: u16,
    /// Correction mode.
    #[arg(long, value_enum, default_value = "absolute")]
    pub mode: ModeArg,
    /// Use the 12 ms `#IPO` cycle instead of 4 ms `#IPO_FAST`.
    #[arg(long)]
    pub ipo12: bool,
    /// ETHERNET Timeout: late replies tolerated before RSI stops.
    #[arg(long, default_value_t = 100)]
    pub timeout: u32,
    /// Built-in tuning name or tuning TOML file: its loop limits set POSCORR and POSCORRMON.
    /// Without it, RSI's defaults (5 mm / 5°, 6 mm / 6°).
    #[arg(long)]
    pub tuning: Option<String>,
    /// Base name of the files.
    #[arg(long, default_value = "forcecell_rsi")]
    pub name: String,
    /// Output directory.
    #[arg(long, default_value = "out/rsi")]
    pub out: PathBuf,
    /// Leave out the process channels (FcCmd/FcState) and write the plain RSI_MOVECORR template:
    /// force control then runs from the first cycle at the tuning's set-point.
    #[arg(long)]
    pub no_process: bool,
    /// Polishing segments for the KRL template: FORCE_N:LENGTH_MM, comma-separated.
    #[arg(long, default_value = "10:50,30:100,10:50")]
    pub segments: String,
    /// Feed speed along the path, mm/s.
    #[arg(long, default_value_t = 20.0)]
    pub feed_mm_s: f64,
    /// FcCmd.Ramp for every set-point change, s (0: the tuning's own rate).
    #[arg(long, default_value_t = 0.5)]
    pub ramp: f64,
    /// How long the program waits for PRESSING and for OFF before it ends the pass cleanly, s.
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true, value_parser = wait_timeout_s)]
    pub wait_timeout: f64,
    /// $SEN_PINT index the program writes FcCmd.Mode to.
    #[arg(long, default_value_t = 1)]
    pub pint_mode: u8,
    /// $SEN_PINT index the program writes FcCmd.Seg to.
    #[arg(long, default_value_t = 2)]
    pub pint_seg: u8,
    /// $SEN_PINT index RSI writes FcState.State to.
    #[arg(long, default_value_t = 3)]
    pub pint_state: u8,
    /// $SEN_PINT index RSI writes FcState.Fault to.
    #[arg(long, default_value_t = 4)]
    pub pint_fault: u8,
    /// $SEN_PREA index the program writes FcCmd.F to.
    #[arg(long, default_value_t = 1)]
    pub prea_force: u8,
    /// $SEN_PREA index the program writes FcCmd.Ramp to.
    #[arg(long, default_value_t = 2)]
    pub prea_ramp: u8,
    /// $SEN_PREA index RSI writes FcState.F (measured force) to.
    #[arg(long, default_value_t = 3)]
    pub prea_measured: u8,
}

/// Parse a finite number in `[lo, hi]`; `why` is the physical reason for the bounds.
fn bounded(s: &str, lo: f64, hi: f64, unit: &str, why: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number"))?;
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(format!(
            "{} {unit} is outside [{lo}, {hi}] {unit}: {why}",
            s.trim()
        ))
    }
}

/// A sensor poll rate, Hz.
pub fn poll_rate_hz(s: &str) -> Result<f64, String> {
    bounded(
        s,
        1.0,
        10_000.0,
        "Hz",
        "the driver polls at most 10 kHz, and below 1 Hz every sample is stale before the next",
    )
}

/// How long a simulated node serves, s.
pub fn serve_seconds(s: &str) -> Result<f64, String> {
    let v = bounded(
        s,
        0.0,
        604_800.0,
        "s",
        "at most a week (Ctrl-C or SIGTERM ends it sooner; omit the flag to serve until then)",
    )?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err("0 s: the node must serve for a positive time".into())
    }
}

/// A force a simulated sensor reports, N.
pub fn sensor_force_n(s: &str) -> Result<f64, String> {
    bounded(
        s,
        -10_000.0,
        10_000.0,
        "N",
        "beyond the range of any F/T sensor this node simulates",
    )
}

/// Gauge noise of a simulated sensor, counts (standard deviation).
pub fn noise_counts(s: &str) -> Result<f64, String> {
    bounded(
        s,
        0.0,
        10_000.0,
        "counts",
        "a standard deviation is not negative, and 10 000 counts is noise larger than any reading",
    )
}

/// The CAN board's turnaround allowance, µs.
pub fn turnaround_us(s: &str) -> Result<u64, String> {
    let v: u64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a whole number of µs"))?;
    if v <= 10_000_000 {
        Ok(v)
    } else {
        Err(format!(
            "{v} µs is above 10 000 000 µs (10 s): a CAN board answers within milliseconds (a slow virtual interface within seconds), and every request waits this long before it times out"
        ))
    }
}

/// A control period, s.
pub fn period_s(s: &str) -> Result<f64, String> {
    bounded(
        s,
        1e-4,
        1.0,
        "s",
        "robot position loops run at 1 Hz to 10 kHz",
    )
}

/// A position-loop lag or a pure delay, s.
pub fn lag_s(s: &str) -> Result<f64, String> {
    bounded(
        s,
        0.0,
        1.0,
        "s",
        "a robot loop answering a second or more late cannot be force-controlled",
    )
}

/// A surface stiffness, N/m.
pub fn stiffness_n_per_m(s: &str) -> Result<f64, String> {
    let v = bounded(
        s,
        0.0,
        1e10,
        "N/m",
        "from any soft surface up to steel on steel",
    )?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err("0 N/m: a surface the tool presses on has a positive stiffness".into())
    }
}

/// A force set-point, N.
pub fn set_point_n(s: &str) -> Result<f64, String> {
    let v = bounded(
        s,
        0.0,
        10_000.0,
        "N",
        "a polishing set-point presses (> 0) and stays within an F/T sensor's range",
    )?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err("0 N: the set-point must press on the surface".into())
    }
}

/// The longest KRL wait of `rsi-config --wait-timeout`, s: `$TIMER` counts ms in a 32-bit INT.
pub const MAX_WAIT_TIMEOUT_S: f64 = 2_147_483.0;

/// How long the robot program waits for a process state, s.
pub fn wait_timeout_s(s: &str) -> Result<f64, String> {
    let v = bounded(
        s,
        0.0,
        MAX_WAIT_TIMEOUT_S,
        "s",
        "the robot program compares it with $TIMER, which counts ms in KRL's 32-bit INT",
    )?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err("0 s: the program must wait a positive time".into())
    }
}

/// A force a simulated Robotiq FT 300 reports, N.
pub fn ft300_force_n(s: &str) -> Result<f64, String> {
    bounded(
        s,
        -300.0,
        300.0,
        "N",
        "the FT 300 measures ±300 N (its stream's 16-bit counts saturate at ±327.67 N)",
    )
}

/// A Robotiq simulated sensor's force noise, N (standard deviation).
pub fn noise_n(s: &str) -> Result<f64, String> {
    bounded(
        s,
        0.0,
        1_000.0,
        "N",
        "a standard deviation is not negative, and 1000 N is noise beyond an FT 300's 300 N range",
    )
}

/// `forcecell egm-config`: the ABB controller's side of EGM path correction.
#[derive(Args, Debug, Clone)]
pub struct EgmConfigArgs {
    /// forcecell's address as the robot reaches it (the UDPUC device's -RemoteAddress).
    #[arg(long)]
    pub host: Ipv4Addr,
    /// forcecell's EGM port (-RemotePortNumber; the port the EGM link binds).
    #[arg(long, default_value_t = 6510, value_parser = robot_port)]
    pub port: u16,
    /// The UDPUC device's name (transmission protocol -Name, EGMSetupUC's device).
    #[arg(long, default_value = "FcEgmDevice")]
    pub device: String,
    /// The External Motion Interface Data instance (EGMSetupUC's configuration).
    #[arg(long, default_value = "FcPathCorr")]
    pub ext_motion: String,
    /// The RAPID module's name (file NAME.mod and NAME-settings.txt).
    #[arg(long, default_value = "FcEgm")]
    pub module: String,
    /// The tool (tooldata) of the pass; its tframe is EGM's sensor frame.
    #[arg(long, default_value = "tool0")]
    pub tool: String,
    /// The work object (wobjdata) of the pass's targets.
    #[arg(long, default_value = "wobj0")]
    pub wobj: String,
    /// The longest wait of the handshake (PRESSING, OFF), s.
    #[arg(long, default_value_t = 5.0)]
    pub max_wait: f64,
    /// The path-correction range per axis, mm: the cell file's `robot.correction_mm` (forcecell's
    /// envelope stays within 90 % of it).
    #[arg(long, default_value_t = 5.0)]
    pub correction_mm: f64,
    /// Output directory.
    #[arg(long, default_value = "out/egm")]
    pub out: PathBuf,
    /// Replace files of the same names in the output directory.
    #[arg(long)]
    pub force: bool,
}

/// A UDP port the robot sends to (0 would let the OS choose one the robot cannot know).
pub fn robot_port(s: &str) -> Result<u16, String> {
    let v: u16 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a port (1..=65535)"))?;
    if v == 0 {
        Err("port 0 lets the OS choose one at random; the robot's file needs the real port (1..=65535)".into())
    } else {
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_parser_refuses_the_absurd_and_says_why() {
        assert_eq!(poll_rate_hz("500"), Ok(500.0));
        assert!(poll_rate_hz("1e-20").unwrap_err().contains("stale"));
        assert!(poll_rate_hz("nan").is_err() && poll_rate_hz("inf").is_err());
        assert!(serve_seconds("1e20").unwrap_err().contains("week"));
        assert!(serve_seconds("0").is_err());
        assert!(sensor_force_n("nan").is_err());
        assert_eq!(sensor_force_n("-5"), Ok(-5.0));
        assert!(turnaround_us("18446744073709551615").is_err());
        assert_eq!(turnaround_us("20000"), Ok(20_000));
        assert!(period_s("1e300").is_err() && lag_s("1e8").is_err());
        assert!(stiffness_n_per_m("0").is_err() && set_point_n("-1").is_err());
        assert!(robot_port("0").unwrap_err().contains("port 0"));
        assert_eq!(robot_port("6008"), Ok(6008));
    }
}
