//! What the robot controller needs for a forcecell pass over EGM path correction, as text: the UDPUC
//! transmission-protocol entry, the external-motion-interface settings and a RAPID module. Sans-IO:
//! [`EgmCellConfig::render`] returns the files' names and contents; the application writes them.
//!
//! **None of it has been loaded into a real IRC5, an OmniCore or RobotStudio.** The instructions and
//! their arguments (`EGMGetId`, `EGMSetupUC … \PathCorr \APTR`, `EGMActMove … \SampleRate`,
//! `EGMMoveL`, `EGMStop … EGM_STOP_HOLD`, `EGMReset`, `WaitUntil … \MaxTime \TimeFlag`) and the
//! UDPUC attributes (`-Name`, `-Type "UDPUC"`, `-RemoteAddress`, `-RemotePortNumber`) are the ones
//! public RAPID programs and open EGM clients use; what is marked *unverified* in the output is not
//! confirmed by anything public the project found.

use std::fmt::Write as _;
use std::net::Ipv4Addr;

/// The UDP port forcecell's EGM link listens on unless told otherwise.
pub const DEFAULT_PORT: u16 = 6510;

/// The names and numbers an integrator must match between the robot and forcecell.
#[derive(Debug, Clone, PartialEq)]
pub struct EgmCellConfig {
    /// forcecell's host as the robot reaches it (the UDPUC `-RemoteAddress`).
    pub host: Ipv4Addr,
    /// forcecell's EGM port (the UDPUC `-RemotePortNumber`, the link's bind port).
    pub port: u16,
    /// The UDPUC device (transmission protocol `-Name`, `EGMSetupUC`'s device argument).
    pub device: String,
    /// The external-motion-interface (MotionProcess) settings instance (`EGMSetupUC`'s config).
    pub ext_motion: String,
    /// The RAPID module's name (also the file name, `NAME.mod`).
    pub module: String,
    /// The motion task's mechanical unit (`ROB_1`).
    pub robot: String,
    /// The tool (`tooldata`) the pass runs with; its `tframe` is the EGM sensor frame.
    pub tool: String,
    /// The work object (`wobjdata`) of the pass's targets.
    pub wobj: String,
    /// EGM's cycle, ms (`EGMActMove \SampleRate`); a multiple of 4.
    pub sample_rate_ms: u32,
    /// The longest wait for forcecell's answer in the handshake, s (`WaitUntil \MaxTime`).
    pub max_wait: f64,
    /// The largest path correction per axis the cell runs with, mm: the robot's correction range
    /// that forcecell's cell file names as `correction_mm` (its envelope stays within 90 % of it).
    pub correction_mm: f64,
}

/// What a cell file can be checked against in the settings file [`EgmCellConfig::settings`] wrote:
/// where the UDPUC entry sends and the correction range it names. Read back by
/// [`SettingsFacts::parse`], the one reader of the one writer.
#[derive(Debug, Clone, PartialEq)]
pub struct SettingsFacts {
    /// The UDPUC entry's `-RemoteAddress`.
    pub host: Option<Ipv4Addr>,
    /// The UDPUC entry's `-RemotePortNumber`.
    pub port: Option<u16>,
    /// The path-correction range, mm.
    pub correction_mm: Option<f64>,
}

/// The line of the settings file that names the correction range (its number follows, in mm).
const CORRECTION_LINE: &str = "path-correction range per axis (cell file robot.correction_mm):";

impl SettingsFacts {
    /// The facts in a settings file's text; a fact not found is `None`.
    pub fn parse(text: &str) -> Self {
        let after = |key: &str| {
            text.split(key)
                .nth(1)
                .map(|rest| rest.trim_start().trim_start_matches('"'))
        };
        let host = after("-RemoteAddress").and_then(|r| r.split('"').next()?.parse().ok());
        let port = after("-RemotePortNumber")
            .and_then(|r| r.split(|c: char| !c.is_ascii_digit()).next()?.parse().ok());
        let correction_mm =
            after(CORRECTION_LINE).and_then(|r| r.split_whitespace().next()?.parse().ok());
        Self {
            host,
            port,
            correction_mm,
        }
    }
}

/// The generated module's default name (its state variables' module for Robot Web Services).
pub const DEFAULT_MODULE: &str = "FcEgm";

impl EgmCellConfig {
    /// Defaults for a robot controller reaching forcecell at `host`.
    pub fn new(host: Ipv4Addr) -> Self {
        Self {
            host,
            port: DEFAULT_PORT,
            device: "FcEgmDevice".into(),
            ext_motion: "FcPathCorr".into(),
            module: DEFAULT_MODULE.into(),
            robot: "ROB_1".into(),
            tool: "tool0".into(),
            wobj: "wobj0".into(),
            sample_rate_ms: 4,
            max_wait: 5.0,
            correction_mm: 5.0,
        }
    }

    /// Checks every name and number before anything is written.
    pub fn validate(&self) -> Result<(), String> {
        for (what, name) in [
            ("device", &self.device),
            ("external-motion settings", &self.ext_motion),
            ("module", &self.module),
            ("robot", &self.robot),
            ("tool", &self.tool),
            ("work object", &self.wobj),
        ] {
            rapid_name(name).map_err(|e| format!("{what} name {name:?}: {e}"))?;
        }
        if self.host.is_unspecified() || self.host.is_multicast() || self.host.is_broadcast() {
            return Err(format!(
                "host {} is not an address the robot can send to (give forcecell's address on the robot's network)",
                self.host
            ));
        }
        if self.port == 0 {
            return Err("port 0: the robot needs a fixed port to send to".into());
        }
        if self.sample_rate_ms == 0 || !self.sample_rate_ms.is_multiple_of(4) {
            return Err(format!(
                "sample rate {} ms: EGM's cycle is a multiple of 4 ms",
                self.sample_rate_ms
            ));
        }
        if !(self.correction_mm.is_finite() && (0.1..=100.0).contains(&self.correction_mm)) {
            return Err(format!(
                "correction range {} mm: must be in [0.1, 100] mm (a path correction bounds a small \
                 deviation from the programmed path)",
                self.correction_mm
            ));
        }
        if !(self.max_wait.is_finite() && (0.1..=60.0).contains(&self.max_wait)) {
            return Err(format!(
                "max wait {} s: must be in [0.1, 60] s (a bounded wait, long enough for a ramp)",
                self.max_wait
            ));
        }
        Ok(())
    }

    /// The files: `(file name, contents)`, the RAPID module first.
    pub fn render(&self) -> Result<Vec<(String, String)>, String> {
        self.validate()?;
        Ok(vec![
            (format!("{}.mod", self.module), self.rapid_module()),
            (format!("{}-settings.txt", self.module), self.settings()),
        ])
    }

    /// The UDPUC entry of the transmission-protocol topic (`COM_TRP` in `SIO.cfg`).
    pub fn udpuc_entry(&self) -> String {
        format!(
            "COM_TRP:\n\n      -Name \"{}\" -Type \"UDPUC\" -RemoteAddress \"{}\"\\\n      -RemotePortNumber {}\n",
            self.device, self.host, self.port
        )
    }

    /// The controller settings: the UDPUC entry and the external-motion-interface instance.
    pub fn settings(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "forcecell egm-config: the controller settings for EGM path correction (module {}).\n\
             None of this has been loaded into a real IRC5, an OmniCore or RobotStudio.\n",
            self.module
        );
        let _ = writeln!(
            s,
            "1. Communication > Transmission Protocol (SIO.cfg, topic COM_TRP): a UDPUC device named\n   \
             \"{dev}\" sending to forcecell at {host}, port {port} (the port forcecell's EGM link\n   \
             binds). As a cfg entry:\n",
            dev = self.device,
            host = self.host,
            port = self.port
        );
        for line in self.udpuc_entry().lines() {
            let _ = writeln!(s, "   {line}");
        }
        let _ = writeln!(
            s,
            "\n   Users of open EGM clients report that the robot drops replies from any other address\n   \
             (*unverified*): forcecell should send from that address (one interface towards the robot)."
        );
        let _ = writeln!(
            s,
            "\n2. Motion > External Motion Interface Data (MOC.cfg, topic EXT_MOTION_DATA): an instance\n   \
             named \"{ext}\" (EGMSetupUC's configuration argument). *Unverified*: the attribute names\n   \
             and defaults; the intent is path correction with the correction applied as sent (no\n   \
             extra filtering beyond EGM's own), and a communication timeout long enough for forcecell's\n   \
             start (EGMSetupUC \\CommTimeout otherwise).",
            ext = self.ext_motion
        );
        let _ = writeln!(
            s,
            "\n   The {CORRECTION_LINE} {mm} mm\n   \
             Whatever the controller uses to bound a path correction must allow this much per axis;\n   \
             forcecell keeps its envelope within 90 % of it (*unverified* which EGM setting bounds a\n   \
             path correction: none public was found; the simulated IRC5 clamps to it per axis).",
            mm = self.correction_mm
        );
        let _ = writeln!(
            s,
            "\n3. The RAPID module {m}.mod: load it into the motion task of {r}; teach fc_start and\n   \
             fc_end (the pass's start and end, in {w}; fc_via too for an arc); call FcPass (a line)\n   \
             or FcArcPass (an arc through fc_via). The names to match are listed\n   \
             in its header.",
            m = self.module,
            r = self.robot,
            w = self.wobj
        );
        let _ = writeln!(
            s,
            "\n4. RobotWare: the EGM option, and RobotWare 7 (OmniCore) for the process command: the module\n   \
             hands fc_cmd to EGM with EGMActMove \\DataToSensor (a PERS dnum array, sent in\n   \
             EgmRobot.RAPIDfromRobot.dnum). Public RAPID shows \\DataToSensor on EGMActPose and\n   \
             EGMActJoint; that EGMActMove takes it is *unverified*: if the module does not load, the\n   \
             argument is refused, and the pass can only run without the process command (cell file\n   \
             robot.process = false). RobotWare 6 (IRC5) has no RAPIDfromRobot at all. The state\n   \
             (fc_phase, fc_force, fc_fault) has no way back in a path correction (EgmSensorPathCorr\n   \
             carries no RAPID data): forcecell writes those PERS numbers over Robot Web Services 2.0\n   \
             (HTTPS; cell file robot.rws = \"https://CONTROLLER-IP\", rws_user, rws_password,\n   \
             rws_fingerprint), in AUTO (in manual mode the pendant must grant write access). Tested\n   \
             against the project's simulated controller, curl and Python only: unverified on a controller."
        );
        s
    }

    /// The RAPID module.
    pub fn rapid_module(&self) -> String {
        let c = self;
        let mut s = String::new();
        let _ = write!(
            s,
            r#"MODULE {module}
    ! Generated by forcecell egm-config: a force-controlled pass with EGM path correction.
    ! NONE OF THIS HAS RUN ON A REAL IRC5, AN OMNICORE OR ROBOTSTUDIO.
    !
    ! Names the integrator must match:
    !   UDPUC device "{device}"  (SIO.cfg COM_TRP -Name; sends to {host}:{port}, forcecell's EGM port)
    !   External Motion Interface Data "{ext}"  (MOC.cfg EXT_MOTION_DATA instance)
    !   mechanical unit {robot}, tool {tool}, work object {wobj}
    !   robtargets fc_start, fc_end  (teach them: FcPass runs a line from fc_start to fc_end)
    !   robtarget fc_via  (teach it: FcArcPass runs a circle from fc_start through fc_via to fc_end)
    !   PERS num fc_phase, fc_force, fc_fault  (written by forcecell: the process state)
    !   PERS dnum fc_cmd{{4}}  (the command, handed to EGM by EGMActMove \DataToSensor; forcecell
    !     reads it from RAPIDfromRobot.dnum[1..4]: mode 0 OFF / 1 PRESS / 2 RELEASE, force N, ramp s,
    !     segment number)
    ! Phases (fc_phase): 0 OFF, 1 APPROACH, 2 RAMP, 3 PRESSING, 4 RELEASE, 9 FAULT.
    ! Faults (fc_fault): 0 none, 1 sensor lost, 2 force limit, 3 correction limit, 4 bad command,
    !   5 contact lost, 6 hold timeout; a fault is latched until the command goes back to OFF.
    !
    ! RobotWare 7: \DataToSensor fills RAPIDfromRobot.dnum from fc_cmd every EGM cycle. *Unverified*
    ! that EGMActMove takes \DataToSensor (public RAPID shows it on EGMActPose and EGMActJoint), and
    ! forcecell writes fc_phase/fc_force/fc_fault over Robot Web Services 2.0 (HTTPS; unverified on a
    ! controller; in manual mode the pendant must grant write access).

    CONST num FC_OFF := 0;
    CONST num FC_PRESS := 1;
    CONST num FC_RELEASE := 2;
    CONST num FC_PH_OFF := 0;
    CONST num FC_PH_PRESSING := 3;
    CONST num FC_PH_FAULT := 9;
    ! The longest wait for forcecell's answer, s: every wait below is bounded by it.
    CONST num FC_MAX_WAIT := {max_wait};

    PERS num fc_phase := 0;
    PERS num fc_force := 0;
    PERS num fc_fault := 0;
    PERS dnum fc_cmd{{4}} := [0, 0, 0, 0];
    VAR egmident fc_egm_id;
    VAR bool fc_timed_out := FALSE;
    PERS robtarget fc_start := [[0, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]];
    PERS robtarget fc_end := [[0, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]];
    PERS robtarget fc_via := [[0, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]];

    ! One pass: to the start (a fine point), EGM on, press, the corrected segment, release, EGM off.
    PROC FcPass()
        MoveL fc_start, v100, fine, {tool} \WObj:={wobj};
        FcEgmStart;
        IF FcPress(20, 0.5, 1) THEN
            EGMMoveL fc_egm_id, fc_end, v100, fine, {tool} \WObj:={wobj};
            FcRelease 0.5, 1;
        ENDIF
        FcEgmEnd;
    ENDPROC

    ! One circular pass: to the start, EGM on, press, the corrected arc through fc_via, release, EGM off.
    PROC FcArcPass()
        MoveL fc_start, v100, fine, {tool} \WObj:={wobj};
        FcEgmStart;
        IF FcPress(20, 0.5, 1) THEN
            EGMMoveC fc_egm_id, fc_via, fc_end, v100, fine, {tool} \WObj:={wobj};
            FcRelease 0.5, 1;
        ENDIF
        FcEgmEnd;
    ENDPROC

    ! EGM path correction from UDPUC device "{device}", settings "{ext}", every {rate} ms.
    PROC FcEgmStart()
        EGMReset fc_egm_id;
        EGMGetId fc_egm_id;
        EGMSetupUC {robot}, fc_egm_id, "{ext}", "{device}" \PathCorr \APTR;
        EGMActMove fc_egm_id, {tool}.tframe \SampleRate:={rate} \DataToSensor:=fc_cmd;
    ENDPROC

    ! The command for forcecell.
    PROC FcSetCmd(num mode, num force, num ramp, num segment)
        ! EGM sends fc_cmd in RAPIDfromRobot.dnum from the next cycle on (\DataToSensor above).
        fc_cmd := [NumToDnum(mode), NumToDnum(force), NumToDnum(ramp), NumToDnum(segment)];
    ENDPROC

    ! PRESS and wait (bounded) for PRESSING; FALSE on a fault or no answer.
    FUNC bool FcPress(num force, num ramp, num segment)
        FcSetCmd FC_PRESS, force, ramp, segment;
        WaitUntil fc_phase = FC_PH_PRESSING OR fc_phase = FC_PH_FAULT \MaxTime:=FC_MAX_WAIT \TimeFlag:=fc_timed_out;
        IF fc_timed_out OR fc_phase = FC_PH_FAULT THEN
            TPWrite "forcecell: no PRESSING, fault " \Num:=fc_fault;
            RETURN FALSE;
        ENDIF
        RETURN TRUE;
    ENDFUNC

    ! RELEASE and wait (bounded) for OFF.
    PROC FcRelease(num ramp, num segment)
        FcSetCmd FC_RELEASE, 0, ramp, segment;
        WaitUntil fc_phase = FC_PH_OFF OR fc_phase = FC_PH_FAULT \MaxTime:=FC_MAX_WAIT \TimeFlag:=fc_timed_out;
        IF fc_timed_out THEN
            TPWrite "forcecell: release not confirmed, force N " \Num:=fc_force;
        ENDIF
    ENDPROC

    ! The clean end: OFF (re-arms a latched fault), wait (bounded) for OFF, stop and release EGM.
    PROC FcEgmEnd()
        FcSetCmd FC_OFF, 0, 0, 0;
        WaitUntil fc_phase = FC_PH_OFF \MaxTime:=FC_MAX_WAIT \TimeFlag:=fc_timed_out;
        IF fc_timed_out THEN
            TPWrite "forcecell: OFF not confirmed";
        ENDIF
        EGMStop fc_egm_id, EGM_STOP_HOLD;
        EGMReset fc_egm_id;
    ENDPROC
ENDMODULE
"#,
            module = c.module,
            device = c.device,
            host = c.host,
            port = c.port,
            ext = c.ext_motion,
            robot = c.robot,
            tool = c.tool,
            wobj = c.wobj,
            rate = c.sample_rate_ms,
            max_wait = c.max_wait,
        );
        s
    }
}

/// A RAPID identifier: a letter, then letters, digits or `_`, at most 32 characters.
pub fn rapid_name(name: &str) -> Result<(), String> {
    let mut chars = name.chars();
    match chars.next() {
        None => return Err("empty".into()),
        Some(c) if !c.is_ascii_alphabetic() => return Err("must start with a letter".into()),
        _ => {}
    }
    if !chars.all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err("only letters, digits and _".into());
    }
    if name.len() > 32 {
        return Err("at most 32 characters".into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg() -> EgmCellConfig {
        EgmCellConfig::new(Ipv4Addr::new(192, 168, 125, 100))
    }

    /// The code without comments (`!` to the end of the line; no string in the module contains `!`).
    fn code(text: &str) -> Vec<String> {
        text.lines()
            .map(|l| l.split('!').next().unwrap_or("").trim().to_string())
            .filter(|l| !l.is_empty())
            .collect()
    }

    /// Whole-word occurrences of `word` in `line`.
    fn count_word(line: &str, word: &str) -> usize {
        line.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .filter(|w| w.eq_ignore_ascii_case(word))
            .count()
    }

    #[test]
    fn every_declared_name_is_used() {
        let lines = code(&cfg().rapid_module());
        let mut declared = Vec::new();
        for l in &lines {
            let w: Vec<&str> = l
                .split(|c: char| c.is_whitespace() || "({;:".contains(c))
                .filter(|w| !w.is_empty())
                .collect();
            match w.as_slice() {
                ["CONST" | "VAR" | "PERS", _ty, name, ..] => declared.push(name.to_string()),
                ["PROC", name, ..] | ["FUNC", _, name, ..] => declared.push(name.to_string()),
                _ => {}
            }
        }
        assert!(declared.len() >= 20, "{declared:?}");
        // FcPass and FcArcPass are the entry points the integrator's own main calls.
        for name in declared
            .iter()
            .filter(|n| *n != "FcPass" && *n != "FcArcPass")
        {
            let uses: usize = lines.iter().map(|l| count_word(l, name)).sum();
            assert!(uses >= 2, "{name} is declared and never used");
        }
    }

    #[test]
    fn every_wait_is_bounded() {
        let lines = code(&cfg().rapid_module());
        let waits: Vec<&String> = lines
            .iter()
            .filter(|l| l.starts_with("WaitUntil"))
            .collect();
        assert_eq!(waits.len(), 3);
        for w in waits {
            assert!(
                w.contains("\\MaxTime:=FC_MAX_WAIT") && w.contains("\\TimeFlag:=fc_timed_out"),
                "{w}"
            );
        }
        assert!(
            !lines
                .iter()
                .any(|l| l.starts_with("WaitTime") || l.starts_with("WaitDI"))
        );
    }

    #[test]
    fn blocks_balance() {
        let lines = code(&cfg().rapid_module());
        let mut stack = Vec::new();
        for l in &lines {
            let first = l.split_whitespace().next().unwrap();
            match first {
                "MODULE" | "PROC" | "FUNC" | "IF" => stack.push(first),
                "ENDMODULE" | "ENDPROC" | "ENDFUNC" | "ENDIF" => {
                    let open = stack
                        .pop()
                        .unwrap_or_else(|| panic!("{first} without opening"));
                    assert_eq!(format!("END{open}"), first, "{l}");
                }
                _ => {}
            }
        }
        assert!(stack.is_empty(), "unclosed {stack:?}");
        assert_eq!(lines.first().unwrap(), "MODULE FcEgm");
        assert_eq!(lines.last().unwrap(), "ENDMODULE");
    }

    #[test]
    fn the_names_given_reach_the_instructions() {
        let mut c = cfg();
        c.port = 6600;
        c.device = "MyDev".into();
        c.ext_motion = "MyCorr".into();
        c.tool = "tPad".into();
        c.wobj = "wPart".into();
        let m = c.rapid_module();
        assert!(
            m.contains("EGMSetupUC ROB_1, fc_egm_id, \"MyCorr\", \"MyDev\" \\PathCorr \\APTR;")
        );
        assert!(
            m.contains("EGMActMove fc_egm_id, tPad.tframe \\SampleRate:=4 \\DataToSensor:=fc_cmd;")
        );
        assert!(m.contains("EGMMoveL fc_egm_id, fc_end, v100, fine, tPad \\WObj:=wPart;"));
        assert!(m.contains("EGMMoveC fc_egm_id, fc_via, fc_end, v100, fine, tPad \\WObj:=wPart;"));
        assert!(m.contains("EGMStop fc_egm_id, EGM_STOP_HOLD;"));
        let e = c.udpuc_entry();
        assert!(e.contains("-Name \"MyDev\" -Type \"UDPUC\" -RemoteAddress \"192.168.125.100\""));
        assert!(e.contains("-RemotePortNumber 6600"));
        let s = c.settings();
        assert!(s.contains("\"MyCorr\"") && s.contains("port 6600"));
    }

    #[test]
    fn bad_names_and_numbers_are_refused() {
        type Edit = fn(&mut EgmCellConfig);
        let cases: Vec<(Edit, &str)> = vec![
            (|c| c.device = "".into(), "device"),
            (|c| c.module = "1Fc".into(), "module"),
            (|c| c.tool = "tool 0".into(), "tool"),
            (|c| c.wobj = "w\"x".into(), "work object"),
            (|c| c.ext_motion = "a".repeat(33), "external-motion"),
            (|c| c.host = Ipv4Addr::UNSPECIFIED, "host"),
            (|c| c.port = 0, "port"),
            (|c| c.sample_rate_ms = 6, "sample rate"),
            (|c| c.max_wait = f64::NAN, "max wait"),
            (|c| c.max_wait = 0.0, "max wait"),
            (|c| c.correction_mm = 0.0, "correction range"),
            (|c| c.correction_mm = f64::INFINITY, "correction range"),
        ];
        for (bad, what) in cases {
            let mut c = cfg();
            bad(&mut c);
            let e = c.render().unwrap_err();
            assert!(e.contains(what), "{e}");
        }
        assert!(cfg().render().is_ok());
    }

    #[test]
    fn the_settings_facts_read_back_what_the_settings_wrote() {
        let mut c = cfg();
        c.port = 6611;
        c.correction_mm = 7.5;
        let f = SettingsFacts::parse(&c.settings());
        assert_eq!(f.host, Some(Ipv4Addr::new(192, 168, 125, 100)));
        assert_eq!(f.port, Some(6611));
        assert_eq!(f.correction_mm, Some(7.5));
        let none = SettingsFacts::parse("nothing here");
        assert_eq!(
            (none.host, none.port, none.correction_mm),
            (None, None, None)
        );
    }

    #[test]
    fn both_corrected_moves_run_between_press_and_release_with_the_data_exchange_on() {
        let lines = code(&cfg().rapid_module());
        for (entry, mv) in [
            ("PROC FcPass()", "EGMMoveL"),
            ("PROC FcArcPass()", "EGMMoveC"),
        ] {
            let start = lines.iter().position(|l| l == entry).unwrap();
            let body: Vec<&String> = lines[start..]
                .iter()
                .take_while(|l| *l != "ENDPROC")
                .collect();
            let at = |w: &str| {
                body.iter()
                    .position(|l| l.starts_with(w))
                    .unwrap_or_else(|| panic!("{w} in {entry}"))
            };
            assert!(at("FcEgmStart") < at("IF FcPress("), "{entry}");
            assert!(at("IF FcPress(") < at(mv), "{entry}");
            assert!(at(mv) < at("FcRelease"), "{entry}");
            assert!(at("ENDIF") < at("FcEgmEnd"), "{entry}");
        }
        // The command goes out in RAPIDfromRobot: fc_cmd is a PERS dnum array handed to EGMActMove.
        assert!(lines.iter().any(|l| l.starts_with("PERS dnum fc_cmd{4}")));
        let act = lines.iter().find(|l| l.starts_with("EGMActMove")).unwrap();
        assert!(act.contains("\\DataToSensor:=fc_cmd"), "{act}");
    }
}
