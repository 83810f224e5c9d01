//! The live view: `forcecell sim --live` serves the recording's channels over the Foxglove WebSocket
//! protocol; a client on the loopback port gets `serverInfo`, every channel advertised with its
//! protobuf schema, and, once subscribed, `messageData` frames with the run's values.

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Command, Stdio};

use forcecell::recorder::Record;
use scenario::telemetry;
use tungstenite::Message;
use tungstenite::client::IntoClientRequest;

struct Kill(std::process::Child);

impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn a_client_on_the_live_port_gets_the_channels_and_messages() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/paper-fig9.toml"),
    )
    .unwrap()
    .replace("name = \"paper-fig9\"", "name = \"long\"")
    .replace("duration = 2.0", "duration = 60.0");
    std::fs::write(dir.path().join("long.toml"), scenario).unwrap();
    let mut child = Kill(
        Command::new(env!("CARGO_BIN_EXE_forcecell"))
            .args([
                "sim",
                "--scenario",
                "long.toml",
                "--plant",
                "p2",
                "--live",
                "127.0.0.1:0",
                "--out",
                "res",
            ])
            .current_dir(dir.path())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let stdout = child.0.stdout.take().unwrap();
    let mut lines = BufReader::new(stdout).lines();
    let addr = loop {
        let line = lines
            .next()
            .expect("sim ended before serving the live view")
            .unwrap();
        if let Some(rest) = line.strip_prefix("live view: ws://") {
            break rest.split_whitespace().next().unwrap().to_string();
        }
    };
    let mut req = format!("ws://{addr}").into_client_request().unwrap();
    req.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.websocket.v1".parse().unwrap(),
    );
    let (mut ws, resp) = tungstenite::client(req, TcpStream::connect(&addr).unwrap()).unwrap();
    assert_eq!(
        resp.headers()["Sec-WebSocket-Protocol"],
        "foxglove.websocket.v1"
    );
    let text = |m: Message| -> serde_json::Value {
        match m {
            Message::Text(t) => serde_json::from_str(&t).unwrap(),
            other => panic!("expected a text message, got {other:?}"),
        }
    };
    let info = text(ws.read().unwrap());
    assert_eq!(info["op"], "serverInfo");
    let adv = text(ws.read().unwrap());
    assert_eq!(adv["op"], "advertise");
    let channels = adv["channels"].as_array().unwrap();
    for c in &forcecell::recorder::CHANNELS {
        let ch = channels
            .iter()
            .find(|ch| ch["topic"] == c.topic)
            .unwrap_or_else(|| panic!("{} not advertised", c.topic));
        assert_eq!(ch["encoding"], "protobuf");
        assert_eq!(ch["schemaEncoding"], "protobuf");
        assert_eq!(ch["schemaName"], c.schema_name());
        // The schema is the FileDescriptorSet in base64, naming the channel's message.
        let schema = unbase64(ch["schema"].as_str().unwrap());
        let set = <prost_types::FileDescriptorSet as prost::Message>::decode(&schema[..]).unwrap();
        assert!(
            set.file[0]
                .message_type
                .iter()
                .any(|m| format!("forcecell.{}", m.name()) == c.schema_name()),
            "{}",
            c.topic
        );
    }
    let cycle = channels.iter().find(|c| c["topic"] == "/cycle").unwrap()["id"].clone();
    let truth = channels.iter().find(|c| c["topic"] == "/truth").unwrap()["id"].clone();
    ws.send(Message::text(
        serde_json::json!({"op": "subscribe", "subscriptions": [
            {"id": 7, "channelId": cycle}, {"id": 9, "channelId": truth}]})
        .to_string(),
    ))
    .unwrap();
    let (mut cycles, mut last_t) = (0, 0u64);
    while cycles < 40 {
        let Message::Binary(b) = ws.read().unwrap() else {
            continue;
        };
        assert_eq!(b[0], 0x01, "messageData opcode");
        let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
        let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
        // The truth comes only when a simulation ends.
        assert_eq!(sub, 7, "a message for subscription {sub}");
        let mut rec = Record::unknown();
        telemetry::decode(&telemetry::CYCLE, &b[13..], &mut rec).unwrap();
        cycles += 1;
        assert_eq!(rec.row.f_r, 5.0);
        assert!(rec.row.x_cmd.is_finite());
        assert!(t >= last_t, "timestamps in order");
        last_t = t;
        assert_eq!(
            t,
            (rec.row.t * 1e9).round() as u64,
            "timestamp is the cycle time"
        );
    }
}

/// Standard base64 back to bytes.
fn unbase64(s: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => panic!("not base64: {c}"),
    };
    let mut out = Vec::new();
    for quad in s.as_bytes().chunks(4) {
        let data: Vec<u8> = quad.iter().copied().filter(|&c| c != b'=').collect();
        let n = data
            .iter()
            .enumerate()
            .fold(0u32, |n, (i, &c)| n | (u32::from(value(c)) << (18 - 6 * i)));
        for k in 0..data.len().saturating_sub(1) {
            out.push((n >> (16 - 8 * k)) as u8);
        }
    }
    out
}

/// `sim --live --hold`: the scenario runs, every file is written, and the live view stays open until
/// Ctrl-C, which then ends the command cleanly (status 0, the files complete). The earlier run's
/// files it replaces are named before the run.
#[test]
fn sim_live_hold_serves_after_the_scenario_until_ctrl_c() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("res")).unwrap();
    std::fs::write(dir.path().join("res/paper-fig9.csv"), "an earlier run").unwrap();
    let mut child = Kill(
        Command::new(env!("CARGO_BIN_EXE_forcecell"))
            .args([
                "sim",
                "--sensor",
                "inproc",
                "--robot",
                "inproc",
                "--live",
                "127.0.0.1:0",
                "--hold",
                "--out",
                "res",
            ])
            .current_dir(dir.path())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let stdout = child.0.stdout.take().unwrap();
    let mut lines = BufReader::new(stdout).lines();
    let mut before = Vec::new();
    let addr = loop {
        let line = lines
            .next()
            .unwrap_or_else(|| panic!("sim ended without holding: {before:?}"))
            .unwrap();
        if let Some(rest) = line.strip_prefix("holding the live view on ws://") {
            break rest.split_whitespace().next().unwrap().to_string();
        }
        before.push(line);
    };
    let said = before.join("\n");
    assert!(
        said.contains("replacing an earlier run's") && said.contains("res/paper-fig9.csv"),
        "{said}"
    );
    // The scenario is over and its files are complete...
    assert!(said.contains("recorded"), "{said}");
    let res = dir.path().join("res");
    assert!(res.join("paper-fig9.mcap").is_file());
    assert!(!res.join("paper-fig9.mcap.partial").exists());
    assert!(res.join("paper-fig9.png").is_file());
    let csv = std::fs::read_to_string(res.join("paper-fig9.csv")).unwrap();
    assert!(csv.starts_with("t,f,"), "the earlier file replaced");
    // ... and the live view still serves.
    assert!(child.0.try_wait().unwrap().is_none(), "still running");
    let mut req = format!("ws://{addr}").into_client_request().unwrap();
    req.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        "foxglove.websocket.v1".parse().unwrap(),
    );
    let (mut ws, _) = tungstenite::client(req, TcpStream::connect(&addr).unwrap()).unwrap();
    match ws.read().unwrap() {
        Message::Text(t) => {
            let v: serde_json::Value = serde_json::from_str(&t).unwrap();
            assert_eq!(v["op"], "serverInfo");
        }
        other => panic!("expected serverInfo, got {other:?}"),
    }
    // Ctrl-C ends it cleanly: the forcecell process this test started, by its id.
    let st = Command::new("/bin/kill")
        .args(["-INT", &child.0.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    let rest: Vec<String> = lines.map_while(Result::ok).collect();
    let status = child.0.wait().unwrap();
    assert_eq!(status.code(), Some(0), "{rest:?}");
    assert!(rest.iter().any(|l| l == "live view closed"), "{rest:?}");
    let names: Vec<String> = std::fs::read_dir(&res)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') || n.ends_with(".partial"))
        .collect();
    assert!(names.is_empty(), "left behind: {names:?}");
}
