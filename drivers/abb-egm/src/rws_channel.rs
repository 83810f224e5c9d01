//! The process state to the RAPID program over Robot Web Services 2.0: the socket shell around
//! [`crate::rws`]. The control cycle never waits for it: [`RwsChannel::publish`] leaves the newest state
//! in a one-slot mailbox (a newer state replaces one not yet written; a state is never written after a
//! newer one) and a thread of its own writes it over one kept-alive HTTPS connection, reconnecting after
//! an error. Connecting, each write and each read are bounded by [`RwsConfig::timeout`]; a failure is
//! counted and said in [`RwsReport`], the state is tried again (a newer one first) after a pause, and the
//! RAPID program's bounded waits end the pass if the state never arrives.
//!
//! TLS: a controller's certificate is self-signed, so no certificate authority vouches for it; the
//! channel pins its SHA-256 ([`RwsConfig::fingerprint`], as `openssl x509 -fingerprint -sha256` prints
//! it). Without a pin the first certificate is accepted and its fingerprint reported, to be pinned. The
//! handshake's signature is verified against the certificate's key either way.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use hal::ProcessState;
use rustls::client::danger::{HandshakeSignatureValid, ServerCertVerified, ServerCertVerifier};
use rustls::crypto::{
    CryptoProvider, WebPkiSupportedAlgorithms, verify_tls12_signature, verify_tls13_signature,
};
use rustls::pki_types::{CertificateDer, ServerName, UnixTime};
use rustls::{ClientConfig, ClientConnection, DigitallySignedStruct, SignatureScheme, StreamOwned};
use sha2::{Digest, Sha256};

use crate::process::StateChannel;
use crate::rws::{CookieJar, RwsTarget, WriteOutcome, fingerprint_text, parse_message};

/// Where and how to write.
#[derive(Clone, Debug)]
pub struct RwsConfig {
    /// The controller's HTTPS address.
    pub addr: SocketAddr,
    /// The name the certificate is asked for (SNI); the address when none.
    pub server_name: Option<String>,
    /// The variables and the credentials.
    pub target: RwsTarget,
    /// The controller certificate's SHA-256 (`None`: accept the first, report it).
    pub fingerprint: Option<[u8; 32]>,
    /// Bound of connecting, of each write and of each read.
    pub timeout: Duration,
}

/// Default bound of each network step (a controller answers a symbol write in milliseconds).
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(500);
/// Pause after a failure before the next try.
pub const RETRY_PAUSE: Duration = Duration::from_millis(200);

/// What the channel did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RwsReport {
    /// States written whole (all three variables).
    pub states: u64,
    /// Symbol writes answered 2xx.
    pub writes: u64,
    /// Attempts that failed (a connection, a write, a refusal).
    pub failures: u64,
    /// Connections opened.
    pub connects: u64,
    /// The last failure, if the last attempt failed.
    pub failing: Option<String>,
    /// The last failure ever.
    pub last_error: Option<String>,
    /// The certificate the controller presented.
    pub fingerprint: Option<[u8; 32]>,
}

impl std::fmt::Display for RwsReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "RWS: {} states written ({} symbol writes), {} failures, {} connections",
            self.states, self.writes, self.failures, self.connects
        )?;
        if let Some(e) = &self.last_error {
            write!(f, "; last error: {e}")?;
        }
        if let Some(fp) = &self.fingerprint {
            write!(
                f,
                "; controller certificate SHA-256 {}",
                fingerprint_text(fp)
            )?;
        }
        Ok(())
    }
}

#[derive(Default)]
struct Mail {
    pending: Option<ProcessState>,
    stop: bool,
}

struct Shared {
    mail: Mutex<Mail>,
    cv: Condvar,
    report: Mutex<RwsReport>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// A [`StateChannel`] writing the state's three `PERS num` over RWS 2.0.
pub struct RwsChannel {
    shared: Arc<Shared>,
    worker: Option<JoinHandle<()>>,
}

/// A handle on a channel's [`RwsReport`] that outlives the link holding the channel.
#[derive(Clone)]
pub struct RwsReportHandle(Arc<Shared>);

impl RwsReportHandle {
    /// The report so far.
    pub fn report(&self) -> RwsReport {
        lock(&self.0.report).clone()
    }
}

impl RwsChannel {
    /// Start the writer thread (it connects when the first state comes).
    pub fn start(config: RwsConfig) -> std::io::Result<Self> {
        let shared = Arc::new(Shared {
            mail: Mutex::new(Mail::default()),
            cv: Condvar::new(),
            report: Mutex::new(RwsReport::default()),
        });
        let tls = tls_config(config.fingerprint, shared.clone());
        let worker = {
            let shared = shared.clone();
            std::thread::Builder::new()
                .name("rws".into())
                .spawn(move || Writer::new(config, tls, shared).run())?
        };
        Ok(Self {
            shared,
            worker: Some(worker),
        })
    }

    /// A handle on the report.
    pub fn report_handle(&self) -> RwsReportHandle {
        RwsReportHandle(self.shared.clone())
    }

    /// Write whatever is pending (bounded by the timeouts) and stop the thread.
    pub fn finish(&mut self) {
        lock(&self.shared.mail).stop = true;
        self.shared.cv.notify_one();
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}

impl Drop for RwsChannel {
    fn drop(&mut self) {
        self.finish();
    }
}

impl StateChannel for RwsChannel {
    /// Hand `state` to the writer: never waits for the network; wakes the writer only when it may be
    /// waiting (its mailbox was empty), so a cycle makes no system call while a state is in flight.
    fn publish(&mut self, state: &ProcessState) -> Result<(), String> {
        if self.worker.as_ref().is_none_or(JoinHandle::is_finished) {
            return Err("the RWS writer thread has ended".into());
        }
        let was_empty = {
            let mut m = lock(&self.shared.mail);
            m.pending.replace(*state).is_none()
        };
        if was_empty {
            self.shared.cv.notify_one();
        }
        Ok(())
    }

    fn report(&self) -> Option<String> {
        Some(lock(&self.shared.report).to_string())
    }
}

struct Writer {
    config: RwsConfig,
    tls: Arc<ClientConfig>,
    shared: Arc<Shared>,
    conn: Option<StreamOwned<ClientConnection, TcpStream>>,
    jar: CookieJar,
    buf: Vec<u8>,
}

impl Writer {
    fn new(config: RwsConfig, tls: Arc<ClientConfig>, shared: Arc<Shared>) -> Self {
        Self {
            config,
            tls,
            shared,
            conn: None,
            jar: CookieJar::default(),
            buf: Vec::new(),
        }
    }

    fn run(mut self) {
        loop {
            let (state, stopping) = {
                let mut m = lock(&self.shared.mail);
                while m.pending.is_none() && !m.stop {
                    m = self.shared.cv.wait(m).unwrap_or_else(|e| e.into_inner());
                }
                (m.pending.take(), m.stop)
            };
            let Some(state) = state else { return };
            let result = self.write_state(&state);
            let mut r = lock(&self.shared.report);
            match result {
                Ok(()) => {
                    r.states += 1;
                    r.failing = None;
                }
                Err(e) => {
                    r.failures += 1;
                    r.failing = Some(e.clone());
                    r.last_error = Some(e);
                    drop(r);
                    self.conn = None;
                    if stopping {
                        return;
                    }
                    // Try this state again unless a newer one came meanwhile.
                    let mut m = lock(&self.shared.mail);
                    if m.pending.is_none() {
                        m.pending = Some(state);
                    }
                    drop(m);
                    std::thread::sleep(RETRY_PAUSE);
                }
            }
            if stopping && lock(&self.shared.mail).pending.is_none() {
                return;
            }
        }
    }

    fn write_state(&mut self, state: &ProcessState) -> Result<(), String> {
        for (name, value) in RwsTarget::state_writes(state) {
            self.write_symbol(name, value)?;
            lock(&self.shared.report).writes += 1;
        }
        Ok(())
    }

    fn connect(&mut self) -> Result<(), String> {
        let c = &self.config;
        let tcp = TcpStream::connect_timeout(&c.addr, c.timeout)
            .map_err(|e| format!("connecting to RWS at {}: {e}", c.addr))?;
        tcp.set_read_timeout(Some(c.timeout))
            .and_then(|()| tcp.set_write_timeout(Some(c.timeout)))
            .and_then(|()| tcp.set_nodelay(true))
            .map_err(|e| format!("RWS socket: {e}"))?;
        let name = match &c.server_name {
            Some(n) => ServerName::try_from(n.clone())
                .map_err(|e| format!("RWS server name {n:?}: {e}"))?,
            None => ServerName::from(c.addr.ip()),
        };
        let conn =
            ClientConnection::new(self.tls.clone(), name).map_err(|e| format!("RWS TLS: {e}"))?;
        self.conn = Some(StreamOwned::new(conn, tcp));
        self.jar.clear();
        lock(&self.shared.report).connects += 1;
        Ok(())
    }

    fn write_symbol(&mut self, name: &str, value: f64) -> Result<(), String> {
        let request = self.config.target.set_request(name, value, &self.jar);
        self.exchange(name, &request)
    }

    /// Send `request` (about symbol `name`) and judge the answer; connects first when needed.
    fn exchange(&mut self, name: &str, request: &[u8]) -> Result<(), String> {
        if self.conn.is_none() {
            self.connect()?;
        }
        let addr = self.config.addr;
        let stream = self.conn.as_mut().ok_or("no RWS connection")?;
        stream
            .write_all(request)
            .and_then(|()| stream.flush())
            .map_err(|e| format!("RWS at {addr}: {e}"))?;
        self.buf.clear();
        let mut chunk = [0u8; 4096];
        let response = loop {
            if let Some((m, _)) =
                parse_message(&self.buf, true).map_err(|e| format!("RWS at {addr} answered {e}"))?
            {
                break m;
            }
            let n = stream
                .read(&mut chunk)
                .map_err(|e| format!("RWS at {addr}: {e}"))?;
            if n == 0 {
                return Err(format!("RWS at {addr} closed the connection"));
            }
            self.buf.extend_from_slice(&chunk[..n]);
        };
        if response.closes() {
            self.conn = None;
        }
        match WriteOutcome::of(&response, &mut self.jar) {
            WriteOutcome::Written => Ok(()),
            other => Err(format!("RWS request about {name}: {other}")),
        }
    }
}

/// Check a controller before a run (`forcecell check`): connect, agree on TLS (the pinned certificate),
/// and read `fc_phase` with the credentials. Returns the certificate's SHA-256; writes nothing.
pub fn probe(config: &RwsConfig) -> Result<[u8; 32], String> {
    let shared = Arc::new(Shared {
        mail: Mutex::new(Mail::default()),
        cv: Condvar::new(),
        report: Mutex::new(RwsReport::default()),
    });
    let tls = tls_config(config.fingerprint, shared.clone());
    let mut w = Writer::new(config.clone(), tls, shared.clone());
    let request = config
        .target
        .get_request(crate::rws::STATE_SYMBOLS[0], &CookieJar::default());
    let result = w.exchange(crate::rws::STATE_SYMBOLS[0], &request);
    let seen = lock(&shared.report).fingerprint;
    result?;
    seen.ok_or_else(|| "no certificate seen".into())
}

/// The TLS client configuration: ring's algorithms, the pinned (or reported) certificate.
fn tls_config(pin: Option<[u8; 32]>, shared: Arc<Shared>) -> Arc<ClientConfig> {
    let provider = crypto_provider();
    let verifier = Arc::new(Pinned {
        pin,
        shared,
        algorithms: provider.signature_verification_algorithms,
    });
    let config = ClientConfig::builder_with_provider(provider.clone())
        .with_safe_default_protocol_versions()
        .expect("ring's provider supports the default protocol versions")
        .dangerous()
        .with_custom_certificate_verifier(verifier)
        .with_no_client_auth();
    Arc::new(config)
}

/// The ring provider forcecell's TLS uses (the simulated controller's too). rustls marks it deprecated
/// because ring has no post-quantum key exchange; its classical groups (X25519, P-256, P-384) are what a
/// controller's web server offers, and the alternative provider (aws-lc-rs) needs CMake to build.
#[allow(deprecated)]
pub fn crypto_provider() -> Arc<CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

struct Pinned {
    pin: Option<[u8; 32]>,
    shared: Arc<Shared>,
    algorithms: WebPkiSupportedAlgorithms,
}

impl std::fmt::Debug for Pinned {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pinned").field("pin", &self.pin).finish()
    }
}

impl ServerCertVerifier for Pinned {
    fn verify_server_cert(
        &self,
        end_entity: &CertificateDer<'_>,
        _intermediates: &[CertificateDer<'_>],
        _server_name: &ServerName<'_>,
        _ocsp_response: &[u8],
        _now: UnixTime,
    ) -> Result<ServerCertVerified, rustls::Error> {
        let seen: [u8; 32] = Sha256::digest(end_entity.as_ref()).into();
        lock(&self.shared.report).fingerprint = Some(seen);
        match self.pin {
            Some(pin) if pin != seen => Err(rustls::Error::General(format!(
                "the controller's certificate (SHA-256 {}) is not the pinned one (robot.rws_fingerprint {})",
                fingerprint_text(&seen),
                fingerprint_text(&pin)
            ))),
            _ => Ok(ServerCertVerified::assertion()),
        }
    }

    fn verify_tls12_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        verify_tls12_signature(message, cert, dss, &self.algorithms)
    }

    fn verify_tls13_signature(
        &self,
        message: &[u8],
        cert: &CertificateDer<'_>,
        dss: &DigitallySignedStruct,
    ) -> Result<HandshakeSignatureValid, rustls::Error> {
        verify_tls13_signature(message, cert, dss, &self.algorithms)
    }

    fn supported_verify_schemes(&self) -> Vec<SignatureScheme> {
        self.algorithms.supported_schemes()
    }
}
