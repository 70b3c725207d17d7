//! What a verb runs against: the station, its controllers, the publishers
//! the language sends through and the simulator, with the name lookups
//! every verb needs.

use std::net::SocketAddr;
use std::sync::Arc;

use futures::future::BoxFuture;

use super::LangError;
use super::args::Target;
use crate::hub::ControlHub;
use mech_core::Gcs;
use mech_core::router::{Publishers, RouterHandle};

/// Sender name of everything the command language publishes.
pub const SENDER: &str = "gcs";

/// Starts and stops simulated agents for `spawn` and `--demo`. The GCS core
/// does not depend on the simulator; the binary plugs one in.
pub trait SimSpawner: Send + std::fmt::Debug {
    /// Starts `count` simulated agents registering with `router` at
    /// `addr` (when the router authenticates, the spawner gives it a key
    /// for each agent); returns their names.
    fn spawn(
        &mut self,
        count: usize,
        addr: SocketAddr,
        router: RouterHandle,
    ) -> BoxFuture<'_, Result<Vec<String>, String>>;
    /// Stops every agent this spawner started.
    fn shutdown(&mut self) -> BoxFuture<'_, ()>;
}

/// Asks another station to route one of its robots. A bridge between
/// stations plugs one in; without it, other stations' robots are shown but
/// cannot be routed from here.
pub trait RemoteRoutes: Send + Sync + std::fmt::Debug {
    /// Asks `station` to route its `robot` to `channel` (`None`: to none).
    /// That station decides (whether this station's operator may); the
    /// answer says what it did, or why not.
    fn request_route(
        &self,
        station: &str,
        robot: &str,
        channel: Option<&str>,
    ) -> BoxFuture<'_, Result<String, String>>;
}

/// One simulator shared by every executor of a station: `spawn` from any
/// operator's session starts agents in it, and only the station stops them
/// ([`SharedSpawner::shutdown_all`]); an executor's own shutdown (an
/// operator detaching) leaves them running.
#[derive(Debug, Clone)]
pub struct SharedSpawner(Arc<tokio::sync::Mutex<Box<dyn SimSpawner>>>);

impl SharedSpawner {
    pub fn new(spawner: Box<dyn SimSpawner>) -> SharedSpawner {
        SharedSpawner(Arc::new(tokio::sync::Mutex::new(spawner)))
    }

    /// Stops every agent any session spawned.
    pub async fn shutdown_all(&self) {
        self.0.lock().await.shutdown().await;
    }
}

impl SimSpawner for SharedSpawner {
    fn spawn(
        &mut self,
        count: usize,
        addr: SocketAddr,
        router: RouterHandle,
    ) -> BoxFuture<'_, Result<Vec<String>, String>> {
        let inner = self.0.clone();
        Box::pin(async move { inner.lock().await.spawn(count, addr, router).await })
    }

    fn shutdown(&mut self) -> BoxFuture<'_, ()> {
        Box::pin(async {})
    }
}

/// The state behind an [`Executor`](super::Executor), handed to each verb's
/// `apply`.
#[derive(Debug)]
pub(super) struct Context {
    pub(super) gcs: Gcs,
    pub(super) spawner: Option<Box<dyn SimSpawner>>,
    /// Who the commands are from: the sender name of everything this
    /// context publishes ([`SENDER`] unless an operator's session says).
    pub(super) sender: String,
    /// One publisher per channel under `sender`, so a channel's sequence
    /// numbers run on from one command to the next.
    pub(super) publishers: Publishers,
    /// Fleet and offboard controllers started by this executor's commands.
    pub(super) control: ControlHub,
    /// Route requests to other stations, when a bridge is plugged in.
    pub(super) remote_routes: Option<Arc<dyn RemoteRoutes>>,
    /// Where `record start` without a file records (rotating files), and
    /// where an operator's `record start FILE` must stay.
    pub(super) record_dir: Option<std::path::PathBuf>,
    /// Where `mission save`, `mission load`, `arena load` and `record
    /// start FILE` may read and write.
    pub(super) files: crate::files::FileAccess,
}

impl Context {
    pub(super) fn new(gcs: Gcs) -> Context {
        Context {
            control: ControlHub::new(gcs.clone()),
            publishers: gcs.router().publishers(SENDER),
            sender: SENDER.to_string(),
            gcs,
            spawner: None,
            remote_routes: None,
            record_dir: None,
            files: crate::files::FileAccess::Station,
        }
    }

    /// Robots named by `target` that this station drives; an error at the
    /// target if it names nothing, or names another station's robot (shown
    /// here read-only).
    pub(super) fn resolve(&self, target: &Target) -> Result<Vec<String>, LangError> {
        let robots = self.resolve_shown(target)?;
        let remote = self.gcs.with_fleet(|f| {
            robots
                .iter()
                .find_map(|r| Some((r.clone(), f.robot(r)?.remote.clone()?)))
        });
        match remote {
            None => Ok(robots),
            Some((robot, station)) => Err(LangError::new(
                target.span,
                format!(
                    "{robot} is a robot of station {station}, shown here read-only \
                     (only `route` reaches it, as a request to {station})"
                ),
            )),
        }
    }

    /// Every robot named by `target`, other stations' included; an error at
    /// the target if it names nothing.
    pub(super) fn resolve_shown(&self, target: &Target) -> Result<Vec<String>, LangError> {
        self.gcs
            .with_fleet(|f| f.resolve(&target.name))
            .ok_or_else(|| {
                LangError::new(
                    target.span,
                    format!("no robot or cluster named {:?}", target.name),
                )
            })
    }
}
