//! The recorder's thread: takes what the router's tap queued, in order,
//! and writes it to MCAP (raw bytes, decisions, events, telemetry and poses
//! per robot, operator commands), keeping a copy of the fleet model fed by
//! the same events, from which it draws the event log (`foxglove.Log`) and
//! the scene (`foxglove.SceneUpdate`) and begins each rotated file with a
//! snapshot. Chunks are closed every second; when a rotating file reaches
//! its size it is finished and the next begun.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::file::McapFile;
use super::{RecordError, RecordTarget, RecordingStatus, encode, rotate, scene, schema, snapshot};
use crate::event::{Event, Stamped};
use crate::fleet::Fleet;
use crate::router::TapCounts;
use crate::router::{OperatorRecord, Tapped, TappedMessage};
use crate::sync::lock;

/// How often chunks are closed and written out (and the status updated).
const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// While records keep coming, the thread takes them in batches this far
/// apart, sleeping between, instead of waiting on the queue: a thread
/// waiting on the queue is woken by the router's offer of each record (a
/// system call, and on another core an interrupt, on the router's hot
/// path). The records wait this long at most; the file is written every
/// [`FLUSH_EVERY`] anyway.
const BATCH_EVERY: Duration = Duration::from_millis(5);

/// State the recorder's handle reads.
#[derive(Debug)]
pub(super) struct Shared {
    pub(super) status: Mutex<RecordingStatus>,
    /// The taps' counts: records the tap could not queue (full or closed
    /// queue) and records queued but not written because writing had
    /// failed (`dropped`), records queued, refused messages not recorded.
    pub(super) taps: TapCounts,
    /// Router messages, events and MCAP messages written so far.
    pub(super) messages: AtomicU64,
    pub(super) events: AtomicU64,
    pub(super) written: AtomicU64,
}

/// The writer's state.
pub(super) struct Writer {
    target: RecordTarget,
    compress: bool,
    file: Option<McapFile>,
    /// Files begun so far.
    files: Vec<PathBuf>,
    /// The fleet model as of the last event written.
    replica: Fleet,
    /// The station's fleet model (for cluster definitions, which are not
    /// events).
    live: Arc<Mutex<Fleet>>,
    router_start_ns: u64,
    scene_hz: f64,
    last_scene: Option<Duration>,
    log_seq: u64,
    /// Router time of the last record.
    last_at: Duration,
    shared: Arc<Shared>,
    /// The router's count of received messages when recording began, and
    /// when it ended.
    received_before: u64,
    received_end: Option<u64>,
    /// Robot name -> (telemetry, pose) channel ids in the current file.
    robot_channels: std::collections::HashMap<String, (u16, u16)>,
}

impl std::fmt::Debug for Writer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Writer").field("file", &self.file).finish()
    }
}

/// What [`Writer::new`] needs.
#[derive(Debug)]
pub(super) struct WriterSetup {
    pub(super) target: RecordTarget,
    pub(super) compress: bool,
    pub(super) scene_hz: f64,
    pub(super) live: Arc<Mutex<Fleet>>,
    pub(super) router_start_ns: u64,
    pub(super) shared: Arc<Shared>,
}

impl Writer {
    /// Opens the first file (so a bad path is an error before recording
    /// starts).
    pub(super) fn new(setup: WriterSetup) -> Result<Writer, RecordError> {
        // Replaced by the fleet model as recording begins (`Tapped::Begin`).
        let replica = Fleet::new(crate::fleet::FleetConfig::default());
        let mut w = Writer {
            target: setup.target,
            compress: setup.compress,
            file: None,
            files: Vec::new(),
            replica,
            live: setup.live,
            router_start_ns: setup.router_start_ns,
            scene_hz: setup.scene_hz,
            last_scene: None,
            log_seq: 0,
            last_at: Duration::ZERO,
            shared: setup.shared,
            received_before: 0,
            received_end: None,
            robot_channels: Default::default(),
        };
        w.open()?;
        Ok(w)
    }

    /// The file being written.
    pub(super) fn path(&self) -> PathBuf {
        self.files.last().cloned().unwrap_or_default()
    }

    fn open(&mut self) -> Result<(), RecordError> {
        let (path, fresh) = match &self.target {
            RecordTarget::File(p) => (p.clone(), false),
            RecordTarget::NewFile(p) => (p.clone(), true),
            RecordTarget::Rotating { dir, keep, .. } => {
                rotate::prune(dir, keep.saturating_sub(1));
                let name = rotate::next_name(dir, mech_proto::unix_micros() / 1_000_000);
                (name, false)
            }
        };
        let mut meta = BTreeMap::new();
        meta.insert("format".into(), "1".into());
        meta.insert(
            "router_start_unix_ns".into(),
            self.router_start_ns.to_string(),
        );
        meta.insert("station_version".into(), env!("CARGO_PKG_VERSION").into());
        meta.insert("file_index".into(), self.files.len().to_string());
        self.file = Some(McapFile::create(&path, fresh, self.compress, meta)?);
        self.files.push(path);
        self.robot_channels.clear();
        Ok(())
    }

    fn ns(&self, at: Duration) -> u64 {
        super::unix_ns(self.router_start_ns, at)
    }

    fn put(
        &mut self,
        topic: &str,
        schema: Option<&'static str>,
        seq: Option<u32>,
        at: Duration,
        data: &[u8],
    ) -> Result<(), RecordError> {
        let ns = self.ns(at);
        let Some(file) = self.file.as_mut() else {
            return Ok(());
        };
        let id = file.channel(topic, schema)?;
        file.write(id, seq, ns, data)?;
        self.shared.written.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }

    /// Writes one queued record.
    pub(super) fn take(&mut self, t: Tapped) -> Result<(), RecordError> {
        match t {
            Tapped::Message(m) => self.message(&m),
            Tapped::Event(s) => self.event(&s),
            Tapped::Operator(o) => self.operator(&o),
            Tapped::Begin {
                at,
                fleet,
                received,
            } => {
                self.replica = *fleet;
                self.received_before = received;
                self.begin(at)
            }
            Tapped::End { received } => self.end(received),
        }
    }

    fn message(&mut self, m: &TappedMessage) -> Result<(), RecordError> {
        self.last_at = self.last_at.max(m.at);
        self.shared.messages.fetch_add(1, Ordering::Relaxed);
        self.put(schema::RAW, None, Some(m.number as u32), m.at, &m.bytes)?;
        if encode::has_decision(m) {
            let json = encode::decision(m);
            self.put(
                schema::DECISIONS,
                Some(schema::MECH_DECISION),
                None,
                m.at,
                &json,
            )?;
        }
        Ok(())
    }

    fn event(&mut self, s: &Stamped) -> Result<(), RecordError> {
        self.last_at = self.last_at.max(s.at);
        self.shared.events.fetch_add(1, Ordering::Relaxed);
        match &s.event {
            Event::Telemetry { robot, telemetry } => self.telemetry(s.at, robot, telemetry)?,
            _ => {
                let json = encode::event(s);
                self.put(schema::EVENTS, Some(schema::MECH_EVENT), None, s.at, &json)?;
            }
        }
        self.replica.apply(s);
        self.log_lines()?;
        self.maybe_scene(s.at)
    }

    fn telemetry(
        &mut self,
        at: Duration,
        robot: &str,
        t: &mech_proto::Telemetry,
    ) -> Result<(), RecordError> {
        let (telemetry, pose) = self.robot_channels(robot)?;
        let ns = self.ns(at);
        let Some(file) = self.file.as_mut() else {
            return Ok(());
        };
        file.write(telemetry, None, ns, &encode::telemetry(t))?;
        file.write(pose, None, ns, &encode::pose(ns, &t.pose))?;
        self.shared.written.fetch_add(2, Ordering::Relaxed);
        Ok(())
    }

    fn robot_channels(&mut self, robot: &str) -> Result<(u16, u16), RecordError> {
        if let Some(ids) = self.robot_channels.get(robot) {
            return Ok(*ids);
        }
        let Some(file) = self.file.as_mut() else {
            return Ok((0, 0));
        };
        let telemetry = file.channel(
            &schema::telemetry_topic(robot),
            Some(schema::MECH_TELEMETRY),
        )?;
        let pose = file.channel(&schema::pose_topic(robot), Some(schema::POSE_IN_FRAME))?;
        self.robot_channels
            .insert(robot.to_string(), (telemetry, pose));
        Ok((telemetry, pose))
    }

    fn operator(&mut self, o: &OperatorRecord) -> Result<(), RecordError> {
        self.last_at = self.last_at.max(o.at);
        let json = encode::operator(o);
        self.put(
            schema::OPERATOR,
            Some(schema::MECH_OPERATOR),
            None,
            o.at,
            &json,
        )?;
        let verdict = if o.ok { "ok" } else { "failed" };
        let text = format!("> {} ({verdict}): {}", o.text, o.summary);
        let severity = if o.ok {
            crate::fleet::Severity::Info
        } else {
            crate::fleet::Severity::Warn
        };
        let line = encode::log_line(self.ns(o.at), severity, &text, "operator");
        self.put(schema::LOG, Some(schema::FOXGLOVE_LOG), None, o.at, &line)
    }

    /// New lines of the replica's event log, as `foxglove.Log`.
    fn log_lines(&mut self) -> Result<(), RecordError> {
        let lines: Vec<(Duration, crate::fleet::Severity, String, u64)> = self
            .replica
            .log_after(self.log_seq)
            .map(|e| (e.at, e.severity, e.text.clone(), e.seq))
            .collect();
        for (at, severity, text, seq) in lines {
            let line = encode::log_line(self.ns(at), severity, &text, "mech");
            self.put(schema::LOG, Some(schema::FOXGLOVE_LOG), None, at, &line)?;
            self.log_seq = seq;
        }
        Ok(())
    }

    /// The scene, at most every scene period of router time (longer for a
    /// big fleet: half a millisecond per robot), with cluster changes.
    fn maybe_scene(&mut self, at: Duration) -> Result<(), RecordError> {
        let period = scene::period(self.scene_hz, self.replica.robots.len());
        if self.last_scene.is_some_and(|last| at < last + period) {
            return Ok(());
        }
        self.last_scene = Some(at);
        self.clusters(at, false)?;
        let scene = scene::scene(self.ns(at), &self.replica);
        self.put(schema::SCENE, Some(schema::SCENE_UPDATE), None, at, &scene)
    }

    /// Writes the cluster definitions if they changed (or `always`).
    fn clusters(&mut self, at: Duration, always: bool) -> Result<(), RecordError> {
        let live = lock(&self.live).clusters.clone();
        if !always && live == self.replica.clusters {
            return Ok(());
        }
        self.replica.clusters = live;
        let json = encode::clusters(at, &self.replica.clusters);
        self.put(
            schema::CLUSTERS,
            Some(schema::MECH_CLUSTERS),
            None,
            at,
            &json,
        )
    }

    /// Begins a file with the replica as snapshot events at `at`.
    fn begin(&mut self, at: Duration) -> Result<(), RecordError> {
        self.last_at = self.last_at.max(at);
        self.log_seq = self.replica.log.back().map_or(0, |e| e.seq);
        for event in snapshot::events(&self.replica) {
            let json = encode::event(&Stamped { at, event });
            self.put(schema::SNAPSHOT, Some(schema::MECH_EVENT), None, at, &json)?;
        }
        self.clusters(at, true)?;
        self.last_scene = None;
        self.maybe_scene(at)
    }

    /// Closes the current chunk, publishes the status, and rotates when a
    /// rotating file has reached its size.
    pub(super) fn flush(&mut self) -> Result<(), RecordError> {
        let Some(file) = self.file.as_mut() else {
            return Ok(());
        };
        let size = file.flush()?;
        self.publish(size, None);
        if let RecordTarget::Rotating { max_file_bytes, .. } = self.target {
            if size >= max_file_bytes {
                self.finish_file()?;
                self.open()?;
                let at = self.last_at;
                self.begin(at)?;
            }
        }
        Ok(())
    }

    /// Notes the router's final count of received messages (recording
    /// ends): the last file's closing metadata says how many it received
    /// while recording, next to how many were recorded.
    fn end(&mut self, received: u64) -> Result<(), RecordError> {
        self.received_end = Some(received);
        Ok(())
    }

    fn finish_file(&mut self) -> Result<(), RecordError> {
        let Some(file) = self.file.take() else {
            return Ok(());
        };
        let count = |c: &AtomicU64| c.load(Ordering::Relaxed).to_string();
        let mut end = BTreeMap::new();
        end.insert("router_messages".into(), count(&self.shared.messages));
        end.insert("events".into(), count(&self.shared.events));
        end.insert("dropped".into(), count(&self.shared.taps.dropped));
        end.insert(
            "refused_unrecorded".into(),
            count(&self.shared.taps.unrecorded),
        );
        if let Some(received) = self.received_end {
            let during = received.saturating_sub(self.received_before);
            end.insert("router_received".into(), during.to_string());
        }
        file.finish(end)
    }

    /// Finishes the last file; the status says how it ended.
    pub(super) fn finish(mut self, error: Option<String>) {
        let path = self.path();
        let size = self.file.as_mut().and_then(|f| f.flush().ok()).unwrap_or(0);
        let error = match self.finish_file() {
            Ok(()) => error,
            Err(e) => error.or(Some(e.to_string())),
        };
        let size = std::fs::metadata(&path).map_or(size, |m| m.len());
        self.publish(size, error);
        lock(&self.shared.status).active = false;
    }

    fn publish(&self, bytes: u64, error: Option<String>) {
        let mut s = lock(&self.shared.status);
        s.file = self.path();
        s.files = self.files.clone();
        s.bytes = bytes;
        if error.is_some() {
            s.error = error;
        }
    }
}

/// The thread's loop: wait for a record; while records keep coming, take
/// them in batches [`BATCH_EVERY`] apart; flush every second; finish when
/// every sender is gone. After a write error nothing more is written: what
/// still arrives is counted as dropped.
pub(super) fn run(mut w: Writer, rx: Receiver<Tapped>) {
    let mut last_flush = std::time::Instant::now();
    let mut failed: Option<String> = None;
    let take = |w: &mut Writer, t: Tapped, failed: &mut Option<String>| {
        if failed.is_some() {
            w.shared.taps.dropped.fetch_add(1, Ordering::Relaxed);
        } else if let Err(e) = w.take(t) {
            *failed = Some(fail(w, e));
        }
    };
    // Whether the last look at the queue found it empty: then the thread
    // waits on it, else it sleeps and takes the next batch.
    let mut idle = true;
    'run: loop {
        if idle {
            match rx.recv_timeout(FLUSH_EVERY) {
                Ok(t) => take(&mut w, t, &mut failed),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
        } else {
            std::thread::sleep(BATCH_EVERY);
        }
        let mut got = 0usize;
        loop {
            match rx.try_recv() {
                Ok(t) => {
                    take(&mut w, t, &mut failed);
                    got += 1;
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => break 'run,
            }
        }
        idle = got == 0;
        if failed.is_none() && last_flush.elapsed() >= FLUSH_EVERY {
            last_flush = std::time::Instant::now();
            if let Err(e) = w.flush() {
                failed = Some(fail(&w, e));
            }
        }
    }
    w.finish(failed);
}

fn fail(w: &Writer, e: RecordError) -> String {
    tracing::error!(error = %e, "recording stopped");
    let message = e.to_string();
    lock(&w.shared.status).error = Some(message.clone());
    message
}
