//! The view model: what a station sends about the fleet and a UI shows, as
//! a plain snapshot of robots, channels and clusters refreshed from the
//! core's fleet model (`mech_core::fleet`) and router; the attach protocol
//! carries it ([`crate::wire`]).
//!
//! The UI never derives link state, routes or failsafes itself; it copies
//! them from the core, so screens and tests can be built from fixed values.

use mech_proto::{
    Computation, ControlMode, FailsafeState, Health, Intervention, MissionProgress, Pose,
    SafetyReport, SafetyState, Telemetry, Velocity, VelocitySource,
};
use serde::{Deserialize, Serialize};

/// The arena robots are kept inside, as the map draws it (the core's
/// type: boundary, keep-outs, slow zones, obstacle discs, margin).
pub use mech_core::ArenaShape;

/// Rates each way, loss and round trip of a robot's link, as the router
/// measures them (the core's type, copied).
pub use mech_core::LinkQuality;
/// Link to a robot as the router judges it from its timeouts (the core's
/// type: the UI copies it, never derives it).
pub use mech_core::LinkState;
pub use mech_core::auth::Security;
/// A robot's autopilot as its notices told the station (the core's type).
pub use mech_core::fleet::AutopilotState;

/// How long a robot's path stays on the map.
pub const TRAIL_SECONDS: f64 = 10.0;

/// How a card spells a link state.
pub fn link_label(link: LinkState) -> &'static str {
    match link {
        LinkState::Connected => "Connected",
        LinkState::Stale => "Stale",
        LinkState::Lost => "Lost",
    }
}

/// Route of a robot: the channel the router forwards, and whether the agent
/// has acknowledged it yet.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct RouteView {
    /// Empty = routed to none.
    pub channel: String,
    pub acknowledged: bool,
}

/// One robot, as the cards and the map show it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotView {
    pub name: String,
    /// Router-assigned id.
    pub id: u16,
    pub platform: String,
    /// What the robot last said of itself, as the fleet model holds it.
    /// The attach protocol carries its pose, velocity and where that
    /// comes from, mode, computation, failsafe, health, battery and
    /// mission, at the robot's top level ([`CardTelemetry`]); a client
    /// reads the rest as the defaults (the channel the robot obeys is in
    /// `route`, its safety layer in `safety`).
    #[serde(flatten, with = "CardTelemetry")]
    pub telemetry: Telemetry,
    pub route: RouteView,
    pub link: LinkState,
    /// Live links and radio budget of a robot with a radio
    /// (`wifi*+radio 14Hz`); empty for a robot on UDP alone.
    pub links: String,
    /// The robot's driver fault text while it reports the fault.
    pub fault: Option<String>,
    /// Where the robot went in the last [`TRAIL_SECONDS`],
    /// oldest first (x, y in m): the core's recorded path, not a copy the
    /// UI keeps.
    pub trail: Vec<(f64, f64)>,
    /// The link as the router measures it (absent from an older
    /// station's snapshot: not measured).
    #[serde(default)]
    pub quality: LinkQuality,
    /// The other station this robot belongs to (shown read-only, through
    /// a bridge); `None` for this station's robots. Absent in the attach
    /// protocol from a station that predates it.
    #[serde(default)]
    pub remote: Option<String>,
    /// While the router no longer hears the robot (link stale or lost):
    /// seconds since its last telemetry, so pose, speed, mode and failsafe
    /// are shown as what it last said, not as live. `None` while it is
    /// heard (and from a station that predates it).
    #[serde(default)]
    pub stale_for: Option<f64>,
    /// The robot's autopilot (armed, flight mode, whether it answers) for a
    /// robot flown by one; `None` for any other (and from a station that
    /// predates it).
    #[serde(default)]
    pub autopilot: Option<AutopilotState>,
    /// Its fleet safety layer, when it reports one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyView>,
    /// The mission the station itself last sent it (an operator's
    /// waypoints, a script's), for tools attached to the station; `None`
    /// when it sent none (missions of external controllers go from their
    /// sender to the robot).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sent_mission: Option<MissionView>,
    /// Why the robot stands still with a mission: it stored the station's
    /// mission, but runs it only once routed to its channel. The words the
    /// event log says too, with the command that starts it; `None` when no
    /// mission waits so (and from a station that predates it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mission_held: Option<String>,
}

/// A robot's telemetry as the attach protocol carries it, each field at
/// the robot's top level where it has always been (`docs/control-protocol.md`,
/// *Fleet*); the fields skipped do not cross.
#[derive(Serialize, Deserialize)]
#[serde(remote = "Telemetry")]
struct CardTelemetry {
    pose: Pose,
    velocity: Velocity,
    mode: ControlMode,
    #[serde(skip)]
    channel: String,
    computation: Computation,
    failsafe: FailsafeState,
    health: Health,
    /// Fraction `[0, 1]`.
    battery: Option<f64>,
    #[serde(skip)]
    position_quality: f64,
    #[serde(skip)]
    actuators: Vec<f64>,
    mission: Option<MissionProgress>,
    #[serde(skip)]
    stale: u32,
    /// Measured by wheel encoders, or following from the commands.
    velocity_source: VelocitySource,
    #[serde(skip)]
    safety: Option<SafetyReport>,
}

/// A mission the station sent a robot.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MissionView {
    pub id: u32,
    /// The channel it was sent on (`wp/gcs`).
    pub channel: String,
    pub waypoints: Vec<mech_proto::Waypoint>,
    pub looped: bool,
}

/// A robot's fleet safety layer, as its card shows it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SafetyView {
    /// What the robot reports: on, off, or no arena yet.
    pub state: SafetyState,
    /// What the layer limits now (`None`: nothing).
    pub intervention: Intervention,
    /// Interventions begun so far, every reason together.
    pub interventions: u64,
    /// Switched off, or asked to be: shown as an alarm.
    pub alarm: bool,
    /// The disc the layer keeps apart and inside, m: the robot's radius
    /// grown by `position_error` (0 when unknown).
    pub footprint: f64,
    /// How far the robot's position estimate may be from the truth, m.
    pub position_error: f64,
}

impl RobotView {
    /// Ground speed, m/s.
    pub fn speed(&self) -> f64 {
        let v = self.telemetry.velocity;
        v.vx.hypot(v.vy)
    }

    /// Heading in degrees, `(-180, 180]`, counter-clockwise from +x.
    pub fn heading_deg(&self) -> f64 {
        let d = self.telemetry.pose.heading.to_degrees().rem_euclid(360.0);
        if d > 180.0 { d - 360.0 } else { d }
    }

    /// A robot with only a name and a position, every status at its default.
    pub fn at(name: &str, id: u16, platform: &str, x: f64, y: f64, heading: f64) -> Self {
        Self {
            name: name.to_string(),
            id,
            platform: platform.to_string(),
            telemetry: Telemetry {
                pose: Pose {
                    x,
                    y,
                    z: 0.0,
                    heading,
                },
                ..Telemetry::default()
            },
            route: RouteView::default(),
            link: LinkState::Connected,
            links: String::new(),
            fault: None,
            trail: Vec::new(),
            quality: LinkQuality::default(),
            remote: None,
            stale_for: None,
            autopilot: None,
            safety: None,
            sent_mission: None,
            mission_held: None,
        }
    }
}

/// A live controller channel seen by the router.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelView {
    pub name: String,
    /// Last publisher's sender name.
    pub publisher: String,
    pub rate_hz: f64,
}

/// A named group of robots driven together, as the map and the routes
/// panel show it: its members from the fleet model and, once a cluster
/// controller runs it, what that controller reports (not to be confused
/// with [`mech_control::ClusterView`], the controller's own account).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClusterOnScreen {
    pub name: String,
    pub members: Vec<String>,
    /// What the cluster controller reports, once it runs this cluster.
    pub control: Option<ClusterControlView>,
}

/// A cluster controller's last period, as the map and the routes panel
/// show it (copied from [`mech_control::ControlHub::snapshot`]).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ClusterControlView {
    /// Cluster pose being tracked (x, y, heading).
    pub desired: Option<(f64, f64, f64)>,
    /// Cluster pose measured from the members (x, y, heading).
    pub measured: Option<(f64, f64, f64)>,
    /// Slot target and tracking error of each commanded member.
    pub slots: Vec<SlotView>,
    /// Members with stale telemetry (not commanded).
    pub lost: Vec<String>,
    /// Members not routed to the cluster's channel (or not registered).
    pub absent: Vec<String>,
}

/// One member's slot in the formation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SlotView {
    pub robot: String,
    /// Slot position, m.
    pub x: f64,
    pub y: f64,
    /// Distance from the member to its slot, m.
    pub error: f64,
}

impl ClusterControlView {
    /// The view of one cluster controller's status.
    pub fn from_status(s: &mech_control::ClusterStatus) -> ClusterControlView {
        let pose = |p: &mech_proto::ClusterPose| (p.x, p.y, p.heading);
        ClusterControlView {
            desired: s.desired.as_ref().map(pose),
            measured: s.measured.as_ref().map(pose),
            slots: s
                .slots
                .iter()
                .map(|t| SlotView {
                    robot: t.robot.clone(),
                    x: t.x,
                    y: t.y,
                    error: t.error,
                })
                .collect(),
            lost: s.lost.clone(),
            absent: s.absent.clone(),
        }
    }
}

/// The arena rectangle from the config, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ArenaBounds {
    pub min_x: f64,
    pub min_y: f64,
    pub max_x: f64,
    pub max_y: f64,
}

/// Everything the core reports in one refresh.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FleetSnapshot {
    pub robots: Vec<RobotView>,
    pub channels: Vec<ChannelView>,
    /// E-stop engaged (latched) fleet-wide.
    pub estop: bool,
    /// Clusters, when the source keeps them (`None` leaves the UI's own).
    pub clusters: Option<Vec<ClusterOnScreen>>,
    /// Whether the station checks signatures (and how exposed it is if not).
    pub security: Security,
    /// Messages the station refused (bad tag, replay, not permitted...).
    pub rejected: u64,
    /// Where a replayed recording is (`None` for a live station).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replay: Option<ReplayClock>,
    /// The station's arena, when it has one (drawn on the map).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arena: Option<ArenaShape>,
}

impl FleetSnapshot {
    /// The robots whose safety layer is off (an alarm in the status bar).
    pub fn safety_off(&self) -> impl Iterator<Item = &RobotView> {
        self.robots
            .iter()
            .filter(|r| r.safety.is_some_and(|s| s.alarm))
    }
}

/// A replay's position, pace and span, in seconds of router time.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ReplayClock {
    pub at: f64,
    pub start: f64,
    pub end: f64,
    /// Recording seconds per wall-clock second.
    pub speed: f64,
    pub paused: bool,
}

impl ReplayClock {
    /// As the status bar shows it: `replay 12.3/60.0 s x2 paused`.
    pub fn label(&self) -> String {
        format!(
            "replay {:.1}/{:.1} s x{} {}",
            self.at,
            self.end,
            self.speed,
            if self.paused { "paused" } else { "playing" }
        )
    }
}

/// Short labels of protocol enums for the fleet table and cards: narrower
/// than their written names (`as_str`: `steering-throttle`, `estopped`),
/// and shouting the states an operator must not miss.
pub fn mode_str(m: ControlMode) -> &'static str {
    match m {
        ControlMode::Idle => "idle",
        ControlMode::Actuators => "actuators",
        ControlMode::SteeringThrottle => "steer-thr",
        ControlMode::VelocityHeading => "vel-head",
        ControlMode::Twist => "twist",
        ControlMode::Waypoints => "waypoints",
        ControlMode::Stopped => "stopped",
    }
}

pub fn failsafe_str(f: FailsafeState) -> &'static str {
    match f {
        FailsafeState::Ok => "ok",
        FailsafeState::ChannelSilent => "silent",
        FailsafeState::RouterLost => "router-lost",
        FailsafeState::EStopped => "E-STOPPED",
        FailsafeState::Fault => "fault",
    }
}

/// How a card tags a speed: measured by encoders or following from the
/// commands (a stuck wheel shows as a commanded speed with no measured one).
pub fn velocity_source_str(v: VelocitySource) -> &'static str {
    match v {
        VelocitySource::Measured => "meas",
        VelocitySource::Commanded => "cmd",
    }
}

/// How a card names what the safety layer does to a robot's commands.
pub fn intervention_str(i: Intervention) -> &'static str {
    i.as_str()
}

pub fn health_str(h: Health) -> &'static str {
    match h {
        Health::Ok => "ok",
        Health::Degraded => "degraded",
        Health::Fault => "FAULT",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_robot_crosses_the_attach_protocol_with_the_keys_it_always_had() {
        let mut r = RobotView::at("robot_1", 1, "diff-drive", 1.0, 2.0, 0.5);
        r.telemetry.mode = ControlMode::Twist;
        r.telemetry.battery = Some(0.8);
        r.telemetry.velocity_source = VelocitySource::Measured;
        let v = serde_json::to_value(&r).unwrap();
        let mut keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        keys.sort_unstable();
        assert_eq!(
            keys,
            [
                "autopilot",
                "battery",
                "computation",
                "failsafe",
                "fault",
                "health",
                "id",
                "link",
                "links",
                "mission",
                "mode",
                "name",
                "platform",
                "pose",
                "quality",
                "remote",
                "route",
                "stale_for",
                "trail",
                "velocity",
                "velocity_source",
            ]
        );
        assert_eq!(v["pose"]["x"], 1.0);
        assert_eq!(v["mode"], 4, "numeric, as docs/protocol.md numbers it");
        assert_eq!(serde_json::from_value::<RobotView>(v).unwrap(), r);
        // What the card does not show stays at the station.
        r.telemetry.actuators = vec![0.5, -0.5];
        let back: RobotView = serde_json::from_value(serde_json::to_value(&r).unwrap()).unwrap();
        assert!(back.telemetry.actuators.is_empty());
    }
}
