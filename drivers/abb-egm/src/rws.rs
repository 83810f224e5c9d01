//! Robot Web Services 2.0 (RobotWare 7, OmniCore), the process state's way back to the RAPID program,
//! without I/O: the requests as bytes, the responses parsed from bytes.
//!
//! A path correction (`EgmSensorPathCorr`) carries no data to RAPID, so the state (phase, force, fault)
//! goes over the controller's REST interface instead: each number is written to a `PERS num` of the
//! generated module ([`crate::rapid`]) by updating the RAPID symbol's value:
//!
//! ```text
//! POST /rw/rapid/symbol/RAPID/{task}/{module}/{name}/data HTTP/1.1
//! Authorization: Basic base64(user:password)
//! Accept: application/xhtml+xml;v=2.0
//! Content-Type: application/x-www-form-urlencoded;v=2.0
//!
//! value=3
//! ```
//!
//! answered `204 No Content`. RWS 2.0 is served over HTTPS only (the shell, [`crate::rws_channel`],
//! does TLS and pins the controller's self-signed certificate); the session cookies the controller
//! sets are sent back, so one connection stays one session (a controller serves a bounded number of
//! sessions). The order of the three writes is fault, force, then phase: a program that wakes on a
//! phase reads the fault and force that belong to it.
//!
//! RobotWare 6 (RWS 1.0: HTTP with Digest authentication, `/rw/rapid/symbol/data/…?action=set`) is not
//! implemented: RobotWare 6's EGM has no `RAPIDfromRobot`, so the process command cannot reach
//! forcecell there and the state has nothing to answer. Writing a `PERS` variable over RWS needs no
//! mastership in automatic mode; in manual mode the controller asks for the pendant's permission
//! (remote manual mode privilege), which forcecell does not request — run passes in AUTO.

use core::fmt;

use hal::ProcessState;

use crate::process::{STATE_NUMBERS, state_to_numbers};

/// HTTPS port of RWS 2.0 on a controller.
pub const DEFAULT_PORT: u16 = 443;
/// The RAPID task of a single-robot controller.
pub const DEFAULT_TASK: &str = "T_ROB1";
/// The user a controller ships with.
pub const DEFAULT_USER: &str = "Default User";
/// That user's shipped password.
pub const DEFAULT_PASSWORD: &str = "robotics";
/// The module's variables in [`state_to_numbers`]'s order (phase, force, fault).
pub const STATE_SYMBOLS: [&str; STATE_NUMBERS] = ["fc_phase", "fc_force", "fc_fault"];
/// The order the state is written in: indices into [`STATE_SYMBOLS`] (fault, force, phase last).
pub const WRITE_ORDER: [usize; STATE_NUMBERS] = [2, 1, 0];
/// Largest response head (status line and headers) accepted, bytes.
pub const MAX_HEAD: usize = 16 * 1024;
/// Largest body accepted, bytes (a symbol write's error page is a few hundred).
pub const MAX_BODY: usize = 64 * 1024;

/// Where the RAPID variables are and who may write them.
#[derive(Clone, PartialEq, Eq)]
pub struct RwsTarget {
    /// `host:port` as the `Host` header names it.
    pub authority: String,
    /// User.
    pub user: String,
    /// Password.
    pub password: String,
    /// RAPID task.
    pub task: String,
    /// The module that declares the variables (`egm-config`'s module name).
    pub module: String,
}

impl fmt::Debug for RwsTarget {
    // The password is not printed.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("RwsTarget")
            .field("authority", &self.authority)
            .field("user", &self.user)
            .field("task", &self.task)
            .field("module", &self.module)
            .finish_non_exhaustive()
    }
}

impl RwsTarget {
    /// The resource of symbol `name`'s value.
    pub fn symbol_path(&self, name: &str) -> String {
        format!(
            "/rw/rapid/symbol/RAPID/{}/{}/{name}/data",
            self.task, self.module
        )
    }

    /// The request that sets symbol `name` to `value`, carrying `cookies`.
    pub fn set_request(&self, name: &str, value: f64, cookies: &CookieJar) -> Vec<u8> {
        let body = format!("value={}", rapid_num(value));
        let mut out = format!(
            "POST {} HTTP/1.1\r\nHost: {}\r\nAuthorization: Basic {}\r\n\
             Accept: application/xhtml+xml;v=2.0\r\n\
             Content-Type: application/x-www-form-urlencoded;v=2.0\r\n\
             Content-Length: {}\r\nConnection: keep-alive\r\n",
            self.symbol_path(name),
            self.authority,
            base64(format!("{}:{}", self.user, self.password).as_bytes()),
            body.len()
        );
        if let Some(c) = cookies.header() {
            out.push_str("Cookie: ");
            out.push_str(&c);
            out.push_str("\r\n");
        }
        out.push_str("\r\n");
        out.push_str(&body);
        out.into_bytes()
    }

    /// The request that reads symbol `name`'s value (to check that it exists and the user may read it).
    pub fn get_request(&self, name: &str, cookies: &CookieJar) -> Vec<u8> {
        let mut out = format!(
            "GET {} HTTP/1.1\r\nHost: {}\r\nAuthorization: Basic {}\r\n\
             Accept: application/xhtml+xml;v=2.0\r\nConnection: keep-alive\r\n",
            self.symbol_path(name),
            self.authority,
            base64(format!("{}:{}", self.user, self.password).as_bytes()),
        );
        if let Some(c) = cookies.header() {
            out.push_str("Cookie: ");
            out.push_str(&c);
            out.push_str("\r\n");
        }
        out.push_str("\r\n");
        out.into_bytes()
    }

    /// The three writes of `state`, in [`WRITE_ORDER`]: (symbol, value).
    pub fn state_writes(state: &ProcessState) -> [(&'static str, f64); STATE_NUMBERS] {
        let v = state_to_numbers(state);
        WRITE_ORDER.map(|i| (STATE_SYMBOLS[i], v[i]))
    }
}

/// A number as RAPID reads a `num` literal: a whole number without a point, else at most six
/// decimals with trailing zeros dropped (a `num` is a single-precision float: six decimals are below
/// its resolution at the forces written). Never NaN or infinite (the state's numbers are finite).
pub fn rapid_num(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if v.fract() == 0.0 && v.abs() < 1e15 {
        return format!("{v:.0}");
    }
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// Session cookies: what the controller set, sent back with every request.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CookieJar(Vec<(String, String)>);

impl CookieJar {
    /// Take one `Set-Cookie` value (its attributes ignored; a cookie of the same name replaced).
    pub fn absorb(&mut self, set_cookie: &str) {
        let pair = set_cookie.split(';').next().unwrap_or("").trim();
        let Some((name, value)) = pair.split_once('=') else {
            return;
        };
        let (name, value) = (name.trim(), value.trim());
        if name.is_empty() {
            return;
        }
        match self.0.iter_mut().find(|(n, _)| n == name) {
            Some(slot) => slot.1 = value.to_string(),
            None => self.0.push((name.to_string(), value.to_string())),
        }
    }

    /// The `Cookie` header's value, if any cookie is held.
    pub fn header(&self) -> Option<String> {
        (!self.0.is_empty()).then(|| {
            self.0
                .iter()
                .map(|(n, v)| format!("{n}={v}"))
                .collect::<Vec<_>>()
                .join("; ")
        })
    }

    /// Forget every cookie (a new connection, a new session).
    pub fn clear(&mut self) {
        self.0.clear();
    }
}

/// An HTTP message that breaks the protocol (or a limit).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum HttpError {
    /// The head passed [`MAX_HEAD`] bytes without ending.
    HeadTooLong,
    /// The body is longer than [`MAX_BODY`].
    BodyTooLong(usize),
    /// The status or request line is not HTTP/1.x.
    BadStartLine(String),
    /// A header line without a colon, or not UTF-8.
    BadHeader(String),
    /// `Content-Length` or a chunk size that is not a number.
    BadLength(String),
    /// A chunked body broken off or malformed.
    BadChunk,
}

impl fmt::Display for HttpError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::HeadTooLong => write!(f, "HTTP head longer than {MAX_HEAD} bytes"),
            Self::BodyTooLong(n) => write!(f, "HTTP body of {n} bytes (at most {MAX_BODY})"),
            Self::BadStartLine(l) => write!(f, "not an HTTP/1.x start line: {l:?}"),
            Self::BadHeader(l) => write!(f, "malformed HTTP header line: {l:?}"),
            Self::BadLength(v) => write!(f, "malformed HTTP length: {v:?}"),
            Self::BadChunk => f.write_str("malformed chunked HTTP body"),
        }
    }
}

impl std::error::Error for HttpError {}

/// A parsed HTTP message: the start line's parts, the headers (names in lower case) and the body.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Message {
    /// Request: method, path, version. Response: version, status code, reason.
    pub start: [String; 3],
    /// Headers, names lower-cased, in order.
    pub headers: Vec<(String, String)>,
    /// The body (de-chunked).
    pub body: Vec<u8>,
}

impl Message {
    /// The first header called `name` (lower case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }

    /// A response's status code (`None`: not a number).
    pub fn status(&self) -> Option<u16> {
        self.start[1].parse().ok()
    }

    /// The peer closes the connection after this message.
    pub fn closes(&self) -> bool {
        self.header("connection")
            .is_some_and(|v| v.eq_ignore_ascii_case("close"))
            || self.start[0] == "HTTP/1.0"
    }
}

/// Parse one HTTP/1.x message from the front of `buf`: `Ok(None)` until it is whole, then the message
/// and the bytes it took. `response`: a status line is expected (else a request line).
pub fn parse_message(buf: &[u8], response: bool) -> Result<Option<(Message, usize)>, HttpError> {
    let Some(head_end) = find(buf, b"\r\n\r\n") else {
        return if buf.len() > MAX_HEAD {
            Err(HttpError::HeadTooLong)
        } else {
            Ok(None)
        };
    };
    if head_end > MAX_HEAD {
        return Err(HttpError::HeadTooLong);
    }
    let head = core::str::from_utf8(&buf[..head_end])
        .map_err(|_| HttpError::BadHeader("(not UTF-8)".into()))?;
    let mut lines = head.split("\r\n");
    let first = lines.next().unwrap_or("");
    let mut parts = first.splitn(3, ' ');
    let start = [
        parts.next().unwrap_or("").to_string(),
        parts.next().unwrap_or("").to_string(),
        parts.next().unwrap_or("").to_string(),
    ];
    let version_ok = |v: &str| v == "HTTP/1.1" || v == "HTTP/1.0";
    let ok = if response {
        version_ok(&start[0]) && start[1].len() == 3 && start[1].bytes().all(|b| b.is_ascii_digit())
    } else {
        !start[0].is_empty() && start[1].starts_with('/') && version_ok(&start[2])
    };
    if !ok {
        return Err(HttpError::BadStartLine(first.chars().take(80).collect()));
    }
    let mut headers = Vec::new();
    for line in lines {
        let (n, v) = line
            .split_once(':')
            .ok_or_else(|| HttpError::BadHeader(line.chars().take(80).collect()))?;
        headers.push((n.trim().to_ascii_lowercase(), v.trim().to_string()));
    }
    let mut msg = Message {
        start,
        headers,
        body: Vec::new(),
    };
    let body_at = head_end + 4;
    let rest = &buf[body_at..];
    let chunked = msg
        .header("transfer-encoding")
        .is_some_and(|v| v.to_ascii_lowercase().contains("chunked"));
    // A response to a request without a body of its own (204, 304, 1xx) has none.
    let bodiless = response && matches!(msg.status(), Some(100..=199 | 204 | 304));
    if bodiless {
        return Ok(Some((msg, body_at)));
    }
    if chunked {
        return Ok(dechunk(rest)?.map(|(body, used)| {
            msg.body = body;
            (msg, body_at + used)
        }));
    }
    let len = match msg.header("content-length") {
        Some(v) => v
            .parse::<usize>()
            .map_err(|_| HttpError::BadLength(v.into()))?,
        None => 0,
    };
    if len > MAX_BODY {
        return Err(HttpError::BodyTooLong(len));
    }
    if rest.len() < len {
        return Ok(None);
    }
    msg.body = rest[..len].to_vec();
    Ok(Some((msg, body_at + len)))
}

/// A chunked body from the front of `buf`: the body and the bytes it took, `None` until whole.
fn dechunk(buf: &[u8]) -> Result<Option<(Vec<u8>, usize)>, HttpError> {
    let mut body = Vec::new();
    let mut at = 0;
    loop {
        let Some(eol) = find(&buf[at..], b"\r\n") else {
            return if buf.len() - at > MAX_HEAD {
                Err(HttpError::BadChunk)
            } else {
                Ok(None)
            };
        };
        let line = core::str::from_utf8(&buf[at..at + eol]).map_err(|_| HttpError::BadChunk)?;
        let size_text = line.split(';').next().unwrap_or("").trim();
        let size = usize::from_str_radix(size_text, 16)
            .map_err(|_| HttpError::BadLength(size_text.chars().take(20).collect()))?;
        at += eol + 2;
        if size == 0 {
            // Trailers (none expected) end with an empty line.
            let Some(end) = find(&buf[at..], b"\r\n") else {
                return Ok(None);
            };
            if end != 0 {
                return Err(HttpError::BadChunk);
            }
            return Ok(Some((body, at + 2)));
        }
        if body.len() + size > MAX_BODY {
            return Err(HttpError::BodyTooLong(body.len() + size));
        }
        if buf.len() < at + size + 2 {
            return Ok(None);
        }
        if &buf[at + size..at + size + 2] != b"\r\n" {
            return Err(HttpError::BadChunk);
        }
        body.extend_from_slice(&buf[at..at + size]);
        at += size + 2;
    }
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// What a symbol write's response means.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WriteOutcome {
    /// Written (2xx).
    Written,
    /// The controller refused the user or password (401).
    Unauthorized,
    /// Any other status: the code and the first line of the body.
    Refused(u16, String),
}

impl WriteOutcome {
    /// The outcome of `response` to a symbol write; its cookies go into `jar`.
    pub fn of(response: &Message, jar: &mut CookieJar) -> Self {
        for (n, v) in &response.headers {
            if n == "set-cookie" {
                jar.absorb(v);
            }
        }
        match response.status().unwrap_or(0) {
            200..=299 => Self::Written,
            401 => Self::Unauthorized,
            code => Self::Refused(
                code,
                String::from_utf8_lossy(&response.body)
                    .lines()
                    .map(str::trim)
                    .find(|l| !l.is_empty())
                    .unwrap_or("")
                    .chars()
                    .take(120)
                    .collect(),
            ),
        }
    }
}

impl fmt::Display for WriteOutcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Written => f.write_str("written"),
            Self::Unauthorized => f.write_str(
                "401: the controller refused the RWS user or password (robot.rws_user, rws_password)",
            ),
            Self::Refused(404, _) => f.write_str(
                "404: no such RAPID symbol (is the generated module loaded, in the task and module \
                 robot.rws_task and rws_module name?)",
            ),
            Self::Refused(code, why) => write!(f, "HTTP {code}: {why}"),
        }
    }
}

/// The form field `name` of an `application/x-www-form-urlencoded` body, decoded.
pub fn form_field(body: &[u8], name: &str) -> Option<String> {
    let text = core::str::from_utf8(body).ok()?;
    text.split('&').find_map(|kv| {
        let (k, v) = kv.split_once('=')?;
        (url_decode(k)? == name).then(|| url_decode(v)).flatten()
    })
}

fn url_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        match b[i] {
            b'+' => out.push(b' '),
            b'%' => {
                let hex = core::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
                out.push(u8::from_str_radix(hex, 16).ok()?);
                i += 2;
            }
            c => out.push(c),
        }
        i += 1;
    }
    String::from_utf8(out).ok()
}

const B64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// Standard base64 with padding (RFC 4648): the `Basic` credentials here; the application's Foxglove
/// server sends its binary schemas with it too (`forcecell::live`).
pub fn base64(data: &[u8]) -> String {
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
    for chunk in data.chunks(3) {
        let n = chunk
            .iter()
            .enumerate()
            .fold(0u32, |n, (i, &b)| n | u32::from(b) << (16 - 8 * i));
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(B64[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Decode standard base64 with padding (`None`: not base64).
pub fn base64_decode(text: &str) -> Option<Vec<u8>> {
    let t = text.trim().as_bytes();
    if !t.len().is_multiple_of(4) {
        return None;
    }
    let mut out = Vec::with_capacity(t.len() / 4 * 3);
    for chunk in t.chunks(4) {
        let pad = chunk.iter().rev().take_while(|&&c| c == b'=').count();
        if pad > 2 {
            return None;
        }
        let mut n = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            let v = if i >= 4 - pad {
                0
            } else {
                B64.iter().position(|&x| x == c)? as u32
            };
            n |= v << (18 - 6 * i);
        }
        out.extend_from_slice(&[(n >> 16) as u8, (n >> 8) as u8, n as u8][..3 - pad]);
    }
    Some(out)
}

/// The user and password of a `Basic` `Authorization` header (`None`: another scheme, or malformed).
pub fn basic_credentials(authorization: &str) -> Option<(String, String)> {
    let (scheme, rest) = authorization.trim().split_once(' ')?;
    if !scheme.eq_ignore_ascii_case("basic") {
        return None;
    }
    let text = String::from_utf8(base64_decode(rest)?).ok()?;
    let (u, p) = text.split_once(':')?;
    Some((u.to_string(), p.to_string()))
}

/// A certificate's SHA-256 as colon-separated upper-case hex (as `openssl x509 -fingerprint -sha256`
/// prints it).
pub fn fingerprint_text(sha256: &[u8; 32]) -> String {
    sha256
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(":")
}

/// A fingerprint from text: 64 hex digits, colons (or none) between bytes, any case.
pub fn parse_fingerprint(text: &str) -> Option<[u8; 32]> {
    let hex: String = text.chars().filter(|&c| c != ':').collect();
    if hex.len() != 64 || !hex.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    let mut out = [0u8; 32];
    for (i, o) in out.iter_mut().enumerate() {
        *o = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok()?;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use hal::{ProcessFault, ProcessPhase};

    fn target() -> RwsTarget {
        RwsTarget {
            authority: "192.168.125.1:443".into(),
            user: DEFAULT_USER.into(),
            password: DEFAULT_PASSWORD.into(),
            task: DEFAULT_TASK.into(),
            module: "FcEgm".into(),
        }
    }

    #[test]
    fn base64_matches_rfc_4648_vectors_and_round_trips() {
        for (plain, enc) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.as_bytes()), enc);
            assert_eq!(base64_decode(enc).unwrap(), plain.as_bytes());
        }
        assert_eq!(
            base64(b"Default User:robotics"),
            "RGVmYXVsdCBVc2VyOnJvYm90aWNz"
        );
        for bad in ["Zg=", "Z===", "Zm9v!A==", "===="] {
            assert_eq!(base64_decode(bad), None, "{bad}");
        }
    }

    #[test]
    fn a_symbol_write_is_the_rws_2_request_with_basic_credentials_and_the_cookies() {
        let mut jar = CookieJar::default();
        let r = String::from_utf8(target().set_request("fc_phase", 3.0, &jar)).unwrap();
        assert!(
            r.starts_with("POST /rw/rapid/symbol/RAPID/T_ROB1/FcEgm/fc_phase/data HTTP/1.1\r\n"),
            "{r}"
        );
        for h in [
            "Host: 192.168.125.1:443\r\n",
            "Authorization: Basic RGVmYXVsdCBVc2VyOnJvYm90aWNz\r\n",
            "Accept: application/xhtml+xml;v=2.0\r\n",
            "Content-Type: application/x-www-form-urlencoded;v=2.0\r\n",
            "Content-Length: 7\r\n",
        ] {
            assert!(r.contains(h), "{h:?} in {r}");
        }
        assert!(r.ends_with("\r\n\r\nvalue=3"), "{r}");
        assert!(!r.contains("Cookie:"));
        jar.absorb("-http-session-=3::http.session::abc; path=/; HttpOnly");
        jar.absorb("ABBCX=42; path=/");
        jar.absorb("ABBCX=43");
        let r = String::from_utf8(target().set_request("fc_force", 20.5, &jar)).unwrap();
        assert!(
            r.contains("Cookie: -http-session-=3::http.session::abc; ABBCX=43\r\n"),
            "{r}"
        );
        assert!(r.ends_with("value=20.5"));
        // The request parses as one (the simulated controller's parser).
        let (m, used) = parse_message(r.as_bytes(), false).unwrap().unwrap();
        assert_eq!(used, r.len());
        assert_eq!(form_field(&m.body, "value").as_deref(), Some("20.5"));
        assert_eq!(
            basic_credentials(m.header("authorization").unwrap()),
            Some((DEFAULT_USER.into(), DEFAULT_PASSWORD.into()))
        );
    }

    #[test]
    fn numbers_are_written_as_rapid_reads_them() {
        for (v, s) in [
            (0.0, "0"),
            (-0.0, "0"),
            (3.0, "3"),
            (9.0, "9"),
            (20.25, "20.25"),
            (19.999_999_9, "20"),
            (-1.5, "-1.5"),
            (0.000_000_4, "0"),
            (1.0 / 3.0, "0.333333"),
        ] {
            assert_eq!(rapid_num(v), s, "{v}");
        }
    }

    #[test]
    fn the_state_is_written_fault_then_force_then_phase() {
        let s = ProcessState {
            phase: ProcessPhase::Fault,
            force: f64::NAN,
            fault: ProcessFault::ForceLimit,
        };
        let w = RwsTarget::state_writes(&s);
        assert_eq!(w[0], ("fc_fault", ProcessFault::ForceLimit.code() as f64));
        assert_eq!(w[1], ("fc_force", 0.0), "an unknown force is 0, never NaN");
        assert_eq!(w[2], ("fc_phase", ProcessPhase::Fault.code() as f64));
    }

    #[test]
    fn responses_parse_whole_in_pieces_and_chunked() {
        let r = b"HTTP/1.1 204 No Content\r\nSet-Cookie: ABBCX=7; path=/\r\n\r\n";
        for cut in 0..r.len() {
            assert_eq!(parse_message(&r[..cut], true).unwrap(), None, "{cut}");
        }
        let (m, used) = parse_message(r, true).unwrap().unwrap();
        assert_eq!((m.status(), used), (Some(204), r.len()));
        let mut jar = CookieJar::default();
        assert_eq!(WriteOutcome::of(&m, &mut jar), WriteOutcome::Written);
        assert_eq!(jar.header().as_deref(), Some("ABBCX=7"));

        let two =
            b"HTTP/1.1 400 Bad Request\r\nContent-Length: 5\r\n\r\nbad\r\nHTTP/1.1 204 OK\r\n\r\n";
        let (m, used) = parse_message(two, true).unwrap().unwrap();
        assert_eq!(m.body, b"bad\r\n");
        assert!(matches!(
            WriteOutcome::of(&m, &mut jar),
            WriteOutcome::Refused(400, ref w) if w == "bad"
        ));
        let (m, _) = parse_message(&two[used..], true).unwrap().unwrap();
        assert_eq!(m.status(), Some(204));

        let c = b"HTTP/1.1 404 Not Found\r\nTransfer-Encoding: chunked\r\n\r\n4\r\nno s\r\n6;x=1\r\nymbol!\r\n0\r\n\r\n";
        for cut in 0..c.len() {
            assert_eq!(parse_message(&c[..cut], true).unwrap(), None, "{cut}");
        }
        let (m, used) = parse_message(c, true).unwrap().unwrap();
        assert_eq!((m.body.as_slice(), used), (&b"no symbol!"[..], c.len()));
        assert!(
            WriteOutcome::of(&m, &mut jar)
                .to_string()
                .contains("no such RAPID symbol")
        );
        let m = parse_message(
            b"HTTP/1.1 401 Unauthorized\r\nContent-Length: 0\r\n\r\n",
            true,
        )
        .unwrap()
        .unwrap()
        .0;
        assert_eq!(WriteOutcome::of(&m, &mut jar), WriteOutcome::Unauthorized);
    }

    #[test]
    fn malformed_messages_are_errors_not_panics() {
        let bad: [&[u8]; 8] = [
            b"SSH-2.0-OpenSSH\r\n\r\n",
            b"HTTP/1.1 2x4 No\r\n\r\n",
            b"HTTP/1.1 200 OK\r\nno colon here\r\n\r\n",
            b"HTTP/1.1 200 OK\r\nContent-Length: -3\r\n\r\n",
            b"HTTP/1.1 200 OK\r\nContent-Length: 99999999\r\n\r\n",
            b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n",
            b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n2\r\nabX\r\n",
            b"HTTP/1.1 200 OK\r\n\xff\xfe: x\r\n\r\n",
        ];
        for b in bad {
            assert!(
                parse_message(b, true).is_err(),
                "{:?}",
                String::from_utf8_lossy(b)
            );
        }
        let endless = vec![b'a'; MAX_HEAD + 1];
        assert_eq!(parse_message(&endless, true), Err(HttpError::HeadTooLong));
        assert!(parse_message(b"GET nothing HTTP/1.1\r\n\r\n", false).is_err());
    }

    #[test]
    fn form_fields_and_credentials_decode() {
        assert_eq!(
            form_field(b"a=1&value=2.5", "value").as_deref(),
            Some("2.5")
        );
        assert_eq!(
            form_field(b"value=%2D1%2E5", "value").as_deref(),
            Some("-1.5")
        );
        assert_eq!(form_field(b"value=%zz", "value"), None);
        assert_eq!(form_field(b"other=1", "value"), None);
        assert_eq!(basic_credentials("Digest username=x"), None);
        assert_eq!(basic_credentials("Basic !!!!"), None);
    }

    #[test]
    fn fingerprints_print_and_parse_as_openssl_shows_them() {
        let mut f = [0u8; 32];
        f[0] = 0xAB;
        f[31] = 0x01;
        let t = fingerprint_text(&f);
        assert!(t.starts_with("AB:00:") && t.ends_with(":01") && t.len() == 95);
        assert_eq!(parse_fingerprint(&t), Some(f));
        assert_eq!(
            parse_fingerprint(&t.replace(':', "").to_lowercase()),
            Some(f)
        );
        assert_eq!(parse_fingerprint("AB:CD"), None);
        assert_eq!(parse_fingerprint(&"g".repeat(64)), None);
    }

    #[test]
    fn the_password_is_not_in_debug_output() {
        assert!(!format!("{:?}", target()).contains(DEFAULT_PASSWORD));
    }
}
