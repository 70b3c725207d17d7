//! Serial radio link (XBee in transparent mode, or any UART): messages
//! framed with the protocol's COBS + CRC-32 serial framing, so a corrupted
//! or dropped byte costs one frame and the stream resynchronises at the next
//! delimiter.
//!
//! A serial port is a byte stream (`Read` + `Write`), not a custom trait.
//! [`SerialLink`] frames and deframes over any such stream; [`spawn`] runs
//! one on its own threads for the agent's async loop.

use std::io::{Read, Write};

use mech_proto::Envelope;
use mech_proto::framing::{SerialDecoder, SerialRead, write_serial_message};
use tokio::sync::mpsc;

use crate::runtime::Io;

/// Framing over a byte stream.
#[derive(Debug)]
pub struct SerialLink<S> {
    stream: S,
    decoder: SerialDecoder,
    out: Vec<u8>,
    /// Frames dropped for a bad checksum, bad COBS or a bad message.
    pub corrupt_frames: u64,
}

impl<S> SerialLink<S> {
    pub fn new(stream: S) -> SerialLink<S> {
        SerialLink {
            stream,
            decoder: SerialDecoder::new(),
            out: Vec::with_capacity(256),
            corrupt_frames: 0,
        }
    }

    pub fn into_inner(self) -> S {
        self.stream
    }
}

impl<S: Write> SerialLink<S> {
    /// Writes one framed message. A leading delimiter flushes any garbage a
    /// receiver holds from a half-sent frame.
    pub fn send(&mut self, env: &Envelope) -> std::io::Result<()> {
        let bytes = mech_proto::encode(env)
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidInput, e))?;
        self.send_bytes(&bytes)
    }

    /// Writes one encoded (possibly signed) message as a frame.
    pub fn send_bytes(&mut self, message: &[u8]) -> std::io::Result<()> {
        self.out.clear();
        self.out.push(0);
        write_serial_message(message, &mut self.out);
        self.stream.write_all(&self.out)?;
        self.stream.flush()
    }
}

impl<S: Read> SerialLink<S> {
    /// The next decoded message: reads once from the stream (blocking up to
    /// its timeout) if none is already waiting. `Ok(None)`: nothing yet.
    /// Corrupt frames are counted and skipped.
    pub fn poll(&mut self) -> std::io::Result<Option<Envelope>> {
        Ok(self
            .poll_bytes()?
            .and_then(|bytes| match mech_proto::decode(&bytes) {
                Ok(env) => Some(env),
                Err(e) => {
                    self.corrupt_frames += 1;
                    tracing::debug!(error = %e, "serial frame dropped");
                    None
                }
            }))
    }

    /// Like [`SerialLink::poll`], but the message's bytes (checksum
    /// checked, not decoded): what an authenticating receiver needs.
    pub fn poll_bytes(&mut self) -> std::io::Result<Option<Vec<u8>>> {
        if let Some(bytes) = self.next_good() {
            return Ok(Some(bytes));
        }
        let mut buf = [0u8; 512];
        match SerialRead::of(self.stream.read(&mut buf)) {
            SerialRead::Bytes(n) => self.decoder.push(&buf[..n]),
            SerialRead::Idle => {}
            SerialRead::Failed(e) => return Err(e),
        }
        Ok(self.next_good())
    }

    fn next_good(&mut self) -> Option<Vec<u8>> {
        while let Some(result) = self.decoder.next_bytes() {
            match result {
                Ok(bytes) => return Some(bytes),
                Err(e) => {
                    self.corrupt_frames += 1;
                    tracing::debug!(error = %e, "serial frame dropped");
                }
            }
        }
        None
    }
}

/// Runs a serial link on two threads (reader, writer) and returns the
/// agent loop's [`Io`]. `reader` must return from `read` periodically (a
/// port timeout) so the thread notices when the agent has stopped.
pub fn spawn<R, W>(reader: R, writer: W) -> Io
where
    R: Read + Send + 'static,
    W: Write + Send + 'static,
{
    let (in_tx, incoming) = mpsc::channel(64);
    let (outgoing, out_rx) = std::sync::mpsc::channel::<Vec<u8>>();
    std::thread::spawn(move || {
        let mut link = SerialLink::new(reader);
        loop {
            match link.poll_bytes() {
                Ok(Some(bytes)) => {
                    if in_tx.blocking_send(bytes).is_err() {
                        break;
                    }
                }
                Ok(None) => {
                    if in_tx.is_closed() {
                        break;
                    }
                }
                Err(e) => {
                    tracing::error!(error = %e, "serial link read");
                    break;
                }
            }
        }
    });
    std::thread::spawn(move || {
        let mut link = SerialLink::new(writer);
        while let Ok(bytes) = out_rx.recv() {
            if let Err(e) = link.send_bytes(&bytes) {
                tracing::warn!(error = %e, "serial link write");
            }
        }
    });
    Io::Frames { incoming, outgoing }
}

/// Opens a serial port for [`spawn`] (feature `serial`).
#[cfg(feature = "serial")]
pub fn open(path: &str, baud: u32) -> Result<Io, serialport::Error> {
    let port = serialport::new(path, baud)
        .timeout(std::time::Duration::from_millis(50))
        .open()?;
    let writer = port.try_clone()?;
    Ok(spawn(port, writer))
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::{Body, Header, Heartbeat};

    #[test]
    fn round_trips_and_skips_corrupt_frames() {
        let env = |n| {
            Envelope::new(
                Header {
                    seq: n,
                    sender: "r".into(),
                    ..Header::default()
                },
                Body::Heartbeat(Heartbeat::new(n as u64)),
            )
        };
        let mut tx = SerialLink::new(Vec::new());
        tx.send(&env(1)).unwrap();
        let mut bytes = tx.into_inner();
        let good = bytes.clone();
        bytes.extend_from_slice(&[0x17, 0x00, 0xff, 0x42, 0x99]);
        let mut flipped = good.clone();
        flipped[4] ^= 0x20;
        bytes.extend_from_slice(&flipped);
        let mut tx = SerialLink::new(bytes);
        tx.send(&env(2)).unwrap();
        let bytes = tx.into_inner();
        let mut rx = SerialLink::new(std::io::Cursor::new(bytes));
        let mut got = vec![];
        while let Ok(Some(e)) = rx.poll() {
            got.push(e.header.seq);
        }
        assert_eq!(got, vec![1, 2]);
        assert!(rx.corrupt_frames >= 2, "{}", rx.corrupt_frames);
    }
}
