//! A Foxglove viewer as Foxglove and Lichtblick are one
//! (`foxglove.websocket.v1` over a WebSocket), for the live view's tests:
//! what it was sent, subscribing by topic, the channels a recording has,
//! and clients that send garbage or flood the server with requests.

use std::collections::HashMap;
use std::io::{Read, Write};
use std::net::SocketAddr;
use std::time::{Duration, Instant};

use futures::{SinkExt, StreamExt};
use mech_core::record::schema;
use serde_json::{Value, json};
use tokio::net::TcpStream;
use tokio_tungstenite::WebSocketStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;

/// What a client got.
#[derive(Debug)]
pub enum Got {
    Text(Value),
    Data { sub: u32, ns: u64, msg: Value },
    Closed,
}

/// A client as Foxglove is one: advertised channels by topic.
pub struct Client {
    pub ws: WebSocketStream<TcpStream>,
    pub channels: HashMap<String, Value>,
}

/// How the server closed a connection: the status messages it sent last
/// and its close frame's code and reason (`None`: it closed without one).
#[derive(Debug)]
pub struct Closing {
    pub statuses: Vec<String>,
    pub code: Option<u16>,
    pub reason: String,
}

pub async fn handshake(
    addr: SocketAddr,
    subprotocol: bool,
) -> Result<WebSocketStream<TcpStream>, String> {
    let tcp = TcpStream::connect(addr).await.map_err(|e| e.to_string())?;
    handshake_over(tcp, addr, subprotocol).await
}

/// The handshake over a TCP connection the caller made (with the socket
/// options it wants).
pub async fn handshake_over(
    tcp: TcpStream,
    addr: SocketAddr,
    subprotocol: bool,
) -> Result<WebSocketStream<TcpStream>, String> {
    let mut req = format!("ws://{addr}/")
        .into_client_request()
        .expect("request");
    if subprotocol {
        req.headers_mut().insert(
            "Sec-WebSocket-Protocol",
            HeaderValue::from_static("foxglove.websocket.v1"),
        );
    }
    let (ws, resp) = tokio_tungstenite::client_async(req, tcp)
        .await
        .map_err(|e| e.to_string())?;
    assert_eq!(
        resp.headers()
            .get("Sec-WebSocket-Protocol")
            .map(|v| v.as_bytes()),
        Some(&b"foxglove.websocket.v1"[..])
    );
    Ok(ws)
}

impl Client {
    pub async fn connect(addr: SocketAddr) -> Client {
        let ws = handshake(addr, true).await.expect("handshake");
        Client::over(ws).await
    }

    /// A client over a WebSocket whose handshake is done.
    pub async fn over(ws: WebSocketStream<TcpStream>) -> Client {
        let mut c = Client {
            ws,
            channels: HashMap::new(),
        };
        match c.next(Duration::from_secs(10)).await {
            Some(Got::Text(v)) => assert_eq!(v["op"], "serverInfo", "{v}"),
            other => panic!("first message: {other:?}"),
        }
        c
    }

    /// The next message within `wait` (advertised channels noted).
    pub async fn next(&mut self, wait: Duration) -> Option<Got> {
        let m = match tokio::time::timeout(wait, self.ws.next()).await {
            Err(_) => return None,
            Ok(None | Some(Err(_))) => return Some(Got::Closed),
            Ok(Some(Ok(m))) => m,
        };
        Some(match m {
            Message::Text(t) => {
                let v: Value = serde_json::from_str(t.as_str()).expect("JSON text");
                if v["op"] == "advertise" {
                    for ch in v["channels"].as_array().expect("channels") {
                        let topic = ch["topic"].as_str().expect("topic").to_string();
                        self.channels.insert(topic, ch.clone());
                    }
                }
                Got::Text(v)
            }
            Message::Binary(b) => {
                assert_eq!(b[0], 1, "message data");
                let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                let ns = u64::from_le_bytes(b[5..13].try_into().unwrap());
                let msg = serde_json::from_slice(&b[13..]).expect("JSON payload");
                Got::Data { sub, ns, msg }
            }
            Message::Close(_) => Got::Closed,
            Message::Ping(_) => {
                // Answered now, as a browser does, not at the next read.
                let _ = self.ws.flush().await;
                Got::Text(Value::Null)
            }
            _ => Got::Text(Value::Null),
        })
    }

    /// Reads everything until the server's close frame (or the end of the
    /// connection), within `wait`: the status messages on the way and the
    /// close frame's code and reason.
    pub async fn closing(&mut self, wait: Duration) -> Closing {
        let deadline = tokio::time::Instant::now() + wait;
        let mut statuses = Vec::new();
        loop {
            let m = match tokio::time::timeout_at(deadline, self.ws.next()).await {
                Err(_) => panic!("not closed within {wait:?}; statuses {statuses:?}"),
                Ok(None | Some(Err(_))) => None,
                Ok(Some(Ok(m))) => Some(m),
            };
            match m {
                None => {
                    return Closing {
                        statuses,
                        code: None,
                        reason: String::new(),
                    };
                }
                Some(Message::Close(frame)) => {
                    return Closing {
                        statuses,
                        code: frame.as_ref().map(|f| u16::from(f.code)),
                        reason: frame.map(|f| f.reason.to_string()).unwrap_or_default(),
                    };
                }
                Some(Message::Text(t)) => {
                    let v: Value = serde_json::from_str(t.as_str()).unwrap_or_default();
                    if v["op"] == "status" {
                        statuses.push(v["message"].as_str().unwrap_or_default().to_string());
                    }
                }
                Some(_) => {}
            }
        }
    }

    /// Reads until `topic` is advertised.
    pub async fn channel(&mut self, topic: &str) -> Value {
        let deadline = Instant::now() + Duration::from_secs(30);
        while !self.channels.contains_key(topic) {
            assert!(Instant::now() < deadline, "{topic} never advertised");
            self.next(Duration::from_secs(1)).await;
        }
        self.channels[topic].clone()
    }

    pub async fn send(&mut self, v: Value) {
        self.ws
            .send(Message::Text(v.to_string().into()))
            .await
            .expect("sent");
    }

    pub async fn subscribe(&mut self, sub: u32, topic: &str) {
        let id = self.channel(topic).await["id"].clone();
        self.send(json!({"op": "subscribe", "subscriptions": [{"id": sub, "channelId": id}]}))
            .await;
    }
}

/// Each channel is a recording's: the topic, its schema name, the JSON
/// Schema a recording holds, JSON messages.
pub async fn check_channels(c: &mut Client) {
    let expected = [
        (schema::SCENE.to_string(), schema::SCENE_UPDATE),
        (schema::LOG.to_string(), schema::FOXGLOVE_LOG),
        (schema::EVENTS.to_string(), schema::MECH_EVENT),
        (schema::CLUSTERS.to_string(), schema::MECH_CLUSTERS),
        (schema::pose_topic("robot_1"), schema::POSE_IN_FRAME),
        (schema::pose_topic("robot_2"), schema::POSE_IN_FRAME),
        (schema::telemetry_topic("robot_1"), schema::MECH_TELEMETRY),
    ];
    for (topic, name) in expected {
        let ch = c.channel(&topic).await;
        assert_eq!(ch["schemaName"], name, "{topic}");
        assert_eq!(ch["encoding"], "json", "{topic}");
        assert_eq!(ch["schemaEncoding"], "jsonschema", "{topic}");
        let text = ch["schema"].as_str().expect("schema text");
        let sent: Value = serde_json::from_str(text).expect("schema is JSON");
        assert_eq!(sent, schema::schema(name), "{topic}");
    }
}

/// A client that sends garbage of every kind is told why and cut (close
/// code 1008, policy, with the reason); a
/// plain TCP client and a WebSocket client without the subprotocol are
/// refused at the handshake.
pub async fn garbage(addr: SocketAddr) {
    let mut raw = std::net::TcpStream::connect(addr).expect("tcp");
    raw.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    raw.write_all(b"\x00\xffGET nonsense\r\n\r\n")
        .expect("garbage sent");
    let mut reply = Vec::new();
    let _ = raw.read_to_end(&mut reply);
    assert!(
        !String::from_utf8_lossy(&reply).contains(" 101 "),
        "no upgrade"
    );
    let Err(err) = handshake(addr, false).await else {
        panic!("a client without the subprotocol is refused")
    };
    assert!(err.contains("400"), "{err}");

    let mut c = Client::connect(addr).await;
    let big = "x".repeat(100 << 10);
    for i in 0..100 {
        let m = match i % 4 {
            0 => Message::Text("not json".into()),
            1 => Message::Binary(vec![0xff; 64].into()),
            2 => Message::Text(
                r#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":9999}]}"#.into(),
            ),
            _ => Message::Text(r#"{"op":"advertise","channels":[]}"#.into()),
        };
        if c.ws.send(m).await.is_err() {
            break;
        }
    }
    let _ = c.ws.send(Message::Text(big.into())).await;
    let closing = c.closing(Duration::from_secs(20)).await;
    assert!(
        closing.statuses.len() > 1,
        "the client was told why: {closing:?}"
    );
    assert_eq!(closing.code, Some(1008), "{closing:?}");
    assert!(
        closing.reason.starts_with("too many bad requests"),
        "{closing:?}"
    );
}

/// A client that floods the server with requests, then subscribes to
/// everything and never reads again.
pub async fn flood(addr: SocketAddr) -> Client {
    let mut c = Client::connect(addr).await;
    check_channels(&mut c).await;
    let ids: Vec<Value> = c.channels.values().map(|ch| ch["id"].clone()).collect();
    for round in 0..2000u32 {
        let id = &ids[round as usize % ids.len()];
        c.send(json!({"op": "subscribe", "subscriptions": [{"id": round, "channelId": id}]}))
            .await;
        c.send(json!({"op": "unsubscribe", "subscriptionIds": [round]}))
            .await;
    }
    let all: Vec<Value> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| json!({"id": 100_000 + i, "channelId": id}))
        .collect();
    c.send(json!({"op": "subscribe", "subscriptions": all}))
        .await;
    c
}

pub fn position(pose: &Value) -> (f64, f64) {
    let p = &pose["pose"]["position"];
    (p["x"].as_f64().expect("x"), p["y"].as_f64().expect("y"))
}

pub fn entity_ids(scene: &Value) -> Vec<String> {
    scene["entities"]
        .as_array()
        .expect("entities")
        .iter()
        .map(|e| e["id"].as_str().expect("id").to_string())
        .collect()
}
