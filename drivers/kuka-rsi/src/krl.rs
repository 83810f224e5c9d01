//! The robot-side files that match a forcecell configuration: the Ethernet config XML and a KRL
//! program template with the RSI settings it relies on spelled out.

use core::fmt::Write as _;

use crate::config::{EthernetConfig, Indx};
use crate::limits::PoscorrLimits;
use crate::link::CorrectionMode;
use crate::process::{FC_CMD, FC_STATE};

/// What the robot must be set up with: the Ethernet config, the KRL template and the signal-flow
/// context (`.rsix`, [`RobotSetup::rsix`]) it loads; the template's header lists the context's objects
/// and parameters too (for RSI 3, where the diagram is drawn in RSI Visual).
#[derive(Clone, Debug, PartialEq)]
pub struct RobotSetup {
    /// The Ethernet config the ETHERNET object loads.
    pub ethernet: EthernetConfig,
    /// Correction mode for `RSI_ON`.
    pub mode: CorrectionMode,
    /// `#IPO_FAST` (4 ms) when true, `#IPO` (12 ms) otherwise.
    pub ipo_fast: bool,
    /// ETHERNET `Timeout`: late replies tolerated before RSI stops.
    pub timeout: u32,
    /// ETHERNET `Precision`: decimals the robot sends.
    pub precision: u8,
    /// POSCORR limits (the driver's envelope lies inside).
    pub poscorr: PoscorrLimits,
    /// POSCORRMON limits (translation m, rotation rad).
    pub poscorrmon: PoscorrLimits,
    /// Base name of the files (`<name>.xml`, `<name>.src`, `<name>.rsix`).
    pub name: String,
    /// The polishing process over the process channels; `None` writes the plain RSI template.
    /// When set, `ethernet` must declare the `FcCmd` / `FcState` elements
    /// ([`EthernetConfig::with_process`]).
    pub process: Option<ProcessSetup>,
}

/// Which `$SEN_PINT` / `$SEN_PREA` entries carry the process channels between the robot program and
/// RSI. Inputs to RSI are read from KRL through SEN_PINT / SEN_PREA objects, outputs are written to
/// KRL through MAP2SEN_PINT / MAP2SEN_PREA objects. The object names and the indices' meaning are
/// unverified against KUKA's manual: every index is configurable and listed in both generated files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProcessIo {
    /// `$SEN_PINT[..]` → `FcCmd.Mode`.
    pub mode_pint: u8,
    /// `$SEN_PINT[..]` → `FcCmd.Seg`.
    pub seg_pint: u8,
    /// `$SEN_PREA[..]` → `FcCmd.F` (N).
    pub force_prea: u8,
    /// `$SEN_PREA[..]` → `FcCmd.Ramp` (s).
    pub ramp_prea: u8,
    /// `FcState.State` → `$SEN_PINT[..]`.
    pub state_pint: u8,
    /// `FcState.Fault` → `$SEN_PINT[..]`.
    pub fault_pint: u8,
    /// `FcState.F` (N) → `$SEN_PREA[..]`.
    pub measured_prea: u8,
}

impl Default for ProcessIo {
    /// `$SEN_PINT[1]` Mode, `[2]` Seg, `[3]` State, `[4]` Fault; `$SEN_PREA[1]` F, `[2]` Ramp,
    /// `[3]` measured F.
    fn default() -> Self {
        Self {
            mode_pint: 1,
            seg_pint: 2,
            force_prea: 1,
            ramp_prea: 2,
            state_pint: 3,
            fault_pint: 4,
            measured_prea: 3,
        }
    }
}

impl ProcessIo {
    /// The largest `$SEN_PINT` / `$SEN_PREA` index (the arrays hold 20 entries; unverified).
    pub const MAX_INDEX: u8 = 20;

    /// Indices within 1..=20, none used twice in the same array.
    pub fn validate(&self) -> Result<(), String> {
        let pint = [
            ("mode", self.mode_pint),
            ("seg", self.seg_pint),
            ("state", self.state_pint),
            ("fault", self.fault_pint),
        ];
        let prea = [
            ("force", self.force_prea),
            ("ramp", self.ramp_prea),
            ("measured force", self.measured_prea),
        ];
        for (array, list) in [("$SEN_PINT", &pint[..]), ("$SEN_PREA", &prea[..])] {
            for (k, (name, i)) in list.iter().enumerate() {
                if !(1..=Self::MAX_INDEX).contains(i) {
                    return Err(format!(
                        "{array} index {i} for {name} is outside 1..={}",
                        Self::MAX_INDEX
                    ));
                }
                if let Some((other, _)) = list[..k].iter().find(|(_, j)| j == i) {
                    return Err(format!("{array}[{i}] is used for both {other} and {name}"));
                }
            }
        }
        Ok(())
    }
}

/// One path segment of the polishing template.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Force set-point, N (> 0).
    pub force: f64,
    /// Path length, m (> 0), moved along the base's X in the template (replace with the taught path).
    pub length: f64,
}

/// The polishing program of the KRL template.
#[derive(Clone, Debug, PartialEq)]
pub struct ProcessSetup {
    /// `$SEN_PINT` / `$SEN_PREA` indices.
    pub io: ProcessIo,
    /// The path segments, in order (at least one).
    pub segments: Vec<Segment>,
    /// Feed speed along the path, m/s.
    pub feed: f64,
    /// `FcCmd.Ramp`, s (0: the tuning's own rate).
    pub ramp: f64,
    /// How long the program waits for PRESSING (after PRESS) and for OFF (after RELEASE), s.
    pub wait_timeout: f64,
    /// The `$TIMER` used for those waits.
    pub timer: u8,
    /// The interrupt (its number is its priority) that catches a FAULT mid-path.
    pub interrupt: u8,
    /// The `$FLAG` the fault's interrupt routine sets for the main program.
    pub flag: u16,
}

impl ProcessSetup {
    /// Three segments of 10, 30, 10 N over 50, 100, 50 mm at 20 mm/s, ramp 0.5 s, waits of 10 s on
    /// `$TIMER[1]`, default indices.
    pub fn default_polish() -> Self {
        Self {
            io: ProcessIo::default(),
            segments: vec![
                Segment {
                    force: 10.0,
                    length: 0.05,
                },
                Segment {
                    force: 30.0,
                    length: 0.10,
                },
                Segment {
                    force: 10.0,
                    length: 0.05,
                },
            ],
            feed: 0.02,
            ramp: 0.5,
            wait_timeout: 10.0,
            timer: 1,
            interrupt: 21,
            flag: 1,
        }
    }

    /// Check the values.
    pub fn validate(&self) -> Result<(), String> {
        self.io.validate()?;
        if self.segments.is_empty() {
            return Err("the polishing program needs at least one segment".into());
        }
        for (k, s) in self.segments.iter().enumerate() {
            if !(s.force.is_finite() && s.force > 0.0 && s.length.is_finite() && s.length > 0.0) {
                return Err(format!(
                    "segment {}: force and length must be > 0, got {} N, {} m",
                    k + 1,
                    s.force,
                    s.length
                ));
            }
        }
        if !(self.feed.is_finite() && self.feed > 0.0 && self.feed <= 2.0) {
            return Err(format!("feed must be in (0, 2] m/s, got {}", self.feed));
        }
        if !(self.ramp.is_finite() && self.ramp >= 0.0) {
            return Err(format!("ramp must be >= 0 s, got {}", self.ramp));
        }
        if !(self.wait_timeout.is_finite() && self.wait_timeout > 0.0) {
            return Err(format!(
                "wait timeout must be > 0 s, got {}",
                self.wait_timeout
            ));
        }
        // The program compares $TIMER (ms) with it: a KRL INT is 32-bit.
        if self.wait_timeout * 1000.0 > f64::from(i32::MAX) {
            return Err(format!(
                "wait timeout must be at most {} s (KRL's $TIMER counts ms in a 32-bit INT), got {}",
                i32::MAX / 1000,
                self.wait_timeout
            ));
        }
        if !(1..=32).contains(&self.timer) {
            return Err(format!("$TIMER index must be 1..=32, got {}", self.timer));
        }
        // KSS reserves priorities 3 and 40..=80 for the system.
        if !(1..=128).contains(&self.interrupt)
            || self.interrupt == 3
            || (40..=80).contains(&self.interrupt)
        {
            return Err(format!(
                "interrupt must be 1..=128 but not 3 or 40..=80 (system), got {}",
                self.interrupt
            ));
        }
        if !(1..=1024).contains(&self.flag) {
            return Err(format!("$FLAG index must be 1..=1024, got {}", self.flag));
        }
        Ok(())
    }

    /// The mapping between `$SEN_PINT`/`$SEN_PREA` and the Ethernet elements, one line each, for the
    /// header comments and for the integrator.
    pub fn mapping(&self, ethernet: &EthernetConfig) -> Vec<String> {
        let indx = |tag: &str| {
            ethernet
                .send
                .iter()
                .chain(&ethernet.receive)
                .find(|e| e.tag == tag)
                .map_or_else(
                    || "missing".to_owned(),
                    |e| match e.indx {
                        Indx::Channel(i) => format!("INDX {i}"),
                        Indx::Internal => "INTERNAL".to_owned(),
                    },
                )
        };
        let io = &self.io;
        // The legends are hal's code tables (KRL's own spelling: upper case for modes and states).
        let mode_legend = hal::ProcessMode::legend().to_uppercase();
        let mut out = vec![
            "KRL -> RSI (ETHERNET inputs, read through SEN_PINT / SEN_PREA objects):".to_owned(),
        ];
        for (var, tag, what) in [
            (
                format!("$SEN_PINT[{}]", io.mode_pint),
                format!("{FC_CMD}.Mode"),
                mode_legend.as_str(),
            ),
            (
                format!("$SEN_PREA[{}]", io.force_prea),
                format!("{FC_CMD}.F"),
                "force set-point, N",
            ),
            (
                format!("$SEN_PREA[{}]", io.ramp_prea),
                format!("{FC_CMD}.Ramp"),
                "ramp time, s",
            ),
            (
                format!("$SEN_PINT[{}]", io.seg_pint),
                format!("{FC_CMD}.Seg"),
                "path segment number",
            ),
        ] {
            out.push(format!("  {var:<14} -> {tag:<14} ({}) {what}", indx(&tag)));
        }
        out.push(
            "RSI -> KRL (ETHERNET outputs, written through MAP2SEN_PINT / MAP2SEN_PREA objects):"
                .to_owned(),
        );
        let fault_legend = hal::ProcessFault::legend();
        let phase_legend = hal::ProcessPhase::legend().to_uppercase();
        for (var, tag, what) in [
            (
                format!("$SEN_PINT[{}]", io.state_pint),
                format!("{FC_STATE}.State"),
                phase_legend.as_str(),
            ),
            (
                format!("$SEN_PREA[{}]", io.measured_prea),
                format!("{FC_STATE}.F"),
                "measured normal force, N",
            ),
            (
                format!("$SEN_PINT[{}]", io.fault_pint),
                format!("{FC_STATE}.Fault"),
                &fault_legend,
            ),
        ] {
            out.push(format!("  {var:<14} <- {tag:<14} ({}) {what}", indx(&tag)));
        }
        out.push(
            "UNVERIFIED: the object names SEN_PINT, SEN_PREA, MAP2SEN_PINT, MAP2SEN_PREA and these indices"
                .to_owned(),
        );
        out.push(
            "are not checked against KUKA's RSI manual; check them in RSI Visual before the first run."
                .to_owned(),
        );
        out
    }
}

impl RobotSetup {
    /// The file names and contents to copy to the robot.
    pub fn files(&self) -> Vec<(String, String)> {
        vec![
            (format!("{}.xml", self.name), self.xml()),
            (format!("{}.src", self.name), self.krl()),
            (format!("{}.rsix", self.name), self.rsix()),
        ]
    }

    /// Check the values (the process program and that the config carries its channels).
    pub fn validate(&self) -> Result<(), String> {
        self.ethernet.validate().map_err(|e| e.to_string())?;
        if let Some(p) = &self.process {
            p.validate()?;
            let has = |list: &[crate::config::ConfigElement], tag: &str| {
                list.iter().any(|e| e.tag.starts_with(tag))
            };
            if !has(&self.ethernet.send, "FcCmd.") || !has(&self.ethernet.receive, "FcState.") {
                return Err(
                    "the polishing template needs the FcCmd/FcState elements in the Ethernet config"
                        .into(),
                );
            }
        }
        Ok(())
    }

    /// The Ethernet config XML; with the process channels, a header comment lists how they map to
    /// `$SEN_PINT` / `$SEN_PREA`.
    pub fn xml(&self) -> String {
        let body = self.ethernet.to_xml();
        let Some(p) = &self.process else {
            return body;
        };
        let mut x = String::new();
        let _ = writeln!(x, "<!--");
        let _ = writeln!(
            x,
            "  Generated by forcecell rsi-config for {}.src: RSI Ethernet config with the process channels.",
            self.name
        );
        for line in p.mapping(&self.ethernet) {
            // An XML comment must not contain a double hyphen.
            let _ = writeln!(x, "  {}", line.replace("--", "-"));
        }
        let _ = writeln!(x, "-->");
        x.push_str(&body);
        x
    }

    /// The KRL program template: the polishing program when [`process`](Self::process) is set,
    /// else the plain `RSI_MOVECORR` template.
    pub fn krl(&self) -> String {
        if let Some(p) = &self.process {
            return self.polish_krl(p);
        }
        let mode = match self.mode {
            CorrectionMode::Absolute => "#ABSOLUTE",
            CorrectionMode::Relative => "#RELATIVE",
        };
        let ipo = if self.ipo_fast { "#IPO_FAST" } else { "#IPO" };
        let n = &self.name;
        let mut k = String::new();
        let _ = writeln!(k, "DEF {n}()");
        let _ = writeln!(
            k,
            "  ; Generated by `forcecell rsi-config`: RSI for forcecell's force control."
        );
        self.header(&mut k);
        let _ = writeln!(k, "  DECL INT ret");
        let _ = writeln!(k, "  DECL INT CONTID");
        let _ = writeln!(k);
        let _ = writeln!(k, "  BAS(#INITMOV, 0)");
        let _ = writeln!(k, "  PTP $AXIS_ACT_MEAS");
        let _ = writeln!(k, "  ; move to the start of the polishing path here");
        let _ = writeln!(k);
        let _ = writeln!(k, "  ret = RSI_CREATE(\"{n}.rsix\", CONTID, TRUE)");
        let _ = writeln!(k, "  IF (ret <> RSIOK) THEN");
        let _ = writeln!(k, "    HALT");
        let _ = writeln!(k, "  ENDIF");
        let _ = writeln!(k, "  ret = RSI_ON({mode}, {ipo})");
        let _ = writeln!(k, "  IF (ret <> RSIOK) THEN");
        let _ = writeln!(k, "    HALT");
        let _ = writeln!(k, "  ENDIF");
        let _ = writeln!(k, "  RSI_MOVECORR()");
        let _ = writeln!(k, "  ret = RSI_OFF()");
        let _ = writeln!(k, "  ret = RSI_DELETE(CONTID)");
        let _ = writeln!(k, "END");
        k
    }
}

fn krl_real(v: f64) -> String {
    format!("{v:.3}")
}

impl RobotSetup {
    fn header(&self, k: &mut String) {
        let n = &self.name;
        let e = &self.ethernet;
        let _ = writeln!(
            k,
            "  ; Ethernet config: {n}.xml -> C:\\KRC\\ROBOTER\\Config\\User\\Common\\SensorInterface"
        );
        let _ = writeln!(
            k,
            "  ; The PC ({}:{}) must be listening before RSI_ON.",
            e.ip, e.port
        );
        let _ = writeln!(k, "  ;");
        let _ = writeln!(
            k,
            "  ; Signal flow {n}.rsix (written beside this file, RSI 4.1+; on RSI 3 draw it) contains:"
        );
        let _ = writeln!(
            k,
            "  ;   ETHERNET  ConfigFile={n}.xml  Timeout={}  Precision={}",
            self.timeout, self.precision
        );
        let outputs: Vec<String> = e
            .receive
            .iter()
            .map(|r| match r.indx {
                Indx::Channel(i) => format!("{i}={}", r.tag),
                Indx::Internal => r.tag.clone(),
            })
            .collect();
        let _ = writeln!(k, "  ;   ETHERNET outputs: {}", outputs.join(" "));
        let inputs: Vec<String> = e
            .send
            .iter()
            .filter_map(|r| match r.indx {
                Indx::Channel(i) => Some(format!("{i}={}", r.tag)),
                Indx::Internal => None,
            })
            .collect();
        if !inputs.is_empty() {
            let _ = writeln!(k, "  ;   ETHERNET inputs: {}", inputs.join(" "));
        }
        let _ = writeln!(
            k,
            "  ;   POSCORR   RefCorrSys=#TOOL  limits X/Y/Z +-{:.3} mm, MaxRotAngle {:.3} deg  <- RKorr.X..C",
            crate::wire::m_to_mm(self.poscorr.translation),
            self.poscorr.rotation.to_degrees()
        );
        let _ = writeln!(
            k,
            "  ;   POSCORRMON MaxTrans {:.3} mm, MaxRotAngle {:.3} deg",
            crate::wire::m_to_mm(self.poscorrmon.translation),
            self.poscorrmon.rotation.to_degrees()
        );
        if e.receive.iter().any(|r| r.tag == "Stop") {
            let _ = writeln!(
                k,
                "  ;   STOP      <- Stop (ends RSI_MOVECORR on its rising edge)"
            );
        }
        let _ = writeln!(
            k,
            "  ;   HOLDON of RKorr: {}",
            match self.mode {
                CorrectionMode::Absolute => "1 (hold the last total on a late reply)",
                CorrectionMode::Relative => "0 (never re-apply a stale increment)",
            }
        );
    }

    fn polish_krl(&self, p: &ProcessSetup) -> String {
        let mode = match self.mode {
            CorrectionMode::Absolute => "#ABSOLUTE",
            CorrectionMode::Relative => "#RELATIVE",
        };
        let ipo = if self.ipo_fast { "#IPO_FAST" } else { "#IPO" };
        let n = &self.name;
        let io = &p.io;
        let md = format!("$SEN_PINT[{}]", io.mode_pint);
        let sg = format!("$SEN_PINT[{}]", io.seg_pint);
        let fo = format!("$SEN_PREA[{}]", io.force_prea);
        let rp = format!("$SEN_PREA[{}]", io.ramp_prea);
        let st = format!("$SEN_PINT[{}]", io.state_pint);
        let fa = format!("$SEN_PINT[{}]", io.fault_pint);
        let tm = format!("$TIMER[{}]", p.timer);
        let tms = format!("$TIMER_STOP[{}]", p.timer);
        let fl = format!("$FLAG[{}]", p.flag);
        let irq = p.interrupt;
        let wait_ms = (p.wait_timeout * 1000.0).round() as u64;
        // A `WAIT FOR` bounded by the timer: `cond` or the wait timeout.
        let wait = |k: &mut String, indent: &str, cond: &str| {
            let _ = writeln!(k, "{indent}{tm} = 0");
            let _ = writeln!(k, "{indent}{tms} = FALSE");
            let _ = writeln!(k, "{indent}WAIT FOR {cond} OR ({tm} > {wait_ms})");
            let _ = writeln!(k, "{indent}{tms} = TRUE");
        };
        let first = p.segments[0];
        let mut k = String::new();
        let _ = writeln!(k, "DEF {n}()");
        let _ = writeln!(
            k,
            "  ; Generated by `forcecell rsi-config`: a polishing pass with forcecell holding the force"
        );
        let _ = writeln!(
            k,
            "  ; over RSI's process channels (FcCmd to the PC, FcState back)."
        );
        self.header(&mut k);
        let _ = writeln!(k, "  ;");
        let _ = writeln!(k, "  ; Process channels:");
        for line in p.mapping(&self.ethernet) {
            let _ = writeln!(k, "  ;   {line}");
        }
        let _ = writeln!(k, "  ;");
        let _ = writeln!(
            k,
            "  ; Per-segment values are set by TRIGGER at the start of each LIN, not in the advance run."
        );
        let _ = writeln!(
            k,
            "  ; Waits use {tm} and end after {:.1} s; messages use MsgNotify (KSS 8.3 MsgLib; unverified).",
            p.wait_timeout
        );
        let _ = writeln!(
            k,
            "  ; A FAULT mid-path is caught by INTERRUPT {irq} and flagged in {fl} (change both if the cell uses them)."
        );
        let _ = writeln!(
            k,
            "  ; P_ABOVE (start of the path, clear of the surface) must be taught before the first run;"
        );
        let _ = writeln!(
            k,
            "  ; the LIN_REL moves along the base X stand in for the taught path of each segment."
        );
        let _ = writeln!(k, "  DECL INT ret");
        let _ = writeln!(k, "  DECL INT CONTID");
        let _ = writeln!(k, "  DECL E6POS P_ABOVE");
        let _ = writeln!(k);
        let _ = writeln!(k, "  BAS(#INITMOV, 0)");
        let _ = writeln!(k, "  ; 1. above the part");
        let _ = writeln!(k, "  PTP P_ABOVE");
        let _ = writeln!(k);
        let _ = writeln!(k, "  ; 2. RSI on, process OFF");
        let _ = writeln!(k, "  {md} = 0");
        let _ = writeln!(k, "  {fo} = 0.0");
        let _ = writeln!(k, "  {rp} = {}", krl_real(p.ramp));
        let _ = writeln!(k, "  {sg} = 0");
        let _ = writeln!(k, "  ret = RSI_CREATE(\"{n}.rsix\", CONTID, TRUE)");
        let _ = writeln!(k, "  IF (ret <> RSIOK) THEN");
        let _ = writeln!(k, "    HALT");
        let _ = writeln!(k, "  ENDIF");
        let _ = writeln!(k, "  ret = RSI_ON({mode}, {ipo})");
        let _ = writeln!(k, "  IF (ret <> RSIOK) THEN");
        let _ = writeln!(k, "    HALT");
        let _ = writeln!(k, "  ENDIF");
        let _ = writeln!(k);
        let _ = writeln!(
            k,
            "  ; 3. PRESS with the first segment's force; wait for PRESSING (State 3)"
        );
        let _ = writeln!(k, "  {fo} = {}", krl_real(first.force));
        let _ = writeln!(k, "  {sg} = 1");
        let _ = writeln!(k, "  {md} = 1");
        wait(&mut k, "  ", &format!("({st} == 3) OR ({st} == 9)"));
        let _ = writeln!(k, "  IF {st} <> 3 THEN");
        let _ = writeln!(
            k,
            "    ; no PRESSING (timeout or FAULT): release, switch off, end cleanly"
        );
        let _ = writeln!(k, "    {md} = 2");
        wait(&mut k, "    ", &format!("({st} == 0) OR ({st} == 9)"));
        let _ = writeln!(k, "    {md} = 0");
        let _ = writeln!(k, "    ret = RSI_OFF()");
        let _ = writeln!(k, "    ret = RSI_DELETE(CONTID)");
        let _ = writeln!(
            k,
            "    MsgNotify(\"forcecell: no PRESSING after PRESS (timeout or fault, see {fa}); pass ended\")"
        );
        let _ = writeln!(k, "    RETURN");
        let _ = writeln!(k, "  ENDIF");
        let _ = writeln!(k);
        let _ = writeln!(
            k,
            "  ; 4. the path at feed speed (FC_PATH); a FAULT (State 9) on the way interrupts it:"
        );
        let _ = writeln!(
            k,
            "  ;    FC_FAULT brakes, sets {fl} and RESUMEs here. forcecell has already backed the tool"
        );
        let _ = writeln!(
            k,
            "  ;    off along -z; the program lifts clear before OFF brings the correction back to zero."
        );
        let _ = writeln!(k, "  {fl} = FALSE");
        let _ = writeln!(k, "  INTERRUPT DECL {irq} WHEN {st} == 9 DO FC_FAULT()");
        let _ = writeln!(k, "  INTERRUPT ON {irq}");
        let _ = writeln!(k, "  FC_PATH()");
        let _ = writeln!(k, "  INTERRUPT OFF {irq}");
        let _ = writeln!(k, "  IF {fl} THEN");
        let _ = writeln!(k, "    LIN_REL {{Z 50.0}} ; lift clear (base Z) first");
        let _ = writeln!(k, "    {md} = 0");
        wait(&mut k, "    ", &format!("({st} == 0)"));
        let _ = writeln!(k, "    ret = RSI_OFF()");
        let _ = writeln!(k, "    ret = RSI_DELETE(CONTID)");
        let _ = writeln!(
            k,
            "    MsgNotify(\"forcecell: FAULT mid-path (code in {fa}); pass aborted\")"
        );
        let _ = writeln!(k, "    RETURN");
        let _ = writeln!(k, "  ENDIF");
        let _ = writeln!(k);
        let _ = writeln!(k, "  ; 5. RELEASE; wait for OFF (State 0)");
        let _ = writeln!(k, "  {md} = 2");
        wait(&mut k, "  ", &format!("({st} == 0) OR ({st} == 9)"));
        let _ = writeln!(k, "  IF {st} <> 0 THEN");
        let _ = writeln!(
            k,
            "    MsgNotify(\"forcecell: not OFF after RELEASE (timeout or fault, see {fa})\")"
        );
        let _ = writeln!(k, "  ENDIF");
        let _ = writeln!(k, "  {md} = 0");
        let _ = writeln!(k, "  ret = RSI_OFF()");
        let _ = writeln!(k, "  ret = RSI_DELETE(CONTID)");
        let _ = writeln!(k, "  LIN_REL {{Z 50.0}} ; lift clear (base Z)");
        let _ = writeln!(k, "END");
        let _ = writeln!(k);
        let _ = writeln!(k, "DEF FC_PATH()");
        let _ = writeln!(k, "  ; each segment with its force and number");
        let _ = writeln!(k, "  $VEL.CP = {}", krl_real(p.feed));
        for (i, s) in p.segments.iter().enumerate() {
            let seg = i + 1;
            let _ = writeln!(
                k,
                "  ; segment {seg}: {:.2} N over {:.1} mm",
                s.force,
                crate::wire::m_to_mm(s.length)
            );
            let _ = writeln!(
                k,
                "  TRIGGER WHEN DISTANCE=0 DELAY=0 DO {fo} = {}",
                krl_real(s.force)
            );
            let _ = writeln!(k, "  TRIGGER WHEN DISTANCE=0 DELAY=0 DO {sg} = {seg}");
            let _ = writeln!(k, "  LIN_REL {{X {:.1}}}", crate::wire::m_to_mm(s.length));
        }
        let _ = writeln!(
            k,
            "  WAIT SEC 0 ; advance-run stop: a RESUME must find the advance run in this level"
        );
        let _ = writeln!(k, "END");
        let _ = writeln!(k);
        let _ = writeln!(k, "DEF FC_FAULT()");
        let _ = writeln!(
            k,
            "  ; forcecell latched a FAULT (code in {fa}) and backs the tool off: stop the path"
        );
        let _ = writeln!(k, "  INTERRUPT OFF {irq}");
        let _ = writeln!(k, "  BRAKE");
        let _ = writeln!(k, "  {fl} = TRUE");
        let _ = writeln!(k, "  RESUME");
        let _ = writeln!(k, "END");
        k
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ProcessChannels;

    #[test]
    fn the_mapping_legends_are_hals_code_tables() {
        let ethernet = EthernetConfig::forcecell(core::net::Ipv4Addr::LOCALHOST, 49152, false)
            .with_process(ProcessChannels::default());
        let lines = ProcessSetup::default_polish().mapping(&ethernet);
        let line = |tag: &str| {
            lines
                .iter()
                .find(|l| l.contains(tag))
                .unwrap_or_else(|| panic!("no {tag} in {lines:#?}"))
                .clone()
        };
        assert!(line(".Mode").ends_with(") 0 OFF, 1 PRESS, 2 RELEASE"));
        assert!(
            line(".State").ends_with(") 0 OFF, 1 APPROACH, 2 RAMP, 3 PRESSING, 4 RELEASE, 9 FAULT")
        );
        assert!(line(".Fault").ends_with(
            ") 0 none, 1 sensor lost, 2 force limit, 3 correction limit, 4 bad command, \
             5 contact lost, 6 hold timeout"
        ));
    }
}
