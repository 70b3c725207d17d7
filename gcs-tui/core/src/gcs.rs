//! The running station: the router, the fleet model it feeds, and the
//! neighbour broadcaster beside them (fleet safety), started together and
//! shared by everything above them (command language, controllers, TUI,
//! scripts).

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use mech_proto::{Mission, Waypoint};
use serde::Deserialize;

use crate::arena::ArenaConfig;
use crate::auth::{AuthConfig, AuthMode, DEFAULT_WINDOW, Keyring};
use crate::config::ConfigError;
use crate::fleet::{Fleet, FleetConfig};
use crate::neighbours::NeighbourConfig;
use crate::neighbours::broadcast::Broadcaster;
use crate::record::{RecordConfig, RecordError, RecordTarget, Recorder, RecordingStatus};
use crate::router::{Router, RouterConfig, RouterError, RouterHandle};
use crate::sync::lock;

/// The core's sections of the configuration: `[router]`, `[fleet]`,
/// `[auth]`, `[record]`, `[arena]` and `[neighbours]`.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CoreConfig {
    pub router: RouterConfig,
    pub fleet: FleetConfig,
    pub auth: AuthConfig,
    pub record: RecordConfig,
    /// The arena robots are kept inside (fleet safety); none by default.
    /// A file it names (`file = ...`) is read before the station starts
    /// ([`ArenaConfig::resolve`]).
    pub arena: Option<ArenaConfig>,
    /// How robots are told about their neighbours while there is an arena.
    pub neighbours: NeighbourConfig,
}

impl CoreConfig {
    /// Checks every section. Whether a router listening beyond loopback has
    /// keys is checked when it starts ([`CoreConfig::auth_mode`]), after
    /// command-line overrides of its endpoints.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.router.validate()?;
        self.fleet.validate()?;
        self.record.validate()?;
        self.neighbours.validate()?;
        if let Some(arena) = &self.arena {
            arena
                .validate()
                .map_err(|m| ConfigError(format!("{}: {}", m.path, m.message)))?;
        }
        self.auth.validate()
    }

    /// Whether the station will authenticate, given where it listens.
    pub fn auth_mode(&self) -> Result<AuthMode, ConfigError> {
        let mut endpoints = vec![self.router.udp];
        endpoints.extend(self.router.tcp);
        self.auth.resolve(&endpoints)
    }

    /// What would keep the station from starting that the sections alone
    /// do not show: a router listening beyond loopback without keys, and
    /// every key file that does not load (`mech-gcs --check`). Empty when
    /// it would start.
    pub fn start_problems(&self) -> Vec<ConfigError> {
        match self.auth_mode() {
            Err(e) => vec![e],
            Ok(AuthMode::Off) => Vec::new(),
            Ok(AuthMode::Required) => self.auth.key_problems(),
        }
    }

    /// The keyring the router starts with (reading the key files), or
    /// `None` when unauthenticated.
    pub fn keyring(&self) -> Result<Option<Keyring>, ConfigError> {
        match self.auth_mode()? {
            AuthMode::Off => Ok(None),
            AuthMode::Required => Ok(Some(Keyring::new(
                self.auth.load_keys()?,
                self.auth.window.unwrap_or(DEFAULT_WINDOW),
                mech_proto::unix_micros(),
            ))),
        }
    }
}

/// A running ground station: the router, the fleet model it feeds and the
/// neighbour broadcaster. Cloning is cheap; every clone sees the same
/// fleet.
#[derive(Debug, Clone)]
pub struct Gcs {
    router: RouterHandle,
    fleet: Arc<Mutex<Fleet>>,
    config: Arc<CoreConfig>,
    running: Arc<Mutex<Option<Router>>>,
    recorder: Arc<Mutex<Option<Recorder>>>,
    broadcaster: Arc<Broadcaster>,
}

impl Gcs {
    /// Binds the router's endpoints, starts routing with the configured
    /// arena (if any), and starts the neighbour broadcaster (which sends
    /// while there is an arena).
    pub async fn start(config: CoreConfig) -> Result<Gcs, RouterError> {
        let fleet = Arc::new(Mutex::new(Fleet::new(config.fleet.clone())));
        let keyring = config.keyring()?;
        let router = Router::start(config.router.clone(), keyring, fleet.clone()).await?;
        let handle = router.handle();
        if let Some(arena) = &config.arena {
            // A file not read yet is taken from the working directory.
            match arena.resolve(Path::new(".")) {
                Ok(arena) => handle.set_arena(Some(arena.shape())).await,
                Err(e) => {
                    router.shutdown().await;
                    return Err(e.into());
                }
            }
        }
        let broadcaster = Broadcaster::start(handle.clone(), fleet.clone(), config.neighbours);
        Ok(Gcs {
            router: handle,
            fleet,
            config: Arc::new(config),
            running: Arc::new(Mutex::new(Some(router))),
            recorder: Arc::new(Mutex::new(None)),
            broadcaster: Arc::new(broadcaster),
        })
    }

    /// The router: publish, route, send missions, e-stop, subscribe.
    pub fn router(&self) -> &RouterHandle {
        &self.router
    }

    /// The router and fleet-model settings it started with.
    pub fn config(&self) -> &CoreConfig {
        &self.config
    }

    /// A copy of the fleet model with current channels and counters.
    pub fn snapshot(&self) -> Fleet {
        let channels = self.router.channels();
        let counters = self.router.counters();
        let mut fleet = self.with_fleet(Fleet::clone);
        for (name, robot) in fleet.robots.iter_mut() {
            if let Some(t) = counters.robots.get(name) {
                robot.traffic = *t;
            }
        }
        fleet.channels = channels;
        fleet.counters = counters;
        fleet
    }

    /// Reads the fleet model in place (no copy); keep `f` short, the router
    /// waits for it to apply events.
    ///
    /// Lock order: the router applies events to the fleet model holding its
    /// delivery lock (delivery, then fleet), never its tables. So reading
    /// the router from inside `f` (`channels()`, `counters()`) is safe, but
    /// never make it act (`set_route`, publishing, e-stop: anything that
    /// makes events waits for the delivery lock). [`Gcs::snapshot`] reads
    /// the router first anyway, so the fleet is held for the copy alone.
    /// The same holds for [`Gcs::update_fleet`].
    pub fn with_fleet<R>(&self, f: impl FnOnce(&Fleet) -> R) -> R {
        f(&lock(&self.fleet))
    }

    /// Changes GCS-side state of the fleet model (clusters, waypoint drafts,
    /// log lines). Same lock order as [`Gcs::with_fleet`]: nothing that makes
    /// the router act inside `f`.
    pub fn update_fleet<R>(&self, f: impl FnOnce(&mut Fleet) -> R) -> R {
        f(&mut lock(&self.fleet))
    }

    /// Sends `waypoints` to `robot` as a mission on `channel` from
    /// `sender`, with the station's arrival radius (`fleet.arrival_radius`)
    /// and a fresh id, repeated until the robot acknowledges it. Returns the
    /// mission id.
    pub async fn send_waypoints(
        &self,
        sender: &str,
        robot: &str,
        channel: &str,
        waypoints: Vec<Waypoint>,
        looped: bool,
    ) -> Result<u32, RouterError> {
        let mission = Mission {
            id: 0,
            waypoints,
            looped,
            arrival_radius: self.config.fleet.arrival_radius,
            start_index: 0,
        };
        self.router
            .send_mission(sender, robot, channel, mission)
            .await
    }

    /// Starts recording everything the router sees to `target` (see
    /// [`crate::record`]); returns the first file. One recording at a time.
    pub fn start_recording(&self, target: RecordTarget) -> Result<PathBuf, RecordError> {
        let mut slot = lock(&self.recorder);
        if let Some(r) = slot.as_ref().filter(|r| r.status().active) {
            return Err(RecordError::AlreadyRecording(r.status().file));
        }
        let recorder = Recorder::start(
            target,
            &self.config.record,
            self.fleet.clone(),
            &self.router,
        )?;
        recorder.attach(&self.router, &self.fleet);
        let file = recorder.status().file;
        *slot = Some(recorder);
        Ok(file)
    }

    /// Starts recording into the configured `[record]` directory (or
    /// `log_dir`), in rotating files capped by `max_file_mb` and `keep`:
    /// what `serve` records by default.
    pub fn start_default_recording(&self, log_dir: &Path) -> Result<PathBuf, RecordError> {
        self.start_recording(self.config.record.rotating(log_dir))
    }

    /// Stops recording: what is queued is written and the file finished.
    /// Returns how it went, or `None` if nothing was recording.
    pub async fn stop_recording(&self) -> Option<RecordingStatus> {
        let recorder = lock(&self.recorder).take()?;
        let router = self.router.clone();
        let finished = tokio::task::spawn_blocking(move || recorder.finish(&router)).await;
        finished.ok()
    }

    /// How the recording is going, if there is one.
    pub fn recording(&self) -> Option<RecordingStatus> {
        lock(&self.recorder).as_ref().map(Recorder::status)
    }

    /// Stops the neighbour broadcaster and the router, then finishes the
    /// recording (so it holds everything the router did). Other clones
    /// then see a stopped router.
    pub async fn shutdown(&self) {
        self.broadcaster.stop();
        let router = lock(&self.running).take();
        if let Some(r) = router {
            r.shutdown().await;
        }
        self.stop_recording().await;
    }
}
