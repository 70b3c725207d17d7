//! Reading a recording back ([`crate::record`] wrote it): the station
//! events in the order they happened, operator commands, and the fleet
//! model at any instant, without a router or a socket.
//!
//! [`Replay::open`] reads the whole file and checks it: every chunk is
//! decompressed and every message decoded once, and the fleet model is
//! kept at checkpoints (about 64 over the recording) so that
//! [`Replay::fleet_at`] and [`Cursor::seek`] start from the nearest one. A
//! truncated or corrupt file is not an error as long as something before
//! the damage can be read: [`Replay::damage`] says what is wrong, and
//! everything before it replays. A file that is not a MECH recording at all
//! is an error.
//!
//! For a player: [`Replay::cursor`] gives a [`Cursor`] that moves forward
//! through the recording applying what happened to its fleet model
//! ([`Cursor::advance_to`]), and jumps anywhere ([`Cursor::seek`]).

mod read;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::event::Stamped;
use crate::fleet::{Fleet, FleetConfig};
use crate::router::OperatorRecord;
use read::Chunk;

/// One thing the recording holds, with its router time.
#[derive(Debug, Clone, PartialEq)]
pub enum Entry {
    /// A station event (telemetry included).
    Event(Stamped),
    /// The state at the start of a file, as an event: applied to the fleet
    /// model, but not something that happened at that time.
    Snapshot(Stamped),
    /// An operator command and its outcome.
    Operator(OperatorRecord),
    /// The station's clusters, by name, with their members.
    Clusters {
        at: Duration,
        clusters: BTreeMap<String, Vec<String>>,
    },
}

impl Entry {
    /// Router time of the entry.
    pub fn at(&self) -> Duration {
        match self {
            Entry::Event(s) | Entry::Snapshot(s) => s.at,
            Entry::Operator(o) => o.at,
            Entry::Clusters { at, .. } => *at,
        }
    }

    /// Applies the entry to a fleet model.
    pub fn apply(&self, fleet: &mut Fleet) {
        match self {
            Entry::Event(s) | Entry::Snapshot(s) => fleet.apply(s),
            Entry::Operator(_) => {}
            Entry::Clusters { clusters, .. } => {
                fleet.clusters.clear();
                for (name, members) in clusters {
                    fleet.set_cluster(name, members.clone());
                }
            }
        }
    }
}

/// Why a recording cannot be replayed at all.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error("cannot read {path}: {error}")]
    Read {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path} is not a MECH recording: {why}")]
    NotARecording { path: PathBuf, why: String },
}

/// The fleet model after every entry up to a router time.
#[derive(Debug, Clone)]
struct Checkpoint {
    /// Next chunk to read from.
    chunk: usize,
    /// Router time of the last entry applied.
    at: Duration,
    fleet: Fleet,
}

/// An opened recording. See the module docs.
#[derive(Debug)]
pub struct Replay {
    path: PathBuf,
    chunks: Vec<Chunk>,
    kinds: read::Channels,
    router_start_ns: u64,
    first: Duration,
    last: Duration,
    checkpoints: Vec<Checkpoint>,
    damage: Option<String>,
    counts: BTreeMap<String, u64>,
    end: Option<BTreeMap<String, String>>,
    fleet_config: FleetConfig,
}

/// Checkpoints kept over a recording (fewer for a short one).
const CHECKPOINTS: u32 = 64;

impl Replay {
    /// Opens and checks a recording, with the default fleet settings.
    pub fn open(path: &Path) -> Result<Replay, ReplayError> {
        Replay::open_with(path, FleetConfig::default())
    }

    /// Opens and checks a recording; its fleet models use `config` (trail
    /// length, event log size).
    pub fn open_with(path: &Path, config: FleetConfig) -> Result<Replay, ReplayError> {
        let bytes = std::fs::read(path).map_err(|error| ReplayError::Read {
            path: path.to_owned(),
            error,
        })?;
        let scanned = read::scan(&bytes).map_err(|why| ReplayError::NotARecording {
            path: path.to_owned(),
            why,
        })?;
        let mut replay = Replay {
            path: path.to_owned(),
            chunks: scanned.chunks,
            kinds: read::Channels::default(),
            router_start_ns: scanned.router_start_ns,
            first: Duration::ZERO,
            last: Duration::ZERO,
            checkpoints: Vec::new(),
            damage: scanned.damage,
            counts: BTreeMap::new(),
            end: scanned.end,
            fleet_config: config,
        };
        replay.index();
        Ok(replay)
    }

    /// Decodes every chunk once: channels, counts, times and checkpoints.
    /// The first chunk that cannot be read ends the recording there.
    fn index(&mut self) {
        let span = read::span(&self.chunks, self.router_start_ns);
        let every = (span / CHECKPOINTS).max(Duration::from_secs(1));
        let mut fleet = Fleet::new(self.fleet_config.clone());
        let mut last_checkpoint: Option<Duration> = None;
        let mut times: Option<(Duration, Duration)> = None;
        for i in 0..self.chunks.len() {
            let at = times.map_or(Duration::ZERO, |(_, last)| last);
            if last_checkpoint.is_none_or(|t| at >= t + every) {
                self.checkpoints.push(Checkpoint {
                    chunk: i,
                    at,
                    fleet: fleet.clone(),
                });
                last_checkpoint = Some(at);
            }
            let entries = match read::chunk(
                &self.chunks[i],
                &mut self.kinds,
                self.router_start_ns,
                &mut self.counts,
            ) {
                Ok(e) => e,
                Err(e) => {
                    self.damage.get_or_insert(format!(
                        "chunk {} of {}: {e}",
                        i + 1,
                        self.chunks.len()
                    ));
                    self.chunks.truncate(i);
                    break;
                }
            };
            for e in &entries {
                let t = e.at();
                times = Some(times.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
                e.apply(&mut fleet);
            }
        }
        (self.first, self.last) = times.unwrap_or_default();
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What is wrong with the file, if anything: everything before it is
    /// replayed, nothing after.
    pub fn damage(&self) -> Option<&str> {
        self.damage.as_deref()
    }

    /// Router time of the first entry.
    pub fn start(&self) -> Duration {
        self.first
    }

    /// Router time of the last entry.
    pub fn end(&self) -> Duration {
        self.last
    }

    /// How long the recording runs.
    pub fn duration(&self) -> Duration {
        self.last.saturating_sub(self.first)
    }

    /// Unix time of router time 0, nanoseconds.
    pub fn router_start_unix_ns(&self) -> u64 {
        self.router_start_ns
    }

    /// MCAP messages per topic, in the readable part.
    pub fn counts(&self) -> &BTreeMap<String, u64> {
        &self.counts
    }

    /// The closing metadata (`mech.end`): present when the recorder
    /// finished the file.
    pub fn end_metadata(&self) -> Option<&BTreeMap<String, String>> {
        self.end.as_ref()
    }

    /// Every entry, in recorded order.
    pub fn entries(&self) -> Entries<'_> {
        Entries {
            replay: self,
            chunk: 0,
            pending: Vec::new().into_iter(),
        }
    }

    /// The station events in recorded order (telemetry included; snapshot
    /// events and operator commands left out).
    pub fn events(&self) -> impl Iterator<Item = Stamped> + '_ {
        self.entries().filter_map(|e| match e {
            Entry::Event(s) => Some(s),
            _ => None,
        })
    }

    /// A cursor at the start of the recording.
    pub fn cursor(&self) -> Cursor<'_> {
        let mut c = Cursor {
            replay: self,
            entries: self.entries(),
            next: None,
            fleet: Fleet::new(self.fleet_config.clone()),
            at: Duration::ZERO,
        };
        c.seek(Duration::ZERO);
        c
    }

    /// The fleet model after everything up to router time `t`.
    pub fn fleet_at(&self, t: Duration) -> Fleet {
        let mut c = self.cursor();
        c.seek(t);
        c.fleet
    }
}

/// Every entry of a replay, chunk by chunk.
#[derive(Debug)]
pub struct Entries<'a> {
    replay: &'a Replay,
    chunk: usize,
    pending: std::vec::IntoIter<Entry>,
}

impl Iterator for Entries<'_> {
    type Item = Entry;

    fn next(&mut self) -> Option<Entry> {
        loop {
            if let Some(e) = self.pending.next() {
                return Some(e);
            }
            let chunk = self.replay.chunks.get(self.chunk)?;
            self.chunk += 1;
            // Every chunk kept was read once when the file was opened.
            let entries = read::entries(chunk, &self.replay.kinds, self.replay.router_start_ns);
            self.pending = entries.into_iter();
        }
    }
}

/// A position in a replay with the fleet model there: moves forward
/// entry by entry, or jumps (from the nearest checkpoint).
#[derive(Debug)]
pub struct Cursor<'a> {
    replay: &'a Replay,
    entries: Entries<'a>,
    /// The next entry, read but not applied.
    next: Option<Entry>,
    fleet: Fleet,
    at: Duration,
}

impl Cursor<'_> {
    /// The fleet model at the cursor.
    pub fn fleet(&self) -> &Fleet {
        &self.fleet
    }

    /// Router time of the cursor.
    pub fn at(&self) -> Duration {
        self.at
    }

    /// Whether every entry has been applied.
    pub fn finished(&mut self) -> bool {
        self.peek().is_none()
    }

    fn peek(&mut self) -> Option<&Entry> {
        if self.next.is_none() {
            self.next = self.entries.next();
        }
        self.next.as_ref()
    }

    /// Applies every entry up to router time `t` and returns them, in
    /// order (a player shows the events among them).
    pub fn advance_to(&mut self, t: Duration) -> Vec<Entry> {
        let mut applied = Vec::new();
        while self.peek().is_some_and(|e| e.at() <= t) {
            if let Some(e) = self.next.take() {
                e.apply(&mut self.fleet);
                applied.push(e);
            }
        }
        self.at = self.at.max(t);
        applied
    }

    /// Moves to router time `t` (backwards too), from the last checkpoint
    /// at or before it.
    pub fn seek(&mut self, t: Duration) {
        let replay = self.replay;
        let checkpoint = replay.checkpoints.iter().rev().find(|c| c.at <= t);
        match checkpoint {
            Some(c) => {
                self.fleet = c.fleet.clone();
                self.entries = Entries {
                    replay,
                    chunk: c.chunk,
                    pending: Vec::new().into_iter(),
                };
                self.at = c.at;
            }
            None => {
                self.fleet = Fleet::new(replay.fleet_config.clone());
                self.entries = replay.entries();
                self.at = Duration::ZERO;
            }
        }
        self.next = None;
        self.advance_to(t);
        self.at = t;
    }
}
