//! The attach protocol's messages: one JSON object per line, each with a
//! `type` (docs/control-protocol.md). A client sends [`ToStation`], the
//! station answers with [`FromStation`]. Both sides read with
//! [`read_message`], which bounds a line's length, so a peer that never
//! sends a newline cannot grow a buffer without limit.

use mech_proto::{ClusterVelocity, Command};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use tokio::io::{AsyncBufRead, AsyncBufReadExt};

use crate::view::{ArenaBounds, FleetSnapshot};
use mech_core::auth::Security;

/// Version of this protocol; a station refuses a client of another.
pub const PROTOCOL: u32 = 1;

/// The longest line either side accepts (a snapshot of a large fleet is
/// the longest message).
pub const MAX_LINE: usize = 4 << 20;

/// The longest line a station accepts from a client: commands are short.
pub const MAX_CLIENT_LINE: usize = 64 << 10;

/// A client's message to the station.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ToStation {
    /// The first message: which protocol, who (a label on a local socket,
    /// ignored over TCP where the key names the operator) and what the
    /// client wants streamed.
    Hello {
        protocol: u32,
        #[serde(default)]
        operator: Option<String>,
        #[serde(default)]
        stream: Streams,
    },
    /// The answer to a [`FromStation::Challenge`]: the operator key's tag
    /// (hex) over the challenge (see [`challenge_region`]).
    Auth { tag: String },
    /// A command-language line; its [`FromStation::Result`] carries `id`.
    Line { id: u64, text: String },
    /// A teleop command on `channel` for each of `robots` (a gamepad or the
    /// keyboard; no command-language verb says this at a pad's rate).
    Publish {
        channel: String,
        robots: Vec<String>,
        command: Command,
    },
    /// A pad's velocity for a cluster's controller; it lapses unless
    /// repeated.
    DriveCluster {
        cluster: String,
        velocity: ClusterVelocity,
    },
    /// The client is leaving.
    Bye,
}

/// What a client wants streamed to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Streams {
    /// Fleet snapshots (a TUI).
    pub snapshots: bool,
    /// Event-log lines (a TUI), starting with the recent ones.
    pub log: bool,
    /// Router events as `--script` prints them (a script).
    pub events: bool,
}

/// The station's message to a client.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum FromStation {
    /// Over TCP, before anything else: prove you hold an operator key.
    Challenge { nonce: String },
    /// Attached.
    Welcome(Welcome),
    /// The whole fleet as the TUI draws it.
    Snapshot { seq: u64, fleet: FleetSnapshot },
    /// A line of the station's event log.
    Log {
        seq: u64,
        /// Station time, s.
        t: f64,
        level: LogLevel,
        text: String,
    },
    /// A router event, the object `--script` prints (its own `type` is
    /// `event`, so the object is sent as it is).
    #[serde(rename = "event")]
    Event(serde_json::Map<String, serde_json::Value>),
    /// The outcome of [`ToStation::Line`] `id`.
    Result(LineResult),
    /// Something the client sent was refused (bad message, not permitted);
    /// the station keeps the connection unless it says `Bye`.
    Refused { reason: String },
    /// The station closes the connection.
    Bye { reason: String },
}

/// What a client learns on attaching.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Welcome {
    pub protocol: u32,
    /// The operator the station logs this client's commands under.
    pub operator: String,
    /// The router's UDP endpoint.
    pub router: String,
    pub security: Security,
    /// Channel prefix of this operator's gamepads: pad N publishes on
    /// `{pads}/N`.
    pub pads: String,
    /// Channel of this operator's keyboard teleop.
    pub keys: String,
    /// The arena outline, when the station knows one.
    pub arena: Option<ArenaBounds>,
}

/// The outcome of one command line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineResult {
    pub id: u64,
    /// Station time when it finished, s.
    pub t: f64,
    pub ok: bool,
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub summary: String,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub details: Vec<String>,
    /// Why it failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Column (1-based, in characters) of the mistake in the line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub column: Option<usize>,
}

/// Severity of an event-log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogLevel {
    Info,
    Warn,
    Error,
}

/// The bytes an operator key signs to attach over TCP: a fixed label, the
/// station's nonce and the operator's name, so a tag answers one challenge
/// for one name only.
pub fn challenge_region(nonce: &[u8], operator: &str) -> Vec<u8> {
    let mut region = b"mech-attach/1\0".to_vec();
    region.extend_from_slice(nonce);
    region.push(0);
    region.extend_from_slice(operator.as_bytes());
    region
}

/// Bytes as lowercase hex.
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Hex digits as bytes (`None` unless an even count of hex digits).
pub fn unhex(text: &str) -> Option<Vec<u8>> {
    if text.len() % 2 != 0 || !text.is_ascii() {
        return None;
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16).ok())
        .collect()
}

/// Why reading a message failed.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("line longer than {0} bytes")]
    TooLong(usize),
    #[error("not valid UTF-8")]
    NotText,
    #[error("{0}")]
    Json(#[from] serde_json::Error),
}

/// Reads the next message (one line of at most `max` bytes); `Ok(None)` at
/// the end of the stream. Blank lines are skipped. A line too long is
/// consumed up to its newline so the next one reads cleanly.
pub async fn read_message<T: DeserializeOwned>(
    r: &mut (impl AsyncBufRead + Unpin),
    buf: &mut Vec<u8>,
    max: usize,
) -> Result<Option<T>, ReadError> {
    loop {
        buf.clear();
        match read_line(r, buf, max).await? {
            Line::End => return Ok(None),
            Line::TooLong => return Err(ReadError::TooLong(max)),
            Line::Complete => {}
        }
        let text = std::str::from_utf8(buf).map_err(|_| ReadError::NotText)?;
        if text.trim().is_empty() {
            continue;
        }
        return Ok(Some(serde_json::from_str(text)?));
    }
}

enum Line {
    Complete,
    TooLong,
    End,
}

/// One line into `buf` (without its newline), never keeping more than
/// `max` bytes.
async fn read_line(
    r: &mut (impl AsyncBufRead + Unpin),
    buf: &mut Vec<u8>,
    max: usize,
) -> std::io::Result<Line> {
    let mut too_long = false;
    loop {
        let chunk = r.fill_buf().await?;
        if chunk.is_empty() {
            return Ok(if buf.is_empty() && !too_long {
                Line::End
            } else if too_long {
                Line::TooLong
            } else {
                Line::Complete
            });
        }
        let (take, done) = match chunk.iter().position(|&b| b == b'\n') {
            Some(i) => (i, true),
            None => (chunk.len(), false),
        };
        if !too_long && buf.len() + take <= max {
            buf.extend_from_slice(&chunk[..take]);
        } else {
            too_long = true;
            buf.clear();
        }
        r.consume(take + usize::from(done));
        if done {
            return Ok(if too_long {
                Line::TooLong
            } else {
                Line::Complete
            });
        }
    }
}

/// A message as one line, newline included.
pub fn to_line<T: Serialize>(message: &T) -> String {
    let mut line = serde_json::to_string(message)
        .unwrap_or_else(|e| format!("{{\"type\":\"refused\",\"reason\":\"unencodable: {e}\"}}"));
    line.push('\n');
    line
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::Twist;

    async fn read_all<T: DeserializeOwned>(input: &[u8], max: usize) -> Vec<Result<T, String>> {
        let mut r = tokio::io::BufReader::with_capacity(7, input);
        let mut buf = Vec::new();
        let mut out = Vec::new();
        loop {
            match read_message::<T>(&mut r, &mut buf, max).await {
                Ok(Some(m)) => out.push(Ok(m)),
                Ok(None) => return out,
                Err(e) => out.push(Err(e.to_string())),
            }
        }
    }

    #[tokio::test]
    async fn messages_round_trip_as_lines() {
        let sent = vec![
            ToStation::Hello {
                protocol: PROTOCOL,
                operator: Some("ana".into()),
                stream: Streams {
                    snapshots: true,
                    log: true,
                    events: false,
                },
            },
            ToStation::Line {
                id: 7,
                text: "route robot_1 joy/0".into(),
            },
            ToStation::Publish {
                channel: "joy/ana/0".into(),
                robots: vec!["robot_1".into()],
                command: Command::Twist(Twist {
                    vx: 0.5,
                    ..Twist::default()
                }),
            },
            ToStation::Bye,
        ];
        let text: String = sent.iter().map(to_line).collect();
        let got: Vec<ToStation> = read_all(text.as_bytes(), MAX_CLIENT_LINE)
            .await
            .into_iter()
            .map(Result::unwrap)
            .collect();
        assert_eq!(got, sent);
    }

    #[tokio::test]
    async fn a_long_line_is_refused_and_the_next_one_still_reads() {
        let long = format!("{}\n", "x".repeat(100));
        let input = format!("{long}{{\"type\":\"bye\"}}\n");
        let got = read_all::<ToStation>(input.as_bytes(), 50).await;
        assert_eq!(got.len(), 2);
        assert!(got[0].as_ref().unwrap_err().contains("longer than 50"));
        assert_eq!(got[1].as_ref().unwrap(), &ToStation::Bye);
    }

    #[tokio::test]
    async fn garbage_gets_a_message_never_a_panic() {
        let input = b"{\"type\":\"line\"}\nnot json\n\xff\xfe\n{\"type\":\"hello\",\"protocol\":1,\"evil\":1}\n";
        let got = read_all::<ToStation>(input, MAX_CLIENT_LINE).await;
        assert_eq!(got.len(), 4);
        assert!(got.iter().all(Result::is_err), "{got:?}");
        assert!(got[2].as_ref().unwrap_err().contains("UTF-8"));
    }

    #[test]
    fn hex_round_trips_and_refuses_odd_or_foreign_text() {
        let b = [0u8, 1, 0xab, 0xff];
        assert_eq!(hex(&b), "0001abff");
        assert_eq!(unhex("0001abff").unwrap(), b);
        for bad in ["0", "zz", "é1", "0g"] {
            assert!(unhex(bad).is_none(), "{bad}");
        }
    }

    #[test]
    fn an_event_is_sent_as_script_prints_it() {
        let mut m = serde_json::Map::new();
        m.insert("event".into(), "registered".into());
        m.insert("robot".into(), "robot_1".into());
        let line = to_line(&FromStation::Event(m));
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        assert_eq!(v["type"], "event");
        assert_eq!(v["robot"], "robot_1");
        let back: FromStation = serde_json::from_str(&line).unwrap();
        assert!(matches!(back, FromStation::Event(m) if m["event"] == "registered"));
    }
}
