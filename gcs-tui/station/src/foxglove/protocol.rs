//! The `foxglove.websocket.v1` messages the live view sends and reads: the
//! server's `serverInfo`, `advertise` and `status` (JSON text), message
//! data (binary: opcode 1, subscription id, log time, payload), and the
//! client's `subscribe` and `unsubscribe`. Anything else a client sends is
//! refused with a reason.

use serde::Deserialize;
use serde_json::{Value, json};

/// The WebSocket subprotocol clients ask for.
pub(super) const SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// Opcode of a binary message-data frame.
const MESSAGE_DATA: u8 = 1;

/// A channel as advertised: the topic, its schema (JSON Schema text) and
/// its message encoding (always JSON: Lichtblick cannot decode MessagePack).
#[derive(Debug, Clone)]
pub(super) struct ChannelInfo {
    pub(super) id: u32,
    pub(super) topic: String,
    pub(super) schema_name: &'static str,
    pub(super) schema: String,
}

impl ChannelInfo {
    fn json(&self) -> Value {
        json!({
            "id": self.id, "topic": self.topic, "encoding": "json",
            "schemaName": self.schema_name, "schema": self.schema,
            "schemaEncoding": "jsonschema",
        })
    }
}

/// The first message of every connection.
pub(super) fn server_info(session: &str) -> String {
    json!({
        "op": "serverInfo", "name": concat!("mech-gcs ", env!("CARGO_PKG_VERSION")),
        "capabilities": [], "supportedEncodings": [], "metadata": {},
        "sessionId": session,
    })
    .to_string()
}

/// Channels the client may subscribe to.
pub(super) fn advertise(channels: &[ChannelInfo]) -> String {
    let list: Vec<Value> = channels.iter().map(ChannelInfo::json).collect();
    json!({"op": "advertise", "channels": list}).to_string()
}

/// Severity of a status message.
#[derive(Debug, Clone, Copy)]
pub(super) enum Level {
    Warning = 1,
    Error = 2,
}

/// A status message (Foxglove shows it in its problems list).
pub(super) fn status(level: Level, message: &str) -> String {
    json!({"op": "status", "level": level as u8, "message": message}).to_string()
}

/// A message-data frame for subscription `sub`.
pub(super) fn data(sub: u32, unix_ns: u64, payload: &[u8]) -> Vec<u8> {
    let mut frame = Vec::with_capacity(13 + payload.len());
    frame.push(MESSAGE_DATA);
    frame.extend_from_slice(&sub.to_le_bytes());
    frame.extend_from_slice(&unix_ns.to_le_bytes());
    frame.extend_from_slice(payload);
    frame
}

/// A client's request.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(tag = "op", rename_all = "camelCase")]
pub(super) enum Request {
    Subscribe {
        subscriptions: Vec<Subscription>,
    },
    #[serde(rename_all = "camelCase")]
    Unsubscribe {
        subscription_ids: Vec<u32>,
    },
}

/// One subscription: the client's id for it and the channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "camelCase")]
pub(super) struct Subscription {
    pub(super) id: u32,
    pub(super) channel_id: u32,
}

/// Reads a client's text message; the error says what is wrong with it
/// (requests the live view does not serve, such as publishing, included).
pub(super) fn request(text: &str) -> Result<Request, String> {
    serde_json::from_str(text).map_err(|e| {
        let op = serde_json::from_str::<Value>(text)
            .ok()
            .and_then(|v| v.get("op").and_then(Value::as_str).map(str::to_owned));
        match op {
            Some(op) if op != "subscribe" && op != "unsubscribe" => {
                format!("{op:?} is not served: the live view only shows the fleet")
            }
            _ => format!("unreadable request: {e}"),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_are_read_and_the_rest_refused_with_a_reason() {
        let sub = request(r#"{"op":"subscribe","subscriptions":[{"id":3,"channelId":7}]}"#);
        assert_eq!(
            sub,
            Ok(Request::Subscribe {
                subscriptions: vec![Subscription {
                    id: 3,
                    channel_id: 7
                }]
            })
        );
        let unsub = request(r#"{"op":"unsubscribe","subscriptionIds":[3]}"#);
        assert_eq!(
            unsub,
            Ok(Request::Unsubscribe {
                subscription_ids: vec![3]
            })
        );
        let publish = request(r#"{"op":"advertise","channels":[]}"#).unwrap_err();
        assert!(publish.contains("not served"), "{publish}");
        for bad in ["", "{", "[1]", r#"{"op":"subscribe"}"#, "\u{0}\u{ff}"] {
            assert!(request(bad).unwrap_err().contains("unreadable"), "{bad:?}");
        }
    }

    #[test]
    fn a_data_frame_is_opcode_subscription_time_payload() {
        let f = data(0x0102_0304, 0x1122_3344_5566_7788, b"{}");
        assert_eq!(f[0], 1);
        assert_eq!(&f[1..5], &[4, 3, 2, 1]);
        assert_eq!(
            u64::from_le_bytes(f[5..13].try_into().unwrap()),
            0x1122_3344_5566_7788
        );
        assert_eq!(&f[13..], b"{}");
    }
}
