//! The fleet model: the ground station's view of every robot, cluster,
//! channel, route, waypoint list and e-stop, derived from router events.
//!
//! The router applies each [`Event`] here before any subscriber sees it, so
//! the model never misses a route or link change even when a subscriber lags.
//! The TUI and the script runner read it through [`crate::Gcs::snapshot`] or
//! [`crate::Gcs::with_fleet`]; it holds no sockets and no UI types.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::net::SocketAddr;
use std::time::Duration;

use mech_proto::{
    CommandKind, Computation, ControlMode, FailsafeState, Health, MissionProgress, Pose, Velocity,
    Waypoint,
};

mod config;

pub use config::FleetConfig;

use crate::counters::{ChannelStatus, Counters, Traffic};
use crate::event::{Event, EventSink, LinkState, Stamped};
use crate::sync::lock;

/// A robot's entry in the routing table, as the GCS knows it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RouteState {
    /// Channel the router forwards to this robot now (`None` = none). Takes
    /// effect at the router immediately.
    pub requested: Option<String>,
    /// Epoch of `requested`.
    pub epoch: u32,
    /// Channel the robot has acknowledged (and so is obeying).
    pub acknowledged: Option<String>,
    /// Epoch of `acknowledged`.
    pub acked_epoch: u32,
}

impl RouteState {
    /// Whether the robot has not yet acknowledged the latest route change.
    pub fn is_pending(&self) -> bool {
        self.acked_epoch != self.epoch
    }
}

/// How a mission's delivery went.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Delivery {
    /// Being sent, repeated until acknowledged.
    Sending,
    /// The robot stored it.
    Acked,
    /// The robot refused it.
    Refused(String),
    /// No acknowledgement in time.
    Failed(String),
}

/// A mission sent to a robot.
#[derive(Debug, Clone, PartialEq)]
pub struct SentMission {
    pub id: u32,
    pub channel: String,
    pub waypoints: Vec<Waypoint>,
    pub looped: bool,
    pub delivery: Delivery,
}

/// A robot's waypoints: the list being edited in the GCS (`draft`) and the
/// last mission sent.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WaypointList {
    pub draft: Vec<Waypoint>,
    pub looped: bool,
    pub sent: Option<SentMission>,
}

/// One point of a robot's recent trail.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathPoint {
    pub at: Duration,
    pub x: f64,
    pub y: f64,
}

/// Everything the GCS knows about one robot.
#[derive(Debug, Clone, PartialEq)]
pub struct Robot {
    pub name: String,
    /// Router-assigned id, stable while the GCS runs.
    pub id: u16,
    pub platform: String,
    pub capabilities: Vec<CommandKind>,
    pub motors: u8,
    /// m/s
    pub max_speed: f64,
    /// rad/s
    pub max_yaw_rate: f64,
    pub addr: SocketAddr,
    pub link: LinkState,
    /// Router time of the last telemetry.
    pub last_telemetry: Option<Duration>,
    pub pose: Pose,
    pub velocity: Velocity,
    /// What the robot does with its actuators, from telemetry.
    pub mode: ControlMode,
    /// The channel the robot reports obeying (telemetry).
    pub reported_channel: Option<String>,
    pub route: RouteState,
    pub computation: Computation,
    pub failsafe: FailsafeState,
    pub health: Health,
    /// Fraction in `[0, 1]`.
    pub battery: Option<f64>,
    pub position_quality: f64,
    pub actuators: Vec<f64>,
    pub mission: Option<MissionProgress>,
    pub waypoints: WaypointList,
    /// Recent trail, oldest first.
    pub path: VecDeque<PathPoint>,
    /// Mode the GCS command line uses when it drives this robot.
    pub gcs_mode: Option<CommandKind>,
    /// Traffic counters (copied in by [`crate::Gcs::snapshot`]).
    pub traffic: Traffic,
    /// Id of the last e-stop or release this robot acknowledged.
    pub estop_ack: Option<(bool, u32)>,
}

impl Robot {
    fn new(name: &str, id: u16, addr: SocketAddr) -> Robot {
        Robot {
            name: name.to_string(),
            id,
            platform: String::new(),
            capabilities: Vec::new(),
            motors: 0,
            max_speed: 0.0,
            max_yaw_rate: 0.0,
            addr,
            link: LinkState::Connected,
            last_telemetry: None,
            pose: Pose::default(),
            velocity: Velocity::default(),
            mode: ControlMode::Idle,
            reported_channel: None,
            route: RouteState::default(),
            computation: Computation::Onboard,
            failsafe: FailsafeState::Ok,
            health: Health::Ok,
            battery: None,
            position_quality: 0.0,
            actuators: Vec::new(),
            mission: None,
            waypoints: WaypointList::default(),
            path: VecDeque::new(),
            gcs_mode: None,
            traffic: Traffic::default(),
            estop_ack: None,
        }
    }

    /// Ground speed, m/s.
    pub fn speed(&self) -> f64 {
        self.velocity.vx.hypot(self.velocity.vy)
    }

    /// Heading, rad, counter-clockwise from +x.
    pub fn heading(&self) -> f64 {
        self.pose.heading
    }

    /// Distance (m, in the plane) from the robot to a point.
    pub fn distance_to(&self, x: f64, y: f64) -> f64 {
        (self.pose.x - x).hypot(self.pose.y - y)
    }

    /// Whether the last mission sent was acknowledged and the robot reports
    /// it finished.
    pub fn arrived(&self) -> bool {
        match (&self.waypoints.sent, &self.mission) {
            (Some(sent), Some(p)) => {
                sent.delivery == Delivery::Acked
                    && p.id == sent.id
                    && p.total > 0
                    && p.next >= p.total
            }
            _ => false,
        }
    }

    /// Whether the robot obeys `kind` commands.
    pub fn can(&self, kind: CommandKind) -> bool {
        self.capabilities.contains(&kind)
    }
}

/// A named set of robots.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Cluster {
    pub name: String,
    pub members: Vec<String>,
}

/// E-stop as the GCS last commanded it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct EStopState {
    /// Engaged (latched) until an explicit release.
    pub engaged: bool,
    /// Id of the last e-stop or release.
    pub id: u32,
    /// Robots that have not acknowledged `id` yet.
    pub pending: BTreeSet<String>,
}

/// Severity of an event-log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Severity {
    Debug,
    Info,
    Warn,
    Error,
}

impl Severity {
    pub fn as_str(self) -> &'static str {
        match self {
            Severity::Debug => "debug",
            Severity::Info => "info",
            Severity::Warn => "warn",
            Severity::Error => "error",
        }
    }
}

/// One line of the event log shown to the operator.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogEntry {
    pub at: Duration,
    pub severity: Severity,
    pub text: String,
}

/// The GCS's whole view of the fleet.
#[derive(Debug, Clone)]
pub struct Fleet {
    pub robots: BTreeMap<String, Robot>,
    pub clusters: BTreeMap<String, Cluster>,
    /// Live channels, publisher and rate (copied in by [`crate::Gcs::snapshot`]).
    pub channels: Vec<ChannelStatus>,
    /// Router counters (copied in by [`crate::Gcs::snapshot`]).
    pub counters: Counters,
    pub estop: EStopState,
    /// Most recent last.
    pub log: VecDeque<LogEntry>,
    /// Router endpoints once bound.
    pub udp: Option<SocketAddr>,
    pub tcp: Option<SocketAddr>,
    /// Router time of the last applied event.
    pub now: Duration,
    config: FleetConfig,
}

impl Fleet {
    pub fn new(config: FleetConfig) -> Fleet {
        Fleet {
            robots: BTreeMap::new(),
            clusters: BTreeMap::new(),
            channels: Vec::new(),
            counters: Counters::default(),
            estop: EStopState::default(),
            log: VecDeque::new(),
            udp: None,
            tcp: None,
            now: Duration::ZERO,
            config,
        }
    }

    pub fn robot(&self, name: &str) -> Option<&Robot> {
        self.robots.get(name)
    }

    pub fn robot_mut(&mut self, name: &str) -> Option<&mut Robot> {
        self.robots.get_mut(name)
    }

    /// Robots named by `target`: `all`, a cluster name, or a robot name.
    pub fn resolve(&self, target: &str) -> Option<Vec<String>> {
        if target == "all" {
            return Some(self.robots.keys().cloned().collect());
        }
        if let Some(c) = self.clusters.get(target) {
            return Some(c.members.clone());
        }
        self.robots
            .contains_key(target)
            .then(|| vec![target.to_string()])
    }

    /// Defines (or redefines) a cluster.
    pub fn set_cluster(&mut self, name: &str, members: Vec<String>) {
        self.clusters.insert(
            name.to_string(),
            Cluster {
                name: name.to_string(),
                members,
            },
        );
    }

    /// Appends an operator log line.
    pub fn log(&mut self, severity: Severity, text: impl Into<String>) {
        let at = self.now;
        self.log.push_back(LogEntry {
            at,
            severity,
            text: text.into(),
        });
        while self.log.len() > self.config.event_log.max(1) {
            self.log.pop_front();
        }
    }

    /// Updates the model from one router event.
    pub fn apply(&mut self, stamped: &Stamped) {
        self.now = self.now.max(stamped.at);
        let at = stamped.at;
        match &stamped.event {
            Event::Listening { udp, tcp } => {
                self.udp = Some(*udp);
                self.tcp = *tcp;
                let tcp = tcp.map(|t| format!(", TCP {t}")).unwrap_or_default();
                self.log(
                    Severity::Info,
                    format!("router listening on UDP {udp}{tcp}"),
                );
            }
            Event::Registered {
                robot,
                id,
                addr,
                platform,
                capabilities,
                motors,
                max_speed,
                max_yaw_rate,
                known,
            } => {
                let r = self
                    .robots
                    .entry(robot.clone())
                    .or_insert_with(|| Robot::new(robot, *id, *addr));
                let moved = r.addr != *addr;
                r.id = *id;
                r.addr = *addr;
                r.platform = platform.clone();
                r.capabilities = capabilities.clone();
                r.motors = *motors;
                r.max_speed = *max_speed;
                r.max_yaw_rate = *max_yaw_rate;
                r.link = LinkState::Connected;
                let text = match (known, moved) {
                    (false, _) => format!("{robot} ({platform}) connected from {addr}"),
                    (true, true) => format!("{robot} re-registered from new address {addr}"),
                    (true, false) => format!("{robot} re-registered"),
                };
                self.log(Severity::Info, text);
            }
            Event::Link { robot, state } => {
                if let Some(r) = self.robots.get_mut(robot) {
                    r.link = *state;
                }
                let severity = if *state == LinkState::Lost {
                    Severity::Warn
                } else {
                    Severity::Info
                };
                self.log(severity, format!("{robot} link {}", state.as_str()));
            }
            Event::Telemetry {
                robot,
                telemetry: t,
            } => {
                let spacing = self.config.path_spacing;
                let history = self.config.path_history;
                if let Some(r) = self.robots.get_mut(robot) {
                    r.last_telemetry = Some(at);
                    r.pose = t.pose;
                    r.velocity = t.velocity;
                    r.mode = t.mode;
                    r.reported_channel = (!t.channel.is_empty()).then(|| t.channel.clone());
                    r.computation = t.computation;
                    r.failsafe = t.failsafe;
                    r.health = t.health;
                    r.battery = t.battery;
                    r.position_quality = t.position_quality;
                    r.actuators.clone_from(&t.actuators);
                    r.mission = t.mission;
                    let far = r
                        .path
                        .back()
                        .is_none_or(|p| (p.x - t.pose.x).hypot(p.y - t.pose.y) >= spacing);
                    if far {
                        r.path.push_back(PathPoint {
                            at,
                            x: t.pose.x,
                            y: t.pose.y,
                        });
                        while r.path.len() > history {
                            r.path.pop_front();
                        }
                    }
                }
            }
            Event::RouteChanged {
                robot,
                channel,
                epoch,
            } => {
                if let Some(r) = self.robots.get_mut(robot) {
                    r.route.requested = channel.clone();
                    r.route.epoch = *epoch;
                }
                self.log(
                    Severity::Info,
                    format!("{robot} routed to {} (pending)", show(channel)),
                );
            }
            Event::RouteAcked {
                robot,
                channel,
                epoch,
            } => {
                if let Some(r) = self.robots.get_mut(robot) {
                    r.route.acknowledged = channel.clone();
                    r.route.acked_epoch = *epoch;
                }
                self.log(
                    Severity::Info,
                    format!("{robot} acknowledged route {}", show(channel)),
                );
            }
            Event::MissionSent {
                robot,
                channel,
                id,
                waypoints,
                looped,
            } => {
                if let Some(r) = self.robots.get_mut(robot) {
                    r.waypoints.sent = Some(SentMission {
                        id: *id,
                        channel: channel.clone(),
                        waypoints: waypoints.clone(),
                        looped: *looped,
                        delivery: Delivery::Sending,
                    });
                }
                self.log(
                    Severity::Info,
                    format!(
                        "mission {id} ({} waypoints) sent to {robot} on {channel}",
                        waypoints.len()
                    ),
                );
            }
            Event::MissionAcked {
                robot,
                id,
                accepted,
                reason,
            } => {
                if let Some(sent) = self
                    .robots
                    .get_mut(robot)
                    .and_then(|r| r.waypoints.sent.as_mut())
                {
                    if sent.id == *id {
                        sent.delivery = if *accepted {
                            Delivery::Acked
                        } else {
                            Delivery::Refused(reason.clone())
                        };
                    }
                }
                if *accepted {
                    self.log(Severity::Info, format!("{robot} acknowledged mission {id}"));
                } else {
                    self.log(
                        Severity::Warn,
                        format!("{robot} refused mission {id}: {reason}"),
                    );
                }
            }
            Event::MissionFailed { robot, id, reason } => {
                if let Some(sent) = self
                    .robots
                    .get_mut(robot)
                    .and_then(|r| r.waypoints.sent.as_mut())
                {
                    if sent.id == *id {
                        sent.delivery = Delivery::Failed(reason.clone());
                    }
                }
                self.log(
                    Severity::Error,
                    format!("mission {id} to {robot} failed: {reason}"),
                );
            }
            Event::EStop { engage, id } => {
                self.estop.engaged = *engage;
                self.estop.id = *id;
                self.estop.pending = self.robots.keys().cloned().collect();
                let what = if *engage {
                    "E-STOP engaged"
                } else {
                    "e-stop released"
                };
                self.log(
                    if *engage {
                        Severity::Error
                    } else {
                        Severity::Warn
                    },
                    format!("{what} (id {id})"),
                );
            }
            Event::EStopAcked { robot, engage, id } => {
                if let Some(r) = self.robots.get_mut(robot) {
                    r.estop_ack = Some((*engage, *id));
                }
                if *id == self.estop.id && *engage == self.estop.engaged {
                    self.estop.pending.remove(robot);
                }
            }
            Event::EStopComplete { engage, id } => {
                if *id == self.estop.id && *engage == self.estop.engaged {
                    self.estop.pending.clear();
                }
                let what = if *engage { "e-stop" } else { "release" };
                self.log(
                    Severity::Info,
                    format!("every robot acknowledged {what} {id}"),
                );
            }
            Event::ChannelPublisher { channel, publisher } => {
                self.log(
                    Severity::Info,
                    format!("channel {channel} published by {publisher}"),
                );
            }
            Event::ClusterCommand { .. } => {}
            Event::Bye { robot, reason } => {
                if let Some(r) = self.robots.get_mut(robot) {
                    r.link = LinkState::Lost;
                }
                self.log(Severity::Warn, format!("{robot} left: {reason}"));
            }
            Event::Notice { from, notice } => {
                let severity = match notice.level {
                    mech_proto::Level::Debug => Severity::Debug,
                    mech_proto::Level::Info => Severity::Info,
                    mech_proto::Level::Warn => Severity::Warn,
                    mech_proto::Level::Error => Severity::Error,
                };
                self.log(severity, format!("{from}: {}", notice.text));
            }
            Event::BadPacket { from, error } => {
                self.log(Severity::Warn, format!("bad packet from {from}: {error}"));
            }
        }
    }
}

/// The fleet model behind its lock is where the router delivers events.
impl EventSink for std::sync::Mutex<Fleet> {
    fn apply(&self, event: &Stamped) {
        lock(self).apply(event);
    }
}

fn show(channel: &Option<String>) -> &str {
    channel.as_deref().unwrap_or("none")
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::{Telemetry, Velocity};

    fn at(ms: u64, event: Event) -> Stamped {
        Stamped {
            at: Duration::from_millis(ms),
            event,
        }
    }

    fn registered(name: &str) -> Event {
        Event::Registered {
            robot: name.into(),
            id: 1,
            addr: "127.0.0.1:9000".parse().unwrap(),
            platform: "diff-drive".into(),
            capabilities: vec![CommandKind::Twist],
            motors: 2,
            max_speed: 1.0,
            max_yaw_rate: 2.0,
            known: false,
        }
    }

    fn telemetry(x: f64, mission: Option<MissionProgress>) -> Telemetry {
        Telemetry {
            pose: Pose {
                x,
                y: 0.0,
                z: 0.0,
                heading: 0.5,
            },
            velocity: Velocity {
                vx: 0.3,
                vy: 0.4,
                vz: 0.0,
                wz: 0.0,
            },
            mode: ControlMode::Twist,
            channel: "joy/0".into(),
            computation: Computation::Onboard,
            failsafe: FailsafeState::Ok,
            health: Health::Ok,
            battery: Some(0.5),
            position_quality: 1.0,
            actuators: vec![0.1, 0.2],
            mission,
        }
    }

    #[test]
    fn route_is_pending_until_acknowledged() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        f.apply(&at(
            1,
            Event::RouteChanged {
                robot: "robot_1".into(),
                channel: Some("joy/0".into()),
                epoch: 1,
            },
        ));
        let r = f.robot("robot_1").unwrap();
        assert!(r.route.is_pending());
        assert_eq!(r.route.requested.as_deref(), Some("joy/0"));
        assert_eq!(r.route.acknowledged, None);
        f.apply(&at(
            2,
            Event::RouteAcked {
                robot: "robot_1".into(),
                channel: Some("joy/0".into()),
                epoch: 1,
            },
        ));
        let r = f.robot("robot_1").unwrap();
        assert!(!r.route.is_pending());
        assert_eq!(r.route.acknowledged.as_deref(), Some("joy/0"));
    }

    #[test]
    fn telemetry_updates_pose_speed_and_a_spaced_trail() {
        let mut cfg = FleetConfig::default();
        cfg.path_history = 2;
        cfg.path_spacing = 0.5;
        let mut f = Fleet::new(cfg);
        f.apply(&at(0, registered("robot_1")));
        for (i, x) in [0.0, 0.1, 1.0, 2.0].into_iter().enumerate() {
            f.apply(&at(
                i as u64,
                Event::Telemetry {
                    robot: "robot_1".into(),
                    telemetry: telemetry(x, None),
                },
            ));
        }
        let r = f.robot("robot_1").unwrap();
        assert_eq!(r.pose.x, 2.0);
        assert!((r.speed() - 0.5).abs() < 1e-12);
        let xs: Vec<f64> = r.path.iter().map(|p| p.x).collect();
        assert_eq!(xs, vec![1.0, 2.0]);
    }

    #[test]
    fn arrival_needs_the_acked_mission_to_finish() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        f.apply(&at(
            1,
            Event::MissionSent {
                robot: "robot_1".into(),
                channel: "wp/gcs".into(),
                id: 7,
                waypoints: vec![Waypoint {
                    x: 1.0,
                    y: 0.0,
                    z: 0.0,
                    time: None,
                }],
                looped: false,
            },
        ));
        let done = Some(MissionProgress {
            id: 7,
            next: 1,
            total: 1,
        });
        f.apply(&at(
            2,
            Event::Telemetry {
                robot: "robot_1".into(),
                telemetry: telemetry(1.0, done),
            },
        ));
        assert!(
            !f.robot("robot_1").unwrap().arrived(),
            "not acknowledged yet"
        );
        f.apply(&at(
            3,
            Event::MissionAcked {
                robot: "robot_1".into(),
                id: 7,
                accepted: true,
                reason: String::new(),
            },
        ));
        assert!(f.robot("robot_1").unwrap().arrived());
        let other = Some(MissionProgress {
            id: 6,
            next: 1,
            total: 1,
        });
        f.apply(&at(
            4,
            Event::Telemetry {
                robot: "robot_1".into(),
                telemetry: telemetry(1.0, other),
            },
        ));
        assert!(
            !f.robot("robot_1").unwrap().arrived(),
            "an older mission finishing is not arrival"
        );
    }

    #[test]
    fn targets_resolve_to_robots_clusters_and_all() {
        let mut f = Fleet::new(FleetConfig::default());
        f.apply(&at(0, registered("robot_1")));
        f.apply(&at(0, registered("robot_2")));
        f.set_cluster("c1", vec!["robot_2".into()]);
        assert_eq!(f.resolve("all").unwrap().len(), 2);
        assert_eq!(f.resolve("c1").unwrap(), vec!["robot_2".to_string()]);
        assert_eq!(f.resolve("robot_1").unwrap(), vec!["robot_1".to_string()]);
        assert!(f.resolve("robot_9").is_none());
    }

    #[test]
    fn event_log_is_bounded() {
        let mut cfg = FleetConfig::default();
        cfg.event_log = 3;
        let mut f = Fleet::new(cfg);
        for i in 0..10 {
            f.log(Severity::Info, format!("line {i}"));
        }
        assert_eq!(f.log.len(), 3);
        assert_eq!(f.log.back().unwrap().text, "line 9");
    }
}
