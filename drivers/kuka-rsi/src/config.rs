//! The robot's Ethernet config (`RSI_EthernetConfig.xml`): read it, write it, and derive from it the
//! [`Schema`]s of the two messages.
//!
//! The same file drives the driver (what to expect in `<Rob>`, what to send in `<Sen>`), the simulated
//! controller (the opposite) and what `forcecell rsi-config` writes for the robot.

use core::fmt::Write as _;
use std::net::Ipv4Addr;

use crate::codec::{Direction, Schema, ValueType};
use crate::xml::{Cursor, ParseError, skip_declaration};

/// `INDX` of an element: an internal value, or a channel 1–64 of the ETHERNET object.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Indx {
    /// `INDX="INTERNAL"` (the `DEF_*` tags).
    Internal,
    /// `INDX="1"` … `INDX="64"`.
    Channel(u8),
}

/// One `<ELEMENT …/>` of the `SEND` or `RECEIVE` section.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigElement {
    /// `TAG`: `DEF_RIst`, `RKorr.X`, `Stop`, …
    pub tag: String,
    /// `TYPE`.
    pub ty: ValueType,
    /// `INDX`.
    pub indx: Indx,
    /// `HOLDON` (receive elements only): on a late reply keep the last value (true) or reset to 0.
    pub holdon: Option<bool>,
}

impl ConfigElement {
    /// A user channel.
    pub fn channel(tag: &str, ty: ValueType, indx: u8, holdon: Option<bool>) -> Self {
        Self {
            tag: tag.to_owned(),
            ty,
            indx: Indx::Channel(indx),
            holdon,
        }
    }

    /// An internal (`DEF_*`) value.
    pub fn internal(tag: &str, ty: ValueType) -> Self {
        Self {
            tag: tag.to_owned(),
            ty,
            indx: Indx::Internal,
            holdon: None,
        }
    }
}

/// The robot's Ethernet config.
#[derive(Clone, Debug, PartialEq)]
pub struct EthernetConfig {
    /// `IP_NUMBER`: the address of the PC (the server the robot sends to).
    pub ip: Ipv4Addr,
    /// `PORT`.
    pub port: u16,
    /// `SENTYPE`: the `Type` the robot expects in `<Sen>`.
    pub sentype: String,
    /// `ONLYSEND`: the robot only sends and expects no reply.
    pub onlysend: bool,
    /// `SEND`: what the robot sends, in order.
    pub send: Vec<ConfigElement>,
    /// `RECEIVE`: what the robot expects back, in order.
    pub receive: Vec<ConfigElement>,
}

/// An error in an Ethernet config file.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigError(pub String);

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "RSI Ethernet config: {}", self.0)
    }
}

impl std::error::Error for ConfigError {}

impl hal::Error for ConfigError {
    fn kind(&self) -> hal::ErrorKind {
        hal::ErrorKind::Config
    }
}

impl From<String> for ConfigError {
    fn from(s: String) -> Self {
        Self(s)
    }
}

const POSE: [&str; 6] = ["X", "Y", "Z", "A", "B", "C"];
const AXES: [&str; 6] = ["A1", "A2", "A3", "A4", "A5", "A6"];
const EXT: [&str; 6] = ["E1", "E2", "E3", "E4", "E5", "E6"];

impl EthernetConfig {
    /// The config forcecell uses: the PC at `ip:port`, SENTYPE `ImFree`; the robot sends `RIst`, `RSol`,
    /// `AIPos`, `ASPos` and `Delay`; it receives `RKorr X..C` and `Stop`. `RKorr` HOLDON is 1 for
    /// absolute corrections (hold the last total on a late reply) and 0 for relative ones (never
    /// re-apply a stale increment).
    pub fn forcecell(ip: Ipv4Addr, port: u16, relative: bool) -> Self {
        let send = ["DEF_RIst", "DEF_RSol", "DEF_AIPos", "DEF_ASPos"]
            .into_iter()
            .map(|t| ConfigElement::internal(t, ValueType::Double))
            .chain([ConfigElement::internal("DEF_Delay", ValueType::Long)])
            .collect();
        let mut receive: Vec<ConfigElement> = POSE
            .iter()
            .zip(1u8..)
            .map(|(a, i)| {
                ConfigElement::channel(&format!("RKorr.{a}"), ValueType::Double, i, Some(!relative))
            })
            .collect();
        receive.push(ConfigElement::channel(
            "Stop",
            ValueType::Bool,
            7,
            Some(false),
        ));
        Self {
            ip,
            port,
            sentype: "ImFree".to_owned(),
            onlysend: false,
            send,
            receive,
        }
    }

    /// Parse the XML text of a config. Tolerates comments, a declaration and any whitespace.
    pub fn parse(text: &str) -> Result<Self, ConfigError> {
        // Windows editors (and WorkVisual exports) start the file with a UTF-8 byte-order mark.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut ip = None;
        let mut port = None;
        let mut sentype = None;
        let mut onlysend = false;
        let mut send = Vec::new();
        let mut receive = Vec::new();
        walk(text.as_bytes(), |path, attrs, body| {
            let p: Vec<&str> = path.iter().map(String::as_str).collect();
            match p.as_slice() {
                ["ROOT", "CONFIG", "IP_NUMBER"] => {
                    ip = Some(
                        body.parse::<Ipv4Addr>()
                            .map_err(|_| format!("IP_NUMBER {body:?} is not an IPv4 address"))?,
                    )
                }
                ["ROOT", "CONFIG", "PORT"] => {
                    port = Some(
                        body.parse::<u16>()
                            .map_err(|_| format!("PORT {body:?} is not a port number"))?,
                    )
                }
                ["ROOT", "CONFIG", "SENTYPE"] => sentype = Some(body.to_owned()),
                ["ROOT", "CONFIG", "ONLYSEND"] => {
                    onlysend = match body.to_ascii_uppercase().as_str() {
                        "TRUE" => true,
                        "FALSE" => false,
                        _ => return Err(format!("ONLYSEND must be TRUE or FALSE, got {body:?}")),
                    }
                }
                ["ROOT", "SEND", "ELEMENTS", "ELEMENT"] => send.push(element(attrs)?),
                ["ROOT", "RECEIVE", "ELEMENTS", "ELEMENT"] => receive.push(element(attrs)?),
                _ => {}
            }
            Ok(())
        })?;
        let cfg = Self {
            ip: ip.ok_or_else(|| ConfigError("CONFIG has no IP_NUMBER".into()))?,
            port: port.ok_or_else(|| ConfigError("CONFIG has no PORT".into()))?,
            sentype: sentype.ok_or_else(|| ConfigError("CONFIG has no SENTYPE".into()))?,
            onlysend,
            send,
            receive,
        };
        cfg.validate()?;
        Ok(cfg)
    }

    /// Check channels and derive both schemas once.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (section, list) in [("SEND", &self.send), ("RECEIVE", &self.receive)] {
            let mut used = [false; 65];
            for e in list {
                match e.indx {
                    Indx::Channel(i) if (1..=64).contains(&i) => {
                        if used[i as usize] {
                            return Err(ConfigError(format!("{section}: INDX {i} is used twice")));
                        }
                        used[i as usize] = true;
                    }
                    Indx::Channel(i) => {
                        return Err(ConfigError(format!(
                            "{section}: INDX {i} of {} is outside 1..64",
                            e.tag
                        )));
                    }
                    Indx::Internal if !e.tag.starts_with("DEF_") => {
                        return Err(ConfigError(format!(
                            "{section}: {} is INTERNAL but not a DEF_ tag",
                            e.tag
                        )));
                    }
                    Indx::Internal => {}
                }
            }
        }
        self.rob_schema(4)?;
        self.sen_schema(4)?;
        Ok(())
    }

    /// What force control needs of this configuration, checked when a run loads it, before anything
    /// moves; the error is one line naming what is missing and how to add it.
    ///
    /// * `ONLYSEND` must be `FALSE`: a robot that takes no reply takes no correction.
    /// * RECEIVE must carry the Cartesian correction `RKorr.X`, `RKorr.Y`, `RKorr.Z` (`A`, `B`, `C`
    ///   optional). forcecell corrects the tool's position in Cartesian space; a configuration with
    ///   axis corrections only (`AK`/`AKorr`) is refused rather than mapped through the robot's
    ///   kinematics, which forcecell does not model.
    /// * RECEIVE must carry `Stop` (BOOL): the end of every run is a clean `Stop`.
    /// * SEND must carry `DEF_RIst` and `DEF_RSol` (the loop's position and path).
    /// * With `process`, SEND must carry `FcCmd` and RECEIVE `FcState` (the process channels).
    ///
    /// `IPOC` is not in the file: RSI adds it to every message; a datagram without it is dropped.
    pub fn check_for_control(&self, process: bool) -> Result<(), ConfigError> {
        if self.onlysend {
            return Err(ConfigError(
                "ONLYSEND is TRUE: the robot takes no reply, so no correction can reach it (set ONLYSEND to FALSE)".into(),
            ));
        }
        let has = |list: &[ConfigElement], tag: &str| list.iter().any(|e| e.tag == tag);
        let missing: Vec<String> = ["X", "Y", "Z"]
            .iter()
            .map(|a| format!("RKorr.{a}"))
            .filter(|t| !has(&self.receive, t))
            .collect();
        if !missing.is_empty() {
            let axis = self
                .receive
                .iter()
                .any(|e| e.tag.starts_with("AK") || e.tag.starts_with("AKorr"));
            return Err(ConfigError(format!(
                "RECEIVE has no Cartesian correction {} ({}forcecell corrects in Cartesian space and does not map corrections through the robot's kinematics; add RKorr.X..C DOUBLE channels wired to POSCORR)",
                missing.join(", "),
                if axis {
                    "it has axis corrections only: "
                } else {
                    ""
                }
            )));
        }
        if !has(&self.receive, "Stop") {
            return Err(ConfigError(
                "RECEIVE has no Stop channel: forcecell could not end the robot's correction cleanly (add <ELEMENT TAG=\"Stop\" TYPE=\"BOOL\" INDX=\"n\" HOLDON=\"0\"/> wired to the STOP object)".into(),
            ));
        }
        for t in ["DEF_RIst", "DEF_RSol"] {
            if !has(&self.send, t) {
                return Err(ConfigError(format!(
                    "SEND has no {t}: forcecell needs the robot's actual and commanded positions (add <ELEMENT TAG=\"{t}\" TYPE=\"DOUBLE\" INDX=\"INTERNAL\"/>)"
                )));
            }
        }
        if process {
            let cmd = self.send.iter().any(|e| e.tag.starts_with("FcCmd."));
            let state = self.receive.iter().any(|e| e.tag.starts_with("FcState."));
            if !cmd || !state {
                let what = match (cmd, state) {
                    (false, false) => "SEND has no FcCmd and RECEIVE no FcState",
                    (false, true) => "SEND has no FcCmd",
                    _ => "RECEIVE has no FcState",
                };
                return Err(ConfigError(format!(
                    "process = true but {what}: the robot program cannot command the process (`forcecell rsi-config` writes them unless --no-process; or set process = false)"
                )));
            }
        }
        Ok(())
    }

    /// The `<Rob>` schema: what the robot sends, doubles written with `precision` decimals
    /// (the ETHERNET object's `Precision`).
    pub fn rob_schema(&self, precision: u8) -> Result<Schema, ConfigError> {
        let mut s = Schema::new(Direction::Rob, "KUKA", precision)?;
        for e in &self.send {
            match e.tag.strip_prefix("DEF_") {
                Some(internal) => push_internal(&mut s, "SEND", &e.tag, internal, e.ty, false)?,
                _ => push_user(&mut s, e)?,
            }
        }
        Ok(s)
    }

    /// The `<Sen>` schema: what the robot expects back, `Type` = SENTYPE.
    pub fn sen_schema(&self, precision: u8) -> Result<Schema, ConfigError> {
        let mut s = Schema::new(Direction::Sen, &self.sentype, precision)
            .map_err(|e| ConfigError(format!("SENTYPE: {e}")))?;
        for e in &self.receive {
            match e.tag.strip_prefix("DEF_") {
                Some(internal) if e.indx == Indx::Internal => push_internal(
                    &mut s,
                    "RECEIVE",
                    &e.tag,
                    internal,
                    e.ty,
                    e.holdon.unwrap_or(false),
                )?,
                _ => push_user(&mut s, e)?,
            }
        }
        Ok(s)
    }

    /// The XML text of this config, as the robot expects it in `C:\KRC\ROBOTER\Config\User\Common\SensorInterface`.
    pub fn to_xml(&self) -> String {
        let mut x = String::new();
        let _ = writeln!(x, "<ROOT>");
        let _ = writeln!(x, "  <CONFIG>");
        let _ = writeln!(x, "    <IP_NUMBER>{}</IP_NUMBER>", self.ip);
        let _ = writeln!(x, "    <PORT>{}</PORT>", self.port);
        let _ = writeln!(x, "    <SENTYPE>{}</SENTYPE>", self.sentype);
        let _ = writeln!(
            x,
            "    <ONLYSEND>{}</ONLYSEND>",
            if self.onlysend { "TRUE" } else { "FALSE" }
        );
        let _ = writeln!(x, "  </CONFIG>");
        for (section, list) in [("SEND", &self.send), ("RECEIVE", &self.receive)] {
            let _ = writeln!(x, "  <{section}>");
            let _ = writeln!(x, "    <ELEMENTS>");
            for e in list {
                let indx = match e.indx {
                    Indx::Internal => "INTERNAL".to_owned(),
                    Indx::Channel(i) => i.to_string(),
                };
                let _ = write!(
                    x,
                    "      <ELEMENT TAG=\"{}\" TYPE=\"{}\" INDX=\"{indx}\"",
                    e.tag,
                    e.ty.as_config()
                );
                if let Some(h) = e.holdon {
                    let _ = write!(x, " HOLDON=\"{}\"", u8::from(h));
                }
                let _ = writeln!(x, " />");
            }
            let _ = writeln!(x, "    </ELEMENTS>");
            let _ = writeln!(x, "  </{section}>");
        }
        let _ = writeln!(x, "</ROOT>");
        x
    }
}

/// The internal (`INDX="INTERNAL"`) values RSI documents, and the element each becomes on the wire.
/// SEND (robot → PC): `DEF_RIst`, `DEF_RSol` (`X..C`), `DEF_AIPos`, `DEF_ASPos`, `DEF_MACur`
/// (`A1..A6`), `DEF_EIPos`, `DEF_ESPos`, `DEF_MECur` (`E1..E6`), `DEF_Delay` (`<Delay D=…/>`),
/// `DEF_EStr` (`<EStr>text</EStr>`), `DEF_Tech.Cn`/`DEF_Tech.Tn` (`<Tech Cn1..Cn10/>`, n = 1..10).
/// RECEIVE (PC → robot): `DEF_EStr` (a message the robot shows; forcecell sends it empty) and
/// `DEF_Tech.Tn`/`DEF_Tech.Cn` (`<Tech Tn1..Tn10/>`; forcecell sends zeros).
pub const INTERNAL_TAGS: &str = "SEND: DEF_RIst, DEF_RSol, DEF_AIPos, DEF_ASPos, DEF_EIPos, DEF_ESPos, DEF_MACur, DEF_MECur, DEF_Delay, DEF_EStr, DEF_Tech.C1..C10, DEF_Tech.T1..T10; RECEIVE: DEF_EStr, DEF_Tech.T1..T10, DEF_Tech.C1..C10";

fn push_internal(
    s: &mut Schema,
    section: &str,
    tag: &str,
    internal: &str,
    ty: ValueType,
    holdon: bool,
) -> Result<(), ConfigError> {
    let unknown = || {
        ConfigError(format!(
            "{section}: unknown internal tag {tag} (known: {INTERNAL_TAGS})"
        ))
    };
    let send = section == "SEND";
    match internal {
        "RIst" | "RSol" if send => push6(s, internal, POSE, ty)?,
        "AIPos" | "ASPos" | "MACur" if send => push6(s, internal, AXES, ty)?,
        "EIPos" | "ESPos" | "MECur" if send => push6(s, internal, EXT, ty)?,
        "Delay" if send => s.push_attr("Delay", "D", ValueType::Long, false)?,
        "EStr" => s.push_text("EStr", ValueType::String, false)?,
        t if t.starts_with("Tech.C") || t.starts_with("Tech.T") => {
            let (prefix, n) = t["Tech.".len()..].split_at(1);
            let n: u8 = n
                .parse()
                .ok()
                .filter(|n| (1..=10).contains(n))
                .ok_or_else(unknown)?;
            for k in 1..=10 {
                s.push_attr("Tech", &format!("{prefix}{n}{k}"), ty, holdon)?;
            }
        }
        _ => return Err(unknown()),
    }
    Ok(())
}

fn push6(s: &mut Schema, tag: &str, attrs: [&str; 6], ty: ValueType) -> Result<(), ConfigError> {
    for a in attrs {
        s.push_attr(tag, a, ty, false)?;
    }
    Ok(())
}

fn push_user(s: &mut Schema, e: &ConfigElement) -> Result<(), ConfigError> {
    let holdon = e.holdon.unwrap_or(false);
    match e.tag.split_once('.') {
        Some((tag, attr)) => s.push_attr(tag, attr, e.ty, holdon)?,
        None => s.push_text(&e.tag, e.ty, holdon)?,
    }
    Ok(())
}

fn element(attrs: &[(String, String)]) -> Result<ConfigElement, String> {
    let get = |k: &str| {
        attrs
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(k))
            .map(|(_, v)| v.trim())
    };
    let tag = get("TAG").ok_or("ELEMENT without TAG")?;
    let ty = get("TYPE").ok_or_else(|| format!("ELEMENT {tag} without TYPE"))?;
    let ty = ValueType::from_config(ty)
        .ok_or_else(|| format!("ELEMENT {tag}: TYPE {ty:?} is not BOOL, STRING, LONG or DOUBLE"))?;
    let indx = match get("INDX").ok_or_else(|| format!("ELEMENT {tag} without INDX"))? {
        i if i.eq_ignore_ascii_case("INTERNAL") => Indx::Internal,
        i => Indx::Channel(
            i.parse()
                .map_err(|_| format!("ELEMENT {tag}: INDX {i:?} is not INTERNAL or 1..64"))?,
        ),
    };
    let holdon = match get("HOLDON") {
        None => None,
        Some("1") => Some(true),
        Some("0") => Some(false),
        Some(h) => return Err(format!("ELEMENT {tag}: HOLDON {h:?} is not 0 or 1")),
    };
    Ok(ConfigElement {
        tag: tag.to_owned(),
        ty,
        indx,
        holdon,
    })
}

type Attrs = Vec<(String, String)>;

/// Walk a nested XML document; `f(path, attrs, text)` is called for every element when it closes.
fn walk(
    b: &[u8],
    mut f: impl FnMut(&[String], &Attrs, &str) -> Result<(), String>,
) -> Result<(), ConfigError> {
    let at = |e: ParseError| ConfigError(e.to_string());
    let mut c = Cursor::new(b);
    skip_declaration(&mut c).map_err(at)?;
    let mut path: Vec<String> = Vec::new();
    let mut stack: Vec<(Attrs, String)> = Vec::new();
    let mut closed_root = false;
    loop {
        c.skip_ws();
        if c.at_end() {
            break;
        }
        if c.starts_with(b"<!--") {
            c.skip_past(b"-->").map_err(at)?;
        } else if c.starts_with(b"<?") {
            c.skip_past(b"?>").map_err(at)?;
        } else if c.starts_with(b"<!") {
            return Err(ConfigError(format!(
                "DOCTYPE or CDATA at offset {} is not accepted",
                c.i
            )));
        } else if closed_root {
            return Err(ConfigError(format!(
                "content after the root element at offset {}",
                c.i
            )));
        } else if c.starts_with(b"</") {
            c.i += 2;
            let name = c.name().map_err(at)?;
            let name = String::from_utf8_lossy(name).into_owned();
            c.skip_ws();
            c.expect(b'>', "'>'").map_err(at)?;
            if path.last() != Some(&name) {
                return Err(ConfigError(format!(
                    "closing tag </{name}> does not match <{}>",
                    path.last().map_or("(none)", String::as_str)
                )));
            }
            let (attrs, text) = stack.pop().unwrap_or_default();
            f(&path, &attrs, text.trim()).map_err(ConfigError)?;
            path.pop();
            closed_root = path.is_empty();
        } else if c.peek() == Some(b'<') {
            c.i += 1;
            let name = String::from_utf8_lossy(c.name().map_err(at)?).into_owned();
            let mut attrs = Vec::new();
            let closed = c
                .attributes(|n, v, _| {
                    attrs.push((
                        String::from_utf8_lossy(n).into_owned(),
                        String::from_utf8_lossy(v).into_owned(),
                    ));
                    Ok(())
                })
                .map_err(at)?;
            path.push(name);
            if closed {
                f(&path, &attrs, "").map_err(ConfigError)?;
                path.pop();
                closed_root = path.is_empty();
            } else {
                stack.push((attrs, String::new()));
            }
        } else {
            let start = c.i;
            let (text, _) = c.text();
            let text = core::str::from_utf8(text)
                .map_err(|_| ConfigError(format!("text at offset {start} is not UTF-8")))?;
            if text.contains('&') {
                return Err(ConfigError(format!(
                    "entity reference at offset {start} is not accepted"
                )));
            }
            match stack.last_mut() {
                Some((_, t)) => t.push_str(text),
                None => {
                    return Err(ConfigError(format!(
                        "text outside the root element at offset {start}"
                    )));
                }
            }
        }
    }
    if !path.is_empty() {
        return Err(ConfigError(format!(
            "the file ends inside <{}>",
            path.join("><")
        )));
    }
    if !closed_root {
        return Err(ConfigError("no root element".into()));
    }
    Ok(())
}
