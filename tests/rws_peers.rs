//! Robot Web Services against peers the project did not write, over real TCP and TLS on loopback:
//! `curl` (with OpenSSL or GnuTLS) as a client of the simulated controller's endpoint, and Python's
//! standard `http.server` behind its `ssl` module (OpenSSL), with a certificate made by the `openssl`
//! command, as the controller forcecell's state writer talks to. They need `curl`, `python3` and
//! `openssl`, hence ignored; `scripts/test.sh` installs them and runs
//! `cargo test --release --test rws_peers -- --ignored`.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use abb_egm::StateChannel;
use abb_egm::rws::{self, RwsTarget};
use abb_egm::rws_channel::{RwsChannel, RwsConfig};
use hal::{ProcessFault, ProcessPhase, ProcessState};
use sim::irc5::RapidVariables;
use sim::rws::{RwsServer, RwsServerConfig};

/// `curl` against `url`: (HTTP status, body).
fn curl(args: &[&str], url: &str) -> (u16, String) {
    let out = Command::new("curl")
        .args(["-sS", "-k", "--max-time", "20", "-w", "\n%{http_code}"])
        .args(args)
        .arg(url)
        .output()
        .expect("curl (scripts/test.sh installs it)");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let (body, code) = text.rsplit_once('\n').unwrap_or(("", &text));
    (
        code.trim()
            .parse()
            .unwrap_or_else(|_| panic!("curl: {text}")),
        body.to_string(),
    )
}

#[test]
#[ignore = "needs curl (scripts/test.sh installs it and runs this)"]
fn curl_writes_and_reads_the_simulated_controllers_variables() {
    let vars = RapidVariables::default();
    let server = RwsServer::start(RwsServerConfig::default(), vars.clone()).unwrap();
    let url = format!(
        "{}/rw/rapid/symbol/RAPID/T_ROB1/{}/fc_force/data",
        server.url(),
        abb_egm::rapid::DEFAULT_MODULE
    );
    let form = [
        "-H",
        "Content-Type: application/x-www-form-urlencoded;v=2.0",
        "-H",
        "Accept: application/xhtml+xml;v=2.0",
        "-d",
        "value=12.5",
    ];
    let mut with_user = vec!["-u", "Default User:robotics"];
    with_user.extend(form);
    assert_eq!(curl(&with_user, &url).0, 204);
    assert_eq!(vars.read(), Some([0.0, 12.5, 0.0]));
    let (code, body) = curl(&["-u", "Default User:robotics"], &url);
    assert_eq!(code, 200, "{body}");
    assert!(body.contains("\"value\": \"12.5\""), "{body}");
    // A wrong password is refused and writes nothing; an unknown symbol is 404.
    let mut wrong = vec!["-u", "Default User:nope"];
    wrong.extend(form);
    assert_eq!(curl(&wrong, &url).0, 401);
    let other = url.replace("fc_force", "reg1");
    assert_eq!(curl(&with_user, &other).0, 404);
    assert_eq!(vars.read(), Some([0.0, 12.5, 0.0]));
}

const PY_SERVER: &str = r#"
import base64, http.server, ssl, sys
class H(http.server.BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    def do_POST(self):
        n = int(self.headers.get("Content-Length", "0"))
        body = self.rfile.read(n).decode()
        auth = self.headers.get("Authorization", "")
        user = base64.b64decode(auth.split(" ", 1)[1]).decode() if auth.startswith("Basic ") else ""
        print("POST", self.path, body, user, self.headers.get("Cookie", "-"),
              self.headers.get("Content-Type"), flush=True)
        self.send_response(204)
        self.send_header("Set-Cookie", "-http-session-=py1; path=/")
        self.end_headers()
    def log_message(self, *a):
        pass
ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
ctx.load_cert_chain(sys.argv[1], sys.argv[2])
srv = http.server.HTTPServer(("127.0.0.1", 0), H)
srv.socket = ctx.wrap_socket(srv.socket, server_side=True)
print("port", srv.server_address[1], flush=True)
srv.serve_forever()
"#;

#[test]
#[ignore = "needs python3 and openssl (scripts/test.sh installs them and runs this)"]
fn the_state_writer_against_pythons_https_server_and_an_openssl_certificate() {
    let dir = tempfile::tempdir().unwrap();
    let (cert, key) = (dir.path().join("cert.pem"), dir.path().join("key.pem"));
    let made = Command::new("openssl")
        .args([
            "req",
            "-x509",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:P-256",
        ])
        .args(["-nodes", "-days", "2", "-subj", "/CN=127.0.0.1", "-keyout"])
        .arg(&key)
        .arg("-out")
        .arg(&cert)
        .output()
        .expect("openssl (scripts/test.sh installs it)");
    assert!(made.status.success(), "{made:?}");
    let fp = Command::new("openssl")
        .args(["x509", "-noout", "-fingerprint", "-sha256", "-in"])
        .arg(&cert)
        .output()
        .unwrap();
    let fp_text = String::from_utf8_lossy(&fp.stdout);
    // "sha256 Fingerprint=AB:CD:…" (the spelling of the prefix varies between OpenSSL versions).
    let pin = rws::parse_fingerprint(fp_text.trim().rsplit('=').next().unwrap())
        .unwrap_or_else(|| panic!("a fingerprint in {fp_text:?}"));
    let mut py = Command::new("python3")
        .arg("-c")
        .arg(PY_SERVER)
        .arg(&cert)
        .arg(&key)
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 (scripts/test.sh installs it)");
    let mut lines = BufReader::new(py.stdout.take().unwrap()).lines();
    let first = lines.next().unwrap().unwrap();
    let port: u16 = first.strip_prefix("port ").unwrap().parse().unwrap();
    let addr = std::net::SocketAddr::from(([127, 0, 0, 1], port));
    let config = RwsConfig {
        addr,
        server_name: None,
        target: RwsTarget {
            authority: addr.to_string(),
            user: "Default User".into(),
            password: "robotics".into(),
            task: "T_ROB1".into(),
            module: "FcEgm".into(),
        },
        fingerprint: Some(pin),
        timeout: Duration::from_secs(5),
    };
    let mut ch = RwsChannel::start(config).unwrap();
    let report = ch.report_handle();
    ch.publish(&ProcessState {
        phase: ProcessPhase::Pressing,
        force: 20.25,
        fault: ProcessFault::None,
    })
    .unwrap();
    let mut got = Vec::new();
    let end = Instant::now() + Duration::from_secs(30);
    while got.len() < 3 && Instant::now() < end {
        match lines.next() {
            Some(Ok(l)) => got.push(l),
            _ => break,
        }
    }
    ch.finish();
    let _ = py.kill();
    let _ = py.wait();
    let r = report.report();
    assert_eq!(got.len(), 3, "{got:?}\n{r}");
    let base = "/rw/rapid/symbol/RAPID/T_ROB1/FcEgm";
    let ct = "application/x-www-form-urlencoded;v=2.0";
    assert_eq!(
        got[0],
        format!("POST {base}/fc_fault/data value=0 Default User:robotics - {ct}")
    );
    // The cookie Python's server set is sent back.
    assert_eq!(
        got[1],
        format!(
            "POST {base}/fc_force/data value=20.25 Default User:robotics -http-session-=py1 {ct}"
        )
    );
    assert_eq!(
        got[2],
        format!("POST {base}/fc_phase/data value=3 Default User:robotics -http-session-=py1 {ct}")
    );
    assert_eq!((r.states, r.failures, r.connects), (1, 0, 1), "{r}");
    assert_eq!(r.fingerprint, Some(pin));
}
