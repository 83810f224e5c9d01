//! The live view: `forcecell sim --live` serves the recording's channels over the Foxglove WebSocket
//! protocol; a client on the loopback port gets `serverInfo`, every channel advertised with its schema,
//! and, once subscribed, `messageData` frames with the run's values.

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Command, Stdio};

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
    for c in forcecell::recorder::CHANNELS {
        let ch = channels
            .iter()
            .find(|ch| ch["topic"] == c.topic)
            .unwrap_or_else(|| panic!("{} not advertised", c.topic));
        assert_eq!(ch["encoding"], "json");
        assert_eq!(ch["schemaEncoding"], "jsonschema");
        let schema: serde_json::Value =
            serde_json::from_str(ch["schema"].as_str().unwrap()).unwrap();
        assert!(schema["properties"].is_object());
    }
    let force = channels.iter().find(|c| c["topic"] == "/force").unwrap()["id"].clone();
    let position = channels.iter().find(|c| c["topic"] == "/position").unwrap()["id"].clone();
    ws.send(Message::text(
        serde_json::json!({"op": "subscribe", "subscriptions": [
            {"id": 7, "channelId": force}, {"id": 9, "channelId": position}]})
        .to_string(),
    ))
    .unwrap();
    let (mut forces, mut positions, mut last_t) = (0, 0, 0u64);
    while forces < 20 || positions < 20 {
        let Message::Binary(b) = ws.read().unwrap() else {
            continue;
        };
        assert_eq!(b[0], 0x01, "messageData opcode");
        let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
        let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
        let v: serde_json::Value = serde_json::from_slice(&b[13..]).unwrap();
        match sub {
            7 => {
                forces += 1;
                assert_eq!(v["f_r"], 5.0);
                assert!(t >= last_t, "timestamps in order");
                last_t = t;
                let secs = v["t"].as_f64().unwrap();
                assert_eq!(
                    t,
                    (secs * 1e9).round() as u64,
                    "timestamp is the cycle time"
                );
            }
            9 => {
                positions += 1;
                assert!(v["x_cmd"].as_f64().unwrap().is_finite());
            }
            other => panic!("a message for subscription {other}, which was never made"),
        }
    }
}
