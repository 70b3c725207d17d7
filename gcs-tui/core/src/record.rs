//! Recording to MCAP, the format Foxglove and Lichtblick open and
//! [`crate::replay`] reads: every message the router decides (as received,
//! with what was done with it and why), every station event, every operator
//! command, time-stamped, plus views Foxglove draws without plugins (a pose
//! per robot, the fleet as a 3D scene, the event log). `docs/recording.md`
//! lists the topics and schemas.
//!
//! The router offers each record to a bounded queue without waiting (its
//! tap); a [`Recorder`] owns the thread that encodes and writes them, so
//! recording never slows routing: a full queue drops records and counts
//! them ([`RecordingStatus::dropped`]).
//!
//! Modules: [`schema`] (topics and JSON Schemas), [`encode`] (message
//! JSON), [`scene`] (the fleet as a scene), `snapshot` (the fleet model as
//! events, at the start of each file), `rotate` (file names and pruning),
//! `file` (one MCAP file), `writer` (the thread). `schema`, `encode` and
//! `scene` are public so a live view (`mech-gcs --foxglove`) sends the same
//! messages as recordings hold.

pub mod encode;
mod file;
mod rotate;
pub mod scene;
pub mod schema;
mod snapshot;
mod writer;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{SyncSender, sync_channel};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde::Deserialize;

pub use crate::router::OperatorRecord;
pub use file::{METADATA, METADATA_END, PROFILE};

use crate::config::ConfigError;
use crate::fleet::Fleet;
use crate::router::{RouterHandle, Tap, TapCounts, Tapped};
use crate::sync::lock;

/// The `[record]` section: where and how `serve` (and `record start`
/// without a file) record, in files that rotate.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RecordConfig {
    /// Directory of rotating recordings; `None`: the log directory.
    pub dir: Option<PathBuf>,
    /// A file is finished and the next begun at this size, MiB.
    pub max_file_mb: u64,
    /// Rotating recordings kept in the directory; the oldest are deleted,
    /// so recordings take at most about `keep * max_file_mb`.
    pub keep: usize,
    /// Records queued for the writer thread. When it falls this far
    /// behind, new records are dropped and counted, never waited for.
    pub queue: usize,
    /// Most fleet scenes (`/mech/scene`) per second of router time; fewer
    /// for a big fleet (one per half millisecond per robot).
    pub scene_hz: f64,
    /// zstd-compress the file's chunks (about 5-10x smaller).
    pub compress: bool,
}

impl Default for RecordConfig {
    fn default() -> Self {
        RecordConfig {
            dir: None,
            max_file_mb: 256,
            keep: 8,
            queue: 1 << 16,
            scene_hz: 10.0,
            compress: true,
        }
    }
}

impl RecordConfig {
    /// Rejects settings a recorder cannot run with.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.max_file_mb == 0 {
            return Err(ConfigError::new("record.max_file_mb must be at least 1"));
        }
        if self.keep == 0 {
            return Err(ConfigError::new("record.keep must be at least 1"));
        }
        if self.queue == 0 {
            return Err(ConfigError::new("record.queue must be at least 1"));
        }
        if !(self.scene_hz > 0.0 && self.scene_hz <= 100.0) {
            return Err(ConfigError::new(
                "record.scene_hz must be above 0 and at most 100",
            ));
        }
        Ok(())
    }

    /// Rotating files in `dir`, or in `log_dir` when none is configured.
    pub fn rotating(&self, log_dir: &Path) -> RecordTarget {
        RecordTarget::Rotating {
            dir: self.dir.clone().unwrap_or_else(|| log_dir.to_owned()),
            max_file_bytes: self.max_file_mb.saturating_mul(1 << 20),
            keep: self.keep,
        }
    }
}

/// Where a recording goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RecordTarget {
    /// One file, written until recording stops (no size cap); an
    /// existing file of that name is replaced.
    File(PathBuf),
    /// Like [`RecordTarget::File`], but the file must not exist yet: it is
    /// created exclusively (an existing file, or a symbolic link, in its
    /// place is refused, never followed or truncated). What an operator's
    /// `record start FILE` asks for unless it says `overwrite`.
    NewFile(PathBuf),
    /// Files `mech-YYYYMMDD-HHMMSS.mcap` in `dir`: the next is begun when
    /// one reaches `max_file_bytes`, and only the newest `keep` are kept.
    Rotating {
        dir: PathBuf,
        max_file_bytes: u64,
        keep: usize,
    },
}

/// How a recording is going (or went).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RecordingStatus {
    /// The file being written (the last one, once stopped).
    pub file: PathBuf,
    /// Every file begun, oldest first (one unless rotating).
    pub files: Vec<PathBuf>,
    /// Size of the current file at its last flush (each second).
    pub bytes: u64,
    /// Router messages written (each on `/mech/raw`).
    pub messages: u64,
    /// Station events written (telemetry included).
    pub events: u64,
    /// MCAP messages written, on every topic.
    pub written: u64,
    /// Records the router's tap queued.
    pub queued: u64,
    /// Records lost: the queue was full (the writer fell behind), or
    /// writing had failed.
    pub dropped: u64,
    /// Refused messages (unreadable, rejected, shed) past the 100 a second
    /// recorded whole: the recording holds them only in the `refused`
    /// events' counts.
    pub refused_unrecorded: u64,
    /// Why writing stopped, if it failed.
    pub error: Option<String>,
    /// Still recording.
    pub active: bool,
}

/// Why a recording could not start or went wrong.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("cannot create the recording {path}: {source}")]
    Create {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot write the recording {path}: {message}")]
    Write { path: PathBuf, message: String },
    #[error("already recording to {0}")]
    AlreadyRecording(PathBuf),
    #[error("cannot start the recorder thread: {0}")]
    Thread(std::io::Error),
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// When `router` started, in nanoseconds since the Unix epoch: a message's
/// time is this plus its router time ([`unix_ns`]).
pub fn router_start_unix_ns(router: &RouterHandle) -> u64 {
    let elapsed = u64::try_from(router.elapsed().as_nanos()).unwrap_or(0);
    (mech_proto::unix_micros() * 1000).saturating_sub(elapsed)
}

/// Router time `at` in nanoseconds since the Unix epoch, given when the
/// router started ([`router_start_unix_ns`]).
pub fn unix_ns(router_start_ns: u64, at: Duration) -> u64 {
    router_start_ns.saturating_add(u64::try_from(at.as_nanos()).unwrap_or(u64::MAX))
}

/// A recording in progress: the writer thread and what the tap needs.
/// Made by [`crate::Gcs::start_recording`].
#[derive(Debug)]
pub struct Recorder {
    tx: Option<SyncSender<Tapped>>,
    thread: Option<std::thread::JoinHandle<()>>,
    shared: Arc<writer::Shared>,
}

impl Recorder {
    /// Opens the first file and starts the writer thread. Nothing is
    /// recorded until [`Recorder::attach`].
    pub fn start(
        target: RecordTarget,
        config: &RecordConfig,
        fleet: Arc<Mutex<Fleet>>,
        router: &RouterHandle,
    ) -> Result<Recorder, RecordError> {
        config.validate()?;
        let shared = Arc::new(writer::Shared {
            status: Mutex::new(RecordingStatus {
                active: true,
                ..RecordingStatus::default()
            }),
            taps: TapCounts::default(),
            messages: AtomicU64::new(0),
            events: AtomicU64::new(0),
            written: AtomicU64::new(0),
        });
        let router_start_ns = router_start_unix_ns(router);
        let writer = writer::Writer::new(writer::WriterSetup {
            target,
            compress: config.compress,
            scene_hz: config.scene_hz,
            live: fleet,
            router_start_ns,
            shared: shared.clone(),
        })?;
        lock(&shared.status).file = writer.path();
        let (tx, rx) = sync_channel(config.queue);
        let thread = std::thread::Builder::new()
            .name("mech-record".into())
            .spawn(move || writer::run(writer, rx))
            .map_err(RecordError::Thread)?;
        Ok(Recorder {
            tx: Some(tx),
            thread: Some(thread),
            shared,
        })
    }

    /// Puts the tap on `router`, beginning with the fleet model `fleet` as
    /// it stands with every event the router made so far applied (read
    /// while the router delivers no event, so nothing falls between it and
    /// the first record).
    pub(crate) fn attach(&self, router: &RouterHandle, fleet: &Mutex<Fleet>) {
        let Some(tx) = &self.tx else { return };
        let tap = Tap::new(tx.clone(), router.started(), &self.shared.taps);
        drop(router.put_tap(tap, || lock(fleet).clone()));
    }

    /// How the recording is going.
    pub fn status(&self) -> RecordingStatus {
        let mut s = lock(&self.shared.status).clone();
        let count = |c: &AtomicU64| c.load(Ordering::Relaxed);
        s.dropped = count(&self.shared.taps.dropped);
        s.queued = count(&self.shared.taps.queued);
        s.refused_unrecorded = count(&self.shared.taps.unrecorded);
        s.messages = count(&self.shared.messages);
        s.events = count(&self.shared.events);
        s.written = count(&self.shared.written);
        s
    }

    /// Stops: takes the tap off `router`, lets the thread write what is
    /// queued and finish the file, and waits for it (blocking: call from a
    /// blocking context). Returns the final status.
    pub fn finish(mut self, router: &RouterHandle) -> RecordingStatus {
        drop(router.take_tap());
        if let Some(tx) = self.tx.take() {
            // Waits for room: the thread is draining the queue.
            let _ = tx.send(Tapped::End {
                received: router.counters().received,
            });
        }
        if let Some(t) = self.thread.take() {
            if t.join().is_err() {
                lock(&self.shared.status).error = Some("the recorder thread panicked".into());
            }
        }
        let mut s = self.status();
        s.active = false;
        s
    }
}
