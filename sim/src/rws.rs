//! The simulated controller's Robot Web Services 2.0 endpoint: what forcecell's state channel
//! ([`abb_egm::rws_channel`]) writes to on a cell, served over HTTPS on loopback. It takes the symbol
//! writes of the generated module's three state variables (`POST
//! /rw/rapid/symbol/RAPID/{task}/{module}/{name}/data`, form field `value`) into the simulated IRC5's
//! [`RapidVariables`], and answers reads of them (`GET` of the same resource: `{"value": "…"}`).
//! Authentication is HTTP Basic, or the session cookie it set on the first authenticated request.
//! The certificate is self-signed and made at start ([`RwsServer::fingerprint`] to pin it).
//!
//! What it does not model: other resources (404), mastership, RobotWare's session limit, XHTML
//! answers (reads answer JSON).

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use abb_egm::rws::{Message, STATE_SYMBOLS, basic_credentials, form_field, parse_message};
use rustls::pki_types::{CertificateDer, PrivateKeyDer, PrivatePkcs8KeyDer};
use rustls::{ServerConfig, ServerConnection, StreamOwned};
use sha2::{Digest, Sha256};

use crate::irc5::RapidVariables;

/// Who may write, and where the variables are.
#[derive(Clone, Debug)]
pub struct RwsServerConfig {
    /// User.
    pub user: String,
    /// Password.
    pub password: String,
    /// RAPID task.
    pub task: String,
    /// Module declaring the variables.
    pub module: String,
    /// Where to listen (a loopback address; port 0: any).
    pub bind: SocketAddr,
}

impl Default for RwsServerConfig {
    fn default() -> Self {
        Self {
            user: abb_egm::rws::DEFAULT_USER.into(),
            password: abb_egm::rws::DEFAULT_PASSWORD.into(),
            task: abb_egm::rws::DEFAULT_TASK.into(),
            module: abb_egm::rapid::DEFAULT_MODULE.into(),
            bind: SocketAddr::from(([127, 0, 0, 1], 0)),
        }
    }
}

/// What the endpoint served.
#[derive(Debug, Default)]
pub struct RwsServerStats {
    /// Requests parsed.
    pub requests: AtomicU64,
    /// Symbol values written.
    pub writes: AtomicU64,
    /// Requests refused for their credentials (401).
    pub unauthorized: AtomicU64,
    /// Requests refused otherwise (400, 404, 405).
    pub refused: AtomicU64,
    /// TLS connections accepted.
    pub connections: AtomicU64,
}

/// The running endpoint; stops when dropped.
pub struct RwsServer {
    addr: SocketAddr,
    fingerprint: [u8; 32],
    stats: Arc<RwsServerStats>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl RwsServer {
    /// Start serving `vars` with a fresh self-signed certificate for `127.0.0.1` and `localhost`.
    pub fn start(config: RwsServerConfig, vars: RapidVariables) -> std::io::Result<Self> {
        let cert = rcgen::generate_simple_self_signed(vec!["127.0.0.1".into(), "localhost".into()])
            .map_err(std::io::Error::other)?;
        let der: CertificateDer<'static> = cert.cert.der().clone();
        let fingerprint: [u8; 32] = Sha256::digest(der.as_ref()).into();
        let key = PrivateKeyDer::Pkcs8(PrivatePkcs8KeyDer::from(cert.signing_key.serialize_der()));
        let tls = ServerConfig::builder_with_provider(abb_egm::rws_channel::crypto_provider())
            .with_safe_default_protocol_versions()
            .map_err(std::io::Error::other)?
            .with_no_client_auth()
            .with_single_cert(vec![der], key)
            .map_err(std::io::Error::other)?;
        let tls = Arc::new(tls);
        let listener = TcpListener::bind(config.bind)?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let stats = Arc::new(RwsServerStats::default());
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (stats, stop) = (stats.clone(), stop.clone());
            let shared = Arc::new(Endpoint {
                config,
                vars,
                stats: stats.clone(),
                session: Mutex::new(None),
                sessions: AtomicU64::new(0),
            });
            std::thread::Builder::new()
                .name("sim-rws".into())
                .spawn(move || accept_loop(&listener, &tls, &shared, &stop))?
        };
        Ok(Self {
            addr,
            fingerprint,
            stats,
            stop,
            thread: Some(thread),
        })
    }

    /// Where it listens.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The URL a cell file's `robot.rws` names.
    pub fn url(&self) -> String {
        format!("https://{}", self.addr)
    }

    /// Its certificate's SHA-256.
    pub fn fingerprint(&self) -> [u8; 32] {
        self.fingerprint
    }

    /// What it served so far.
    pub fn stats(&self) -> &RwsServerStats {
        &self.stats
    }

    /// Stop accepting and end the connections' threads.
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for RwsServer {
    fn drop(&mut self) {
        self.stop();
    }
}

struct Endpoint {
    config: RwsServerConfig,
    vars: RapidVariables,
    stats: Arc<RwsServerStats>,
    /// The session cookie's value, once one was set.
    session: Mutex<Option<String>>,
    sessions: AtomicU64,
}

fn accept_loop(
    listener: &TcpListener,
    tls: &Arc<ServerConfig>,
    ep: &Arc<Endpoint>,
    stop: &Arc<AtomicBool>,
) {
    let mut conns: Vec<JoinHandle<()>> = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((tcp, _)) => {
                conns.retain(|c| !c.is_finished());
                let (tls, ep, stop) = (tls.clone(), ep.clone(), stop.clone());
                if let Ok(h) = std::thread::Builder::new()
                    .name("sim-rws-conn".into())
                    .spawn(move || serve(tcp, &tls, &ep, &stop))
                {
                    conns.push(h);
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(5)),
        }
    }
    for c in conns {
        let _ = c.join();
    }
}

/// One connection: requests until the client closes, an error, or the stop.
fn serve(tcp: TcpStream, tls: &Arc<ServerConfig>, ep: &Endpoint, stop: &AtomicBool) {
    if tcp.set_nonblocking(false).is_err()
        || tcp
            .set_read_timeout(Some(Duration::from_millis(50)))
            .is_err()
    {
        return;
    }
    let Ok(conn) = ServerConnection::new(tls.clone()) else {
        return;
    };
    ep.stats.connections.fetch_add(1, Ordering::Relaxed);
    let mut s = StreamOwned::new(conn, tcp);
    let mut buf = Vec::new();
    let mut chunk = [0u8; 4096];
    while !stop.load(Ordering::Relaxed) {
        match parse_message(&buf, false) {
            Ok(Some((req, used))) => {
                buf.drain(..used);
                ep.stats.requests.fetch_add(1, Ordering::Relaxed);
                let (answer, close) = ep.answer(&req);
                if s.write_all(&answer).and_then(|()| s.flush()).is_err() || close {
                    return;
                }
                continue;
            }
            Ok(None) => {}
            Err(e) => {
                let body = e.to_string();
                let _ = s.write_all(response(400, "Bad Request", &[], &body).as_bytes());
                let _ = s.flush();
                ep.stats.refused.fetch_add(1, Ordering::Relaxed);
                return;
            }
        }
        match s.read(&mut chunk) {
            Ok(0) => return,
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => return,
        }
    }
}

fn response(code: u16, reason: &str, headers: &[String], body: &str) -> String {
    let mut r = format!("HTTP/1.1 {code} {reason}\r\n");
    for h in headers {
        r.push_str(h);
        r.push_str("\r\n");
    }
    if code != 204 {
        r.push_str(&format!("Content-Length: {}\r\n", body.len()));
    }
    r.push_str("\r\n");
    if code != 204 {
        r.push_str(body);
    }
    r
}

impl Endpoint {
    /// The answer to `req`, and whether the connection then closes.
    fn answer(&self, req: &Message) -> (Vec<u8>, bool) {
        let close = req.closes();
        let refuse = |code, reason: &str, why: &str| {
            self.stats.refused.fetch_add(1, Ordering::Relaxed);
            (response(code, reason, &[], why).into_bytes(), close)
        };
        // Authenticated by the session cookie, or by Basic credentials (which set the cookie).
        let cookie_ok = {
            let session = self.session.lock().unwrap_or_else(|e| e.into_inner());
            session.as_ref().is_some_and(|sid| {
                req.headers.iter().any(|(n, v)| {
                    n == "cookie"
                        && v.split(';')
                            .any(|c| c.trim() == format!("-http-session-={sid}"))
                })
            })
        };
        let basic_ok = req
            .header("authorization")
            .and_then(basic_credentials)
            .is_some_and(|(u, p)| u == self.config.user && p == self.config.password);
        if !cookie_ok && !basic_ok {
            self.stats.unauthorized.fetch_add(1, Ordering::Relaxed);
            let h = ["WWW-Authenticate: Basic realm=\"validusers@robapi.abb\"".to_string()];
            return (response(401, "Unauthorized", &h, "").into_bytes(), close);
        }
        let mut headers = Vec::new();
        if basic_ok && !cookie_ok {
            let n = self.sessions.fetch_add(1, Ordering::Relaxed) + 1;
            let sid = format!("sim-{n}");
            headers.push(format!(
                "Set-Cookie: -http-session-={sid}; path=/; httponly"
            ));
            *self.session.lock().unwrap_or_else(|e| e.into_inner()) = Some(sid);
        }
        let path = req.start[1].split('?').next().unwrap_or("");
        let prefix = format!(
            "/rw/rapid/symbol/RAPID/{}/{}/",
            self.config.task, self.config.module
        );
        let Some(index) = path
            .strip_prefix(&prefix)
            .and_then(|rest| rest.strip_suffix("/data"))
            .and_then(|name| STATE_SYMBOLS.iter().position(|s| *s == name))
        else {
            return refuse(404, "Not Found", "no such RAPID symbol");
        };
        match req.start[0].as_str() {
            "POST" => {
                let Some(v) = form_field(&req.body, "value")
                    .and_then(|t| t.trim().parse::<f64>().ok())
                    .filter(|v| v.is_finite())
                else {
                    return refuse(400, "Bad Request", "value is not a num");
                };
                self.vars.write_one(index, v);
                self.stats.writes.fetch_add(1, Ordering::Relaxed);
                (
                    response(204, "No Content", &headers, "").into_bytes(),
                    close,
                )
            }
            "GET" => {
                let v = self.vars.read().map_or(0.0, |v| v[index]);
                headers.push("Content-Type: application/json".into());
                let body = format!("{{\"value\": \"{v}\"}}");
                (response(200, "OK", &headers, &body).into_bytes(), close)
            }
            _ => refuse(405, "Method Not Allowed", "only GET and POST"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use abb_egm::rws_channel::{RwsChannel, RwsConfig};
    use abb_egm::{StateChannel, rws::RwsTarget};
    use hal::{ProcessFault, ProcessPhase, ProcessState};
    use std::time::Instant;

    fn target(server: &RwsServer, password: &str) -> RwsConfig {
        RwsConfig {
            addr: server.local_addr(),
            server_name: None,
            target: RwsTarget {
                authority: server.local_addr().to_string(),
                user: abb_egm::rws::DEFAULT_USER.into(),
                password: password.into(),
                task: abb_egm::rws::DEFAULT_TASK.into(),
                module: abb_egm::rapid::DEFAULT_MODULE.into(),
            },
            fingerprint: Some(server.fingerprint()),
            timeout: Duration::from_secs(2),
        }
    }

    fn state(phase: ProcessPhase, force: f64, fault: ProcessFault) -> ProcessState {
        ProcessState {
            phase,
            force,
            fault,
        }
    }

    /// Wait (bounded, generously: a shared machine) until `f` holds.
    fn eventually(mut f: impl FnMut() -> bool) -> bool {
        let end = Instant::now() + Duration::from_secs(20);
        while Instant::now() < end {
            if f() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        false
    }

    /// A simulated controller and a channel to it logging in with `password`.
    fn session(
        password: &str,
    ) -> (
        RapidVariables,
        RwsServer,
        RwsChannel,
        abb_egm::rws_channel::RwsReportHandle,
    ) {
        let vars = RapidVariables::default();
        let server = RwsServer::start(RwsServerConfig::default(), vars.clone()).unwrap();
        let ch = RwsChannel::start(target(&server, password)).unwrap();
        let report = ch.report_handle();
        (vars, server, ch, report)
    }

    #[test]
    fn states_written_over_https_land_in_the_rapid_variables_newest_last() {
        let (vars, server, mut ch, report) = session("robotics");
        ch.publish(&state(ProcessPhase::Approach, 0.0, ProcessFault::None))
            .unwrap();
        ch.publish(&state(ProcessPhase::Pressing, 19.5, ProcessFault::None))
            .unwrap();
        assert!(
            eventually(|| vars.read() == Some([3.0, 19.5, 0.0])),
            "{:?} {}",
            vars.read(),
            report.report()
        );
        ch.finish();
        let r = report.report();
        assert_eq!(r.failures, 0, "{r}");
        assert_eq!(r.connects, 1, "one kept-alive connection: {r}");
        assert_eq!(r.fingerprint, Some(server.fingerprint()));
        // One Basic authentication, then the session cookie.
        assert_eq!(server.stats().unauthorized.load(Ordering::Relaxed), 0);
        assert_eq!(server.stats().writes.load(Ordering::Relaxed), 3 * r.states);
    }

    #[test]
    fn a_wrong_password_or_certificate_is_a_failure_said_and_nothing_written() {
        let (vars, server, mut ch, report) = session("wrong");
        ch.publish(&state(ProcessPhase::Off, 0.0, ProcessFault::None))
            .unwrap();
        assert!(eventually(|| report.report().failures >= 1));
        ch.finish();
        let r = report.report();
        assert!(r.last_error.as_deref().unwrap().contains("401"), "{r}");
        assert_eq!(vars.read(), None);

        let mut cfg = target(&server, "robotics");
        cfg.fingerprint = Some([7; 32]);
        let mut ch = RwsChannel::start(cfg).unwrap();
        let report = ch.report_handle();
        ch.publish(&state(ProcessPhase::Off, 0.0, ProcessFault::None))
            .unwrap();
        assert!(eventually(|| report.report().failures >= 1));
        ch.finish();
        let r = report.report();
        assert!(
            r.last_error
                .as_deref()
                .unwrap()
                .contains("not the pinned one"),
            "{r}"
        );
        assert_eq!(vars.read(), None);
    }

    #[test]
    fn a_state_published_while_the_controller_is_away_arrives_when_it_is_back() {
        // Nothing listens at first: the writer fails, pauses, and tries the newest state again.
        let probe = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = probe.local_addr().unwrap();
        drop(probe);
        let vars = RapidVariables::default();
        let sc = RwsServerConfig {
            bind: addr,
            ..RwsServerConfig::default()
        };
        let mut cfg = {
            let s =
                RwsServer::start(RwsServerConfig::default(), RapidVariables::default()).unwrap();
            target(&s, "robotics")
        };
        cfg.addr = addr;
        cfg.fingerprint = None; // the server's certificate is made when it starts
        let mut ch = RwsChannel::start(cfg).unwrap();
        let report = ch.report_handle();
        ch.publish(&state(ProcessPhase::Release, 4.0, ProcessFault::None))
            .unwrap();
        assert!(eventually(|| report.report().failures >= 1));
        ch.publish(&state(ProcessPhase::Fault, 31.0, ProcessFault::ForceLimit))
            .unwrap();
        let server = RwsServer::start(sc, vars.clone()).unwrap();
        let want = [
            ProcessPhase::Fault.code() as f64,
            31.0,
            ProcessFault::ForceLimit.code() as f64,
        ];
        assert!(
            eventually(|| vars.read() == Some(want)),
            "{:?} {}",
            vars.read(),
            report.report()
        );
        ch.finish();
        assert_eq!(report.report().fingerprint, Some(server.fingerprint()));
    }

    #[test]
    fn other_resources_and_bad_values_are_refused() {
        let vars = RapidVariables::default();
        let server = RwsServer::start(RwsServerConfig::default(), vars.clone()).unwrap();
        let ep = Endpoint {
            config: RwsServerConfig::default(),
            vars: vars.clone(),
            stats: Arc::new(RwsServerStats::default()),
            session: Mutex::new(None),
            sessions: AtomicU64::new(0),
        };
        let t = target(&server, "robotics").target;
        let jar = abb_egm::rws::CookieJar::default();
        let ask = |bytes: Vec<u8>| {
            let (m, _) = parse_message(&bytes, false).unwrap().unwrap();
            let (a, _) = ep.answer(&m);
            parse_message(&a, true)
                .unwrap()
                .unwrap()
                .0
                .status()
                .unwrap()
        };
        assert_eq!(ask(t.set_request("fc_phase", 1.0, &jar)), 204);
        assert_eq!(ask(t.set_request("reg1", 1.0, &jar)), 404);
        let nan = String::from_utf8(t.set_request("fc_force", 1.0, &jar))
            .unwrap()
            .replace("value=1", "value=x");
        assert_eq!(ask(nan.into_bytes()), 400);
        let mut other = t.clone();
        other.password = "x".into();
        assert_eq!(ask(other.set_request("fc_phase", 1.0, &jar)), 401);
        assert_eq!(vars.read(), Some([1.0, 0.0, 0.0]));
    }
}
