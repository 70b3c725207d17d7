//! [`Station`]: the running station clients attach to. It owns what
//! outlives any one client: the core ([`Gcs`]), the controllers
//! ([`ControlHub`]) and simulator every session shares, the snapshot and
//! log feed, the listeners and the sessions.

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mech_control::lang::{RemoteRoutes, SharedSpawner, SimSpawner};
use mech_control::{ClusterSpec, ControlHub};
use mech_core::Gcs;
use mech_core::fleet::Severity;
use mech_core::sync::lock;
use tokio::sync::watch;
use tokio::task::JoinSet;

use super::StationConfig;
use super::feed::Feed;
use crate::view::ArenaBounds;

/// How long a stopping station waits for its sessions to say goodbye.
const CLOSE_WAIT: Duration = Duration::from_secs(2);

/// Sessions at once; more are refused (a runaway client cannot exhaust
/// the station).
pub(super) const MAX_SESSIONS: usize = 64;

/// How a client reached the station.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Via {
    /// The TUI of an embedded station, in the same process.
    Local,
    /// The local control socket, by this Unix user.
    Unix { user: String },
    /// TCP from this address (an operator key is required).
    Tcp { peer: SocketAddr },
}

impl std::fmt::Display for Via {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Via::Local => write!(f, "in process"),
            Via::Unix { user } => write!(f, "local socket, user {user}"),
            Via::Tcp { peer } => write!(f, "TCP from {peer}"),
        }
    }
}

/// A running station. Cloning is cheap; every clone is the same station.
#[derive(Debug, Clone)]
pub struct Station {
    pub(super) inner: Arc<Inner>,
}

#[derive(Debug)]
pub(super) struct Inner {
    pub gcs: Gcs,
    pub control: ControlHub,
    pub spawner: Option<SharedSpawner>,
    pub feed: Feed,
    pub arena: Mutex<Option<ArenaBounds>>,
    /// Where `record start` without a file records.
    pub record_dir: Mutex<Option<std::path::PathBuf>>,
    /// Route requests to other stations, when a bridge runs beside.
    pub remote_routes: Mutex<Option<Arc<dyn RemoteRoutes>>>,
    /// Set when the station stops: sessions say Bye and end.
    pub closing: watch::Sender<bool>,
    pub sessions: Mutex<JoinSet<()>>,
    listeners: Mutex<Vec<tokio::task::JoinHandle<()>>>,
}

impl Station {
    /// A station over a started core: the clusters of the configuration
    /// defined, `spawner` (if any) behind `spawn` for every session.
    pub fn start(
        gcs: Gcs,
        clusters: &[ClusterSpec],
        spawner: Option<Box<dyn SimSpawner>>,
        config: &StationConfig,
    ) -> Station {
        let control = ControlHub::new(gcs.clone());
        if let Err(e) = control.apply_config(clusters) {
            gcs.update_fleet(|f| f.log(Severity::Error, e.to_string()));
        }
        let feed = Feed::start(gcs.clone(), control.clone(), config.snapshot_rate);
        Station {
            inner: Arc::new(Inner {
                gcs,
                control,
                spawner: spawner.map(SharedSpawner::new),
                feed,
                arena: Mutex::new(None),
                record_dir: Mutex::new(None),
                remote_routes: Mutex::new(None),
                closing: watch::channel(false).0,
                sessions: Mutex::new(JoinSet::new()),
                listeners: Mutex::new(Vec::new()),
            }),
        }
    }

    /// The arena outline clients are told about (the demo's).
    pub fn set_arena(&self, arena: Option<ArenaBounds>) {
        *lock(&self.inner.arena) = arena;
    }

    /// Where `record start` without a file name records.
    pub fn set_record_dir(&self, dir: Option<std::path::PathBuf>) {
        *lock(&self.inner.record_dir) = dir;
    }

    /// Lets every session's `route robot@station` ask that station,
    /// through a bridge to other stations (`mech-zenoh`).
    pub fn set_remote_routes(&self, routes: Arc<dyn RemoteRoutes>) {
        *lock(&self.inner.remote_routes) = Some(routes);
    }

    pub fn gcs(&self) -> &Gcs {
        &self.inner.gcs
    }

    /// The controllers every session shares.
    pub fn control(&self) -> &ControlHub {
        &self.inner.control
    }

    /// Starts a task serving a listener; it stops with the station.
    pub(super) fn add_listener(&self, task: tokio::task::JoinHandle<()>) {
        lock(&self.inner.listeners).push(task);
    }

    /// Writes a line to the station's event log (every client sees it).
    pub(super) fn log(&self, severity: Severity, text: String) {
        self.inner.gcs.update_fleet(|f| f.log(severity, text));
    }

    /// Stops listening, tells every client Bye, stops the simulated agents
    /// and the core (whose router tells every robot Bye).
    pub async fn shutdown(&self) {
        for l in lock(&self.inner.listeners).drain(..) {
            l.abort();
        }
        self.inner.closing.send_replace(true);
        let mut sessions = std::mem::take(&mut *lock(&self.inner.sessions));
        let all_closed = async { while sessions.join_next().await.is_some() {} };
        if tokio::time::timeout(CLOSE_WAIT, all_closed).await.is_err() {
            tracing::warn!("sessions did not close in time");
        }
        self.inner.feed.stop();
        if let Some(s) = &self.inner.spawner {
            s.shutdown_all().await;
        }
        self.inner.gcs.shutdown().await;
    }
}
