//! `forcecell check --config cell.toml`: everything that can be known before the first robot cycle,
//! one finding a line, each problem with its fix. Ready (exit 0) when nothing failed; a warning
//! (real-time settings refused, an envelope the robot's limits cut) does not stop a run.

use std::fmt;
use std::net::UdpSocket;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::Result;
use hal::ForceSensor;

use crate::cell::{CellConfig, SensorConfig};
use crate::robot::{EgmOptions, RobotKind, RsiOptions};

/// Standard gravity, m/s².
const G: f64 = 9.806_65;
/// How long the sensor is read for its check, s.
const SENSOR_WINDOW: Duration = Duration::from_millis(500);
/// How far the measured weight may lie from the tool model's before the model is wrong for this
/// tool: the larger of this many newtons (an FT 300's noise and a still tool's drift)…
const WEIGHT_TOLERANCE_N: f64 = 1.0;
/// …and this fraction of the model's weight.
const WEIGHT_TOLERANCE_REL: f64 = 0.05;

/// How a finding reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// As it must be.
    Ok,
    /// Works, but not as well as it could: the run goes on.
    Warn,
    /// The run would fail or be unsafe: fix it first.
    Fail,
}

/// One line of the check.
#[derive(Clone, Debug, PartialEq)]
pub struct Finding {
    /// Its verdict.
    pub verdict: Verdict,
    /// What was checked and what was found.
    pub what: String,
    /// How to fix it (for a warning or a failure).
    pub fix: Option<String>,
}

impl Finding {
    fn ok(what: impl Into<String>) -> Self {
        Self {
            verdict: Verdict::Ok,
            what: what.into(),
            fix: None,
        }
    }
    fn warn(what: impl Into<String>, fix: impl Into<String>) -> Self {
        Self {
            verdict: Verdict::Warn,
            what: what.into(),
            fix: Some(fix.into()),
        }
    }
    fn fail(what: impl Into<String>, fix: impl Into<String>) -> Self {
        Self {
            verdict: Verdict::Fail,
            what: what.into(),
            fix: Some(fix.into()),
        }
    }
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let tag = match self.verdict {
            Verdict::Ok => "ok  ",
            Verdict::Warn => "warn",
            Verdict::Fail => "FAIL",
        };
        write!(f, "{tag}  {}", self.what)?;
        if let Some(fix) = &self.fix {
            write!(f, "\n      fix: {fix}")?;
        }
        Ok(())
    }
}

/// Check the cell file at `path`. `Err` when the file itself cannot be read or is invalid (the
/// usual one-line error); otherwise every finding, in order.
pub fn check(path: &Path) -> Result<Vec<Finding>> {
    let cell = CellConfig::load(path)?;
    let mut out = Vec::new();
    out.push(Finding::ok(format!(
        "cell file {} is valid",
        path.display()
    )));
    out.extend(addresses(&cell));
    match cell.tuning() {
        Ok(t) => {
            out.push(Finding::ok(format!("tuning {} loads", t.name)));
            out.extend(limits(&cell, &t));
        }
        Err(e) => out.push(Finding::fail(
            format!("tuning {}: {e:#}", cell.tuning),
            "name a shipped tuning (`forcecell sim --list`) or a tuning file",
        )),
    }
    out.push(sensor(&cell));
    out.extend(realtime(cell.realtime));
    Ok(out)
}

/// The listen address is this PC's and free; the robot's is another machine's.
fn addresses(cell: &CellConfig) -> Vec<Finding> {
    let r = &cell.robot;
    let mut out = Vec::new();
    match UdpSocket::bind(r.listen) {
        Ok(_) => out.push(Finding::ok(format!(
            "listen {} is this PC's address and the port is free",
            r.listen
        ))),
        Err(e) => out.push(Finding::fail(
            format!("listen {}: {e}", r.listen),
            format!(
                "robot.listen must be an address of this PC (`ip -br addr`) on the robot's network \
                 ({}), on a port nothing else uses",
                match r.kind {
                    RobotKind::KukaRsi(_) => "the IP_NUMBER of the robot's Ethernet config",
                    RobotKind::AbbEgm(_) => "the -RemoteAddress of the robot's UDPUC entry",
                }
            ),
        )),
    }
    let local = UdpSocket::bind((r.robot_ip, 0)).is_ok();
    if r.robot_ip.is_loopback() {
        out.push(Finding::ok(format!(
            "robot {} is on loopback: a simulated robot on this PC",
            r.robot_ip
        )));
    } else if local || r.robot_ip == r.listen.ip() {
        out.push(Finding::fail(
            format!("robot {} is this PC's own address", r.robot_ip),
            format!(
                "robot.robot_ip is the robot controller's address (its {} network interface), \
                 not this PC's",
                r.session_name()
            ),
        ));
    } else if r.robot_ip.is_unspecified() {
        out.push(Finding::fail(
            "robot_ip is unspecified (0.0.0.0): datagrams from anywhere would be answered",
            "set robot.robot_ip to the robot controller's address",
        ));
    } else {
        out.push(Finding::ok(format!(
            "robot {} is another machine (datagrams from anyone else are dropped)",
            r.robot_ip
        )));
    }
    out
}

/// The robot's limits against the tuning's envelope, and the robot's own files: per robot kind.
fn limits(cell: &CellConfig, t: &controller::Tuning) -> Vec<Finding> {
    match &cell.robot.kind {
        RobotKind::KukaRsi(o) => rsi_limits(cell, o, t),
        RobotKind::AbbEgm(o) => egm_limits(cell, o, t),
    }
}

/// The tuning's envelope against the 90 % of a robot limit the driver keeps to.
fn envelope(t: &controller::Tuning, limit_mm: f64, name: &str, fix: &str) -> Finding {
    let envelope = t.loop_cfg.max_offset;
    let usable = 0.9 * limit_mm * 1e-3;
    if envelope > usable {
        Finding::warn(
            format!(
                "the tuning's envelope ±{:.1} mm is cut to ±{:.1} mm by {name} {:.1} mm (90 %)",
                envelope * 1e3,
                usable * 1e3,
                limit_mm
            ),
            fix,
        )
    } else {
        Finding::ok(format!(
            "the tuning's envelope ±{:.1} mm lies within {name} {limit_mm:.1} mm",
            envelope * 1e3
        ))
    }
}

/// KUKA RSI: POSCORR and POSCORRMON, the Ethernet config's layout, a `.rsix` beside it.
fn rsi_limits(cell: &CellConfig, o: &RsiOptions, t: &controller::Tuning) -> Vec<Finding> {
    let mut out = vec![envelope(
        t,
        o.poscorr_mm,
        "POSCORR",
        "raise POSCORR on the robot (`forcecell rsi-config --tuning` writes it) and \
         robot.poscorr_mm together, or accept the smaller envelope",
    )];
    if o.poscorrmon_mm < o.poscorr_mm {
        out.push(Finding::fail(
            format!(
                "POSCORRMON {:.1} mm is below POSCORR {:.1} mm: the monitor stops the robot \
                 inside the correction's own range",
                o.poscorrmon_mm, o.poscorr_mm
            ),
            "set robot.poscorrmon_mm (and the robot's POSCORRMON) above robot.poscorr_mm",
        ));
    }
    match cell.robot_spec(t) {
        Ok(_) => {
            out.push(Finding::ok(format!(
                "the Ethernet config ({}) gives the driver what it needs",
                o.ethernet_config
                    .as_ref()
                    .map_or("forcecell's own layout".to_string(), |p| p
                        .display()
                        .to_string())
            )));
            if let Some(p) = &o.ethernet_config {
                out.extend(rsix_beside(p, o.poscorr_mm));
            }
        }
        Err(e) => out.push(Finding::fail(
            format!("{e:#}"),
            "write the robot's files with `forcecell rsi-config` and give that XML as \
             robot.ethernet_config",
        )),
    }
    out
}

/// ABB EGM: the correction range against the envelope, and the settings `egm-config` wrote (the
/// UDPUC entry sends to `listen`, the same correction range).
fn egm_limits(cell: &CellConfig, o: &EgmOptions, t: &controller::Tuning) -> Vec<Finding> {
    let mut out = vec![envelope(
        t,
        o.correction_mm,
        "the path-correction range",
        "raise the robot's path-correction range and robot.correction_mm together \
         (`forcecell egm-config --correction-mm`), or accept the smaller envelope",
    )];
    match cell.robot_spec(t) {
        Ok(_) => match &o.egm_settings {
            Some(p) => out.push(Finding::ok(format!(
                "{}: the UDPUC entry sends to port {} and the path-correction range is {:.1} mm, \
                 as the cell file says",
                p.display(),
                cell.robot.listen.port(),
                o.correction_mm
            ))),
            None => out.push(Finding::warn(
                "no robot.egm_settings: the robot's UDPUC entry and correction range are not checked \
                 against the cell file",
                "write the robot's files with `forcecell egm-config` and give its \
                 NAME-settings.txt as robot.egm_settings",
            )),
        },
        Err(e) => out.push(Finding::fail(
            format!("{e:#}"),
            "write the robot's files with `forcecell egm-config` (--host, --port, \
             --correction-mm as in the cell file) and give its NAME-settings.txt as \
             robot.egm_settings",
        )),
    }
    if cell.robot.process {
        out.push(rws_reachable(o));
    }
    out
}

/// With the process contract over EGM: the controller's Robot Web Services answers a read of
/// `fc_phase` with the cell file's credentials, over TLS with the pinned certificate (nothing is written).
fn rws_reachable(o: &EgmOptions) -> Finding {
    let cfg = match o.rws_config() {
        Ok(Some(c)) => c,
        Ok(None) => {
            return Finding::fail(
                "robot.process = true over EGM without robot.rws: the process state has no way back",
                "set robot.rws = \"https://IP\" (the controller's Robot Web Services 2.0)",
            );
        }
        Err(e) => return Finding::fail(format!("{e:#}"), "fix robot.rws* in the cell file"),
    };
    let url = format!("https://{}", cfg.addr);
    match abb_egm::rws_channel::probe(&cfg) {
        Ok(_) if cfg.fingerprint.is_some() => Finding::ok(format!(
            "Robot Web Services at {url}: {}/{} readable, the pinned certificate presented",
            cfg.target.module,
            abb_egm::rws::STATE_SYMBOLS[0]
        )),
        Ok(fp) => Finding::warn(
            format!(
                "Robot Web Services at {url}: {}/{} readable, but its certificate is not pinned \
                 (SHA-256 {})",
                cfg.target.module,
                abb_egm::rws::STATE_SYMBOLS[0],
                abb_egm::rws::fingerprint_text(&fp)
            ),
            "after checking it on the controller, set robot.rws_fingerprint to that SHA-256",
        ),
        Err(e) => Finding::fail(
            format!("Robot Web Services at {url}: {e}"),
            "check robot.rws, the user and password, that the generated module is loaded in the \
             task, and that the controller runs RobotWare 7 (RWS 2.0)",
        ),
    }
}

/// A signal-flow context (`.rsix`) beside the Ethernet config: its POSCORR against the cell file's.
fn rsix_beside(xml: &Path, poscorr_mm: f64) -> Option<Finding> {
    let rsix = xml.with_extension("rsix");
    let text = std::fs::read_to_string(&rsix).ok()?;
    let upper = text
        .split("<Parameter ")
        .filter(|p| p.contains("Name=\"UpperLimZ\""))
        .find_map(|p| {
            let v = p.split("ParamValue=\"").nth(1)?.split('"').next()?;
            v.parse::<f64>().ok()
        });
    Some(match upper {
        Some(mm) if (mm - poscorr_mm).abs() < 1e-6 => Finding::ok(format!(
            "{}: POSCORR {mm:.1} mm agrees with robot.poscorr_mm",
            rsix.display()
        )),
        Some(mm) => Finding::fail(
            format!(
                "{}: POSCORR is {mm:.1} mm, robot.poscorr_mm says {poscorr_mm:.1} mm",
                rsix.display()
            ),
            "make robot.poscorr_mm the POSCORR the robot runs (rewrite both with \
             `forcecell rsi-config`)",
        ),
        None => Finding::warn(
            format!("{}: no POSCORR limit found in it", rsix.display()),
            "check POSCORR in the robot's RSI editor against robot.poscorr_mm",
        ),
    })
}

/// The sensor answers, and the gravity section matches the tool hanging on it.
fn sensor(cell: &CellConfig) -> Finding {
    let name = match &cell.sensor {
        SensorConfig::Ati { can, base, .. } => format!("ATI sensor at base {base:#x} on {can}"),
        SensorConfig::Robotiq { port, .. } => format!("Robotiq FT 300 on {}", port.display()),
    };
    let mut s = match cell.sensor.open(false, None) {
        Ok(s) => s,
        Err(e) => {
            return Finding::fail(
                format!("{name}: {e:#}"),
                "check the cable, the power, the interface (`ip -details link show`) or the \
                 serial device, and the address in [sensor]",
            );
        }
    };
    let start = Instant::now();
    let (mut n, mut sum) = (0u32, hal::Vector3::zeros());
    while start.elapsed() < SENSOR_WINDOW {
        if let Ok(x) = s.read()
            && x.wrench.is_finite()
        {
            n += 1;
            sum += x.wrench.force;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    if n == 0 {
        return Finding::fail(
            format!("{name}: no sample in {} ms", SENSOR_WINDOW.as_millis()),
            "the sensor answered its start-up but streams nothing: check its rate and wiring",
        );
    }
    let mean = sum / f64::from(n);
    let Some(g) = &cell.gravity else {
        return Finding::ok(format!(
            "{name} answers: {n} samples, |F| {:.2} N (no [gravity] section to check)",
            mean.norm()
        ));
    };
    if cell.sensor.zero_at_start() {
        return Finding::ok(format!(
            "{name} answers: {n} samples (zeroed at start: the weight is checked by `forcecell \
             calibrate`)"
        ));
    }
    let weight = (mean - hal::Vector3::from(g.force_bias)).norm();
    let model = g.signed_mass.abs() * G;
    let tol = WEIGHT_TOLERANCE_N.max(WEIGHT_TOLERANCE_REL * model);
    if (weight - model).abs() <= tol {
        Finding::ok(format!(
            "{name} answers: {n} samples; the tool weighs {weight:.2} N, the [gravity] model \
             {model:.2} N"
        ))
    } else {
        Finding::fail(
            format!(
                "{name}: the tool weighs {weight:.2} N less the bias, the [gravity] model says \
                 {model:.2} N (±{tol:.2} N)"
            ),
            "run `forcecell calibrate` with this tool and paste the [gravity] section it prints",
        )
    }
}

/// The cell file's real-time settings, tried on a scratch thread.
fn realtime(want: crate::rt::Realtime) -> Vec<Finding> {
    let applied = std::thread::spawn(move || want.apply_to_cycle_thread())
        .join()
        .unwrap_or_default();
    // The memory lock is the process's: the check must not keep it.
    let _ = nix::sys::mman::munlockall();
    let refused = applied.refusals();
    if refused.is_empty() {
        vec![Finding::ok(format!(
            "real-time settings granted (SCHED_FIFO {}, memory lock)",
            want.priority
        ))]
    } else {
        refused
            .into_iter()
            .map(|r| {
                let (what, fix) = r.split_once(": ").unwrap_or((r, ""));
                Finding::warn(what.to_string(), fix.to_string())
            })
            .collect()
    }
}

/// Whether the findings say ready (nothing failed).
pub fn ready(findings: &[Finding]) -> bool {
    findings.iter().all(|f| f.verdict != Verdict::Fail)
}
