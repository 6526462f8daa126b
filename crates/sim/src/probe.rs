//! A minimal client of Foxglove's live protocol that subscribes to every
//! advertised channel and counts what arrives — what Foxglove would ask of
//! the live server, for `topspin bench latency --live` and the tests.
//!
//! The protocol is `foxglove.websocket.v1`, which the SDK (0.30) negotiates
//! under the name `foxglove.sdk.v1` (same messages; it refuses the old name
//! with 400). The client offers both. As used here: the server sends JSON text frames
//! `{"op":"serverInfo",…}` and `{"op":"advertise","channels":[{id, topic,
//! encoding, schemaName, schema, schemaEncoding}, …]}`; the client answers
//! `{"op":"subscribe","subscriptions":[{"id","channelId"}, …]}`; messages
//! then come as binary frames: opcode `0x01`, subscription id (u32 LE), log
//! time (u64 LE, ns), the message.

use std::collections::{BTreeMap, HashMap};
use std::io::ErrorKind;
use std::net::{SocketAddr, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;

use tungstenite::Message;
use tungstenite::client::IntoClientRequest;

/// The WebSocket subprotocols offered, the SDK's name first: the
/// `foxglove.websocket.v1` protocol, as the SDK names it, and its old name.
pub(crate) const SUBPROTOCOLS: [&str; 2] = ["foxglove.sdk.v1", "foxglove.websocket.v1"];
/// Binary frame opcode of a message on a subscription.
pub(crate) const OP_MESSAGE_DATA: u8 = 0x01;

/// What one channel delivered.
#[derive(Clone, Debug, Default)]
pub struct ChannelSeen {
    /// The channel's `schemaName`, as advertised.
    pub schema_name: String,
    /// The channel's message `encoding`, as advertised.
    pub encoding: String,
    /// Messages received on it.
    pub messages: u64,
    /// Bytes of those messages, frame headers not counted.
    pub bytes: u64,
    /// The first message's log time and bytes.
    pub first: Option<(u64, Vec<u8>)>,
}

/// What the probe saw, by topic.
#[derive(Clone, Debug, Default)]
pub struct ProbeReport {
    /// `name` of the server's `serverInfo`.
    pub server_name: String,
    /// What each advertised channel delivered, by topic.
    pub channels: BTreeMap<String, ChannelSeen>,
    /// Binary frames that were not well-formed message data.
    pub malformed: u64,
}

impl ProbeReport {
    /// Messages over all channels.
    pub fn messages(&self) -> u64 {
        self.channels.values().map(|c| c.messages).sum()
    }
}

/// A probe failure.
#[derive(Debug, thiserror::Error)]
pub enum ProbeError {
    /// No connection to the server before `stop` or the patience ran out.
    #[error("connecting to {addr}: {message}")]
    Connect {
        /// The server's address.
        addr: SocketAddr,
        /// The last connect error.
        message: String,
    },
    #[error("protocol: {0}")]
    /// The WebSocket or the server's messages failed (handshake, subprotocol, JSON).
    Protocol(String),
}

/// Connects to `addr` (retrying until `stop` or `patience`), subscribes to
/// every channel advertised, and counts messages until `stop`.
pub fn spawn(
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    patience: std::time::Duration,
) -> JoinHandle<Result<ProbeReport, ProbeError>> {
    std::thread::Builder::new()
        .name("topspin-probe".into())
        .spawn(move || run(addr, &stop, patience))
        .expect("spawning a thread")
}

fn connect(addr: SocketAddr, stop: &AtomicBool, patience: std::time::Duration) -> Result<TcpStream, ProbeError> {
    let start = topspin_daemon::clock::now();
    loop {
        match TcpStream::connect(addr) {
            Ok(s) => return Ok(s),
            Err(e)
                if topspin_daemon::clock::secs_since(start) > patience.as_secs_f64()
                    || stop.load(Ordering::Relaxed) =>
            {
                return Err(ProbeError::Connect { addr, message: e.to_string() });
            }
            Err(_) => std::thread::sleep(std::time::Duration::from_millis(20)),
        }
    }
}

fn run(addr: SocketAddr, stop: &AtomicBool, patience: std::time::Duration) -> Result<ProbeReport, ProbeError> {
    let stream = connect(addr, stop, patience)?;
    let proto = |e: &dyn std::fmt::Display| ProbeError::Protocol(e.to_string());
    let mut request = format!("ws://{addr}/").into_client_request().map_err(|e| proto(&e))?;
    let offer = SUBPROTOCOLS.join(", ");
    request.headers_mut().insert("Sec-WebSocket-Protocol", offer.parse().map_err(|e| proto(&e))?);
    let (mut ws, response) = tungstenite::client(request, stream).map_err(|e| proto(&e))?;
    let agreed = response.headers().get("Sec-WebSocket-Protocol").and_then(|v| v.to_str().ok());
    if !agreed.is_some_and(|a| SUBPROTOCOLS.contains(&a)) {
        return Err(ProbeError::Protocol(format!("server agreed to subprotocol {agreed:?}")));
    }
    ws.get_ref().set_read_timeout(Some(std::time::Duration::from_millis(50))).map_err(|e| proto(&e))?;
    let mut report = ProbeReport::default();
    // subscription id → topic
    let mut subs: HashMap<u32, String> = HashMap::new();
    let mut next_sub = 1u32;
    while !stop.load(Ordering::Relaxed) {
        let msg = match ws.read() {
            Ok(m) => m,
            Err(tungstenite::Error::Io(e)) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                continue;
            }
            // The server went away (the run ended): what arrived is the report.
            Err(
                tungstenite::Error::ConnectionClosed
                | tungstenite::Error::AlreadyClosed
                | tungstenite::Error::Protocol(tungstenite::error::ProtocolError::ResetWithoutClosingHandshake),
            ) => break,
            Err(tungstenite::Error::Io(e))
                if matches!(e.kind(), ErrorKind::ConnectionReset | ErrorKind::BrokenPipe) =>
            {
                break;
            }
            Err(e) => return Err(proto(&e)),
        };
        match msg {
            Message::Text(text) => {
                let v: serde_json::Value = serde_json::from_str(text.as_str()).map_err(|e| proto(&e))?;
                match v["op"].as_str() {
                    Some("serverInfo") => report.server_name = v["name"].as_str().unwrap_or("").to_owned(),
                    Some("advertise") => {
                        let mut subscriptions = Vec::new();
                        for c in v["channels"].as_array().into_iter().flatten() {
                            let (Some(id), Some(topic)) = (c["id"].as_u64(), c["topic"].as_str()) else { continue };
                            let seen = report.channels.entry(topic.to_owned()).or_default();
                            seen.schema_name = c["schemaName"].as_str().unwrap_or("").to_owned();
                            seen.encoding = c["encoding"].as_str().unwrap_or("").to_owned();
                            subs.insert(next_sub, topic.to_owned());
                            subscriptions.push(serde_json::json!({ "id": next_sub, "channelId": id }));
                            next_sub += 1;
                        }
                        let sub = serde_json::json!({ "op": "subscribe", "subscriptions": subscriptions });
                        ws.send(Message::Text(sub.to_string().into())).map_err(|e| proto(&e))?;
                    }
                    _ => {}
                }
            }
            Message::Binary(b) => {
                let Some((&op, rest)) = b.split_first() else { continue };
                if op != OP_MESSAGE_DATA || rest.len() < 12 {
                    report.malformed += 1;
                    continue;
                }
                let sub = u32::from_le_bytes(rest[0..4].try_into().expect("4 bytes"));
                let log_time = u64::from_le_bytes(rest[4..12].try_into().expect("8 bytes"));
                let Some(topic) = subs.get(&sub) else {
                    report.malformed += 1;
                    continue;
                };
                let seen = report.channels.entry(topic.clone()).or_default();
                seen.messages += 1;
                seen.bytes += rest.len() as u64 - 12;
                if seen.first.is_none() {
                    seen.first = Some((log_time, rest[12..].to_vec()));
                }
            }
            Message::Close(_) => break,
            _ => {}
        }
    }
    let _ = ws.close(None);
    Ok(report)
}
