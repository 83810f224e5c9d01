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
                if section == "RECEIVE" && e.indx == Indx::Internal {
                    return Err(ConfigError(format!(
                        "RECEIVE: {} must be a channel 1..64, not INTERNAL",
                        e.tag
                    )));
                }
            }
        }
        self.rob_schema(4)?;
        self.sen_schema(4)?;
        Ok(())
    }

    /// The `<Rob>` schema: what the robot sends, doubles written with `precision` decimals
    /// (the ETHERNET object's `Precision`).
    pub fn rob_schema(&self, precision: u8) -> Result<Schema, ConfigError> {
        let mut s = Schema::new(Direction::Rob, "KUKA", precision)?;
        for e in &self.send {
            if let Some(internal) = e.tag.strip_prefix("DEF_") {
                match internal {
                    "RIst" | "RSol" => push6(&mut s, internal, POSE, e.ty)?,
                    "AIPos" | "ASPos" | "MACur" => push6(&mut s, internal, AXES, e.ty)?,
                    "EIPos" | "ESPos" | "MECur" => push6(&mut s, internal, EXT, e.ty)?,
                    "Delay" => s.push_attr("Delay", "D", ValueType::Long, false)?,
                    t if t.starts_with("Tech.C") => {
                        let n: u8 = t["Tech.C".len()..]
                            .parse()
                            .ok()
                            .filter(|n| (1..=10).contains(n))
                            .ok_or_else(|| {
                                ConfigError(format!("unknown internal tag {}", e.tag))
                            })?;
                        for k in 1..=10 {
                            s.push_attr("Tech", &format!("C{n}{k}"), e.ty, false)?;
                        }
                    }
                    _ => {
                        return Err(ConfigError(format!(
                            "unknown internal tag {} (known: DEF_RIst, DEF_RSol, DEF_AIPos, DEF_ASPos, DEF_EIPos, DEF_ESPos, DEF_MACur, DEF_MECur, DEF_Delay, DEF_Tech.C1..C10)",
                            e.tag
                        )));
                    }
                }
            } else {
                push_user(&mut s, e)?;
            }
        }
        Ok(s)
    }

    /// The `<Sen>` schema: what the robot expects back, `Type` = SENTYPE.
    pub fn sen_schema(&self, precision: u8) -> Result<Schema, ConfigError> {
        let mut s = Schema::new(Direction::Sen, &self.sentype, precision)
            .map_err(|e| ConfigError(format!("SENTYPE: {e}")))?;
        for e in &self.receive {
            push_user(&mut s, e)?;
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
