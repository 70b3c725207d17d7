//! One robot as the station knows it: identity and platform from its
//! registration, pose and state from telemetry (and how old that is), its
//! autopilot's state from its notices, its route, waypoints, mission and
//! recent trail.

use std::collections::VecDeque;
use std::time::Duration;

use mech_proto::{
    AutopilotNews, CommandKind, Computation, ControlMode, FailsafeState, Health, MissionProgress,
    Pose, Telemetry, Velocity, VelocitySource, Waypoint,
};
use serde::{Deserialize, Serialize};

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

/// A robot's autopilot (PX4, ArduPilot) as the robot's notices told the
/// station (`mech_proto::AutopilotNews`): armed or not, its flight mode,
/// whether it answers. The robot says each change, and says both again
/// whenever it registers, so a station that started later knows them too.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct AutopilotState {
    /// `None` until the robot has said.
    pub armed: Option<bool>,
    /// The firmware's name for the mode (`OFFBOARD`, `GUIDED`, `POSCTL`).
    pub mode: Option<String>,
    /// Its heartbeat stopped, and has not been heard again.
    pub lost: bool,
}

impl AutopilotState {
    /// Takes in one fact from a notice.
    pub fn apply(&mut self, news: &AutopilotNews) {
        match news {
            AutopilotNews::Found(_) | AutopilotNews::HeardAgain => self.lost = false,
            AutopilotNews::Armed(armed) => self.armed = Some(*armed),
            AutopilotNews::Mode(mode) => self.mode = Some(mode.clone()),
            AutopilotNews::Lost(_) => self.lost = true,
        }
    }

    /// As a card and a status line show it: `armed OFFBOARD`, `disarmed
    /// POSCTL`, `autopilot lost`.
    pub fn label(&self) -> String {
        if self.lost {
            return "autopilot lost".into();
        }
        let armed = match self.armed {
            Some(true) => "armed",
            Some(false) => "disarmed",
            None => "arming unknown",
        };
        match &self.mode {
            Some(mode) => format!("{armed} {mode}"),
            None => armed.to_string(),
        }
    }
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
    /// Where the robot registered from.
    pub addr: LinkAddr,
    pub link: LinkState,
    /// Which of its links (UDP, radio) the router hears now, and its radio
    /// telemetry budget.
    pub links: RobotLinks,
    /// Times the robot registered (more than once: it restarted or lost
    /// the router).
    pub registrations: u32,
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
    /// Messages the robot reports it ignored as stale (telemetry).
    pub stale: u32,
    /// Rates each way, loss and round trip, as the router last measured
    /// them (once a second).
    pub quality: LinkQuality,
    /// Whether `velocity` was measured by wheel encoders or follows from
    /// the commanded outputs (telemetry).
    pub velocity_source: VelocitySource,
    /// What the robot's safety layer reports (telemetry); `None` for a
    /// robot without one.
    pub safety: Option<mech_proto::SafetyReport>,
    /// The robot's last driver fault notice ("left wheel stalled: ..."),
    /// kept while its telemetry reports the fault.
    pub fault: Option<String>,
    /// The station this robot belongs to when it is another station's,
    /// shown here read-only through a bridge (`mech-zenoh`); `None` for
    /// this station's own robots. Only that station routes it.
    pub remote: Option<String>,
    /// The robot's autopilot, once it has reported one; `None` for a robot
    /// that drives its own motors.
    pub autopilot: Option<AutopilotState>,
}

impl Robot {
    pub(super) fn new(name: &str, id: u16, addr: LinkAddr) -> Robot {
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
            links: RobotLinks::default(),
            registrations: 0,
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
            stale: 0,
            quality: LinkQuality::default(),
            velocity_source: VelocitySource::Commanded,
            safety: None,
            fault: None,
            remote: None,
            autopilot: None,
        }
    }

    /// How old its last telemetry is at router time `now`, while the router
    /// no longer hears the robot (link stale or lost): everything telemetry
    /// said (pose, speed, mode, failsafe) is then as it was that long ago,
    /// not as it is. `None` while it is heard, or before any telemetry.
    pub fn stale_for(&self, now: Duration) -> Option<Duration> {
        if self.link == LinkState::Connected {
            return None;
        }
        self.last_telemetry.map(|t| now.saturating_sub(t))
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

    /// The robot's last telemetry, as the fleet model keeps it.
    pub fn telemetry(&self) -> Telemetry {
        Telemetry {
            pose: self.pose,
            velocity: self.velocity,
            mode: self.mode,
            channel: self.reported_channel.clone().unwrap_or_default(),
            computation: self.computation,
            failsafe: self.failsafe,
            health: self.health,
            battery: self.battery,
            position_quality: self.position_quality,
            actuators: self.actuators.clone(),
            mission: self.mission,
            stale: self.stale,
            velocity_source: self.velocity_source,
            safety: self.safety,
        }
    }

    /// After a registration, the first telemetry tells whether the robot
    /// still holds the mission it acknowledged: if not (its agent
    /// restarted), the mission is marked lost and its id returned, once.
    pub(super) fn mission_lost(&mut self) -> Option<u32> {
        let sent = self.waypoints.sent.as_mut()?;
        let held = self.mission.is_some_and(|p| p.id == sent.id);
        let on_its_channel = self.reported_channel.as_deref() == Some(sent.channel.as_str());
        if self.registrations > 1
            && on_its_channel
            && sent.delivery == MissionDelivery::Acked
            && !held
        {
            sent.delivery = MissionDelivery::Lost;
            return Some(sent.id);
        }
        None
    }

    /// Whether the robot obeys `kind` commands.
    pub fn can(&self, kind: CommandKind) -> bool {
        self.capabilities.contains(&kind)
    }
}
