//! The running station: the router and the fleet model it feeds, started
//! together and shared by everything above them (command language,
//! controllers, TUI, scripts).

use std::sync::{Arc, Mutex};

use mech_proto::{Mission, Waypoint};
use serde::Deserialize;

use crate::auth::{AuthConfig, AuthMode, DEFAULT_WINDOW, Keyring};
use crate::config::ConfigError;
use crate::fleet::{Fleet, FleetConfig};
use crate::router::{Router, RouterConfig, RouterError, RouterHandle};
use crate::sync::lock;

/// The core's sections of the configuration: `[router]`, `[fleet]` and
/// `[auth]`.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CoreConfig {
    pub router: RouterConfig,
    pub fleet: FleetConfig,
    pub auth: AuthConfig,
}

impl CoreConfig {
    /// Checks every section. Whether a router listening beyond loopback has
    /// keys is checked when it starts ([`CoreConfig::auth_mode`]), after
    /// command-line overrides of its endpoints.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.router.validate()?;
        self.fleet.validate()?;
        self.auth.validate()
    }

    /// Whether the station will authenticate, given where it listens.
    pub fn auth_mode(&self) -> Result<AuthMode, ConfigError> {
        let mut endpoints = vec![self.router.udp];
        endpoints.extend(self.router.tcp);
        self.auth.resolve(&endpoints)
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

/// A running ground station: the router and the fleet model it feeds.
/// Cloning is cheap; every clone sees the same fleet.
#[derive(Debug, Clone)]
pub struct Gcs {
    router: RouterHandle,
    fleet: Arc<Mutex<Fleet>>,
    config: Arc<CoreConfig>,
    running: Arc<Mutex<Option<Router>>>,
}

impl Gcs {
    /// Binds the router's endpoints and starts routing.
    pub async fn start(config: CoreConfig) -> Result<Gcs, RouterError> {
        let fleet = Arc::new(Mutex::new(Fleet::new(config.fleet.clone())));
        let keyring = config.keyring()?;
        let router = Router::start(config.router.clone(), keyring, fleet.clone()).await?;
        Ok(Gcs {
            router: router.handle(),
            fleet,
            config: Arc::new(config),
            running: Arc::new(Mutex::new(Some(router))),
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
    /// Lock order: the router holds its tables while it applies events to
    /// the fleet model (tables, then fleet). So never ask the router for
    /// anything that locks its tables (`channels()`, `counters()`,
    /// `set_route`, publishing) from inside `f`: read those first, then take
    /// the fleet, as [`Gcs::snapshot`] does. The same holds for
    /// [`Gcs::update_fleet`].
    pub fn with_fleet<R>(&self, f: impl FnOnce(&Fleet) -> R) -> R {
        f(&lock(&self.fleet))
    }

    /// Changes GCS-side state of the fleet model (clusters, waypoint drafts,
    /// log lines). Same lock order as [`Gcs::with_fleet`]: nothing that locks
    /// the router's tables inside `f`.
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

    /// Stops the router. Other clones then see a stopped router.
    pub async fn shutdown(&self) {
        let router = lock(&self.running).take();
        if let Some(r) = router {
            r.shutdown().await;
        }
    }
}
