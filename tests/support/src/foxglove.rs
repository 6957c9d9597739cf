//! A Foxglove WebSocket client for `run --foxglove`: the protocol's handshake (subprotocol
//! `foxglove.sdk.v1`), the server's JSON `advertise` messages, `subscribe`, and its binary
//! message-data frames (opcode 1: subscription id, log time, payload), parsed here by hand
//! from the protocol's description rather than with the server's own code.

use std::collections::BTreeMap;
use std::net::TcpStream;
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use tungstenite::client::IntoClientRequest;
use tungstenite::http::HeaderValue;
use tungstenite::{Message, WebSocket};

/// A channel the server advertised.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Advertised {
    pub id: u64,
    pub topic: String,
    pub encoding: String,
    pub schema_name: String,
}

/// One message a subscription delivered.
#[derive(Debug, Clone)]
pub struct Delivered {
    pub topic: String,
    pub log_time_ns: u64,
    pub payload: Vec<u8>,
}

/// A connected client.
pub struct FoxgloveClient {
    ws: WebSocket<TcpStream>,
    /// By topic.
    pub channels: BTreeMap<String, Advertised>,
    /// Subscription id to topic.
    subscriptions: BTreeMap<u32, String>,
    /// The last `time` the server broadcast (ns).
    pub server_time_ns: Option<u64>,
}

impl FoxgloveClient {
    /// Connects to `url` (`ws://HOST:PORT`) and reads the server's greeting until `want`
    /// channels are advertised (or `timeout` passes: a panic naming what was seen).
    pub fn connect(url: &str, want: usize, timeout: Duration) -> Self {
        let addr = url.strip_prefix("ws://").expect("a ws:// URL");
        let stream = TcpStream::connect(addr).unwrap_or_else(|e| panic!("connect {url}: {e}"));
        let mut request = url.into_client_request().expect("a WebSocket request");
        request.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            HeaderValue::from_static("foxglove.sdk.v1"),
        );
        let (ws, response) = tungstenite::client::client(request, stream)
            .unwrap_or_else(|e| panic!("WebSocket handshake with {url}: {e}"));
        assert_eq!(
            response
                .headers()
                .get("sec-websocket-protocol")
                .and_then(|v| v.to_str().ok()),
            Some("foxglove.sdk.v1"),
            "the server speaks Foxglove's protocol"
        );
        // Short reads from here on, so `next` can give up at its deadline (tungstenite keeps
        // a partly read frame across them).
        ws.get_ref()
            .set_read_timeout(Some(Duration::from_millis(200)))
            .expect("read timeout");
        let mut client = Self {
            ws,
            channels: BTreeMap::new(),
            subscriptions: BTreeMap::new(),
            server_time_ns: None,
        };
        let deadline = Instant::now() + timeout;
        while client.channels.len() < want {
            assert!(
                Instant::now() < deadline,
                "{url} advertised only {:?} within {timeout:?}",
                client.channels.keys().collect::<Vec<_>>()
            );
            client.read_one();
        }
        client
    }

    /// Subscribes to `topics` (each must have been advertised).
    pub fn subscribe(&mut self, topics: &[&str]) {
        let mut subs = Vec::new();
        for topic in topics {
            let channel = self
                .channels
                .get(*topic)
                .unwrap_or_else(|| panic!("{topic} was not advertised"));
            let id = u32::try_from(self.subscriptions.len() + 1).expect("few subscriptions");
            self.subscriptions.insert(id, (*topic).to_string());
            subs.push(json!({"id": id, "channelId": channel.id}));
        }
        let text = json!({"op": "subscribe", "subscriptions": subs}).to_string();
        self.ws.send(Message::text(text)).expect("send subscribe");
    }

    /// The next delivered message, or `None` after `timeout` without one.
    pub fn next(&mut self, timeout: Duration) -> Option<Delivered> {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if let Some(d) = self.read_one() {
                return Some(d);
            }
        }
        None
    }

    /// Reads one frame (or times out after the socket's read timeout); returns it if it
    /// was message data.
    fn read_one(&mut self) -> Option<Delivered> {
        let message = match self.ws.read() {
            Ok(m) => m,
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return None;
            }
            Err(e) => panic!("Foxglove connection: {e}"),
        };
        match message {
            Message::Text(text) => {
                let v: Value = serde_json::from_str(text.as_str()).expect("JSON from the server");
                if v["op"] == "advertise" {
                    for c in v["channels"].as_array().expect("channels") {
                        let a = Advertised {
                            id: c["id"].as_u64().expect("channel id"),
                            topic: c["topic"].as_str().expect("topic").to_string(),
                            encoding: c["encoding"].as_str().expect("encoding").to_string(),
                            schema_name: c["schemaName"].as_str().unwrap_or("").to_string(),
                        };
                        self.channels.insert(a.topic.clone(), a);
                    }
                }
                None
            }
            Message::Binary(data) => match data.first() {
                Some(1) if data.len() >= 13 => {
                    let sub = u32::from_le_bytes(data[1..5].try_into().expect("4 bytes"));
                    let log_time_ns = u64::from_le_bytes(data[5..13].try_into().expect("8 bytes"));
                    let topic = self
                        .subscriptions
                        .get(&sub)
                        .unwrap_or_else(|| panic!("data for unknown subscription {sub}"))
                        .clone();
                    Some(Delivered {
                        topic,
                        log_time_ns,
                        payload: data[13..].to_vec(),
                    })
                }
                Some(2) if data.len() >= 9 => {
                    self.server_time_ns =
                        Some(u64::from_le_bytes(data[1..9].try_into().expect("8 bytes")));
                    None
                }
                _ => None,
            },
            _ => None,
        }
    }
}
