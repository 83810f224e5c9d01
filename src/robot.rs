//! The robot of a cell file, whichever family: the `[robot]` section (`kind = "kuka-rsi"`, the
//! default, or `kind = "abb-egm"`), checked whole before anything is opened, and [`RobotSpec::open`],
//! the one place the application turns a robot kind into a running [`hal::RobotLink`]. Adding a robot
//! family is one variant here: its options, its checks, its link.
//!
//! ```toml
//! [robot]                           # KUKA RSI (kind = "kuka-rsi" may be left out)
//! listen = "192.168.1.100:49152"
//! robot_ip = "192.168.1.10"
//! ethernet_config = "forcecell_rsi.xml"
//! mode = "absolute"
//! cycle_ms = 4
//! poscorr_mm = 5.0
//! poscorrmon_mm = 6.0
//! poscorr_deg = 15.0                # rotation limits: only with an orientation-following tuning
//! poscorrmon_deg = 18.0
//! timeout = 100
//! spin_us = 0                       # poll for the datagram this long around when it is due
//!
//! [robot]                           # ABB EGM path correction
//! kind = "abb-egm"
//! listen = "192.168.125.100:6510"   # the UDPUC entry's -RemoteAddress and -RemotePortNumber
//! robot_ip = "192.168.125.1"
//! correction_mm = 5.0               # the robot's path-correction range per axis
//! egm_settings = "robot/FcEgm-settings.txt"   # optional: what `forcecell egm-config` wrote
//! ```

use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result, anyhow, bail};
use controller::Tuning;
use hal::{Correction, Cycle, ErrorKind, RobotLink};
use serde::Deserialize;
use serde::de::Error as _;

/// The options every robot kind has.
const COMMON: &[&str] = &[
    "kind",
    "listen",
    "robot_ip",
    "cycle_ms",
    "watchdog_cycles",
    "max_speed",
    "process",
];
/// KUKA RSI's own options.
const RSI: &[&str] = &[
    "ethernet_config",
    "mode",
    "poscorr_mm",
    "poscorrmon_mm",
    "poscorr_deg",
    "poscorrmon_deg",
    "timeout",
    "spin_us",
];
/// ABB EGM's own options.
const EGM: &[&str] = &[
    "correction_mm",
    "egm_settings",
    "command_slot",
    "rws",
    "rws_user",
    "rws_password",
    "rws_task",
    "rws_module",
    "rws_fingerprint",
];

/// The robot side of a cell.
#[derive(Clone, Debug, PartialEq)]
pub struct RobotConfig {
    /// Where forcecell listens (RSI: the Ethernet config's `IP_NUMBER:PORT`; EGM: the UDPUC entry's
    /// `-RemoteAddress` and `-RemotePortNumber`).
    pub listen: SocketAddr,
    /// The robot controller's address: only its datagrams are accepted.
    pub robot_ip: IpAddr,
    /// The robot's cycle, ms (RSI: 4 or 12; EGM: its sample rate, a multiple of 4).
    pub cycle_ms: u32,
    /// Robot silent this many cycles → the run ends.
    pub watchdog_cycles: u32,
    /// The fastest the tool moves while the link runs, m/s: a reported pose jump beyond it is a
    /// counted fault (`implausible`), never a control input.
    pub max_speed: f64,
    /// The robot program commands the process (RSI: `FcCmd`/`FcState`; EGM: `RAPIDfromRobot.dnum`
    /// and the state channel). `false`: force control from the first cycle at the tuning's set-point.
    pub process: bool,
    /// The family and its own options.
    pub kind: RobotKind,
}

/// A robot family and the options that belong to it alone.
#[derive(Clone, Debug, PartialEq)]
pub enum RobotKind {
    /// KUKA RSI over UDP/XML (`kind = "kuka-rsi"`, the default).
    KukaRsi(RsiOptions),
    /// ABB EGM path correction over UDP/protobuf (`kind = "abb-egm"`).
    AbbEgm(EgmOptions),
}

/// The options shared by every kind, as written.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Common {
    listen: SocketAddr,
    robot_ip: IpAddr,
    #[serde(default = "default_cycle_ms")]
    cycle_ms: u32,
    #[serde(default = "default_watchdog")]
    watchdog_cycles: u32,
    #[serde(default = "default_max_speed")]
    max_speed: f64,
    #[serde(default)]
    process: bool,
}

/// KUKA RSI's own options.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RsiOptions {
    /// The robot's Ethernet config file; default: the layout `forcecell rsi-config` writes.
    #[serde(default)]
    pub ethernet_config: Option<PathBuf>,
    /// `absolute` (default) or `relative`.
    #[serde(default)]
    pub mode: crate::cell::ModeName,
    /// The robot's POSCORR translation limit, mm.
    #[serde(default = "default_poscorr")]
    pub poscorr_mm: f64,
    /// The robot's POSCORRMON translation limit, mm.
    #[serde(default = "default_poscorrmon")]
    pub poscorrmon_mm: f64,
    /// The robot's POSCORR rotation limit, degrees (absent: RSI's default 5° on the robot; an
    /// orientation-following tuning needs it said, and `rsi-config --config` writes it).
    #[serde(default)]
    pub poscorr_deg: Option<f64>,
    /// The robot's POSCORRMON rotation limit, degrees (absent: RSI's default 6°).
    #[serde(default)]
    pub poscorrmon_deg: Option<f64>,
    /// The robot's late-reply budget: the RSI ETHERNET object's `Timeout` (late replies tolerated
    /// before RSI stops the robot; RSI's default 100, as `rsi-config` writes it). The status line and
    /// the summary count the robot's late replies against it and warn at half.
    #[serde(default = "default_timeout")]
    pub timeout: u32,
    /// Poll for the robot's datagram from this long before it is due until this long after,
    /// instead of sleeping in the receive call, µs (the link's `spin`); 0, the default: sleep. Only
    /// worth it with the loop on a CPU of its own (docs/performance.md); at most a quarter cycle.
    #[serde(default)]
    pub spin_us: i64,
}

/// The largest rotation limit a cell file may give, degrees (the orientation stage's own bound).
pub const MAX_ROTATION_DEG: f64 = 30.0;
/// The largest POSCORRMON rotation limit a cell file may give, degrees.
pub const MAX_MONITOR_DEG: f64 = 45.0;

impl RsiOptions {
    /// The robot's POSCORR and POSCORRMON rotation limits, degrees (RSI's defaults 5° and 6° where
    /// the file says nothing).
    pub fn rotation_limits_deg(&self) -> (f64, f64) {
        (
            self.poscorr_deg.unwrap_or(5.0),
            self.poscorrmon_deg.unwrap_or(6.0),
        )
    }
}

/// ABB EGM's own options.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EgmOptions {
    /// The robot's path-correction range per axis, mm (`forcecell egm-config --correction-mm`); the
    /// driver's envelope stays within 90 % of it.
    #[serde(default = "default_correction")]
    pub correction_mm: f64,
    /// The settings file `forcecell egm-config` wrote: when given, its UDPUC entry must send to
    /// `listen` and its correction range must be `correction_mm`.
    #[serde(default)]
    pub egm_settings: Option<PathBuf>,
    /// Index in `RAPIDfromRobot.dnum` of the process mode (force, ramp and segment follow).
    #[serde(default)]
    pub command_slot: usize,
    /// Where the process state goes back to the RAPID program: the controller's Robot Web Services
    /// 2.0, `https://IP[:PORT]` (EGM's path correction cannot carry it; [`abb_egm::rws`]).
    #[serde(default)]
    pub rws: Option<String>,
    /// RWS user (the controller's shipped "Default User" when absent).
    #[serde(default)]
    pub rws_user: Option<String>,
    /// RWS password (the shipped "robotics" when absent).
    #[serde(default)]
    pub rws_password: Option<String>,
    /// The RAPID task of the module (`T_ROB1` when absent).
    #[serde(default)]
    pub rws_task: Option<String>,
    /// The module declaring `fc_phase`, `fc_force`, `fc_fault` (`egm-config`'s `FcEgm` when absent).
    #[serde(default)]
    pub rws_module: Option<String>,
    /// The controller certificate's SHA-256 (`openssl x509 -fingerprint -sha256`); without it the
    /// first certificate is accepted and its fingerprint printed at the end, to be pinned.
    #[serde(default)]
    pub rws_fingerprint: Option<String>,
}

impl EgmOptions {
    /// The state channel's configuration, checked (`None`: no `rws`).
    pub fn rws_config(&self) -> Result<Option<abb_egm::RwsConfig>> {
        use abb_egm::rws;
        let Some(url) = &self.rws else {
            if self.rws_user.is_some()
                || self.rws_password.is_some()
                || self.rws_task.is_some()
                || self.rws_module.is_some()
                || self.rws_fingerprint.is_some()
            {
                bail!(
                    "robot.rws_* options need robot.rws = \"https://IP[:PORT]\" (the controller's Robot Web Services)"
                );
            }
            return Ok(None);
        };
        let bad = |why: &str| {
            anyhow!(
                "robot.rws = {url:?}: {why}; write it as \"https://IP\" or \"https://IP:PORT\" \
                 (the controller's Robot Web Services 2.0, HTTPS; port {} when absent)",
                rws::DEFAULT_PORT
            )
        };
        let rest = url.strip_prefix("https://").ok_or_else(|| {
            bad("not https:// (RWS 2.0 is HTTPS only; RobotWare 6's RWS 1.0 is not supported)")
        })?;
        let rest = rest.strip_suffix('/').unwrap_or(rest);
        let addr: SocketAddr = match rest.parse::<SocketAddr>() {
            Ok(a) => a,
            Err(_) => match rest
                .trim_start_matches('[')
                .trim_end_matches(']')
                .parse::<IpAddr>()
            {
                Ok(ip) => SocketAddr::new(ip, rws::DEFAULT_PORT),
                Err(_) => return Err(bad("not an IP address with an optional port")),
            },
        };
        if addr.port() == 0 || addr.ip().is_unspecified() {
            return Err(bad("port 0 or an unspecified address"));
        }
        let user = self
            .rws_user
            .clone()
            .unwrap_or_else(|| rws::DEFAULT_USER.into());
        let password = self
            .rws_password
            .clone()
            .unwrap_or_else(|| rws::DEFAULT_PASSWORD.into());
        if user.is_empty() || user.contains(':') || user.chars().any(char::is_control) {
            bail!("robot.rws_user must be a non-empty name without ':' or control characters");
        }
        if password.chars().any(char::is_control) {
            bail!("robot.rws_password must not hold control characters");
        }
        let task = self
            .rws_task
            .clone()
            .unwrap_or_else(|| rws::DEFAULT_TASK.into());
        let module = self
            .rws_module
            .clone()
            .unwrap_or_else(|| abb_egm::rapid::DEFAULT_MODULE.into());
        for (key, v) in [("rws_task", &task), ("rws_module", &module)] {
            abb_egm::rapid::rapid_name(v).map_err(|e| anyhow!("robot.{key}: {e}"))?;
        }
        let fingerprint = match &self.rws_fingerprint {
            Some(t) => Some(rws::parse_fingerprint(t).ok_or_else(|| {
                anyhow!(
                    "robot.rws_fingerprint must be a SHA-256 as 64 hex digits (colons allowed), as \
                     `openssl x509 -noout -fingerprint -sha256` prints it, got {t:?}"
                )
            })?),
            None => None,
        };
        Ok(Some(abb_egm::RwsConfig {
            addr,
            server_name: None,
            target: rws::RwsTarget {
                authority: addr.to_string(),
                user,
                password,
                task,
                module,
            },
            fingerprint,
            timeout: abb_egm::rws_channel::DEFAULT_TIMEOUT,
        }))
    }
}

/// The largest late-reply budget accepted (`robot.timeout`): more than a minute of late replies at
/// 4 ms is no budget.
pub const MAX_TIMEOUT: u32 = 10_000;

fn default_cycle_ms() -> u32 {
    4
}
fn default_watchdog() -> u32 {
    25
}
fn default_poscorr() -> f64 {
    5.0
}
fn default_poscorrmon() -> f64 {
    6.0
}
fn default_correction() -> f64 {
    5.0
}
fn default_timeout() -> u32 {
    100
}
fn default_max_speed() -> f64 {
    kuka_rsi::LinkConfig::DEFAULT_MAX_SPEED
}

impl<'de> Deserialize<'de> for RobotConfig {
    /// The section whole: its kind first, then every key judged against that kind — an option of
    /// another kind is refused in one line that names both kinds.
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let mut table = toml::Table::deserialize(d)?;
        let kind = match table.remove("kind") {
            None => "kuka-rsi".to_string(),
            Some(toml::Value::String(s)) => s,
            Some(v) => {
                return Err(D::Error::custom(format!(
                    "robot.kind must be \"kuka-rsi\" or \"abb-egm\", got {v}"
                )));
            }
        };
        let (own, other, other_kind): (&[&str], &[&str], &str) = match kind.as_str() {
            "kuka-rsi" => (RSI, EGM, "abb-egm"),
            "abb-egm" => (EGM, RSI, "kuka-rsi"),
            k => {
                return Err(D::Error::custom(format!(
                    "robot.kind {k:?} is not a robot family forcecell drives: \"kuka-rsi\" or \"abb-egm\""
                )));
            }
        };
        let mut own_table = toml::Table::new();
        for key in table.keys().cloned().collect::<Vec<_>>() {
            if COMMON.contains(&key.as_str()) {
                continue;
            }
            if own.contains(&key.as_str()) {
                if let Some(v) = table.remove(&key) {
                    own_table.insert(key, v);
                }
            } else if other.contains(&key.as_str()) {
                return Err(D::Error::custom(format!(
                    "robot.{key} is a {other_kind} option, and this [robot] is kind = \"{kind}\": \
                     remove it (or set kind = \"{other_kind}\")"
                )));
            } else {
                return Err(D::Error::custom(format!(
                    "robot.{key} is not an option of kind = \"{kind}\" (its options: {}, {})",
                    COMMON[1..].join(", "),
                    own.join(", ")
                )));
            }
        }
        let common: Common = toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| D::Error::custom(format!("robot: {}", e.message())))?;
        let own = toml::Value::Table(own_table);
        let kind = match kind.as_str() {
            "abb-egm" => RobotKind::AbbEgm(own.try_into().map_err(|e: toml::de::Error| {
                D::Error::custom(format!("robot: {}", e.message()))
            })?),
            _ => RobotKind::KukaRsi(own.try_into().map_err(|e: toml::de::Error| {
                D::Error::custom(format!("robot: {}", e.message()))
            })?),
        };
        Ok(Self {
            listen: common.listen,
            robot_ip: common.robot_ip,
            cycle_ms: common.cycle_ms,
            watchdog_cycles: common.watchdog_cycles,
            max_speed: common.max_speed,
            process: common.process,
            kind,
        })
    }
}

impl RobotConfig {
    /// The family's name as the cell file spells it.
    pub fn kind_name(&self) -> &'static str {
        match self.kind {
            RobotKind::KukaRsi(_) => "kuka-rsi",
            RobotKind::AbbEgm(_) => "abb-egm",
        }
    }

    /// The robot's own name for its session (in end messages): `RSI` or `EGM`.
    pub fn session_name(&self) -> &'static str {
        match self.kind {
            RobotKind::KukaRsi(_) => "RSI",
            RobotKind::AbbEgm(_) => "EGM",
        }
    }

    /// The RSI options, if this is a KUKA RSI robot.
    pub fn rsi(&self) -> Option<&RsiOptions> {
        match &self.kind {
            RobotKind::KukaRsi(o) => Some(o),
            RobotKind::AbbEgm(_) => None,
        }
    }

    /// The EGM options, if this is an ABB EGM robot.
    pub fn egm(&self) -> Option<&EgmOptions> {
        match &self.kind {
            RobotKind::AbbEgm(o) => Some(o),
            RobotKind::KukaRsi(_) => None,
        }
    }

    /// The robot's own late-reply budget, when it reports late replies (RSI's `Timeout`; EGM reports
    /// none).
    pub fn late_budget(&self) -> Option<u32> {
        self.rsi().map(|o| o.timeout)
    }

    /// One line for the provenance and the start message.
    pub fn describe(&self) -> String {
        let family = match self.kind {
            RobotKind::KukaRsi(_) => "KUKA RSI",
            RobotKind::AbbEgm(_) => "ABB EGM path correction",
        };
        format!(
            "{family}, listening on {} for {}",
            self.listen, self.robot_ip
        )
    }

    /// Check the values of whichever kind this is (the cycle's bounds first: the watchdog's are
    /// given in cycles).
    pub fn validate(&self) -> Result<()> {
        match &self.kind {
            RobotKind::KukaRsi(o) => {
                if !(1..=MAX_TIMEOUT).contains(&o.timeout) {
                    bail!(
                        "robot.timeout is the RSI ETHERNET object's Timeout, 1..={} late replies (RSI's \
                         default 100), got {}",
                        MAX_TIMEOUT,
                        o.timeout
                    );
                }
                if self.cycle_ms != 4 && self.cycle_ms != 12 {
                    bail!("robot.cycle_ms must be 4 or 12, got {}", self.cycle_ms);
                }
                let quarter = i64::from(self.cycle_ms) * 250;
                if !(0..=quarter).contains(&o.spin_us) {
                    bail!(
                        "robot.spin_us must be 0..={quarter} µs (at most a quarter of the {} ms cycle), got {}",
                        self.cycle_ms,
                        o.spin_us
                    );
                }
                for (n, v) in [
                    ("poscorr_mm", o.poscorr_mm),
                    ("poscorrmon_mm", o.poscorrmon_mm),
                ] {
                    if !(v.is_finite() && v > 0.0) {
                        bail!("robot.{n} must be > 0 mm, got {v}");
                    }
                }
                for (n, v, most, why) in [
                    (
                        "poscorr_deg",
                        o.poscorr_deg,
                        MAX_ROTATION_DEG,
                        "past 30° a pad is on its edge and no orientation stage works",
                    ),
                    (
                        "poscorrmon_deg",
                        o.poscorrmon_deg,
                        MAX_MONITOR_DEG,
                        "a monitor beyond 1.5 × the largest usable POSCORR watches nothing",
                    ),
                ] {
                    if let Some(v) = v
                        && !(v.is_finite() && v > 0.0 && v <= most)
                    {
                        bail!("robot.{n} must be in (0, {most}] degrees ({why}), got {v}");
                    }
                }
                let (rot, mon) = o.rotation_limits_deg();
                if mon <= rot {
                    bail!(
                        "robot.poscorrmon_deg {mon} must be above robot.poscorr_deg {rot} (the \
                         monitor stops the robot beyond what the correction may reach)"
                    );
                }
            }
            RobotKind::AbbEgm(o) => {
                if self.cycle_ms == 0 || !self.cycle_ms.is_multiple_of(4) || self.cycle_ms > 1000 {
                    bail!(
                        "robot.cycle_ms must be EGM's sample rate, a multiple of 4 ms up to 1000, got {}",
                        self.cycle_ms
                    );
                }
                if !(o.correction_mm.is_finite() && (0.1..=100.0).contains(&o.correction_mm)) {
                    bail!(
                        "robot.correction_mm must be 0.1..=100 mm (the robot's path-correction range \
                         per axis, as `forcecell egm-config --correction-mm` writes it), got {}",
                        o.correction_mm
                    );
                }
                if o.command_slot > 1000 {
                    bail!(
                        "robot.command_slot must be 0..=1000 (an index in RAPIDfromRobot.dnum), got {}",
                        o.command_slot
                    );
                }
                let rws = o.rws_config()?;
                if self.process && rws.is_none() {
                    bail!(
                        "robot.process = true over EGM needs robot.rws = \"https://IP\": a path \
                         correction cannot carry the process state back to RAPID, Robot Web Services \
                         writes it (RobotWare 7; or run with process = false)"
                    );
                }
            }
        }
        let cycle = f64::from(self.cycle_ms) * 1e-3;
        let max_watchdog = (crate::cell::MAX_WATCHDOG_S / cycle).round() as u32;
        if !(1..=max_watchdog).contains(&self.watchdog_cycles) {
            bail!(
                "robot.watchdog_cycles must be 1..={max_watchdog} at a {} ms cycle, got {}: a robot silent for more than {} s has stopped sending, and the run must end",
                self.cycle_ms,
                self.watchdog_cycles,
                crate::cell::MAX_WATCHDOG_S
            );
        }
        if self.listen.port() == 0 {
            bail!(
                "robot.listen port 0 lets the OS choose one at random; the robot's configuration needs the real port (1..=65535)"
            );
        }
        Ok(())
    }

    /// Everything the link needs, checked (the robot's files read) before anything is bound: the
    /// driver's envelope inside 90 % of the robot's correction limit and never beyond the tuning's own,
    /// the rate limit of the tuning.
    pub fn spec(&self, tuning: &Tuning) -> Result<RobotSpec> {
        match &self.kind {
            RobotKind::KukaRsi(_) => crate::cell::rsi_link_config(self, tuning).map(RobotSpec::Rsi),
            RobotKind::AbbEgm(o) => self.egm_spec(o, tuning),
        }
    }

    fn egm_spec(&self, o: &EgmOptions, tuning: &Tuning) -> Result<RobotSpec> {
        if tuning.orientation.is_some() {
            bail!(
                "tuning {} follows the part's orientation, and EGM's path correction carries a \
                 translation only (EgmSensorPathCorr has no rotation): on an ABB robot use a tuning \
                 without [orientation] (e.g. robust)",
                tuning.name
            );
        }
        if let Some(p) = &o.egm_settings {
            let text = crate::input::read_text(p, "EGM settings", crate::input::MAX_CONFIG)?;
            egm_settings_agree(self, o, &text).map_err(|e| anyhow!("{}: {e}", p.display()))?;
        }
        let mut lc = abb_egm::LinkConfig::new(self.listen, abb_egm::RobotFilter::Ip(self.robot_ip));
        lc.period = Duration::from_millis(u64::from(self.cycle_ms));
        lc.watchdog_cycles = self.watchdog_cycles;
        lc.max_speed = self.max_speed;
        lc.process = self.process.then_some(abb_egm::CommandSlots {
            first: o.command_slot,
        });
        lc.range = abb_egm::CorrectionRange {
            translation: o.correction_mm * 1e-3,
        };
        lc.limits = abb_egm::Limits {
            max_translation: (0.9 * lc.range.translation).min(tuning.loop_cfg.max_offset),
            max_translation_step: tuning.loop_cfg.max_step,
        };
        // Short waits for the first datagram, so a stop ends the wait (the loop waits again).
        lc.first_contact_timeout = Some(Duration::from_millis(100));
        lc.validate().map_err(|e| anyhow!("robot: {e}"))?;
        Ok(RobotSpec::Egm {
            link: lc,
            state: if self.process { o.rws_config()? } else { None },
        })
    }
}

/// Whether the settings `forcecell egm-config` wrote agree with the cell file: the UDPUC entry sends
/// to `listen` (its port; its address too unless `listen` is a wildcard) and names `correction_mm`.
pub fn egm_settings_agree(r: &RobotConfig, o: &EgmOptions, text: &str) -> Result<(), String> {
    let f = abb_egm::rapid::SettingsFacts::parse(text);
    let Some(port) = f.port else {
        return Err(
            "no UDPUC -RemotePortNumber in it: is it the settings `forcecell egm-config` wrote?"
                .into(),
        );
    };
    if port != r.listen.port() {
        return Err(format!(
            "the UDPUC entry sends to port {port}, robot.listen is {} (rewrite both with `forcecell egm-config --port`)",
            r.listen
        ));
    }
    if let Some(host) = f.host
        && !r.listen.ip().is_unspecified()
        && IpAddr::V4(host) != r.listen.ip()
    {
        return Err(format!(
            "the UDPUC entry sends to {host}, robot.listen is {} (rewrite both with `forcecell egm-config --host`)",
            r.listen
        ));
    }
    match f.correction_mm {
        Some(mm) if (mm - o.correction_mm).abs() < 1e-9 => Ok(()),
        Some(mm) => Err(format!(
            "the path-correction range is {mm} mm, robot.correction_mm says {} mm (rewrite both with `forcecell egm-config --correction-mm`)",
            o.correction_mm
        )),
        None => {
            Err("no path-correction range in it: rewrite it with `forcecell egm-config`".into())
        }
    }
}

/// A robot link's configuration, checked, ready to bind.
#[derive(Clone, Debug)]
pub enum RobotSpec {
    /// KUKA RSI.
    Rsi(kuka_rsi::LinkConfig),
    /// ABB EGM path correction, and where the process state goes back (if anywhere).
    Egm {
        /// The link.
        link: abb_egm::LinkConfig,
        /// The process state's way back (Robot Web Services), with `process = true`.
        state: Option<abb_egm::RwsConfig>,
    },
}

impl RobotSpec {
    /// Bind the link: the one place the application turns a robot kind into a running driver.
    pub fn open(self) -> Result<CellRobot> {
        Ok(match self {
            Self::Rsi(lc) => {
                CellRobot::Rsi(Box::new(kuka_rsi::RsiLink::bind(lc).context("RSI link")?))
            }
            Self::Egm { link, state } => {
                let mut l = abb_egm::EgmLink::bind(link).context("EGM link")?;
                if let Some(cfg) = state {
                    l.set_state_channel(Box::new(
                        abb_egm::RwsChannel::start(cfg).context("the RWS writer")?,
                    ));
                }
                CellRobot::Egm(Box::new(l))
            }
        })
    }
}

/// A running robot link, whichever kind.
pub enum CellRobot {
    /// KUKA RSI.
    Rsi(Box<kuka_rsi::RsiLink>),
    /// ABB EGM path correction.
    Egm(Box<abb_egm::EgmLink>),
}

/// The error of a [`CellRobot`].
#[derive(Debug)]
pub enum CellRobotError {
    /// From the RSI driver.
    Rsi(kuka_rsi::LinkError),
    /// From the EGM driver.
    Egm(abb_egm::LinkError),
}

impl std::fmt::Display for CellRobotError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Rsi(e) => e.fmt(f),
            Self::Egm(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for CellRobotError {}

impl hal::Error for CellRobotError {
    fn kind(&self) -> ErrorKind {
        match self {
            Self::Rsi(e) => e.kind(),
            Self::Egm(e) => e.kind(),
        }
    }
}

impl RobotLink for CellRobot {
    type Error = CellRobotError;

    fn next_cycle(&mut self) -> Result<Cycle, CellRobotError> {
        match self {
            Self::Rsi(l) => l.next_cycle().map_err(CellRobotError::Rsi),
            Self::Egm(l) => l.next_cycle().map_err(CellRobotError::Egm),
        }
    }

    fn reply(&mut self, correction: &Correction) -> Result<(), CellRobotError> {
        match self {
            Self::Rsi(l) => l.reply(correction).map_err(CellRobotError::Rsi),
            Self::Egm(l) => l.reply(correction).map_err(CellRobotError::Egm),
        }
    }
}

impl CellRobot {
    /// The lines due about datagrams rejected while waiting for the robot (RSI; EGM reports its
    /// counters at the end only).
    pub fn rejection_lines(&mut self) -> Vec<String> {
        match self {
            Self::Rsi(l) => l.rejection_lines(),
            Self::Egm(_) => Vec::new(),
        }
    }

    /// The address actually bound.
    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        match self {
            Self::Rsi(l) => l.local_addr(),
            Self::Egm(l) => l.local_addr(),
        }
    }

    /// Say once (at the start) when the kernel gives the link's socket no receive timestamps: its late
    /// replies are then measured from the receive call's return.
    pub fn say_stamps(&self) {
        match self {
            Self::Rsi(l) => crate::rsi::say_stamps(l.kernel_stamps(), "RSI"),
            Self::Egm(l) => crate::rsi::say_stamps(l.kernel_stamps(), "EGM"),
        }
    }

    /// Print the link's counters and latency, and (RSI) what its first cycles showed that degrades
    /// control at the stiffness `kc` N/m, for a `cycle` s loop.
    pub fn print_diagnostics(&self, cycle: f64, kc: f64) {
        match self {
            Self::Rsi(l) => {
                crate::rsi::print_link(l.diagnostics());
                for w in l.diagnostics().advisories(cycle, kc) {
                    println!("{w}");
                }
            }
            Self::Egm(l) => {
                crate::egm::print_link(l.diagnostics());
                if let Some(r) = l.state_report() {
                    println!("  {r}");
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(robot: &str) -> Result<RobotConfig, String> {
        #[derive(Deserialize)]
        struct Wrap {
            robot: RobotConfig,
        }
        toml::from_str::<Wrap>(&format!("[robot]\n{robot}"))
            .map(|w| w.robot)
            .map_err(|e| e.message().to_string())
    }

    #[test]
    fn spin_is_off_by_default_and_at_most_a_quarter_cycle() {
        let base = "listen = \"127.0.0.1:49152\"\nrobot_ip = \"127.0.0.1\"\n";
        let r = parse(base).unwrap();
        assert_eq!(r.rsi().unwrap().spin_us, 0);
        let r = parse(&format!("{base}spin_us = 300\n")).unwrap();
        assert_eq!(r.rsi().unwrap().spin_us, 300);
        assert!(r.validate().is_ok());
        let r = parse(&format!("{base}spin_us = 1001\n")).unwrap();
        let e = r.validate().unwrap_err().to_string();
        assert!(e.contains("robot.spin_us must be 0..=1000 µs"), "{e}");
        let r = parse(&format!("{base}spin_us = -1\n")).unwrap();
        let e = r.validate().unwrap_err().to_string();
        assert!(e.contains("robot.spin_us"), "{e}");
        let e = parse(&format!("{base}kind = \"abb-egm\"\nspin_us = 300\n")).unwrap_err();
        assert!(e.contains("spin_us"), "{e}");
    }

    #[test]
    fn the_kind_defaults_to_rsi_and_each_kind_takes_its_own_options() {
        let r = parse("listen = \"127.0.0.1:49152\"\nrobot_ip = \"127.0.0.1\"\nposcorr_mm = 4.0\n")
            .unwrap();
        assert_eq!(r.kind_name(), "kuka-rsi");
        assert_eq!(r.rsi().unwrap().poscorr_mm, 4.0);
        assert_eq!(r.late_budget(), Some(100));
        let e = parse(
            "kind = \"abb-egm\"\nlisten = \"127.0.0.1:6510\"\nrobot_ip = \"127.0.0.1\"\ncorrection_mm = 3.0\n",
        )
        .unwrap();
        assert_eq!(e.kind_name(), "abb-egm");
        assert_eq!(e.egm().unwrap().correction_mm, 3.0);
        assert_eq!(e.late_budget(), None);
        assert!(e.validate().is_ok());
    }

    #[test]
    fn an_option_of_the_other_kind_is_refused_in_one_line() {
        let e = parse(
            "kind = \"abb-egm\"\nlisten = \"127.0.0.1:6510\"\nrobot_ip = \"127.0.0.1\"\nposcorr_mm = 5.0\n",
        )
        .unwrap_err();
        assert!(
            e.contains("robot.poscorr_mm is a kuka-rsi option") && e.contains("kind = \"abb-egm\""),
            "{e}"
        );
        assert!(!e.contains('\n'), "{e}");
        let e =
            parse("listen = \"127.0.0.1:6510\"\nrobot_ip = \"127.0.0.1\"\ncorrection_mm = 5.0\n")
                .unwrap_err();
        assert!(e.contains("robot.correction_mm is a abb-egm option"), "{e}");
        let e = parse("kind = \"fanuc\"\nlisten = \"127.0.0.1:6510\"\nrobot_ip = \"127.0.0.1\"\n")
            .unwrap_err();
        assert!(e.contains("\"fanuc\" is not a robot family"), "{e}");
        let e = parse("kind = \"abb-egm\"\nlisten = \"127.0.0.1:6510\"\nrobot_ip = \"127.0.0.1\"\nspeed = 1\n")
            .unwrap_err();
        assert!(
            e.contains("robot.speed is not an option of kind = \"abb-egm\""),
            "{e}"
        );
    }

    #[test]
    fn egm_values_are_bounded() {
        let base = "kind = \"abb-egm\"\nlisten = \"127.0.0.1:6510\"\nrobot_ip = \"127.0.0.1\"\n";
        for (extra, want) in [
            ("cycle_ms = 6\n", "multiple of 4"),
            ("correction_mm = 0.0\n", "robot.correction_mm"),
            ("correction_mm = nan\n", "robot.correction_mm"),
            ("process = true\n", "robot.rws"),
            ("rws = \"http://10.0.0.1\"\n", "https"),
            ("rws = \"https://robot.local\"\n", "IP address"),
            ("rws = \"https://10.0.0.1:0\"\n", "port 0"),
            ("rws_user = \"x\"\n", "need robot.rws"),
            (
                "rws = \"https://10.0.0.1\"\nrws_fingerprint = \"AB:CD\"\n",
                "SHA-256",
            ),
            (
                "rws = \"https://10.0.0.1\"\nrws_module = \"1x\"\n",
                "rws_module",
            ),
            (
                "rws = \"https://10.0.0.1\"\nrws_user = \"a:b\"\n",
                "rws_user",
            ),
            ("watchdog_cycles = 0\n", "watchdog_cycles"),
        ] {
            let r = parse(&format!("{base}{extra}")).unwrap();
            let e = r.validate().unwrap_err().to_string();
            assert!(e.contains(want), "{extra}: {e}");
        }
    }

    #[test]
    fn the_settings_egm_config_writes_agree_with_a_matching_cell_and_not_with_another() {
        let r = parse(
            "kind = \"abb-egm\"\nlisten = \"192.168.125.100:6510\"\nrobot_ip = \"192.168.125.1\"\ncorrection_mm = 6.0\n",
        )
        .unwrap();
        let o = r.egm().unwrap().clone();
        let mut c = abb_egm::rapid::EgmCellConfig::new([192, 168, 125, 100].into());
        c.correction_mm = 6.0;
        assert_eq!(egm_settings_agree(&r, &o, &c.settings()), Ok(()));
        c.port = 6511;
        assert!(
            egm_settings_agree(&r, &o, &c.settings())
                .unwrap_err()
                .contains("port 6511")
        );
        c.port = 6510;
        c.correction_mm = 5.0;
        assert!(
            egm_settings_agree(&r, &o, &c.settings())
                .unwrap_err()
                .contains("5 mm, robot.correction_mm says 6 mm")
        );
        c.correction_mm = 6.0;
        c.host = [10, 0, 0, 1].into();
        assert!(
            egm_settings_agree(&r, &o, &c.settings())
                .unwrap_err()
                .contains("sends to 10.0.0.1")
        );
    }
}
