//! Framing for byte streams: length-prefixed frames on TCP
//! ([`write_stream_frame`], [`StreamDecoder`]) and COBS + CRC-32 frames on
//! serial radios ([`write_serial_frame`], [`SerialDecoder`]). UDP needs no
//! framing: one datagram is one message.
//!
//! Decoders are push-based (feed them whatever `read` returned) and never
//! allocate more than one maximum-size frame; [`SerialRead`] says what a
//! serial port's `read` returned means for its reader, and [`Reopen`] when
//! a port that failed is opened again.

use std::time::Duration;

use crate::MAX_MESSAGE_LEN;
use crate::envelope::{Envelope, decode, encode_into};
use crate::error::Error;

/// Bytes of the big-endian length that precedes each TCP frame.
pub const STREAM_PREFIX_LEN: usize = 4;

/// Bytes of the CRC-32 appended to each serial frame before COBS encoding.
pub const SERIAL_CRC_LEN: usize = 4;

/// Longest serial frame on the wire (COBS adds one byte per 254, plus the
/// first code byte and the two delimiters).
pub const MAX_SERIAL_FRAME_LEN: usize =
    MAX_MESSAGE_LEN + SERIAL_CRC_LEN + (MAX_MESSAGE_LEN + SERIAL_CRC_LEN) / 254 + 3;

/// Appends `env` to `out` as `u32 big-endian length || message`.
pub fn write_stream_frame(env: &Envelope, out: &mut Vec<u8>) -> Result<(), Error> {
    let start = out.len();
    out.extend_from_slice(&[0; STREAM_PREFIX_LEN]);
    if let Err(e) = encode_into(env, out) {
        out.truncate(start);
        return Err(e);
    }
    let len = (out.len() - start - STREAM_PREFIX_LEN) as u32;
    out[start..start + STREAM_PREFIX_LEN].copy_from_slice(&len.to_be_bytes());
    Ok(())
}

/// Splits a TCP byte stream into messages.
///
/// A frame whose body fails to decode yields an error and the stream goes on
/// (the length prefix still marks the next frame). A length prefix of zero or
/// above [`MAX_MESSAGE_LEN`] means the stream is out of step for good: the
/// decoder yields that error and then nothing more; close the connection.
#[derive(Debug, Default)]
pub struct StreamDecoder {
    buf: Vec<u8>,
    /// Start of unread data in `buf`; compacted lazily to avoid a memmove
    /// per frame.
    read: usize,
    broken: bool,
}

impl StreamDecoder {
    pub fn new() -> StreamDecoder {
        StreamDecoder::default()
    }

    /// Adds bytes read from the stream.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.broken {
            return;
        }
        if self.read > 0 && self.read == self.buf.len() {
            self.buf.clear();
            self.read = 0;
        } else if self.read > MAX_MESSAGE_LEN {
            self.buf.drain(..self.read);
            self.read = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// Whether a bad length prefix has ended this stream.
    pub fn is_broken(&self) -> bool {
        self.broken
    }

    /// The next complete frame's message bytes, if one has arrived.
    pub fn next_frame(&mut self) -> Option<Result<&[u8], Error>> {
        if self.broken {
            return None;
        }
        let avail = &self.buf[self.read..];
        if avail.len() < STREAM_PREFIX_LEN {
            return None;
        }
        let mut prefix = [0; STREAM_PREFIX_LEN];
        prefix.copy_from_slice(&avail[..STREAM_PREFIX_LEN]);
        let len = u32::from_be_bytes(prefix) as usize;
        if len == 0 {
            self.broken = true;
            return Some(Err(Error::Framing("zero-length stream frame")));
        }
        if len > MAX_MESSAGE_LEN {
            self.broken = true;
            return Some(Err(Error::Oversized {
                len,
                max: MAX_MESSAGE_LEN,
            }));
        }
        if avail.len() < STREAM_PREFIX_LEN + len {
            return None;
        }
        let start = self.read + STREAM_PREFIX_LEN;
        self.read = start + len;
        Some(Ok(&self.buf[start..start + len]))
    }

    /// The next complete message, decoded.
    pub fn next_message(&mut self) -> Option<Result<Envelope, Error>> {
        self.next_frame().map(|frame| frame.and_then(decode))
    }
}

/// Appends `env` to `out` as `0x00 || COBS(message || crc32_le(message)) || 0x00`.
///
/// The leading delimiter ends whatever half-received garbage a receiver holds
/// (a radio that dropped the previous frame's tail), so a damaged frame never
/// swallows the next one; receivers ignore the empty frame it makes.
pub fn write_serial_frame(env: &Envelope, out: &mut Vec<u8>) -> Result<(), Error> {
    let mut raw = Vec::with_capacity(64);
    encode_into(env, &mut raw)?;
    write_serial_message(&raw, out);
    Ok(())
}

/// Appends an already encoded (and possibly signed) message to `out` as a
/// serial frame, like [`write_serial_frame`].
pub fn write_serial_message(message: &[u8], out: &mut Vec<u8>) {
    let mut raw = Vec::with_capacity(message.len() + SERIAL_CRC_LEN);
    raw.extend_from_slice(message);
    let crc = crc32fast::hash(message);
    raw.extend_from_slice(&crc.to_le_bytes());
    out.push(0);
    cobs_encode(&raw, out);
    out.push(0);
}

/// Splits a serial byte stream into messages, resynchronising at every
/// `0x00`: a corrupted byte costs the frame it is in, never the next one.
#[derive(Debug, Default)]
pub struct SerialDecoder {
    /// COBS-encoded bytes of the frame being received.
    frame: Vec<u8>,
    /// The current frame overflowed; skip to the next delimiter.
    skipping: bool,
    /// Complete frames' messages (still encoded), oldest first.
    ready: std::collections::VecDeque<Result<Vec<u8>, Error>>,
}

impl SerialDecoder {
    pub fn new() -> SerialDecoder {
        SerialDecoder::default()
    }

    /// Adds bytes read from the port; complete frames become available from
    /// [`SerialDecoder::next_message`].
    pub fn push(&mut self, bytes: &[u8]) {
        for &b in bytes {
            if b == 0 {
                if self.skipping {
                    self.skipping = false;
                } else if !self.frame.is_empty() {
                    let result = decode_serial_frame(&self.frame);
                    self.ready.push_back(result);
                }
                self.frame.clear();
            } else if !self.skipping {
                if self.frame.len() >= MAX_SERIAL_FRAME_LEN {
                    self.ready.push_back(Err(Error::Oversized {
                        len: self.frame.len() + 1,
                        max: MAX_SERIAL_FRAME_LEN,
                    }));
                    self.frame.clear();
                    self.skipping = true;
                } else {
                    self.frame.push(b);
                }
            }
        }
    }

    /// The next received message (or why a frame was dropped).
    pub fn next_message(&mut self) -> Option<Result<Envelope, Error>> {
        self.next_bytes().map(|r| r.and_then(|m| decode(&m)))
    }

    /// The next received message's bytes, checksum checked but not decoded
    /// (a receiver that authenticates needs the bytes as sent).
    pub fn next_bytes(&mut self) -> Option<Result<Vec<u8>, Error>> {
        self.ready.pop_front()
    }
}

/// What one `read` from a serial port means for its reader: the radio
/// reader at the station and the agent's serial link read a port the same
/// way (a port opened with a read timeout).
#[derive(Debug)]
pub enum SerialRead {
    /// This many bytes arrived: push them into the [`SerialDecoder`].
    Bytes(usize),
    /// Nothing arrived (the port's read timeout, a signal): read again.
    Idle,
    /// The port closed (a read of 0 bytes: `UnexpectedEof`) or failed:
    /// give it up.
    Failed(std::io::Error),
}

impl SerialRead {
    /// Classifies the result of `read` on a serial port.
    pub fn of(result: std::io::Result<usize>) -> SerialRead {
        use std::io::ErrorKind;
        match result {
            Ok(0) => SerialRead::Failed(std::io::Error::new(
                ErrorKind::UnexpectedEof,
                "serial port closed",
            )),
            Ok(n) => SerialRead::Bytes(n),
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::TimedOut | ErrorKind::WouldBlock | ErrorKind::Interrupted
                ) =>
            {
                SerialRead::Idle
            }
            Err(e) => SerialRead::Failed(e),
        }
    }
}

/// When a serial port that failed (a radio unplugged, its pseudo-terminal
/// gone) is opened again, and which failures are news. The station's
/// radios and the agent's serial links follow the same schedule: a try
/// [`Reopen::FIRST`] after the failure, then twice as long each time up to
/// [`Reopen::LONGEST`], so a device that comes back is in use again within
/// about half a second while a missing one costs two `open` calls a
/// second. An outage is reported once, when it begins, and its end once,
/// when the port opens. Time is given, never read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reopen {
    /// The wait before the next try.
    next: Duration,
    /// When the port last opened, while it is open.
    open_since: Option<Duration>,
    /// Whether an outage has been reported and not yet ended.
    down: bool,
}

/// What to do after a failure ([`Reopen::failed`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Retry {
    /// How long to wait before opening the port again.
    pub after: Duration,
    /// Whether this failure begins an outage: report it (later failures of
    /// the same outage are not news).
    pub report: bool,
}

impl Default for Reopen {
    fn default() -> Self {
        Reopen::new()
    }
}

impl Reopen {
    /// The first wait after a failure.
    pub const FIRST: Duration = Duration::from_millis(50);
    /// The longest wait between two tries.
    pub const LONGEST: Duration = Duration::from_millis(500);

    pub fn new() -> Reopen {
        Reopen {
            next: Reopen::FIRST,
            open_since: None,
            down: false,
        }
    }

    /// The port opened at `now`; returns whether this ends an outage
    /// (report it).
    pub fn opened(&mut self, now: Duration) -> bool {
        self.open_since = Some(now);
        std::mem::replace(&mut self.down, false)
    }

    /// Opening the port, or using it, failed at `now`. A port that had
    /// worked for [`Reopen::LONGEST`] starts the schedule afresh; one that
    /// fails again at once (a device that opens and drops) keeps backing
    /// off.
    pub fn failed(&mut self, now: Duration) -> Retry {
        if self
            .open_since
            .take()
            .is_some_and(|t| now.saturating_sub(t) >= Reopen::LONGEST)
        {
            self.next = Reopen::FIRST;
        }
        let after = self.next;
        self.next = (self.next * 2).min(Reopen::LONGEST);
        Retry {
            after,
            report: !std::mem::replace(&mut self.down, true),
        }
    }

    /// Whether the port is in an outage (failed, not opened since).
    pub fn is_down(&self) -> bool {
        self.down
    }
}

/// Undoes COBS and checks the CRC of one frame (without its delimiter).
fn decode_serial_frame(encoded: &[u8]) -> Result<Vec<u8>, Error> {
    let raw = cobs_decode(encoded)?;
    if raw.len() <= SERIAL_CRC_LEN {
        return Err(Error::Framing("serial frame shorter than its checksum"));
    }
    let (msg, crc) = raw.split_at(raw.len() - SERIAL_CRC_LEN);
    let mut le = [0; SERIAL_CRC_LEN];
    le.copy_from_slice(crc);
    let expected = u32::from_le_bytes(le);
    let computed = crc32fast::hash(msg);
    if expected != computed {
        return Err(Error::Checksum { expected, computed });
    }
    let len = msg.len();
    let mut raw = raw;
    raw.truncate(len);
    Ok(raw)
}

/// Consistent Overhead Byte Stuffing: removes every zero byte from `data`.
pub fn cobs_encode(data: &[u8], out: &mut Vec<u8>) {
    let mut code_at = out.len();
    out.push(0);
    let mut code: u8 = 1;
    for &b in data {
        if b == 0 {
            out[code_at] = code;
            code_at = out.len();
            out.push(0);
            code = 1;
        } else {
            out.push(b);
            code += 1;
            if code == 0xff {
                out[code_at] = code;
                code_at = out.len();
                out.push(0);
                code = 1;
            }
        }
    }
    out[code_at] = code;
}

/// Inverse of [`cobs_encode`]; `encoded` holds no zero bytes.
pub fn cobs_decode(encoded: &[u8]) -> Result<Vec<u8>, Error> {
    let mut out = Vec::with_capacity(encoded.len());
    let mut i = 0;
    while i < encoded.len() {
        let code = encoded[i] as usize;
        if code == 0 {
            return Err(Error::Framing("zero byte inside a COBS frame"));
        }
        let end = i + code;
        if end > encoded.len() {
            return Err(Error::Framing("COBS block runs past the frame"));
        }
        out.extend_from_slice(&encoded[i + 1..end]);
        i = end;
        if code < 0xff && i < encoded.len() {
            out.push(0);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use std::io::{Error, ErrorKind};
    use std::time::Duration;

    use super::{Reopen, Retry, SerialRead};

    #[test]
    fn a_serial_read_is_bytes_idle_or_the_end_of_the_port() {
        assert!(matches!(SerialRead::of(Ok(12)), SerialRead::Bytes(12)));
        for idle in [
            ErrorKind::TimedOut,
            ErrorKind::WouldBlock,
            ErrorKind::Interrupted,
        ] {
            let read = SerialRead::of(Err(Error::from(idle)));
            assert!(matches!(read, SerialRead::Idle), "{idle:?}");
        }
        let closed = SerialRead::of(Ok(0));
        assert!(
            matches!(&closed, SerialRead::Failed(e) if e.kind() == ErrorKind::UnexpectedEof),
            "{closed:?}"
        );
        for gone in [ErrorKind::BrokenPipe, ErrorKind::PermissionDenied] {
            let read = SerialRead::of(Err(Error::from(gone)));
            assert!(
                matches!(&read, SerialRead::Failed(e) if e.kind() == gone),
                "{read:?}"
            );
        }
    }

    #[test]
    fn a_failed_port_is_tried_again_sooner_then_later_and_reported_once() {
        let ms = Duration::from_millis;
        let mut r = Reopen::new();
        assert!(!r.opened(ms(0)), "the first open ends no outage");
        let waits: Vec<Retry> = (1..=6).map(|i| r.failed(ms(100 * i))).collect();
        let after: Vec<u64> = waits.iter().map(|w| w.after.as_millis() as u64).collect();
        assert_eq!(
            after,
            [50, 100, 200, 400, 500, 500],
            "doubling to the longest"
        );
        let reported: Vec<bool> = waits.iter().map(|w| w.report).collect();
        assert_eq!(reported, [true, false, false, false, false, false]);
        assert!(r.is_down());
        assert!(r.opened(ms(2_000)), "the device is back: news");
        assert!(!r.is_down());
        // It fails at once again: the schedule goes on backing off.
        let again = r.failed(ms(2_010));
        assert_eq!((again.after, again.report), (ms(500), true));
        // It then works for longer than the longest wait: afresh.
        r.opened(ms(3_000));
        assert_eq!(r.failed(ms(3_600)).after, Reopen::FIRST);
    }
}
