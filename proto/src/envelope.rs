//! The envelope (header + body + authentication tag) and the message codec:
//! [`encode`], [`decode`], the allocation-free header [`peek`] the router uses
//! on its hot path, and [`signed_region`] for message authentication.
//!
//! Wire layout, one MessagePack array of nine elements:
//! `[version, kind, seq, stamp_us, sender, destination, channel, body, auth]`.

use std::fmt;

use serde::{Deserialize, Serialize};
use serde_bytes::ByteBuf;

use crate::body::Body;
use crate::command::Command;
use crate::error::Error;
use crate::names;
use crate::tagged::expect_end;
use crate::{MAX_AUTH_LEN, MAX_MESSAGE_LEN, PROTOCOL_VERSION};

/// Number of elements in the envelope array.
const ENVELOPE_LEN: u32 = 9;

/// Addressing and ordering information carried by every message.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Header {
    /// Per-sender counter, incremented for every message sent (wrapping);
    /// lets receivers count loss and drop stale reordered commands.
    pub seq: u32,
    /// Sender's clock when the message was made, microseconds since the Unix
    /// epoch. Used for latency measurement and logs, never for safety timing.
    pub stamp_us: u64,
    /// Who sent it: a robot name, `gcs`, or a controller's name.
    pub sender: String,
    /// Who it is for: a robot name, [`crate::BROADCAST`], or [`crate::ROUTER`]
    /// / empty for the router itself.
    pub destination: String,
    /// Command channel (`joy/0`, `wp/gcs`, `fleet/c1`, ...); empty for messages
    /// that are not commands.
    pub channel: String,
}

/// Authentication tag over the message's [`signed_region`]. The field exists
/// now so that signing can be added without a new protocol version; its
/// algorithm is chosen by configuration, not by the wire format.
pub type AuthTag = ByteBuf;

/// One MECH message.
#[derive(Debug, Clone, PartialEq)]
pub struct Envelope {
    pub header: Header,
    pub body: Body,
    /// At most [`crate::MAX_AUTH_LEN`] bytes; `None` when unsigned.
    pub auth: Option<AuthTag>,
}

impl Envelope {
    /// An unsigned envelope.
    pub fn new(header: Header, body: Body) -> Envelope {
        Envelope {
            header,
            body,
            auth: None,
        }
    }

    /// Checks the header names and the body (see [`Body::validate`]).
    pub fn validate(&self) -> Result<(), Error> {
        names::name(&self.header.sender, "sender")?;
        names::name(&self.header.destination, "destination")?;
        names::name(&self.header.channel, "channel")?;
        check_auth(self.auth.as_ref())?;
        self.body.validate()
    }
}

impl Serialize for Envelope {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let h = &self.header;
        let mut t = s.serialize_tuple(ENVELOPE_LEN as usize)?;
        t.serialize_element(&PROTOCOL_VERSION)?;
        t.serialize_element(&self.body.kind())?;
        t.serialize_element(&h.seq)?;
        t.serialize_element(&h.stamp_us)?;
        t.serialize_element(&h.sender)?;
        t.serialize_element(&h.destination)?;
        t.serialize_element(&h.channel)?;
        self.body.write_payload(&mut t)?;
        t.serialize_element(&self.auth)?;
        t.end()
    }
}

impl<'de> Deserialize<'de> for Envelope {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct EnvelopeVisitor;
        impl<'de> serde::de::Visitor<'de> for EnvelopeVisitor {
            type Value = Envelope;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a nine-element MECH envelope array")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<Envelope, A::Error> {
                use serde::de::Error as _;
                let next = |i: usize| move || A::Error::invalid_length(i, &EnvelopeVisitor);
                let version: u8 = seq.next_element()?.ok_or_else(next(0))?;
                if version != PROTOCOL_VERSION {
                    return Err(A::Error::custom(format_args!("protocol version {version}")));
                }
                let kind: u8 = seq.next_element()?.ok_or_else(next(1))?;
                let header = Header {
                    seq: seq.next_element()?.ok_or_else(next(2))?,
                    stamp_us: seq.next_element()?.ok_or_else(next(3))?,
                    sender: seq.next_element()?.ok_or_else(next(4))?,
                    destination: seq.next_element()?.ok_or_else(next(5))?,
                    channel: seq.next_element()?.ok_or_else(next(6))?,
                };
                let body = Body::read_payload(kind, &mut seq)?;
                let auth: Option<AuthTag> = seq.next_element()?.ok_or_else(next(8))?;
                expect_end(&mut seq, "envelope")?;
                Ok(Envelope { header, body, auth })
            }
        }
        d.deserialize_tuple(ENVELOPE_LEN as usize, EnvelopeVisitor)
    }
}

/// Encodes `env` as one message (a UDP datagram's whole payload).
///
/// Fails with [`Error::Invalid`] if a field is out of range and with
/// [`Error::Oversized`] if the result would exceed [`MAX_MESSAGE_LEN`].
pub fn encode(env: &Envelope) -> Result<Vec<u8>, Error> {
    let mut out = Vec::with_capacity(64);
    encode_into(env, &mut out)?;
    Ok(out)
}

/// Like [`encode`], appending to `out` (which is left unchanged on error), so
/// hot loops can reuse one buffer.
pub fn encode_into(env: &Envelope, out: &mut Vec<u8>) -> Result<(), Error> {
    env.validate()?;
    let start = out.len();
    if let Err(e) = rmp_serde::encode::write(out, env) {
        out.truncate(start);
        return Err(Error::Encode(e.to_string()));
    }
    let len = out.len() - start;
    if len > MAX_MESSAGE_LEN {
        out.truncate(start);
        return Err(Error::Oversized {
            len,
            max: MAX_MESSAGE_LEN,
        });
    }
    Ok(())
}

/// Decodes one whole message. Every byte must belong to the message; all
/// fields are validated (see [`Envelope::validate`]).
pub fn decode(bytes: &[u8]) -> Result<Envelope, Error> {
    // The typed header checks (size, version, kind) come first so that a
    // newer peer gets "version 2 is not supported", not a parse error.
    peek(bytes)?;
    let mut rest = bytes;
    let env = {
        let mut de = rmp_serde::Deserializer::new(&mut rest);
        Envelope::deserialize(&mut de).map_err(|e| Error::Malformed(e.to_string()))?
    };
    if !rest.is_empty() {
        return Err(Error::Malformed(format!(
            "{} bytes after the message",
            rest.len()
        )));
    }
    env.validate()?;
    Ok(env)
}

/// The header of a message, borrowed from its bytes without decoding the body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Peek<'a> {
    pub kind: u8,
    pub seq: u32,
    pub stamp_us: u64,
    pub sender: &'a str,
    pub destination: &'a str,
    pub channel: &'a str,
    /// Where the body starts in the message's bytes.
    pub body_offset: usize,
}

/// Reads the header of a message (size, version, kind, seq, stamp, names)
/// without allocating or touching the body. The body may still be malformed;
/// only [`decode`] checks it.
pub fn peek(bytes: &[u8]) -> Result<Peek<'_>, Error> {
    if bytes.is_empty() {
        return Err(Error::Empty);
    }
    if bytes.len() > MAX_MESSAGE_LEN {
        return Err(Error::Oversized {
            len: bytes.len(),
            max: MAX_MESSAGE_LEN,
        });
    }
    let malformed = |what: &str| Error::Malformed(format!("bad header: {what}"));
    let mut rd = bytes;
    let len = rmp::decode::read_array_len(&mut rd).map_err(|_| malformed("not an array"))?;
    let version: u64 = rmp::decode::read_int(&mut rd).map_err(|_| malformed("version"))?;
    if version != u64::from(PROTOCOL_VERSION) {
        return Err(Error::Version {
            found: version,
            supported: PROTOCOL_VERSION,
        });
    }
    if len != ENVELOPE_LEN {
        return Err(malformed("envelope must have nine elements"));
    }
    let kind: u64 = rmp::decode::read_int(&mut rd).map_err(|_| malformed("kind"))?;
    if !Body::is_known(kind) {
        return Err(Error::UnknownKind(kind));
    }
    let seq: u32 = rmp::decode::read_int(&mut rd).map_err(|_| malformed("seq"))?;
    let stamp_us: u64 = rmp::decode::read_int(&mut rd).map_err(|_| malformed("stamp"))?;
    let (sender, rd) = rmp::decode::read_str_from_slice(rd).map_err(|_| malformed("sender"))?;
    let (destination, rd) =
        rmp::decode::read_str_from_slice(rd).map_err(|_| malformed("destination"))?;
    let (channel, body) = rmp::decode::read_str_from_slice(rd).map_err(|_| malformed("channel"))?;
    Ok(Peek {
        kind: kind as u8,
        seq,
        stamp_us,
        sender,
        destination,
        channel,
        body_offset: bytes.len() - body.len(),
    })
}

/// Checks a `Command` message whose header [`peek`] returned, decoding only
/// the command: it accepts exactly what [`decode`] accepts for such a
/// message (names, ranges, tag, nothing after the message), without
/// allocating the header's names. This is the router's forwarding check.
pub fn check_command(bytes: &[u8], head: &Peek<'_>) -> Result<Command, Error> {
    if head.kind != COMMAND_KIND {
        return Err(Error::Invalid(format!(
            "kind {} is not a command",
            head.kind
        )));
    }
    names::name(head.sender, "sender")?;
    names::name(head.destination, "destination")?;
    names::name(head.channel, "channel")?;
    let mut rest = bytes
        .get(head.body_offset..)
        .ok_or_else(|| Error::Malformed("header outside the message".into()))?;
    let (command, auth) = {
        let mut de = rmp_serde::Deserializer::new(&mut rest);
        let malformed = |e: rmp_serde::decode::Error| Error::Malformed(e.to_string());
        let command = Command::deserialize(&mut de).map_err(malformed)?;
        let auth = Option::<AuthTag>::deserialize(&mut de).map_err(malformed)?;
        (command, auth)
    };
    if !rest.is_empty() {
        return Err(Error::Malformed(format!(
            "{} bytes after the message",
            rest.len()
        )));
    }
    check_auth(auth.as_ref())?;
    command.validate()?;
    Ok(command)
}

/// Wire kind of [`Body::Command`], for code that branches on
/// [`Peek::kind`] before deciding to decode.
pub const COMMAND_KIND: u8 = 5;

fn check_auth(auth: Option<&AuthTag>) -> Result<(), Error> {
    match auth {
        Some(tag) if tag.len() > MAX_AUTH_LEN => Err(Error::Invalid(format!(
            "authentication tag of {} bytes, at most {MAX_AUTH_LEN} allowed",
            tag.len()
        ))),
        _ => Ok(()),
    }
}

/// The bytes an authentication tag covers: the whole message up to, not
/// including, its final `auth` element. `auth` must be encoded as nil
/// (`0xc0`) or bin 8 (`0xc4 len bytes`), as [`encode`] does.
pub fn signed_region<'a>(bytes: &'a [u8], env: &Envelope) -> Result<&'a [u8], Error> {
    let tail = match &env.auth {
        None => {
            if bytes.last() != Some(&0xc0) {
                return Err(Error::Framing("auth element is not nil"));
            }
            1
        }
        Some(tag) => {
            let n = tag.len();
            let at = bytes
                .len()
                .checked_sub(n + 2)
                .ok_or(Error::Framing("message shorter than its tag"))?;
            if bytes[at] != 0xc4
                || usize::from(bytes[at + 1]) != n
                || &bytes[at + 2..] != tag.as_slice()
            {
                return Err(Error::Framing("auth element is not a bin 8 at the end"));
            }
            n + 2
        }
    };
    Ok(&bytes[..bytes.len() - tail])
}
