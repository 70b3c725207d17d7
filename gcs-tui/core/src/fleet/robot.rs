//! One robot as the station knows it: its registration and its last
//! telemetry as the robot sent them, its link, route, waypoints, mission
//! and recent trail.

use std::collections::VecDeque;
use std::time::Duration;

use mech_proto::{CommandKind, Hello, Telemetry, Waypoint};

use crate::counters::{LinkQuality, Traffic};
use crate::event::{LinkAddr, LinkState, RobotLinks};

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
pub enum MissionDelivery {
    /// Being sent, repeated until acknowledged.
    Sending,
    /// The robot stored it.
    Acked,
    /// The robot refused it.
    Refused(String),
    /// No acknowledgement in time.
    Failed(String),
    /// Acknowledged, but the robot registered again without it (its agent
    /// restarted): it is not running, and resumes only if sent again.
    Lost,
}

/// A mission sent to a robot.
#[derive(Debug, Clone, PartialEq)]
pub struct SentMission {
    pub id: u32,
    pub channel: String,
    pub waypoints: Vec<Waypoint>,
    pub looped: bool,
    pub delivery: MissionDelivery,
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

/// How a robot registered: what it said in its [`Hello`] and what the
/// router made of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// Router-assigned id, stable while the station runs.
    pub id: u16,
    /// The robot's registration as it sent it: platform, capabilities,
    /// motors, limits (for another station's robot, as that station
    /// publishes it).
    pub hello: Hello,
    /// Where the robot registered from.
    pub addr: LinkAddr,
    /// Times the robot registered (more than once: it restarted or lost
    /// the router).
    pub count: u32,
}

/// Everything the GCS knows about one robot.
#[derive(Debug, Clone, PartialEq)]
pub struct Robot {
    /// The name the station shows it under (`robot@station` for another
    /// station's).
    pub name: String,
    pub registration: Registration,
    pub link: LinkState,
    /// Which of its links (UDP, radio) the router hears now, and its radio
    /// telemetry budget.
    pub links: RobotLinks,
    /// Rates each way, loss and round trip, as the router last measured
    /// them (once a second).
    pub quality: LinkQuality,
    /// Traffic counters (copied in by [`crate::Gcs::snapshot`]).
    pub traffic: Traffic,
    /// Router time of the last telemetry; `None` while `telemetry` is the
    /// default of a robot not heard from yet.
    pub last_telemetry: Option<Duration>,
    /// The robot's last telemetry, as it sent it.
    pub telemetry: Telemetry,
    /// The robot's last driver fault notice ("left wheel stalled: ..."),
    /// kept while its telemetry reports the fault.
    pub fault: Option<String>,
    pub route: RouteState,
    pub waypoints: WaypointList,
    /// Recent trail, oldest first.
    pub path: VecDeque<PathPoint>,
    /// Mode the GCS command line uses when it drives this robot.
    pub gcs_mode: Option<CommandKind>,
    /// Id of the last e-stop or release this robot acknowledged.
    pub estop_ack: Option<(bool, u32)>,
    /// Whether the station has this robot's safety layer on (an operator's
    /// `safety off` clears it; the robot's report, in its telemetry, says
    /// when it applies).
    pub safety_enabled: bool,
    /// The station this robot belongs to when it is another station's,
    /// shown here read-only through a bridge (`mech-zenoh`); `None` for
    /// this station's own robots. Only that station routes it.
    pub remote: Option<String>,
}

impl Robot {
    pub(super) fn new(name: &str, id: u16, addr: LinkAddr) -> Robot {
        Robot {
            name: name.to_string(),
            registration: Registration {
                id,
                hello: Hello::default(),
                addr,
                count: 0,
            },
            link: LinkState::Connected,
            links: RobotLinks::default(),
            quality: LinkQuality::default(),
            traffic: Traffic::default(),
            last_telemetry: None,
            telemetry: Telemetry::default(),
            fault: None,
            route: RouteState::default(),
            waypoints: WaypointList::default(),
            path: VecDeque::new(),
            gcs_mode: None,
            estop_ack: None,
            safety_enabled: true,
            remote: None,
        }
    }

    /// The channel the robot reports obeying (telemetry); `None` = none.
    pub fn reported_channel(&self) -> Option<&str> {
        Some(self.telemetry.channel.as_str()).filter(|c| !c.is_empty())
    }

    /// Ground speed, m/s.
    pub fn speed(&self) -> f64 {
        let v = self.telemetry.velocity;
        v.vx.hypot(v.vy)
    }

    /// Heading, rad, counter-clockwise from +x.
    pub fn heading(&self) -> f64 {
        self.telemetry.pose.heading
    }

    /// Distance (m, in the plane) from the robot to a point.
    pub fn distance_to(&self, x: f64, y: f64) -> f64 {
        let p = self.telemetry.pose;
        (p.x - x).hypot(p.y - y)
    }

    /// Whether the last mission sent was acknowledged and the robot reports
    /// it finished.
    pub fn arrived(&self) -> bool {
        match (&self.waypoints.sent, &self.telemetry.mission) {
            (Some(sent), Some(p)) => {
                sent.delivery == MissionDelivery::Acked
                    && p.id == sent.id
                    && p.total > 0
                    && p.next >= p.total
            }
            _ => false,
        }
    }

    /// Whether this station's router drives the robot (not another
    /// station's, shown read-only).
    pub fn is_local(&self) -> bool {
        self.remote.is_none()
    }

    /// After a registration, the first telemetry tells whether the robot
    /// still holds the mission it acknowledged: if not (its agent
    /// restarted), the mission is marked lost and its id returned, once.
    pub(super) fn mission_lost(&mut self) -> Option<u32> {
        let sent = self.waypoints.sent.as_mut()?;
        let held = self.telemetry.mission.is_some_and(|p| p.id == sent.id);
        let reported = &self.telemetry.channel;
        let on_its_channel = !reported.is_empty() && *reported == sent.channel;
        if self.registration.count > 1
            && on_its_channel
            && sent.delivery == MissionDelivery::Acked
            && !held
        {
            sent.delivery = MissionDelivery::Lost;
            return Some(sent.id);
        }
        None
    }

    /// Whether the robot's safety layer is off, or asked to be: an alarm
    /// on its card, in the status bar and in `status`.
    pub fn safety_alarm(&self) -> bool {
        !self.safety_enabled || self.telemetry.safety.is_some_and(|s| s.alarm())
    }

    /// Whether the robot obeys `kind` commands.
    pub fn can(&self, kind: CommandKind) -> bool {
        self.registration.hello.capabilities.contains(&kind)
    }
}
