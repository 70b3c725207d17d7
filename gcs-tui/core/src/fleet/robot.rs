//! One robot as the station knows it: its registration and its last
//! telemetry as the robot sent them (and how old that is), its link, its
//! autopilot's state from its notices, route, waypoints, mission and
//! recent trail.

use std::collections::VecDeque;
use std::time::Duration;

use mech_proto::{AutopilotNews, CommandKind, Hello, Notice, NoticeCode, Telemetry, Waypoint};
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

impl SentMission {
    /// Why the robot does not run this mission although it stored it: it
    /// runs a mission only while routed to the mission's channel, and
    /// `route` (the robot's route now, `None` = none) is another.
    pub fn held(&self, robot: &str, route: Option<&str>) -> Option<String> {
        (self.delivery == MissionDelivery::Acked && route != Some(self.channel.as_str()))
            .then(|| held_mission_text(robot, self.id, &self.channel))
    }
}

/// What the operator is told of a mission a robot stored but does not run,
/// as its channel is not the robot's route: the same words in the event
/// log and on the waypoint panel, with the command that starts it.
pub fn held_mission_text(robot: &str, id: u32, channel: &str) -> String {
    format!(
        "{robot} holds mission {id}; it starts when routed to {channel} (`route {robot} {channel}`)"
    )
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
    /// The robot's autopilot, once it has reported one; `None` for a robot
    /// that drives its own motors.
    pub autopilot: Option<AutopilotState>,
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
            autopilot: None,
        }
    }

    /// What a notice from the robot tells about it: a driver fault's text
    /// (kept while telemetry reports the fault), its autopilot's state.
    pub(super) fn heard_notice(&mut self, notice: &Notice) {
        if notice.code == NoticeCode::DriverFault {
            self.fault = Some(notice.text.clone());
        }
        if let Some(news) = AutopilotNews::parse(&notice.text) {
            self.autopilot.get_or_insert_default().apply(&news);
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
