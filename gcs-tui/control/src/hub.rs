//! The controllers at work: one task that closes every fleet, follow and
//! offboard loop on the fleet model's telemetry and publishes through the
//! router, on the channels that put robots under those controllers.
//!
//! | controller | channel | published as |
//! | --- | --- | --- |
//! | cluster `c1` | `fleet/c1` | one `FleetCommand` per period |
//! | followers of `robot_1` | `follow/robot_1` | one `FleetCommand` per period |
//! | offboard navigation of `robot_2` | `offboard/robot_2` | one `Command` per period |
//!
//! A controller commands only the robots routed to its channel now (the
//! router's table, as the fleet model mirrors it), so re-routing a robot
//! moves it in or out of a controller at the very next period. The task runs
//! at [`HubConfig::rate_hz`] and also at once when asked ([`ControlHub`]
//! methods that change a controller), which is what makes an
//! onboard -> offboard switch take one router hop, not one period.
//!
//! Cluster commands that external programs publish on `fleet/<cluster>`
//! ([`mech_proto::ClusterCommand`]: a velocity or pose goal, optionally a new
//! formation) drive the cluster controller too.
//!
//! [`ControlHub`] composes one module per concern, each owning its state
//! (behind its own lock, never held together with another's) and its
//! tests, and the part of the hub's API that drives it:
//! - [`clusters`]: the cluster controllers (formation, velocity, gamepad
//!   drive, waypoint drafts, tracking statistics);
//! - [`follows`]: follow-the-leader, one leader per follower;
//! - [`navs`]: offboard navigation and the handover between the agent's
//!   loop and the station's;
//! - [`external`]: cluster commands external programs publish;
//! - [`task`]: the control task and its period;
//! - [`period`]: what a period reads and decides, shared by the three
//!   controller concerns.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::Notify;
use tokio::task::JoinHandle;

use crate::cluster::ClusterConfig;
use crate::follow::FollowConfig;
use crate::formation::FormationError;
use crate::offboard::NavConfig;
use crate::spec::{ClusterSpec, SpecError};
use mech_core::Gcs;
use mech_core::router::RouterError;
use mech_core::sync::lock;

mod clusters;
mod external;
mod follows;
mod navs;
mod period;
mod task;

pub use clusters::{ClusterView, TrackingStats};
pub use follows::FollowView;
pub use navs::NavView;

/// Sender name of everything the controllers publish.
pub const SENDER: &str = "gcs-control";

/// The channel of cluster `name`.
pub fn cluster_channel(name: &str) -> String {
    format!("fleet/{name}")
}

/// The channel of `robot`'s offboard navigation.
pub fn offboard_channel(robot: &str) -> String {
    format!("offboard/{robot}")
}

/// The channel of the followers of `leader`.
pub fn follow_channel(leader: &str) -> String {
    format!("follow/{leader}")
}

/// Tuning of the controllers the hub runs.
#[derive(Debug, Clone, PartialEq)]
pub struct HubConfig {
    /// Control periods per second.
    pub rate_hz: f64,
    pub cluster: ClusterConfig,
    pub follow: FollowConfig,
    pub nav: NavConfig,
    /// How long handing navigation back to the agent may wait for its
    /// mission acknowledgement.
    pub handover_timeout: Duration,
    /// A cluster velocity given with [`ControlHub::drive_cluster`] (a gamepad)
    /// expires after this long without a refresh, and the cluster holds.
    pub drive_timeout: Duration,
}

impl Default for HubConfig {
    fn default() -> Self {
        HubConfig {
            rate_hz: 20.0,
            cluster: ClusterConfig::default(),
            follow: FollowConfig::default(),
            nav: NavConfig::default(),
            handover_timeout: Duration::from_secs(2),
            drive_timeout: Duration::from_millis(500),
        }
    }
}

impl HubConfig {
    /// The time between two control periods.
    pub(crate) fn period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / self.rate_hz.clamp(1.0, 200.0))
    }
}

/// Why a control request was refused.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    #[error("no cluster named {0:?}; define it with `cluster NAME ROBOT...`")]
    UnknownCluster(String),
    #[error("no robot named {0:?}")]
    UnknownRobot(String),
    #[error("{0}")]
    Formation(#[from] FormationError),
    #[error("{0} has no mission to navigate; send one first (`waypoint` + `send`)")]
    NoMission(String),
    #[error("{0} is not under offboard navigation")]
    NotOffboard(String),
    #[error("{0} has no cluster waypoints; set them with `cluster-waypoint`")]
    NoClusterWaypoints(String),
    #[error("{0} cannot follow itself")]
    SelfFollow(String),
    #[error("handing {robot} back to onboard navigation failed: {reason}")]
    Handover { robot: String, reason: String },
    #[error("cluster {0:?} in the configuration: {1}")]
    Config(String, SpecError),
    #[error(transparent)]
    Router(#[from] RouterError),
}

/// Everything the controllers are doing, for the TUI and scripts.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ControlSnapshot {
    pub clusters: Vec<ClusterView>,
    pub follows: Vec<FollowView>,
    pub navs: Vec<NavView>,
}

/// What every clone of a hub shares: the station, the tuning, each
/// concern's state behind its own lock, and the control task.
#[derive(Debug)]
struct Shared {
    gcs: Gcs,
    config: HubConfig,
    clusters: Mutex<clusters::Clusters>,
    follows: Mutex<follows::Follows>,
    navs: Mutex<navs::Navs>,
    /// Wakes the control task for an immediate period.
    kick: Notify,
    /// Wakes whoever waits for a switch to offboard to reach its robot
    /// ([`ControlHub::nav_offboard`]) when an offboard command was
    /// forwarded.
    forwarded: Notify,
    task: Mutex<Option<JoinHandle<()>>>,
}

impl Drop for Shared {
    fn drop(&mut self) {
        if let Some(t) = lock(&self.task).take() {
            t.abort();
        }
    }
}

/// The ground station's fleet and offboard controllers; cheap to clone, all
/// clones share the controllers. The control task starts with the first
/// request and stops when the last clone is dropped.
#[derive(Debug, Clone)]
pub struct ControlHub {
    shared: Arc<Shared>,
}

impl ControlHub {
    pub fn new(gcs: Gcs) -> ControlHub {
        ControlHub::with_config(gcs, HubConfig::default())
    }

    /// A hub with no controllers yet. Inside a tokio runtime its task starts
    /// at once (it also keeps each robot's last mission progress); outside
    /// one, at the first request made inside one.
    pub fn with_config(gcs: Gcs, config: HubConfig) -> ControlHub {
        let hub = ControlHub {
            shared: Arc::new(Shared {
                gcs,
                config,
                clusters: Mutex::default(),
                follows: Mutex::default(),
                navs: Mutex::default(),
                kick: Notify::new(),
                forwarded: Notify::new(),
                task: Mutex::new(None),
            }),
        };
        hub.ensure_running();
        hub
    }

    pub fn config(&self) -> &HubConfig {
        &self.shared.config
    }

    pub fn gcs(&self) -> &Gcs {
        &self.shared.gcs
    }

    /// Defines the clusters of the configuration and their formations.
    pub fn apply_config(&self, clusters: &[ClusterSpec]) -> Result<(), ControlError> {
        for c in clusters {
            let formation = c
                .formation()
                .map_err(|e| ControlError::Config(c.name.clone(), e))?;
            self.shared
                .gcs
                .update_fleet(|f| f.set_cluster(&c.name, c.members.clone()));
            self.set_formation(&c.name, formation)?;
        }
        Ok(())
    }

    /// Everything the controllers are doing.
    pub fn snapshot(&self) -> ControlSnapshot {
        // One statement per lock: a guard lives to the end of its
        // statement, so in one struct expression all three would be held.
        let clusters = lock(&self.shared.clusters).views();
        let follows = lock(&self.shared.follows).views();
        let navs = lock(&self.shared.navs).views();
        ControlSnapshot {
            clusters,
            follows,
            navs,
        }
    }

    /// Starts the control task if it is not running. Outside a tokio runtime
    /// it does nothing; the next request made inside one starts it.
    fn ensure_running(&self) {
        if tokio::runtime::Handle::try_current().is_err() {
            return;
        }
        let mut running = lock(&self.shared.task);
        if running.as_ref().is_some_and(|t| !t.is_finished()) {
            return;
        }
        let weak = Arc::downgrade(&self.shared);
        let events = self.shared.gcs.router().subscribe(256, false);
        let publishers = self.shared.gcs.router().publishers(SENDER);
        let period = self.shared.config.period();
        *running = Some(tokio::spawn(task::run(weak, events, publishers, period)));
    }

    /// Runs a control period now instead of at the next tick.
    fn kick(&self) {
        self.ensure_running();
        self.shared.kick.notify_one();
    }
}
