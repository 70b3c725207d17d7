//! Serial radio link (XBee in transparent mode, or any UART): messages
//! framed with the protocol's COBS + CRC-32 serial framing, so a corrupted
//! or dropped byte costs one frame and the stream resynchronises at the next
//! delimiter.
//!
//! A serial port is a byte stream (`Read` + `Write`), not a custom trait.
//! [`SerialLink`] frames and deframes over any such stream; [`spawn`] runs
//! one on its own threads for the agent's async loop, opening the port
//! again whenever it fails.

use std::io::{Read, Write};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Instant;

use mech_proto::Envelope;
use mech_proto::framing::{Reopen, SerialDecoder, SerialRead, write_serial_message};
use tokio::sync::mpsc;

use crate::runtime::{FramesIn, FramesOut, Io};

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

/// A port as opened: its reading and its writing handle (a serial port
/// and its `try_clone`).
pub type OpenedPort = (Box<dyn Read + Send>, Box<dyn Write + Send>);

/// The port's writing side while it is open, and why writing failed, for
/// the reader thread to notice.
#[derive(Default)]
struct WriteSide {
    link: Option<SerialLink<Box<dyn Write + Send>>>,
    failed: Option<String>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Runs a serial link named `port` on two threads and returns the agent
/// loop's [`Io`]. The reader thread opens the port with `open`, reads
/// frames until the port fails (and then closes it), and opens it again on the
/// schedule of [`Reopen`] (a radio unplugged and plugged back, a
/// pseudo-terminal recreated) for as long as the agent runs, also when the
/// port cannot be opened at first. The loop hears of an outage once, when
/// it begins ([`FramesIn::Down`]), and once when it ends
/// ([`FramesIn::Up`]); meanwhile what it sends is dropped. The writer
/// thread writes each message while the port is open; a failed write ends
/// that opening too. When the agent stops, the reader thread ends and
/// leaves the port to the writer thread, which writes what was queued
/// (the agent's Bye; [`FramesOut`] waits for it) and closes the port as it
/// ends. A port must return from `read` periodically (its read timeout) so
/// the reader notices a failed write and the agent stopping.
pub fn spawn<F>(port: &str, mut open: F) -> Io
where
    F: FnMut() -> std::io::Result<OpenedPort> + Send + 'static,
{
    let (in_tx, incoming) = mpsc::channel(64);
    let (queue, out_rx) = std::sync::mpsc::channel::<Vec<u8>>();
    let (done, writer_done) = std::sync::mpsc::channel::<()>();
    let side = Arc::new(Mutex::new(WriteSide::default()));
    let (reader_side, name) = (side.clone(), port.to_string());
    std::thread::spawn(move || {
        let origin = Instant::now();
        let mut schedule = Reopen::new();
        while !in_tx.is_closed() {
            let error = match open() {
                Ok((reader, writer)) => {
                    // The port takes messages before it is said to be back,
                    // so one sent on hearing so is written, not dropped.
                    *lock(&reader_side) = WriteSide {
                        link: Some(SerialLink::new(writer)),
                        failed: None,
                    };
                    if schedule.opened(origin.elapsed()) {
                        tracing::info!(port = %name, "serial link reopened");
                        let text = format!("serial link {name} reopened");
                        if in_tx.blocking_send(FramesIn::Up(text)).is_err() {
                            break;
                        }
                    }
                    match read_frames(SerialLink::new(reader), &in_tx, &reader_side) {
                        Some(e) => {
                            lock(&reader_side).link = None;
                            e
                        }
                        // The agent stopped: the port stays with the
                        // writer thread, which writes what it was given
                        // last (the agent's Bye) and then ends.
                        None => break,
                    }
                }
                Err(e) => e.to_string(),
            };
            let retry = schedule.failed(origin.elapsed());
            if retry.report {
                tracing::warn!(port = %name, error = %error, "serial link failed; reopening it until it returns");
                let text = format!("serial link {name} down: {error}; reopening");
                if in_tx.blocking_send(FramesIn::Down(text)).is_err() {
                    break;
                }
            }
            std::thread::sleep(retry.after);
        }
    });
    std::thread::spawn(move || {
        // Held until the thread ends: `FramesOut` waits for that.
        let _done = done;
        while let Ok(bytes) = out_rx.recv() {
            let mut w = lock(&side);
            let Some(link) = w.link.as_mut() else {
                // The port is down: the message is lost, as on a radio
                // out of range; the outage was reported.
                continue;
            };
            if let Err(e) = link.send_bytes(&bytes) {
                w.link = None;
                w.failed = Some(e.to_string());
            }
        }
    });
    Io::Frames {
        incoming,
        outgoing: FramesOut::new(queue, writer_done),
    }
}

/// Reads frames from one opening of the port into `to` until the port
/// fails (its error, or the writer's), or the agent stops (`None`).
fn read_frames<R: Read>(
    mut link: SerialLink<R>,
    to: &mpsc::Sender<FramesIn>,
    side: &Mutex<WriteSide>,
) -> Option<String> {
    loop {
        match link.poll_bytes() {
            Ok(Some(bytes)) => {
                if to.blocking_send(FramesIn::Frame(bytes)).is_err() {
                    return None;
                }
                continue;
            }
            Ok(None) if to.is_closed() => return None,
            Ok(None) => {}
            Err(e) => return Some(e.to_string()),
        }
        if let Some(e) = lock(side).failed.take() {
            return Some(e);
        }
    }
}

/// A serial port opened for [`spawn`] (feature `serial`): `path` at
/// `baud`, reopened whenever it fails.
#[cfg(feature = "serial")]
pub fn open(path: &str, baud: u32) -> Io {
    let device = path.to_string();
    spawn(path, move || {
        let port = serialport::new(&device, baud)
            .timeout(std::time::Duration::from_millis(50))
            .open()?;
        let writer = port.try_clone()?;
        Ok((
            Box::new(port) as Box<dyn Read + Send>,
            Box::new(writer) as _,
        ))
    })
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

    /// One opening of a fake port: what its reads return, in order, then
    /// nothing (a read timeout) for ever.
    struct FakeRead(std::collections::VecDeque<std::io::Result<Vec<u8>>>);

    impl Read for FakeRead {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            match self.0.pop_front() {
                Some(Ok(bytes)) => {
                    buf[..bytes.len()].copy_from_slice(&bytes);
                    Ok(bytes.len())
                }
                Some(Err(e)) => Err(e),
                None => {
                    std::thread::sleep(std::time::Duration::from_millis(2));
                    Err(std::io::ErrorKind::TimedOut.into())
                }
            }
        }
    }

    /// A fake port's writing side: keeps what it is given; fails every
    /// write after the first `works` ones.
    struct FakeWrite {
        got: Arc<Mutex<Vec<u8>>>,
        works: usize,
    }

    impl Write for FakeWrite {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            if self.works == 0 {
                return Err(std::io::ErrorKind::BrokenPipe.into());
            }
            lock(&self.got).extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            if self.works == 0 {
                return Err(std::io::ErrorKind::BrokenPipe.into());
            }
            self.works -= 1;
            Ok(())
        }
    }

    fn frame(seq: u32) -> Vec<u8> {
        let env = Envelope::new(
            Header {
                seq,
                ..Header::default()
            },
            Body::Heartbeat(Heartbeat::new(1)),
        );
        let mut tx = SerialLink::new(Vec::new());
        tx.send(&env).unwrap();
        tx.into_inner()
    }

    /// What each opening of a fake port gives.
    type Openings = std::collections::VecDeque<std::io::Result<OpenedPort>>;

    /// The openings of a fake port, in order, and where each open one's
    /// writes go: missing twice at start; then a port that delivers a
    /// frame and breaks; missing once; then one whose second write fails;
    /// then one that works.
    fn openings() -> (Openings, Vec<Arc<Mutex<Vec<u8>>>>) {
        let gone = || Err(std::io::Error::from(std::io::ErrorKind::NotFound));
        let writes: Vec<Arc<Mutex<Vec<u8>>>> = (0..3).map(|_| Arc::default()).collect();
        let port = |reads: Vec<std::io::Result<Vec<u8>>>, i: usize, works: usize| {
            let w = FakeWrite {
                got: writes[i].clone(),
                works,
            };
            Ok((
                Box::new(FakeRead(reads.into())) as Box<dyn Read + Send>,
                Box::new(w) as Box<dyn Write + Send>,
            ))
        };
        let broken = || Err(std::io::Error::from(std::io::ErrorKind::BrokenPipe));
        let openings = [
            gone(),
            gone(),
            port(vec![Ok(frame(1)), broken()], 0, 9),
            gone(),
            port(vec![Ok(frame(2))], 1, 1),
            port(vec![], 2, 9),
        ]
        .into_iter()
        .collect();
        (openings, writes)
    }

    /// A reading side that says when it is first read (the port is open)
    /// and when it is dropped.
    struct Dropped {
        reading: Arc<std::sync::atomic::AtomicBool>,
        dropped: Arc<std::sync::atomic::AtomicBool>,
    }

    impl Read for Dropped {
        fn read(&mut self, _: &mut [u8]) -> std::io::Result<usize> {
            self.reading
                .store(true, std::sync::atomic::Ordering::SeqCst);
            std::thread::sleep(std::time::Duration::from_millis(2));
            Err(std::io::ErrorKind::TimedOut.into())
        }
    }

    impl Drop for Dropped {
        fn drop(&mut self) {
            self.dropped
                .store(true, std::sync::atomic::Ordering::SeqCst);
        }
    }

    /// A writing side whose first write waits until `gate` opens.
    struct Gated {
        gate: std::sync::mpsc::Receiver<()>,
        got: Arc<Mutex<Vec<u8>>>,
        first: bool,
    }

    impl Write for Gated {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            if std::mem::take(&mut self.first) {
                let _ = self.gate.recv();
            }
            lock(&self.got).extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn what_the_agent_sent_before_it_stopped_is_written_after() {
        // The agent stops: the reader thread ends at once (its end of
        // the link dropped), and what was queued for the writer (the
        // agent's Bye), held up behind a slow write, is still written, by
        // the time the sending end is dropped (the agent may exit then). A
        // reader that closed the port as it ended lost the Bye whenever
        // the writer thread had not yet run (a busy machine).
        let dropped = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let reading = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let (open_gate, gate) = std::sync::mpsc::channel();
        let got: Arc<Mutex<Vec<u8>>> = Arc::default();
        let mut port = Some((
            Box::new(Dropped {
                reading: reading.clone(),
                dropped: dropped.clone(),
            }) as Box<dyn Read + Send>,
            Box::new(Gated {
                gate,
                got: got.clone(),
                first: true,
            }) as Box<dyn Write + Send>,
        ));
        // Owned by the reader thread (in its `open`): dropped as it ends.
        let ended = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let thread_ends = Dropped {
            reading: Arc::default(),
            dropped: ended.clone(),
        };
        let Io::Frames { incoming, outgoing } = spawn("/dev/fake", move || {
            std::hint::black_box(&thread_ends);
            port.take()
                .ok_or_else(|| std::io::ErrorKind::NotFound.into())
        }) else {
            panic!("a framed link");
        };
        let deadline = || std::time::Instant::now() + std::time::Duration::from_secs(10);
        let written = || {
            let mut d = SerialDecoder::new();
            d.push(&lock(&got));
            std::iter::from_fn(|| d.next_bytes()).count()
        };
        let until = deadline();
        while !reading.load(std::sync::atomic::Ordering::SeqCst) {
            assert!(std::time::Instant::now() < until, "the port never opened");
            std::thread::yield_now();
        }
        drop(incoming);
        let until = deadline();
        while !ended.load(std::sync::atomic::Ordering::SeqCst) {
            assert!(
                std::time::Instant::now() < until,
                "the reader thread did not end"
            );
            std::thread::yield_now();
        }
        assert!(dropped.load(std::sync::atomic::Ordering::SeqCst));
        outgoing.send(vec![0x91, 0x01]).unwrap();
        outgoing.send(vec![0x91, 0x02]).unwrap();
        let opener = std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(50));
            open_gate.send(()).unwrap();
        });
        drop(outgoing);
        assert_eq!(written(), 2, "both written before the sending end is gone");
        opener.join().unwrap();
    }

    #[test]
    fn a_port_that_fails_is_reopened_and_each_outage_reported_once() {
        let gone = || Err(std::io::Error::from(std::io::ErrorKind::NotFound));
        let (mut openings, writes) = openings();
        let Io::Frames {
            mut incoming,
            outgoing,
        } = spawn("/dev/fake", move || {
            openings.pop_front().unwrap_or_else(gone)
        })
        else {
            panic!("a framed link");
        };
        let mut next = || incoming.blocking_recv().expect("the link runs");
        let said = |news: FramesIn| match news {
            FramesIn::Down(t) => format!("down {t}"),
            FramesIn::Up(t) => format!("up {t}"),
            FramesIn::Frame(b) => {
                format!("frame {}", mech_proto::decode(&b).unwrap().header.seq)
            }
        };
        let mut seen: Vec<String> = (0..5).map(|_| said(next())).collect();
        assert!(
            seen[0].starts_with("down serial link /dev/fake down:"),
            "{seen:?}"
        );
        assert_eq!(
            seen[1..],
            [
                "up serial link /dev/fake reopened",
                "frame 1",
                "down serial link /dev/fake down: broken pipe; reopening",
                "up serial link /dev/fake reopened",
            ],
            "the two failures of the first outage are reported once"
        );
        assert_eq!(said(next()), "frame 2");
        outgoing.send(vec![0x91, 0x01]).unwrap();
        outgoing.send(vec![0x91, 0x02]).unwrap();
        // The second write failed: the port is opened again.
        seen.clear();
        seen.push(said(next()));
        seen.push(said(next()));
        assert_eq!(
            seen,
            [
                "down serial link /dev/fake down: broken pipe; reopening",
                "up serial link /dev/fake reopened",
            ]
        );
        outgoing.send(vec![0x91, 0x03]).unwrap();
        let written = |i: usize| {
            let mut d = SerialDecoder::new();
            d.push(&lock(&writes[i]));
            std::iter::from_fn(|| d.next_bytes())
                .map(|b| b.unwrap())
                .collect::<Vec<_>>()
        };
        assert_eq!(written(1), [vec![0x91, 0x01]]);
        // The writer thread writes it: wait until it has (a deadline only
        // so a failure says so instead of hanging).
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
        while written(2).is_empty() {
            assert!(
                std::time::Instant::now() < deadline,
                "a message sent once the port was said to be back was never written"
            );
            std::thread::yield_now();
        }
        assert_eq!(
            written(2),
            [vec![0x91, 0x03]],
            "written on the port opened last"
        );
    }
}
