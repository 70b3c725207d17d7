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

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex, MutexGuard, Weak};
use std::time::Duration;

use mech_proto::{
    ClusterCommand, ClusterGoal, ClusterVelocity, Command, Formation, FormationKind, Mission,
    MissionProgress, Offset, RobotCommand,
};
use tokio::sync::Notify;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use crate::cluster::{
    ClusterConfig, ClusterController, ClusterMotion, ClusterStatus, ClusterWaypoint,
};
use crate::follow::{FollowConfig, FollowTarget, FollowTheLeader, Follower};
use crate::formation::FormationError;
use crate::offboard::{NavConfig, OffboardNavigator};
use crate::spec::{ClusterSpec, DEFAULT_SPACING, SpecError};
use crate::{ControlEvent, MemberState, PlatformLimits};
use mech_core::fleet::{Cluster, Fleet, Severity};
use mech_core::router::{Delivery, Publishers, RouterError, Subscription};
use mech_core::sync::lock;
use mech_core::{Event, Gcs};

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

/// Running tracking-error statistics of a cluster since its last mission
/// started (or since it was created).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrackingStats {
    /// Member-period samples.
    pub samples: u64,
    /// Largest slot error, m.
    pub max: f64,
    sum_sq: f64,
}

impl TrackingStats {
    fn add(&mut self, error: f64) {
        self.samples += 1;
        self.max = self.max.max(error);
        self.sum_sq += error * error;
    }

    /// Root-mean-square slot error, m.
    pub fn rms(&self) -> f64 {
        if self.samples == 0 {
            0.0
        } else {
            (self.sum_sq / self.samples as f64).sqrt()
        }
    }
}

/// A cluster as displays show it.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterView {
    pub channel: String,
    /// Last step's status: desired and measured cluster pose, slot targets
    /// with per-member tracking error, lost and absent members.
    pub status: ClusterStatus,
    pub stats: TrackingStats,
    /// What the cluster pose is doing: holding, a velocity, or waypoints.
    pub motion: ClusterMotion,
    /// Cluster waypoints set but not sent yet.
    pub draft: Vec<ClusterWaypoint>,
    /// The last waypoint list sent was completed.
    pub finished: bool,
}

/// Followers of one leader as displays show them.
#[derive(Debug, Clone, PartialEq)]
pub struct FollowView {
    pub leader: String,
    pub channel: String,
    pub followers: Vec<Follower>,
    pub targets: Vec<FollowTarget>,
    pub lost: Vec<String>,
}

/// One robot's offboard navigation as displays show it.
#[derive(Debug, Clone, PartialEq)]
pub struct NavView {
    pub robot: String,
    pub channel: String,
    pub progress: MissionProgress,
    /// Distance to the waypoint being approached, m.
    pub distance: Option<f64>,
    /// Telemetry stale: not commanded.
    pub lost: bool,
    /// Time from the `nav ... offboard` request to the first offboard command
    /// the router forwarded to the robot.
    pub switch_latency: Option<Duration>,
}

/// Everything the controllers are doing, for the TUI and scripts.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ControlSnapshot {
    pub clusters: Vec<ClusterView>,
    pub follows: Vec<FollowView>,
    pub navs: Vec<NavView>,
}

#[derive(Debug)]
struct ClusterEntry {
    controller: ClusterController,
    status: Option<ClusterStatus>,
    stats: TrackingStats,
    draft: Vec<ClusterWaypoint>,
    draft_looped: bool,
    finished: bool,
    /// Router time (s) at which a gamepad velocity lapses.
    drive_expires: Option<f64>,
}

#[derive(Debug)]
struct FollowEntry {
    controller: FollowTheLeader,
    targets: Vec<FollowTarget>,
    lost: Vec<String>,
}

#[derive(Debug)]
struct NavEntry {
    nav: OffboardNavigator,
    distance: Option<f64>,
    lost: bool,
    /// When the switch to offboard was requested, until the first command is
    /// forwarded.
    requested_at: Option<Instant>,
    switch_latency: Option<Duration>,
}

#[derive(Debug, Default)]
struct HubState {
    clusters: BTreeMap<String, ClusterEntry>,
    follows: BTreeMap<String, FollowEntry>,
    navs: BTreeMap<String, NavEntry>,
    /// Last mission progress each robot reported: an agent reports progress
    /// only while routed to the mission's channel, and a switch to offboard
    /// must still know where it got to.
    progress: BTreeMap<String, MissionProgress>,
}

#[derive(Debug)]
struct Shared {
    gcs: Gcs,
    config: HubConfig,
    state: Mutex<HubState>,
    /// Wakes the control task for an immediate period.
    kick: Notify,
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

/// What one control period decided to publish.
#[derive(Debug)]
enum Outgoing {
    Fleet {
        channel: String,
        parts: Vec<RobotCommand>,
    },
    Nav {
        channel: String,
        robot: String,
        command: Command,
    },
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
                state: Mutex::new(HubState::default()),
                kick: Notify::new(),
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

    /// Starts the control task if it is not running. Outside a tokio runtime
    /// it does nothing; the next request made inside one starts it.
    fn ensure_running(&self) {
        if tokio::runtime::Handle::try_current().is_err() {
            return;
        }
        let mut task = lock(&self.shared.task);
        if task.as_ref().is_some_and(|t| !t.is_finished()) {
            return;
        }
        let weak = Arc::downgrade(&self.shared);
        let events = self.shared.gcs.router().subscribe(256, false);
        let publishers = self.shared.gcs.router().publishers(SENDER);
        let period = Duration::from_secs_f64(1.0 / self.shared.config.rate_hz.clamp(1.0, 200.0));
        *task = Some(tokio::spawn(run(weak, events, publishers, period)));
    }

    /// Runs a control period now instead of at the next tick.
    fn kick(&self) {
        self.ensure_running();
        self.shared.kick.notify_one();
    }

    fn state(&self) -> MutexGuard<'_, HubState> {
        lock(&self.shared.state)
    }

    /// The cluster's controller, created (line formation) on first use.
    fn with_cluster<R>(
        &self,
        name: &str,
        f: impl FnOnce(&mut ClusterEntry) -> Result<R, ControlError>,
    ) -> Result<R, ControlError> {
        self.change_cluster(name, true, f)
    }

    /// [`ControlHub::with_cluster`]; `stale_status` says whether the change
    /// invalidates the last status (a new formation or goal does; a refreshed
    /// gamepad velocity does not, and must not blank displays 20 times a
    /// second).
    fn change_cluster<R>(
        &self,
        name: &str,
        stale_status: bool,
        f: impl FnOnce(&mut ClusterEntry) -> Result<R, ControlError>,
    ) -> Result<R, ControlError> {
        let members = self
            .shared
            .gcs
            .with_fleet(|fl| fl.clusters.get(name).map(|c| c.members.clone()))
            .ok_or_else(|| ControlError::UnknownCluster(name.to_string()))?;
        let mut state = self.state();
        let entry = match state.clusters.entry(name.to_string()) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(v) => {
                let formation = Formation {
                    kind: FormationKind::Line,
                    spacing: DEFAULT_SPACING,
                    offsets: Vec::new(),
                };
                let controller = ClusterController::new(
                    name,
                    members,
                    formation,
                    self.shared.config.cluster.clone(),
                )?;
                v.insert(ClusterEntry {
                    controller,
                    status: None,
                    stats: TrackingStats::default(),
                    draft: Vec::new(),
                    draft_looped: false,
                    finished: false,
                    drive_expires: None,
                })
            }
        };
        let r = f(entry);
        if r.is_ok() && stale_status {
            // The next period's status is the first to reflect the change.
            entry.status = None;
        }
        drop(state);
        self.kick();
        r
    }

    /// Sets a cluster's formation; slots are re-assigned at the next period.
    pub fn set_formation(&self, cluster: &str, formation: Formation) -> Result<(), ControlError> {
        self.with_cluster(cluster, |e| Ok(e.controller.set_formation(formation)?))
    }

    /// Moves a cluster at a cluster-frame velocity until told otherwise.
    pub fn cluster_move(
        &self,
        cluster: &str,
        velocity: ClusterVelocity,
    ) -> Result<(), ControlError> {
        self.with_cluster(cluster, |e| {
            e.controller.set_velocity(velocity);
            e.drive_expires = None;
            e.finished = false;
            Ok(())
        })
    }

    /// Moves a cluster at a velocity that lapses (the cluster holds) unless
    /// refreshed within [`HubConfig::drive_timeout`]: the gamepad mapping.
    pub fn drive_cluster(
        &self,
        cluster: &str,
        velocity: ClusterVelocity,
    ) -> Result<(), ControlError> {
        let expires = self.shared.gcs.router().elapsed().as_secs_f64()
            + self.shared.config.drive_timeout.as_secs_f64();
        self.change_cluster(cluster, false, |e| {
            e.controller.set_velocity(velocity);
            e.drive_expires = Some(expires);
            e.finished = false;
            Ok(())
        })
    }

    /// Stops a cluster where it is.
    pub fn hold_cluster(&self, cluster: &str) -> Result<(), ControlError> {
        self.with_cluster(cluster, |e| {
            e.controller.hold();
            e.drive_expires = None;
            Ok(())
        })
    }

    /// Sets a cluster's waypoint draft (sent with [`ControlHub::send_cluster`]).
    pub fn set_cluster_waypoints(
        &self,
        cluster: &str,
        waypoints: Vec<ClusterWaypoint>,
        looped: bool,
    ) -> Result<(), ControlError> {
        self.with_cluster(cluster, |e| {
            e.draft = waypoints;
            e.draft_looped = looped;
            Ok(())
        })
    }

    /// Whether `cluster` has cluster waypoints waiting to be sent.
    pub fn has_cluster_draft(&self, cluster: &str) -> bool {
        self.state()
            .clusters
            .get(cluster)
            .is_some_and(|e| !e.draft.is_empty())
    }

    /// Starts the cluster on its waypoint draft and resets its tracking
    /// statistics. Returns the number of waypoints.
    pub fn send_cluster(&self, cluster: &str) -> Result<usize, ControlError> {
        self.with_cluster(cluster, |e| {
            if e.draft.is_empty() {
                return Err(ControlError::NoClusterWaypoints(cluster.to_string()));
            }
            e.controller.set_waypoints(e.draft.clone(), e.draft_looped);
            e.drive_expires = None;
            e.finished = false;
            e.stats = TrackingStats::default();
            Ok(e.draft.len())
        })
    }

    /// Makes `follower` keep `offset` (leader frame) from `leader`; it obeys
    /// once routed to `follow/<leader>`. A robot follows one leader at a time.
    pub fn follow(&self, follower: &str, leader: &str, offset: Offset) -> Result<(), ControlError> {
        if follower == leader {
            return Err(ControlError::SelfFollow(follower.to_string()));
        }
        for r in [follower, leader] {
            if !self.shared.gcs.with_fleet(|f| f.robot(r).is_some()) {
                return Err(ControlError::UnknownRobot(r.to_string()));
            }
        }
        let mut state = self.state();
        for (l, e) in state.follows.iter_mut() {
            if l != leader {
                e.controller.remove_follower(follower);
            }
        }
        state
            .follows
            .retain(|_, e| !e.controller.followers().is_empty());
        let config = self.shared.config.follow.clone();
        state
            .follows
            .entry(leader.to_string())
            .or_insert_with(|| FollowEntry {
                controller: FollowTheLeader::new(leader, Vec::new(), config),
                targets: Vec::new(),
                lost: Vec::new(),
            })
            .controller
            .set_follower(follower, offset);
        drop(state);
        self.kick();
        Ok(())
    }

    /// Stops `follower` following anyone.
    pub fn unfollow(&self, follower: &str) {
        let mut state = self.state();
        for e in state.follows.values_mut() {
            e.controller.remove_follower(follower);
        }
        state
            .follows
            .retain(|_, e| !e.controller.followers().is_empty());
    }

    /// Switches `robot` from onboard to offboard navigation of the mission it
    /// holds: the GCS loop takes over at the agent's reported next waypoint
    /// and the robot is routed to `offboard/<robot>`. Returns the view of the
    /// new navigation once its first command has been forwarded (or after
    /// one control period if it could not be).
    pub async fn nav_offboard(&self, robot: &str) -> Result<NavView, ControlError> {
        let requested_at = Instant::now();
        let gcs = &self.shared.gcs;
        let radius = gcs.config().fleet.arrival_radius;
        let found = gcs.with_fleet(|f| {
            f.robot(robot).map(|r| {
                let mission = r.waypoints.sent.as_ref().map(|s| Mission {
                    id: s.id,
                    waypoints: s.waypoints.clone(),
                    looped: s.looped,
                    arrival_radius: radius,
                    start_index: 0,
                });
                (mission, r.mission)
            })
        });
        let Some((mission, reported)) = found else {
            return Err(ControlError::UnknownRobot(robot.to_string()));
        };
        let reported = reported.or_else(|| self.state().progress.get(robot).copied());
        let channel = offboard_channel(robot);
        {
            let mut state = self.state();
            if let Some(e) = state.navs.get_mut(robot) {
                // Already navigating offboard (e.g. routed away and back).
                e.nav.set_handover(false);
                e.requested_at = Some(requested_at);
                e.switch_latency = None;
            } else {
                let mission = mission.ok_or_else(|| ControlError::NoMission(robot.to_string()))?;
                let nav = OffboardNavigator::take_over(
                    robot,
                    mission,
                    reported,
                    self.shared.config.nav.clone(),
                );
                state.navs.insert(
                    robot.to_string(),
                    NavEntry {
                        nav,
                        distance: None,
                        lost: false,
                        requested_at: Some(requested_at),
                        switch_latency: None,
                    },
                );
            }
        }
        gcs.router().set_route(robot, Some(&channel)).await?;
        self.kick();
        let deadline =
            requested_at + Duration::from_secs_f64(2.0 / self.shared.config.rate_hz.max(1.0));
        loop {
            let view = self.nav_view(robot);
            match view {
                Some(v) if v.switch_latency.is_some() || Instant::now() >= deadline => {
                    return Ok(v);
                }
                Some(_) => tokio::time::sleep(Duration::from_micros(200)).await,
                None => return Err(ControlError::NotOffboard(robot.to_string())),
            }
        }
    }

    /// Hands navigation back to the agent: the mission goes out again with
    /// `start_index` = the current next waypoint (fresh id), progress is
    /// frozen until the agent acknowledges it, then the robot is routed to
    /// the mission channel and the GCS loop stops. Returns the progress
    /// handed over.
    pub async fn nav_onboard(&self, robot: &str) -> Result<MissionProgress, ControlError> {
        let gcs = &self.shared.gcs;
        let mission = {
            let mut state = self.state();
            let e = state
                .navs
                .get_mut(robot)
                .ok_or_else(|| ControlError::NotOffboard(robot.to_string()))?;
            e.nav.set_handover(true);
            e.nav.onboard_mission(0)
        };
        let progress = MissionProgress {
            id: mission.id,
            next: mission.start_index,
            total: mission.waypoints.len() as u32,
        };
        let channel = gcs.config().fleet.mission_channel.clone();
        // Watch the router's events rather than the fleet model's delivery
        // state: an agent on loopback can acknowledge before the model has
        // recorded the mission as sent.
        let mut events = gcs.router().subscribe(1024, false);
        let id = match gcs
            .router()
            .send_mission(SENDER, robot, &channel, mission)
            .await
        {
            Ok(id) => id,
            Err(e) => {
                self.release_handover(robot);
                return Err(e.into());
            }
        };
        let verdict = tokio::time::timeout(self.shared.config.handover_timeout, async {
            while let Some(ev) = events.recv().await {
                match &ev.event {
                    Event::MissionAcked {
                        robot: r,
                        id: i,
                        accepted,
                        reason,
                    } if r == robot && *i == id => {
                        return if *accepted {
                            Ok(())
                        } else {
                            Err(format!("mission {id} refused: {reason}"))
                        };
                    }
                    Event::MissionFailed {
                        robot: r,
                        id: i,
                        reason,
                    } if r == robot && *i == id => {
                        return Err(format!("mission {id} not delivered: {reason}"));
                    }
                    _ => {}
                }
            }
            Err("the router stopped".to_string())
        })
        .await
        .unwrap_or_else(|_| Err(format!("mission {id} not acknowledged in time")));
        if let Err(reason) = verdict {
            self.release_handover(robot);
            return Err(ControlError::Handover {
                robot: robot.to_string(),
                reason,
            });
        }
        self.state().navs.remove(robot);
        gcs.router().set_route(robot, Some(&channel)).await?;
        Ok(MissionProgress { id, ..progress })
    }

    /// Switches `robot` to the other side: offboard if the GCS loop is not
    /// running for it, onboard if it is (one key in the TUI).
    pub async fn toggle_nav(&self, robot: &str) -> Result<String, ControlError> {
        if self.nav_view(robot).is_some() {
            let p = self.nav_onboard(robot).await?;
            Ok(format!(
                "{robot} onboard from waypoint {} of {}",
                p.next, p.total
            ))
        } else {
            let v = self.nav_offboard(robot).await?;
            Ok(format!(
                "{robot} offboard from waypoint {} of {}",
                v.progress.next, v.progress.total
            ))
        }
    }

    fn release_handover(&self, robot: &str) {
        if let Some(e) = self.state().navs.get_mut(robot) {
            e.nav.set_handover(false);
        }
    }

    /// The status of one cluster.
    pub fn cluster_view(&self, cluster: &str) -> Option<ClusterView> {
        self.state()
            .clusters
            .get(cluster)
            .and_then(|e| cluster_view(cluster, e))
    }

    /// The status of one robot's offboard navigation.
    pub fn nav_view(&self, robot: &str) -> Option<NavView> {
        self.state().navs.get(robot).map(|e| nav_view(robot, e))
    }

    /// Everything the controllers are doing.
    pub fn snapshot(&self) -> ControlSnapshot {
        let state = self.state();
        ControlSnapshot {
            clusters: state
                .clusters
                .iter()
                .filter_map(|(n, e)| cluster_view(n, e))
                .collect(),
            follows: state
                .follows
                .iter()
                .map(|(leader, e)| FollowView {
                    leader: leader.clone(),
                    channel: follow_channel(leader),
                    followers: e.controller.followers().to_vec(),
                    targets: e.targets.clone(),
                    lost: e.lost.clone(),
                })
                .collect(),
            navs: state.navs.iter().map(|(r, e)| nav_view(r, e)).collect(),
        }
    }

    /// One control period on the fleet model's telemetry: every cluster,
    /// follow and offboard controller steps once on the robots routed to it.
    fn period(&self) -> PeriodOutput {
        let mut inputs = self.period_inputs();
        let mut output = PeriodOutput::default();
        let mut state = self.state();
        state.progress.extend(std::mem::take(&mut inputs.progress));
        for (name, e) in state.clusters.iter_mut() {
            e.step(name, &inputs, &mut output);
        }
        for (leader, e) in state.follows.iter_mut() {
            e.step(leader, &inputs, &mut output);
        }
        let nav_timeout = self.shared.config.nav.telemetry_timeout;
        for (robot, e) in state.navs.iter_mut() {
            e.step(robot, &inputs, nav_timeout, &mut output);
        }
        output
    }

    /// What the controllers read from the fleet model this period.
    fn period_inputs(&self) -> PeriodInputs {
        let gcs = &self.shared.gcs;
        let now = gcs.router().elapsed().as_secs_f64();
        let idle = {
            let s = self.state();
            s.clusters.is_empty() && s.follows.is_empty() && s.navs.is_empty()
        };
        gcs.with_fleet(|f| PeriodInputs {
            now,
            states: if idle { Vec::new() } else { member_states(f) },
            routes: f
                .robots
                .iter()
                .map(|(n, r)| (n.clone(), r.route.requested.clone()))
                .collect(),
            clusters: f.clusters.clone(),
            progress: f
                .robots
                .iter()
                .filter_map(|(n, r)| Some((n.clone(), r.mission?)))
                .collect(),
        })
    }

    /// Publishes what a period decided; the first offboard command the router
    /// forwards to a robot completes its switch to offboard.
    async fn publish(&self, publishers: &mut Publishers, outgoing: Vec<Outgoing>) {
        for o in outgoing {
            match o {
                Outgoing::Fleet { channel, parts } => {
                    if let Err(e) = publishers.on(&channel).send_fleet(parts).await {
                        tracing::warn!(%channel, error = %e, "fleet command not published");
                    }
                }
                Outgoing::Nav {
                    channel,
                    robot,
                    command,
                } => match publishers.on(&channel).send(&robot, command).await {
                    Ok(Delivery::Forwarded(_)) => self.forwarded(&robot),
                    Ok(_) => {}
                    Err(e) => {
                        tracing::warn!(%channel, error = %e, "offboard command not published")
                    }
                },
            }
        }
    }

    /// Logs a period's controller events, to tracing and the fleet log.
    fn record(&self, log: Vec<(Severity, String)>) {
        if log.is_empty() {
            return;
        }
        for (severity, text) in &log {
            if *severity >= Severity::Warn {
                tracing::warn!(target: "control", "{text}");
            } else {
                tracing::info!(target: "control", "{text}");
            }
        }
        self.shared.gcs.update_fleet(|f| {
            for (severity, text) in log {
                f.log(severity, text);
            }
        });
    }

    /// Records that the first offboard command for `robot` was forwarded.
    fn forwarded(&self, robot: &str) {
        if let Some(e) = self.state().navs.get_mut(robot) {
            if let Some(at) = e.requested_at.take() {
                e.switch_latency = Some(at.elapsed());
            }
        }
    }

    /// Applies a cluster command an external program published.
    fn external(&self, channel: &str, command: &ClusterCommand) {
        let Some(name) = channel.strip_prefix("fleet/") else {
            return;
        };
        if name != command.cluster {
            return;
        }
        let result = self.with_cluster(name, |e| {
            if let Some(f) = &command.formation {
                e.controller.set_formation(f.clone())?;
            }
            match &command.goal {
                ClusterGoal::Velocity(v) => e.controller.set_velocity(*v),
                ClusterGoal::Pose(p) => e.controller.set_waypoints(
                    vec![ClusterWaypoint {
                        x: p.x,
                        y: p.y,
                        heading: Some(p.heading),
                    }],
                    false,
                ),
            }
            e.drive_expires = None;
            e.finished = false;
            Ok(())
        });
        if let Err(e) = result {
            self.shared.gcs.update_fleet(|f| {
                f.log(
                    Severity::Warn,
                    format!("{channel}: cluster command refused: {e}"),
                )
            });
        }
    }
}

/// What the controllers read from the fleet model at the start of a period.
struct PeriodInputs {
    /// Router time, s.
    now: f64,
    /// Every robot with telemetry (none while no controller runs).
    states: Vec<MemberState>,
    /// The channel each robot is routed to, as last requested of the router.
    routes: HashMap<String, Option<String>>,
    /// Cluster definitions, whose members the controllers follow.
    clusters: BTreeMap<String, Cluster>,
    /// Mission progress the robots report now.
    progress: Vec<(String, MissionProgress)>,
}

impl PeriodInputs {
    fn routed_to(&self, robot: &str, channel: &str) -> bool {
        self.routes.get(robot).and_then(|r| r.as_deref()) == Some(channel)
    }
}

/// What one control period decided: what to publish and what to log.
#[derive(Debug, Default)]
struct PeriodOutput {
    outgoing: Vec<Outgoing>,
    log: Vec<(Severity, String)>,
}

impl ClusterEntry {
    /// One period of cluster `name` on the robots routed to `fleet/<name>`.
    fn step(&mut self, name: &str, inputs: &PeriodInputs, output: &mut PeriodOutput) {
        let channel = cluster_channel(name);
        if let Some(def) = inputs.clusters.get(name) {
            self.follow_definition(name, def, &mut output.log);
        }
        if self.drive_expires.is_some_and(|t| inputs.now > t) {
            self.controller.hold();
            self.drive_expires = None;
        }
        let routed: Vec<MemberState> = inputs
            .states
            .iter()
            .filter(|s| inputs.routed_to(&s.robot, &channel))
            .cloned()
            .collect();
        let result = self.controller.step(inputs.now, &routed);
        for s in &result.status.slots {
            self.stats.add(s.error);
        }
        for ev in &result.events {
            if *ev == ControlEvent::Finished {
                self.finished = true;
            }
            output.log.push(event_line(name, ev));
        }
        self.status = Some(result.status);
        if !result.commands.is_empty() {
            output.outgoing.push(Outgoing::Fleet {
                channel,
                parts: result.commands,
            });
        }
    }

    /// Takes the members of the fleet model's cluster definition when they
    /// changed: clusters are defined there (command language, TUI,
    /// configuration), not on the controller.
    fn follow_definition(&mut self, name: &str, def: &Cluster, log: &mut Vec<(Severity, String)>) {
        if def.members.as_slice() == self.controller.members() {
            return;
        }
        if let Err(err) = self.controller.set_members(def.members.clone()) {
            log.push((
                Severity::Warn,
                format!("{name}: members not updated: {err}"),
            ));
        }
    }
}

impl FollowEntry {
    /// One period of the followers of `leader`: the leader wherever it is
    /// routed, the followers routed to `follow/<leader>`.
    fn step(&mut self, leader: &str, inputs: &PeriodInputs, output: &mut PeriodOutput) {
        let channel = follow_channel(leader);
        let routed: Vec<MemberState> = inputs
            .states
            .iter()
            .filter(|s| s.robot == leader || inputs.routed_to(&s.robot, &channel))
            .cloned()
            .collect();
        let result = self.controller.step(inputs.now, &routed);
        for ev in &result.events {
            output.log.push(event_line(&channel, ev));
        }
        self.targets = result.targets;
        self.lost = result.lost;
        if !result.commands.is_empty() {
            output.outgoing.push(Outgoing::Fleet {
                channel,
                parts: result.commands,
            });
        }
    }
}

impl NavEntry {
    /// One period of `robot`'s offboard navigation, while it is routed to
    /// `offboard/<robot>`; `timeout` is the navigator's telemetry timeout.
    fn step(
        &mut self,
        robot: &str,
        inputs: &PeriodInputs,
        timeout: f64,
        output: &mut PeriodOutput,
    ) {
        let channel = offboard_channel(robot);
        if !inputs.routed_to(robot, &channel) {
            return;
        }
        let s = inputs.states.iter().find(|s| s.robot == robot);
        let result = self.nav.step(inputs.now, s);
        for ev in &result.events {
            output.log.push(event_line(&channel, ev));
        }
        self.distance = result.distance;
        self.lost = s.is_none_or(|s| s.is_stale(inputs.now, timeout));
        if let Some(command) = result.command {
            output.outgoing.push(Outgoing::Nav {
                channel,
                robot: robot.to_string(),
                command,
            });
        }
    }
}

fn cluster_view(name: &str, e: &ClusterEntry) -> Option<ClusterView> {
    Some(ClusterView {
        channel: cluster_channel(name),
        status: e.status.clone()?,
        stats: e.stats,
        motion: e.controller.motion().clone(),
        draft: e.draft.clone(),
        finished: e.finished,
    })
}

fn nav_view(robot: &str, e: &NavEntry) -> NavView {
    NavView {
        robot: robot.to_string(),
        channel: offboard_channel(robot),
        progress: e.nav.progress(),
        distance: e.distance,
        lost: e.lost,
        switch_latency: e.switch_latency,
    }
}

fn event_line(who: &str, ev: &ControlEvent) -> (Severity, String) {
    match ev {
        ControlEvent::MemberLost { robot } => (
            Severity::Warn,
            format!(
                "{who}: {robot} telemetry lost; no longer commanded (its failsafe will stop it)"
            ),
        ),
        ControlEvent::MemberRecovered { robot } => (
            Severity::Info,
            format!("{who}: {robot} telemetry back; commanded again"),
        ),
        ControlEvent::WaypointReached { index } => {
            (Severity::Info, format!("{who}: waypoint {index} reached"))
        }
        ControlEvent::Finished => (Severity::Info, format!("{who}: last waypoint reached")),
    }
}

/// Controller inputs from the fleet model: every robot with telemetry.
fn member_states(f: &Fleet) -> Vec<MemberState> {
    f.robots
        .values()
        .filter_map(|r| {
            let stamp = r.last_telemetry?;
            Some(MemberState {
                robot: r.name.clone(),
                platform: PlatformLimits::new(
                    &r.platform,
                    &r.capabilities,
                    r.max_speed,
                    r.max_yaw_rate,
                ),
                pose: r.pose,
                velocity: r.velocity,
                stamp: stamp.as_secs_f64(),
            })
        })
        .collect()
}

/// The control task: a period at every tick or kick, publishing through
/// per-channel publishers (so sequence numbers run on per channel).
async fn run(
    shared: Weak<Shared>,
    mut events: Subscription,
    mut publishers: Publishers,
    period: Duration,
) {
    let mut ticker = tokio::time::interval(period);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        {
            let Some(s) = shared.upgrade() else { return };
            let kick = async move { s.kick.notified().await };
            tokio::select! {
                _ = ticker.tick() => {}
                _ = kick => {}
                ev = events.recv() => match ev {
                    Some(ev) => {
                        if let Event::ClusterCommand { channel, command } = &ev.event {
                            if let Some(s) = shared.upgrade() {
                                ControlHub { shared: s }.external(channel, command);
                            }
                        }
                        continue;
                    }
                    None => return,
                },
            }
        }
        let Some(s) = shared.upgrade() else { return };
        let hub = ControlHub { shared: s };
        let output = hub.period();
        hub.publish(&mut publishers, output.outgoing).await;
        hub.record(output.log);
    }
}
