//! Serial radios at the station. One radio carries many robots: it is a
//! broadcast medium (every robot hears every frame; the destination picks
//! the robot), framed with the protocol's COBS + CRC-32 serial framing.
//!
//! Each port has a reader thread, which splits the byte stream into
//! messages and has each decided exactly as a datagram
//! (`crate::router::Shared::decide_frame`), and a writer thread, which sends from
//! a [`RadioQueue`]: e-stops first, then commands, routes, missions and the
//! other control traffic, then heartbeats and the rest. A newer message for
//! the same robot, kind and channel replaces one still waiting (newest
//! wins), so a stale command never waits in the queue behind others. The
//! writer paces itself at the radio's rate, so the queue forms here, where
//! an e-stop can jump it, and not in the radio's own first-in-first-out
//! buffer.
//!
//! A radio that fails (unplugged, its pseudo-terminal gone) is opened again
//! by its reader thread on the schedule of [`Reopen`], also when it cannot
//! be opened at start: the outage is reported once when it begins and once
//! when it ends (an `Event::Radio`, a log line), and while it lasts the
//! queue is emptied and what would go on it dropped and counted, so no
//! command older than the outage is sent when the radio returns.

use std::collections::{HashMap, VecDeque};
use std::io::{Read, Write};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use mech_proto::framing::{Reopen, SerialDecoder, SerialRead, write_serial_message};

use crate::router::tables::Peer;
use crate::router::{RouterError, SerialEndpoint, Shared};
use crate::sync::lock;

/// Messages waiting for one radio, at most: beyond it the lowest class is
/// dropped first (and counted).
const QUEUE_LIMIT: usize = 1024;

/// Bytes the writer may send ahead of the radio's rate (one frame or so):
/// the radio's own buffer holds this much at most.
const BURST_BYTES: f64 = 256.0;

/// What goes first on a radio.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Class {
    /// E-stops and releases.
    EStop = 0,
    /// Commands, routes, missions, registration and time answers.
    Control = 1,
    /// Heartbeats, position fixes, notices and anything else.
    Telemetry = 2,
}

impl Class {
    /// The class of a message kind (see docs/protocol.md, *Bodies*).
    pub(crate) fn of(kind: u8) -> Class {
        match kind {
            11 => Class::EStop,
            // Welcome, Command, FleetCommand, Mission, Route, Time.
            2 | 5 | 6 | 7 | 9 | 21 => Class::Control,
            _ => Class::Telemetry,
        }
    }
}

/// Newest wins per destination, kind and channel.
type Key = (String, u8, String);

#[derive(Debug, Default)]
struct Pending {
    /// Per class, keys in the order they first queued.
    order: [VecDeque<Key>; 3],
    waiting: HashMap<Key, Vec<u8>>,
    closed: bool,
    /// The port is down: nothing is queued.
    down: bool,
}

/// Counters of one radio's sending side.
#[derive(Debug, Default)]
pub(crate) struct RadioCounters {
    pub(crate) frames: AtomicU64,
    pub(crate) bytes: AtomicU64,
    /// Messages replaced in the queue by a newer one (newest wins).
    pub(crate) replaced: AtomicU64,
    /// Messages dropped because the queue was full.
    pub(crate) dropped: AtomicU64,
    /// Messages dropped because the port was down.
    pub(crate) lost_down: AtomicU64,
}

/// The outgoing queue of one radio, shared by whoever decides (UDP
/// workers, TCP peers, timers, readers) and the port's threads, with the
/// port's writing side and its state.
#[derive(Debug, Default)]
pub(crate) struct RadioQueue {
    pending: Mutex<Pending>,
    ready: Condvar,
    pub(crate) counters: RadioCounters,
    /// The port's writing side while it is open; the reader thread puts it
    /// here on each opening and takes it away when the port fails.
    port: Mutex<PortSide>,
    /// Since when the port has been down, and why (for `status`).
    outage: Mutex<Option<(Instant, String)>>,
}

/// The writing side of an open port, and why writing it failed (for the
/// reader thread, which owns the opening, to notice).
#[derive(Default)]
struct PortSide {
    writer: Option<Box<dyn Write + Send>>,
    failed: Option<String>,
}

impl std::fmt::Debug for PortSide {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PortSide")
            .field("open", &self.writer.is_some())
            .field("failed", &self.failed)
            .finish()
    }
}

impl RadioQueue {
    /// Queues one message (its encoded bytes) for the radio; never blocks.
    pub(crate) fn push(&self, bytes: &[u8]) {
        let Ok(head) = mech_proto::peek(bytes) else {
            self.counters.dropped.fetch_add(1, Ordering::Relaxed);
            return;
        };
        let class = Class::of(head.kind);
        let key = (
            head.destination.to_string(),
            head.kind,
            head.channel.to_string(),
        );
        let mut p = lock(&self.pending);
        if p.closed {
            return;
        }
        if p.down {
            self.counters.lost_down.fetch_add(1, Ordering::Relaxed);
            return;
        }
        if let Some(slot) = p.waiting.get_mut(&key) {
            slot.clear();
            slot.extend_from_slice(bytes);
            self.counters.replaced.fetch_add(1, Ordering::Relaxed);
            return;
        }
        if p.waiting.len() >= QUEUE_LIMIT && !p.make_room(class) {
            self.counters.dropped.fetch_add(1, Ordering::Relaxed);
            return;
        }
        p.order[class as usize].push_back(key.clone());
        p.waiting.insert(key, bytes.to_vec());
        drop(p);
        self.ready.notify_one();
    }

    /// The next message to send, highest class first; waits for one.
    /// `None` once closed.
    fn pop(&self) -> Option<Vec<u8>> {
        let mut p = lock(&self.pending);
        loop {
            if p.closed {
                return None;
            }
            if let Some(bytes) = p.take() {
                return Some(bytes);
            }
            p = self.ready.wait(p).unwrap_or_else(|e| e.into_inner());
        }
    }

    /// What the radio on `port` sent and what waits.
    pub(super) fn status(&self, port: &SerialEndpoint) -> RadioStatus {
        let count = |c: &AtomicU64| c.load(Ordering::Relaxed);
        RadioStatus {
            port: port.port.clone(),
            baud: port.baud,
            frames: count(&self.counters.frames),
            bytes: count(&self.counters.bytes),
            replaced: count(&self.counters.replaced),
            dropped: count(&self.counters.dropped),
            waiting: self.len(),
            down: lock(&self.outage)
                .as_ref()
                .map(|(since, error)| (since.elapsed(), error.clone())),
            lost_down: count(&self.counters.lost_down),
        }
    }

    /// The port is down since `since` (`error` says why): the queue is
    /// emptied, its messages counted as lost, and nothing more is queued
    /// until [`RadioQueue::up`].
    fn down(&self, since: Instant, error: &str) {
        let mut p = lock(&self.pending);
        p.down = true;
        let n = p.waiting.len() as u64;
        p.waiting.clear();
        p.order.iter_mut().for_each(VecDeque::clear);
        drop(p);
        self.counters.lost_down.fetch_add(n, Ordering::Relaxed);
        let mut outage = lock(&self.outage);
        if outage.is_none() {
            *outage = Some((since, error.to_string()));
        }
    }

    /// The port is open with `writer`: messages are queued again.
    fn up(&self, writer: Box<dyn Write + Send>) {
        *lock(&self.port) = PortSide {
            writer: Some(writer),
            failed: None,
        };
        lock(&self.pending).down = false;
        *lock(&self.outage) = None;
    }

    /// Writes one frame on the open port; a failure (other than a write
    /// timeout) ends this opening of the port, for the reader to notice.
    /// Returns whether the frame went out.
    fn write(&self, frame: &[u8]) -> bool {
        let mut side = lock(&self.port);
        let Some(port) = side.writer.as_mut() else {
            self.counters.lost_down.fetch_add(1, Ordering::Relaxed);
            return false;
        };
        match port.write_all(frame).and_then(|()| port.flush()) {
            Ok(()) => true,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => false,
            Err(e) => {
                side.writer = None;
                side.failed = Some(e.to_string());
                false
            }
        }
    }

    /// Why writing failed since the port last opened, once.
    fn write_failed(&self) -> Option<String> {
        lock(&self.port).failed.take()
    }

    /// Messages waiting.
    pub(crate) fn len(&self) -> usize {
        lock(&self.pending).waiting.len()
    }

    /// Stops the writer (it returns from [`RadioQueue::pop`]).
    pub(crate) fn close(&self) {
        lock(&self.pending).closed = true;
        self.ready.notify_all();
    }
}

impl Pending {
    fn take(&mut self) -> Option<Vec<u8>> {
        for class in 0..self.order.len() {
            while let Some(key) = self.order[class].pop_front() {
                if let Some(bytes) = self.waiting.remove(&key) {
                    return Some(bytes);
                }
            }
        }
        None
    }

    /// Drops the oldest message of a class below `class` to make room.
    fn make_room(&mut self, class: Class) -> bool {
        for lower in (class as usize + 1..self.order.len()).rev() {
            if let Some(key) = self.order[lower].pop_front() {
                self.waiting.remove(&key);
                return true;
            }
        }
        false
    }
}

/// Paces writes at the radio's rate: a byte takes 10 bit times (start,
/// eight data bits, stop).
#[derive(Debug)]
struct Pacer {
    bytes_per_sec: f64,
    /// Bytes written ahead of the radio's rate.
    ahead: f64,
    last: Instant,
}

impl Pacer {
    fn new(baud: u32) -> Pacer {
        Pacer {
            bytes_per_sec: f64::from(baud) / 10.0,
            ahead: 0.0,
            last: Instant::now(),
        }
    }

    /// Accounts for `n` bytes written; sleeps while too far ahead.
    fn wrote(&mut self, n: usize) {
        let now = Instant::now();
        let drained = now.duration_since(self.last).as_secs_f64() * self.bytes_per_sec;
        self.last = now;
        self.ahead = (self.ahead - drained).max(0.0) + n as f64;
        if self.ahead > BURST_BYTES {
            let wait = (self.ahead - BURST_BYTES) / self.bytes_per_sec;
            std::thread::sleep(Duration::from_secs_f64(wait));
        }
    }
}

/// One serial radio at the station, as `RouterHandle::radios` reports it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RadioStatus {
    pub port: String,
    pub baud: u32,
    /// Frames and bytes sent.
    pub frames: u64,
    pub bytes: u64,
    /// Messages replaced in the queue by a newer one (newest wins).
    pub replaced: u64,
    /// Messages dropped because the queue was full.
    pub dropped: u64,
    /// Messages waiting to be sent.
    pub waiting: usize,
    /// While the port is down (it failed, or could not be opened): for how
    /// long, and why. The router keeps opening it again.
    pub down: Option<(Duration, String)>,
    /// Messages dropped because the port was down.
    pub lost_down: u64,
}

/// A radio's port, opened: the reader's and the writer's handles.
pub(crate) type OpenedPort = (Box<dyn Read + Send>, Box<dyn Write + Send>);

/// Opens a radio's port, each time the reader thread asks (at start, and
/// after every failure).
pub(in crate::router) type Opener = Box<dyn FnMut() -> std::io::Result<OpenedPort> + Send>;

/// A radio to run: how to open its port, and where it is configured.
pub(in crate::router) type RadioPort = (Opener, SerialEndpoint);

/// How each configured radio is opened (with serialport, feature
/// `serial`). Nothing is opened yet: a device missing at start is an
/// outage the reader reports and outlasts, as one unplugged later is.
#[cfg(feature = "serial")]
pub(in crate::router) fn open_radios(
    serial: &[SerialEndpoint],
) -> Result<Vec<RadioPort>, RouterError> {
    Ok(serial
        .iter()
        .map(|s| {
            let (path, baud) = (s.port.clone(), s.baud);
            let open: Opener = Box::new(move || {
                let port = serialport::new(&path, baud)
                    .timeout(Duration::from_millis(50))
                    .open()?;
                let writer = port.try_clone()?;
                Ok((
                    Box::new(port) as Box<dyn Read + Send>,
                    Box::new(writer) as _,
                ))
            });
            (open, s.clone())
        })
        .collect())
}

#[cfg(not(feature = "serial"))]
pub(in crate::router) fn open_radios(
    serial: &[SerialEndpoint],
) -> Result<Vec<RadioPort>, RouterError> {
    match serial.first() {
        None => Ok(Vec::new()),
        Some(s) => Err(RouterError::Serial {
            port: s.port.clone(),
            message: "this build has no serial support (feature `serial`)".into(),
        }),
    }
}

/// Starts a reader and a writer thread per radio.
pub(super) fn start(
    shared: &Arc<Shared>,
    ports: Vec<RadioPort>,
) -> Result<Vec<std::thread::JoinHandle<()>>, RouterError> {
    let mut threads = Vec::new();
    for (i, (open, s)) in ports.into_iter().enumerate() {
        let spawn_err = |source| RouterError::Serial {
            port: s.port.clone(),
            message: format!("cannot start its thread: {source}"),
        };
        let sh = shared.clone();
        let index = i as u16;
        threads.push(
            std::thread::Builder::new()
                .name(format!("mech-radio-rx-{i}"))
                .spawn(move || reader(sh, index, open))
                .map_err(spawn_err)?,
        );
        let (q, baud) = (shared.net.radios[i].clone(), s.baud);
        threads.push(
            std::thread::Builder::new()
                .name(format!("mech-radio-tx-{i}"))
                .spawn(move || writer(q, baud))
                .map_err(spawn_err)?,
        );
    }
    Ok(threads)
}

/// Sends the queue's messages as serial frames, on the port while it is
/// open, until the queue closes.
fn writer(queue: Arc<RadioQueue>, baud: u32) {
    let mut pacer = Pacer::new(baud);
    let mut frame = Vec::with_capacity(512);
    while let Some(bytes) = queue.pop() {
        frame.clear();
        write_serial_message(&bytes, &mut frame);
        if !queue.write(&frame) {
            continue;
        }
        queue.counters.frames.fetch_add(1, Ordering::Relaxed);
        queue
            .counters
            .bytes
            .fetch_add(frame.len() as u64, Ordering::Relaxed);
        pacer.wrote(frame.len());
    }
}

/// Owns radio `index`'s port until the router stops: opens it, reads
/// frames (each good message decided like a datagram, each bad frame
/// counted) until it fails, then opens it again on the schedule of
/// [`Reopen`], reporting each outage once when it begins and once when it
/// ends. The port must return from `read` periodically (its read timeout)
/// so the thread sees the router stop and a failed write.
fn reader(shared: Arc<Shared>, index: u16, mut open: Opener) {
    let Some(queue) = shared.net.radios.get(usize::from(index)).cloned() else {
        return;
    };
    let name = shared.net.radio_name(index);
    let origin = Instant::now();
    let mut schedule = Reopen::new();
    let mut first = true;
    while !shared.stopped() {
        let error = match open() {
            Ok((port, writer)) => {
                queue.up(writer);
                if schedule.opened(origin.elapsed()) {
                    tracing::info!(port = %name, "radio reopened");
                    shared.radio_changed(index, None);
                } else if first {
                    tracing::info!(port = %name, "radio open");
                }
                let ended = read_frames(&shared, &queue, index, port);
                queue.down(Instant::now(), ended.as_deref().unwrap_or("stopped"));
                match ended {
                    Some(e) => e,
                    None => return,
                }
            }
            Err(e) => {
                queue.down(Instant::now(), &e.to_string());
                e.to_string()
            }
        };
        first = false;
        let retry = schedule.failed(origin.elapsed());
        if retry.report {
            tracing::warn!(port = %name, error = %error, "radio failed; reopening it until it returns");
            shared.radio_changed(index, Some(error));
        }
        std::thread::sleep(retry.after);
    }
}

/// Reads frames from one opening of a radio's port until it fails (its
/// error, or the writer's) or the router stops (`None`).
fn read_frames(
    shared: &Shared,
    queue: &RadioQueue,
    index: u16,
    mut port: Box<dyn Read + Send>,
) -> Option<String> {
    let mut decoder = SerialDecoder::new();
    let mut buf = [0u8; 1024];
    let from = Peer::Serial(index);
    while !shared.stopped() {
        if let Some(e) = queue.write_failed() {
            return Some(e);
        }
        let n = match SerialRead::of(port.read(&mut buf)) {
            SerialRead::Bytes(n) => n,
            SerialRead::Idle => continue,
            SerialRead::Failed(e) => return Some(e.to_string()),
        };
        decoder.push(&buf[..n]);
        while let Some(frame) = decoder.next_bytes() {
            match frame {
                Ok(bytes) => shared.decide_frame(&bytes, from),
                Err(e) => shared.count_bad(from, e.to_string()),
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::{Body, Command, EStop, Envelope, Header, Heartbeat, Twist};

    fn msg(dest: &str, channel: &str, body: Body) -> Vec<u8> {
        let header = Header {
            destination: dest.into(),
            channel: channel.into(),
            ..Header::default()
        };
        mech_proto::encode(&Envelope::new(header, body)).unwrap()
    }

    fn twist(vx: f64) -> Body {
        Body::Command(Command::Twist(Twist {
            vx,
            ..Twist::default()
        }))
    }

    fn next(q: &RadioQueue) -> Envelope {
        mech_proto::decode(&lock(&q.pending).take().unwrap()).unwrap()
    }

    #[test]
    fn estops_go_first_then_commands_then_heartbeats_and_the_newest_command_wins() {
        let q = RadioQueue::default();
        q.push(&msg("r1", "", Body::Heartbeat(Heartbeat::new(1))));
        q.push(&msg("r1", "joy/0", twist(0.1)));
        q.push(&msg("r2", "joy/0", twist(0.2)));
        q.push(&msg("r1", "joy/0", twist(0.3)));
        q.push(&msg(
            "r2",
            "",
            Body::EStop(EStop {
                engage: true,
                id: 4,
            }),
        ));
        assert_eq!(q.len(), 4, "the newer r1 command replaced the older");
        assert!(matches!(next(&q).body, Body::EStop(_)));
        let first = next(&q);
        assert_eq!(first.header.destination, "r1");
        assert_eq!(first.body, twist(0.3), "in the older one's place");
        assert_eq!(next(&q).body, twist(0.2));
        assert!(matches!(next(&q).body, Body::Heartbeat(_)));
        assert!(lock(&q.pending).take().is_none());
        assert_eq!(q.counters.replaced.load(Ordering::Relaxed), 1);
    }

    #[test]
    fn a_full_queue_drops_telemetry_before_control_and_never_grows() {
        let q = RadioQueue::default();
        for i in 0..QUEUE_LIMIT {
            let dest = format!("r{i}");
            q.push(&msg(&dest, "", Body::Heartbeat(Heartbeat::new(1))));
        }
        q.push(&msg("x", "joy/0", twist(0.1)));
        assert_eq!(q.len(), QUEUE_LIMIT);
        assert_eq!(next(&q).body, twist(0.1), "the command made room");
        q.push(&msg("y", "", Body::Heartbeat(Heartbeat::new(1))));
        q.push(&msg("z", "", Body::Heartbeat(Heartbeat::new(1))));
        assert_eq!(q.len(), QUEUE_LIMIT);
        assert_eq!(q.counters.dropped.load(Ordering::Relaxed), 1);
        q.push(&[0x99]);
        assert_eq!(q.counters.dropped.load(Ordering::Relaxed), 2, "garbage");
    }

    #[test]
    fn the_writer_paces_at_the_radio_rate() {
        // 9600 baud = 960 bytes/s: 20 frames of ~60 bytes take over a second
        // beyond the burst allowance.
        let q = Arc::new(RadioQueue::default());
        for i in 0..20 {
            q.push(&msg(&format!("r{i}"), "joy/0", twist(0.1)));
        }
        let out = Arc::new(Mutex::new(Vec::new()));
        struct Sink(Arc<Mutex<Vec<u8>>>);
        impl Write for Sink {
            fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
                lock(&self.0).extend_from_slice(b);
                Ok(b.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let started = Instant::now();
        q.up(Box::new(Sink(out.clone())));
        let qw = q.clone();
        let t = std::thread::spawn(move || writer(qw, 9600));
        while q.len() > 0 {
            std::thread::sleep(Duration::from_millis(5));
        }
        q.close();
        t.join().unwrap();
        let sent = lock(&out).len();
        let floor = (sent as f64 - BURST_BYTES - 100.0) / 960.0;
        assert!(
            started.elapsed().as_secs_f64() >= floor,
            "{sent} bytes in {:?}",
            started.elapsed()
        );
        let mut d = SerialDecoder::new();
        d.push(&lock(&out));
        let mut n = 0;
        while let Some(m) = d.next_message() {
            m.unwrap();
            n += 1;
        }
        assert_eq!(n, 20);
    }

    #[test]
    fn while_the_port_is_down_nothing_waits_and_a_failed_write_ends_the_opening() {
        struct Broken;
        impl Write for Broken {
            fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
                Err(std::io::ErrorKind::BrokenPipe.into())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let q = RadioQueue::default();
        q.up(Box::new(Broken));
        q.push(&msg("r1", "joy/0", twist(0.1)));
        q.push(&msg("r2", "joy/0", twist(0.1)));
        assert!(!q.write(b"frame"), "the write failed");
        assert!(q.write_failed().is_some_and(|e| e.contains("broken pipe")));
        assert_eq!(q.write_failed(), None, "told once");
        q.down(Instant::now(), "broken pipe");
        assert_eq!(q.len(), 0, "a command older than the outage is never sent");
        q.push(&msg("r1", "joy/0", twist(0.2)));
        assert_eq!(q.len(), 0);
        let status = q.status(&SerialEndpoint {
            port: "/dev/radio".into(),
            baud: 57_600,
        });
        assert_eq!(status.lost_down, 3, "two emptied, one refused");
        assert_eq!(
            status.down.map(|(_, why)| why).as_deref(),
            Some("broken pipe")
        );
        q.up(Box::new(Vec::new()));
        q.push(&msg("r1", "joy/0", twist(0.3)));
        assert_eq!(q.len(), 1, "queued again once open");
        assert!(q.write(b"frame"));
        assert!(
            q.status(&SerialEndpoint {
                port: "/dev/radio".into(),
                baud: 57_600,
            })
            .down
            .is_none()
        );
    }
}
