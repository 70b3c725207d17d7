//! `mech-gcs`: the MECH ground-control station library.
//!
//! Layers, bottom up, none of which depends on a terminal:
//! - [`router`]: the UDP/TCP router with live controller switching;
//! - [`fleet`]: the fleet model derived from router events;
//! - [`lang`]: the command language shared by the TUI command line and
//!   `--script`;
//! - [`script`]: the headless script runner (one JSON line per event);
//! - [`control`]: fleet (cluster, follow-the-leader) and offboard
//!   controllers publishing through the router;
//! - [`config`], [`logging`];
//! - [`gamepad`]: gamepads and keyboard teleop turned into channel commands;
//! - [`ui`]: the terminal user interface over all of the above.
//!
//! [`Gcs`] ties them together: start one, then read the fleet with
//! [`Gcs::snapshot`] / [`Gcs::with_fleet`], act through [`Gcs::router`], and
//! run command-language lines with [`lang::Executor`].

#![cfg_attr(test, allow(clippy::unwrap_used, clippy::field_reassign_with_default))]

pub mod config;
pub mod control;
pub mod fleet;
pub mod gamepad;
pub mod lang;
pub mod logging;
pub mod router;
pub mod script;
pub mod ui;

use std::sync::{Arc, Mutex};

pub use config::GcsConfig;
pub use fleet::Fleet;
pub use router::{Router, RouterError, RouterHandle};

/// A running ground station: the router and the fleet model it feeds.
/// Cloning is cheap; every clone sees the same fleet.
#[derive(Debug, Clone)]
pub struct Gcs {
    router: RouterHandle,
    fleet: Arc<Mutex<Fleet>>,
    config: Arc<GcsConfig>,
    running: Arc<Mutex<Option<Router>>>,
}

impl Gcs {
    /// Binds the router's endpoints and starts routing.
    pub async fn start(config: GcsConfig) -> Result<Gcs, RouterError> {
        let fleet = Arc::new(Mutex::new(Fleet::new(config.fleet.clone())));
        let router = Router::start(config.router.clone(), fleet.clone()).await?;
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

    pub fn config(&self) -> &GcsConfig {
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

    /// Stops the router. Other clones then see a stopped router.
    pub async fn shutdown(&self) {
        let router = lock(&self.running).take();
        if let Some(r) = router {
            r.shutdown().await;
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}
