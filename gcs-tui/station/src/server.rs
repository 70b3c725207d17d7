//! [`Station`]: the running station clients attach to, and its
//! `[station]` section ([`StationConfig`]: where it listens, how often it
//! sends snapshots). It owns what outlives any one client: the core
//! ([`Gcs`]), the controllers ([`ControlHub`]) and simulator every session
//! shares, the snapshot and log feed, the listeners and the sessions.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mech_control::lang::{RemoteRoutes, SharedSpawner, SimSpawner};
use mech_control::{ClusterSpec, ControlHub};
use mech_core::Gcs;
use mech_core::fleet::Severity;
use mech_core::sync::lock;
use serde::Deserialize;
use tokio::sync::watch;
use tokio::task::JoinSet;

use crate::admission::Admission;
use crate::feed::Feed;
use crate::view::ArenaBounds;

/// How long a stopping station waits for its sessions to say goodbye.
const CLOSE_WAIT: Duration = Duration::from_secs(2);

/// `[station]`: where a served station listens for clients.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StationConfig {
    /// The local control socket (default [`default_socket`]).
    pub socket: Option<PathBuf>,
    /// Permission bits of the socket: owner and group by default (0o660);
    /// its directory, when the station creates it, gets the same read and
    /// search bits (0o750).
    pub socket_mode: u32,
    /// TCP endpoint for operators on other machines; each proves an
    /// operator key (`[auth]`). None by default.
    pub tcp: Option<SocketAddr>,
    /// Fleet snapshots per second sent to each TUI (a route change or
    /// other event is sent at once, between them).
    pub snapshot_rate: f64,
}

impl Default for StationConfig {
    fn default() -> Self {
        StationConfig {
            socket: None,
            socket_mode: 0o660,
            tcp: None,
            snapshot_rate: 20.0,
        }
    }
}

impl StationConfig {
    pub fn validate(&self) -> Result<(), mech_core::ConfigError> {
        let bad = |m: String| Err(mech_core::ConfigError(format!("[station] {m}")));
        if !(self.snapshot_rate.is_finite() && (1.0..=100.0).contains(&self.snapshot_rate)) {
            return bad(format!(
                "snapshot_rate = {} is not between 1 and 100 per second",
                self.snapshot_rate
            ));
        }
        if self.socket_mode & !0o777 != 0 || self.socket_mode & 0o600 != 0o600 {
            return bad(format!(
                "socket_mode = {:o} must give the owner read and write and have no bits beyond 0o777",
                self.socket_mode
            ));
        }
        if self.socket_mode & 0o007 != 0 {
            return bad(format!(
                "socket_mode = {:o} lets every user on the machine command the robots; give owner and group only (0o660)",
                self.socket_mode
            ));
        }
        Ok(())
    }

    /// The control socket's path.
    pub fn socket_path(&self) -> PathBuf {
        self.socket.clone().unwrap_or_else(default_socket)
    }
}

/// `$XDG_RUNTIME_DIR/mech/gcs.sock`, or `/tmp/mech-UID/gcs.sock` without a
/// runtime directory: private to the user by default.
pub fn default_socket() -> PathBuf {
    match std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        Some(d) => PathBuf::from(d).join("mech/gcs.sock"),
        None => PathBuf::from(format!("/tmp/mech-{}/gcs.sock", nix::unistd::getuid())),
    }
}

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
    pub(crate) inner: Arc<Inner>,
}

#[derive(Debug)]
pub(crate) struct Inner {
    pub gcs: Gcs,
    pub control: ControlHub,
    pub spawner: Option<SharedSpawner>,
    pub feed: Feed,
    /// The places for clients attaching and attached.
    pub admission: Arc<Admission>,
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
        let admission = Arc::new(Admission::default());
        let log = gcs.clone();
        let refusals = tokio::spawn(crate::admission::say_held(admission.clone(), move |n| {
            let text = format!("attach refused {n} more times (not logged one by one)");
            tracing::warn!("{text}");
            log.update_fleet(|f| f.log(Severity::Warn, text));
        }));
        Station {
            inner: Arc::new(Inner {
                gcs,
                control,
                spawner: spawner.map(SharedSpawner::new),
                feed,
                admission,
                arena: Mutex::new(None),
                record_dir: Mutex::new(None),
                remote_routes: Mutex::new(None),
                closing: watch::channel(false).0,
                sessions: Mutex::new(JoinSet::new()),
                listeners: Mutex::new(vec![refusals]),
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

    /// Starts a task serving a listener (or another task that lives as
    /// long as the station); it stops with the station.
    pub(crate) fn add_listener(&self, task: tokio::task::JoinHandle<()>) {
        lock(&self.inner.listeners).push(task);
    }

    /// Writes a line to the station's event log (every client sees it).
    pub(crate) fn log(&self, severity: Severity, text: String) {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_socket_open_to_everyone_is_refused() {
        let mut c = StationConfig::default();
        assert!(c.validate().is_ok());
        c.socket_mode = 0o666;
        assert!(c.validate().unwrap_err().0.contains("every user"));
        c.socket_mode = 0o060;
        assert!(c.validate().is_err());
        c.socket_mode = 0o600;
        c.snapshot_rate = 0.0;
        assert!(c.validate().is_err());
    }
}
