//! The live view: the recording's channels served over the Foxglove WebSocket protocol
//! (`foxglove.websocket.v1`), so Foxglove (or any client of that protocol) can watch a run.
//!
//! A small server of its own on `tungstenite`: on connect it sends `serverInfo` and `advertise` (every
//! channel of [`CHANNELS`], `protobuf`-encoded, with its schema: the `FileDescriptorSet` in base64);
//! a client's `subscribe`/`unsubscribe` choose what it gets; each message goes out as a binary
//! `messageData` frame (opcode 1, subscription id, timestamp in ns, the protobuf message). The recorder's writer thread feeds it ([`LiveServer::sink`]), never the
//! control loop; a client that cannot keep up loses messages (its queue is bounded), it never slows
//! the writer.

use std::collections::HashMap;
use std::io::ErrorKind as IoKind;
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread;
use std::time::Duration;

use anyhow::{Context, Result};
use serde_json::{Value, json};
use tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tungstenite::{Message, WebSocket};

use crate::recorder::{CHANNELS, ENCODING, LiveSink};

/// The subprotocol Foxglove speaks.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// Messages a client may have queued before newer ones are dropped.
const CLIENT_QUEUE: usize = 4096;

struct Client {
    /// Channel index → subscription id.
    subs: HashMap<usize, u32>,
    tx: SyncSender<Message>,
    dropped: u64,
}

type Clients = Arc<Mutex<Vec<Arc<Mutex<Client>>>>>;

/// A running live server.
pub struct LiveServer {
    addr: SocketAddr,
    clients: Clients,
    stop: Arc<AtomicBool>,
}

impl LiveServer {
    /// Listen on `addr` (port 0: any free port) and accept clients in a thread of its own.
    pub fn bind(addr: SocketAddr) -> Result<Self> {
        let listener = TcpListener::bind(addr)
            .with_context(|| format!("cannot listen on {addr} for the live view"))?;
        let addr = listener.local_addr()?;
        let clients: Clients = Arc::default();
        let stop = Arc::new(AtomicBool::new(false));
        let (c, s) = (clients.clone(), stop.clone());
        thread::Builder::new()
            .name("live-accept".into())
            .spawn(move || {
                for stream in listener.incoming() {
                    if s.load(Ordering::Relaxed) {
                        break;
                    }
                    let Ok(stream) = stream else { continue };
                    let (c, s) = (c.clone(), s.clone());
                    let _ = thread::Builder::new()
                        .name("live-client".into())
                        .spawn(move || {
                            if let Err(e) = serve_client(stream, &c, &s) {
                                eprintln!("live view: a client left: {e}");
                            }
                        });
                }
            })?;
        Ok(Self {
            addr,
            clients,
            stop,
        })
    }

    /// Where it listens.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.clients
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }

    /// The sink the recorder's writer thread calls with every message.
    pub fn sink(&self) -> LiveSink {
        let clients = self.clients.clone();
        Box::new(move |channel, t, payload| {
            let list = clients.lock().unwrap_or_else(PoisonError::into_inner);
            for c in list.iter() {
                let mut c = c.lock().unwrap_or_else(PoisonError::into_inner);
                let Some(&sub) = c.subs.get(&channel) else {
                    continue;
                };
                let mut frame = Vec::with_capacity(13 + payload.len());
                frame.push(0x01);
                frame.extend_from_slice(&sub.to_le_bytes());
                frame.extend_from_slice(&t.to_le_bytes());
                frame.extend_from_slice(payload);
                match c.tx.try_send(Message::binary(frame)) {
                    Ok(()) | Err(TrySendError::Disconnected(_)) => {}
                    Err(TrySendError::Full(_)) => c.dropped += 1,
                }
            }
        })
    }
}

impl Drop for LiveServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Wake the accept loop so it sees the flag.
        let _ = TcpStream::connect(self.addr);
    }
}

/// The `advertise` message for every channel (channel ids are the indices in [`CHANNELS`] + 1).
pub fn advertise() -> Value {
    let channels: Vec<Value> = CHANNELS
        .iter()
        .enumerate()
        .map(|(i, c)| {
            json!({
                "id": i + 1,
                "topic": c.topic,
                "encoding": ENCODING,
                "schemaName": c.schema_name(),
                "schema": abb_egm::rws::base64(&::scenario::telemetry::file_descriptor_set(c)),
                "schemaEncoding": ENCODING,
            })
        })
        .collect();
    json!({"op": "advertise", "channels": channels})
}

fn server_info() -> Value {
    json!({
        "op": "serverInfo",
        "name": concat!("forcecell ", env!("CARGO_PKG_VERSION")),
        "capabilities": [],
        "supportedEncodings": [],
        "metadata": {},
        "sessionId": format!("{:?}", std::time::SystemTime::now()),
    })
}

fn serve_client(stream: TcpStream, clients: &Clients, stop: &AtomicBool) -> Result<()> {
    // The signature is tungstenite's `Callback`: its error type is not ours to shrink.
    #[allow(clippy::result_large_err)]
    let offers_foxglove = |req: &Request, mut resp: Response| -> Result<Response, ErrorResponse> {
        let offered = req
            .headers()
            .get_all("Sec-WebSocket-Protocol")
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(','))
            .any(|p| p.trim() == SUBPROTOCOL);
        if offered {
            resp.headers_mut().insert(
                "Sec-WebSocket-Protocol",
                SUBPROTOCOL.parse().expect("a valid header value"),
            );
        }
        Ok(resp)
    };
    let mut ws = tungstenite::accept_hdr(stream, offers_foxglove)
        .map_err(|e| anyhow::anyhow!("WebSocket handshake: {e}"))?;
    ws.send(Message::text(server_info().to_string()))?;
    ws.send(Message::text(advertise().to_string()))?;
    ws.get_ref()
        .set_read_timeout(Some(Duration::from_millis(10)))?;
    let (tx, rx) = sync_channel(CLIENT_QUEUE);
    let me = Arc::new(Mutex::new(Client {
        subs: HashMap::new(),
        tx,
        dropped: 0,
    }));
    clients
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .push(me.clone());
    let result = client_loop(&mut ws, &me, &rx, stop);
    clients
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .retain(|c| !Arc::ptr_eq(c, &me));
    result
}

fn client_loop(
    ws: &mut WebSocket<TcpStream>,
    me: &Arc<Mutex<Client>>,
    rx: &Receiver<Message>,
    stop: &AtomicBool,
) -> Result<()> {
    while !stop.load(Ordering::Relaxed) {
        match ws.read() {
            Ok(Message::Text(text)) => handle(me, &text),
            Ok(Message::Close(_)) => return Ok(()),
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(e.kind(), IoKind::WouldBlock | IoKind::TimedOut) => {}
            Err(tungstenite::Error::ConnectionClosed | tungstenite::Error::AlreadyClosed) => {
                return Ok(());
            }
            Err(e) => return Err(e.into()),
        }
        let mut wrote = false;
        while let Ok(m) = rx.try_recv() {
            ws.write(m)?;
            wrote = true;
        }
        if wrote {
            ws.flush()?;
        }
    }
    let _ = ws.close(None);
    Ok(())
}

/// A client's `subscribe` / `unsubscribe`; anything else is ignored.
fn handle(me: &Arc<Mutex<Client>>, text: &str) {
    let Ok(v) = serde_json::from_str::<Value>(text) else {
        return;
    };
    let mut c = me.lock().unwrap_or_else(PoisonError::into_inner);
    match v["op"].as_str() {
        Some("subscribe") => {
            for s in v["subscriptions"].as_array().into_iter().flatten() {
                let (Some(id), Some(ch)) = (s["id"].as_u64(), s["channelId"].as_u64()) else {
                    continue;
                };
                if (1..=CHANNELS.len() as u64).contains(&ch) {
                    c.subs.insert(ch as usize - 1, id as u32);
                }
            }
        }
        Some("unsubscribe") => {
            let ids: Vec<u64> = v["subscriptionIds"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(Value::as_u64)
                .collect();
            c.subs.retain(|_, sub| !ids.contains(&u64::from(*sub)));
        }
        _ => {}
    }
}
