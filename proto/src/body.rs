//! Message bodies: every payload a MECH envelope can carry, with units.
//!
//! Each payload is a plain struct encoded as a MessagePack array of its fields
//! in declaration order; C-like enums travel as their `u8` value. Field order
//! is part of the protocol: append new fields only with a new version.

use serde::{Deserialize, Serialize};
use serde_repr::{Deserialize_repr, Serialize_repr};

use crate::command::{Command, CommandKind, finite};
use crate::error::Error;
use crate::names::{name, nonempty_name};
use crate::safety::{Arena, ArenaAck, Neighbours, SafetyReport};
use crate::tagged::tagged_enum;
use crate::{MAX_FLEET_PARTS, MAX_TEXT_LEN, MAX_WAYPOINTS};

/// Registration, robot -> router. Sent at start-up and again whenever the
/// agent has not heard a [`Welcome`] (the router treats a repeat from a new
/// address as the same robot moving, not a new robot). The default says
/// nothing (no name, no platform, no capabilities): what a station holds
/// for a robot whose registration it has not heard.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Hello {
    /// Unique robot name, e.g. `robot_1`; also the envelope sender.
    pub name: String,
    /// Platform ("math package") name: `diff-drive`, `kiwi`, `quadcopter`...
    pub platform: String,
    /// Which command kinds the platform obeys.
    pub capabilities: Vec<CommandKind>,
    /// Number of actuator outputs an [`crate::Actuators`] command should carry.
    pub motors: u8,
    /// Top speed, m/s, so ground-side controllers can plan within it.
    pub max_speed: f64,
    /// Top yaw rate, rad/s.
    pub max_yaw_rate: f64,
    /// Agent software version, free text.
    pub agent_version: String,
}

/// Router -> robot answer to [`Hello`]: the registration is accepted and this
/// is the robot's current route (empty channel = routed to none).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Welcome {
    /// Small numeric id the router gave the robot, stable for its lifetime.
    pub robot_id: u16,
    /// The route now in force; see [`Route`].
    pub route: Route,
    /// Router software version, free text.
    pub router_version: String,
}

/// Liveness, both directions. Agents use router heartbeats to detect a lost
/// router even while routed to none; the router uses agent heartbeats (and
/// telemetry) for link state, and the echo in them for the round-trip time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Heartbeat {
    /// Milliseconds since the sender started.
    pub uptime_ms: u64,
    /// A robot's heartbeat echoes the newest router heartbeat it received,
    /// so the router measures the round trip on its own clock. Added to
    /// version 1 at the end, and left out of the array when absent: a
    /// heartbeat without an echo is the one-element array it always was,
    /// and a one-element heartbeat reads as having none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub echo: Option<Echo>,
}

impl Heartbeat {
    /// A heartbeat with no echo (what the router sends).
    pub fn new(uptime_ms: u64) -> Heartbeat {
        Heartbeat {
            uptime_ms,
            echo: None,
        }
    }
}

/// The router heartbeat a robot echoes: which one (its envelope `seq`) and
/// how long the robot held it before this heartbeat left, which the router
/// subtracts from the time the echo took to come back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Echo {
    /// Envelope sequence number of the router heartbeat echoed.
    pub seq: u32,
    /// Microseconds between receiving it and sending this heartbeat.
    pub held_us: u64,
}

/// Robot pose in the world frame (REP 103): metres and radians, heading
/// counter-clockwise from +x, in `(-pi, pi]`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub heading: f64,
}

/// Robot velocity: linear `vx vy vz` in the world frame (m/s) and yaw rate
/// `wz` (rad/s, counter-clockwise positive).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Velocity {
    pub vx: f64,
    pub vy: f64,
    pub vz: f64,
    pub wz: f64,
}

crate::named_enum! {
    /// What the robot is doing with its actuators right now.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize_repr, Deserialize_repr)]
    #[repr(u8)]
    pub enum ControlMode: "control mode" {
        /// No command yet, or routed to none: actuators at zero.
        #[default]
        Idle = 0 => "idle",
        Actuators = 1 => "actuators",
        SteeringThrottle = 2 => "steering-throttle",
        VelocityHeading = 3 => "velocity-heading",
        Twist = 4 => "twist",
        /// Running an onboard waypoint mission.
        Waypoints = 5 => "waypoints",
        /// Obeying a [`crate::Stop`] command.
        Stopped = 6 => "stopped",
    }
}

crate::named_enum! {
    /// Where the closed loop runs for this robot.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize_repr, Deserialize_repr)]
    #[repr(u8)]
    pub enum Computation: "computation" {
        /// On the robot (onboard waypoint navigation, direct commands).
        #[default]
        Onboard = 0 => "onboard",
        /// In the ground station: the robot is routed to an `offboard/<robot>`
        /// channel that closes the loop on telemetry.
        Offboard = 1 => "offboard",
    }
}

crate::named_enum! {
    /// Why a robot's actuators are being held at zero, if they are.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize_repr, Deserialize_repr)]
    #[repr(u8)]
    pub enum FailsafeState: "failsafe state" {
        /// Not holding: commands are obeyed.
        #[default]
        Ok = 0 => "ok",
        /// The active channel has been silent longer than the failsafe timeout.
        ChannelSilent = 1 => "channel-silent",
        /// No message from the router within the link timeout.
        RouterLost = 2 => "router-lost",
        /// Latched emergency stop; only an explicit release clears it.
        EStopped = 3 => "estopped",
        /// A driver reported an error; the agent zeroed what it could.
        Fault = 4 => "fault",
    }
}

crate::named_enum! {
    /// Overall health as the agent judges it.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize_repr, Deserialize_repr)]
    #[repr(u8)]
    pub enum Health: "health" {
        #[default]
        Ok = 0 => "ok",
        /// Working, but something needs attention (low battery, poor position fix).
        Degraded = 1 => "degraded",
        /// A driver has failed.
        Fault = 2 => "fault",
    }
}

crate::named_enum! {
    /// Where a robot's reported velocity comes from, so the station can tell a
    /// robot that drives from one whose wheel is stuck.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize_repr, Deserialize_repr)]
    #[repr(u8)]
    pub enum VelocitySource: "velocity source" {
        /// The twist the current actuator outputs should produce (the platform's
        /// forward kinematics): what a robot without wheel encoders knows.
        #[default]
        Commanded = 0 => "commanded",
        /// Measured by wheel encoders.
        Measured = 1 => "measured",
    }
}

/// Progress of the mission the robot holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct MissionProgress {
    /// [`Mission::id`] of the mission held.
    pub id: u32,
    /// Index of the waypoint being approached; equals `total` when finished.
    pub next: u32,
    /// Number of waypoints in the mission.
    pub total: u32,
}

/// Robot state, robot -> router -> subscribers, at the agent's telemetry rate
/// (default 20 Hz). The default is a robot not heard from yet: idle, at the
/// origin, nothing reported.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Telemetry {
    pub pose: Pose,
    pub velocity: Velocity,
    pub mode: ControlMode,
    /// Channel the agent obeys (its acknowledged route); empty = none.
    pub channel: String,
    pub computation: Computation,
    pub failsafe: FailsafeState,
    pub health: Health,
    /// Battery charge as a fraction in `[0, 1]`, if known.
    pub battery: Option<f64>,
    /// Position fix quality in `[0, 1]` (1 = fresh fix, no outliers rejected).
    pub position_quality: f64,
    /// Last outputs written to the actuators, each in `[-1, 1]`.
    pub actuators: Vec<f64>,
    pub mission: Option<MissionProgress>,
    /// Messages the robot ignored because one newer from the same source
    /// was already obeyed (commands, routes, missions, e-stops), since it
    /// started. Added to version 1 at the end: a telemetry array of 11
    /// elements reads as 0 here.
    #[serde(default)]
    pub stale: u32,
    /// Whether `velocity` was measured (wheel encoders) or follows from the
    /// commanded outputs. Added to version 1 at the end: telemetry without
    /// it reads as commanded.
    #[serde(default)]
    pub velocity_source: VelocitySource,
    /// What the robot's safety layer is doing (see `docs/safety.md`);
    /// `None` for a robot without one. Added to version 1 at the end, and
    /// left out of the array when `None`: telemetry without it is the
    /// array it always was, and reads as `None`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safety: Option<SafetyReport>,
}

/// Latest arrival time a [`Waypoint`] may ask for, s after the mission
/// starts: a day.
pub const MAX_WAYPOINT_TIME: f64 = 86_400.0;

/// One point of a [`Mission`]: position in metres and an optional arrival time
/// in seconds after the mission starts (the robot chooses its speed to meet
/// it). `z` is ignored by ground robots.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Waypoint {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub time: Option<f64>,
}

/// A waypoint list, delivered reliably: the sender repeats it until a
/// [`MissionAck`] with the same `id` arrives. A robot stores the mission for
/// the envelope's channel and runs it only while routed to that channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mission {
    /// Unique per sender; repeats of one upload share it.
    pub id: u32,
    pub waypoints: Vec<Waypoint>,
    /// Start again from the first waypoint after the last.
    pub looped: bool,
    /// Distance, m, within which a waypoint counts as reached.
    pub arrival_radius: f64,
    /// Index of the first waypoint to approach (to resume a mission that was
    /// partly flown elsewhere, e.g. after an offboard -> onboard switch).
    pub start_index: u32,
}

/// Robot -> sender: a [`Mission`] arrived (or why it was refused).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MissionAck {
    pub id: u32,
    pub accepted: bool,
    /// Empty when accepted.
    pub reason: String,
}

/// One robot's part of a [`FleetCommand`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RobotCommand {
    pub robot: String,
    pub command: Command,
}

/// Commands for several robots on one channel (a fleet controller). The router
/// delivers each robot only its own part, as a plain [`Body::Command`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FleetCommand {
    pub parts: Vec<RobotCommand>,
}

/// Which channel a robot obeys. Router -> robot; the robot answers with a
/// [`RouteAck`] and from then on rejects commands on any other channel.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Route {
    pub robot: String,
    /// Channel name; empty = none (the robot holds still).
    pub channel: String,
    /// Increases with every change of this robot's route, so a late ack of an
    /// older route is not mistaken for the current one.
    pub epoch: u32,
}

/// Robot -> router: this route is now in force.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RouteAck {
    pub robot: String,
    pub channel: String,
    pub epoch: u32,
}

/// Emergency stop (`engage = true`) or its explicit release (`false`). An
/// engaged e-stop is latched by every robot that receives it and holds until a
/// release; the sender repeats until every robot has acknowledged `id`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct EStop {
    pub engage: bool,
    pub id: u32,
}

/// Robot -> router: the [`EStop`] with this `id` and `engage` is in force.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct EStopAck {
    pub engage: bool,
    pub id: u32,
}

/// Ask the router which channels are live.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct ChannelsRequest {}

/// A live channel as the router sees it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Channel {
    pub name: String,
    /// Sender name of the last publisher.
    pub publisher: String,
    /// Messages per second over the last few seconds.
    pub rate_hz: f64,
    /// Robots currently routed to this channel.
    pub robots: Vec<String>,
    /// Milliseconds since the channel's last message.
    pub idle_ms: u64,
}

/// Router answer to [`ChannelsRequest`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Channels {
    pub channels: Vec<Channel>,
}

/// Cluster pose: centroid (m) and orientation (rad) in the world frame, and the
/// formation scale (dimensionless multiplier of the formation offsets).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClusterPose {
    pub x: f64,
    pub y: f64,
    pub heading: f64,
    pub scale: f64,
}

/// Cluster velocity in the cluster frame: `vx vy` m/s, `wz` rad/s, and
/// `scale_rate` (1/s) to grow or shrink the formation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClusterVelocity {
    pub vx: f64,
    pub vy: f64,
    pub wz: f64,
    pub scale_rate: f64,
}

tagged_enum! {
    /// What a cluster should do: move at a velocity or go to a pose.
    #[derive(Debug, Clone, PartialEq)]
    pub enum ClusterGoal {
        Velocity(ClusterVelocity) = 1,
        Pose(ClusterPose) = 2,
    }
}

crate::named_enum! {
    /// Named formation shapes; `Custom` uses [`Formation::offsets`].
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize_repr, Deserialize_repr)]
    #[repr(u8)]
    pub enum FormationKind: "formation" {
        Line = 0 => "line",
        Column = 1 => "column",
        Wedge = 2 => "wedge",
        Circle = 3 => "circle",
        Custom = 4 => "custom",
    }
}

/// Member slot offset in the cluster frame, metres (x forward, y left).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Offset {
    pub x: f64,
    pub y: f64,
}

/// A formation: its shape, the spacing between neighbours (m), and explicit
/// offsets for `Custom` (ignored otherwise).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Formation {
    pub kind: FormationKind,
    pub spacing: f64,
    pub offsets: Vec<Offset>,
}

/// Input to a cluster controller, on its channel: which robots form the
/// cluster, the goal, and optionally a new formation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClusterCommand {
    pub cluster: String,
    pub members: Vec<String>,
    pub goal: ClusterGoal,
    pub formation: Option<Formation>,
}

/// Severity of a [`Notice`].
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize_repr, Deserialize_repr,
)]
#[repr(u8)]
pub enum Level {
    Debug = 0,
    Info = 1,
    Warn = 2,
    Error = 3,
}

/// Machine-readable reason of a [`Notice`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize_repr, Deserialize_repr)]
#[repr(u16)]
pub enum NoticeCode {
    /// Free-form information.
    Text = 0,
    /// A message could not be decoded.
    BadMessage = 1,
    /// A command named a robot the receiver does not know.
    UnknownRobot = 2,
    /// A command arrived on a channel the robot is not routed to.
    NotRouted = 3,
    /// The robot cannot obey this kind of command.
    Unsupported = 4,
    /// The failsafe engaged.
    Failsafe = 5,
    /// A driver failed.
    DriverFault = 6,
    /// The robot's fleet safety layer began limiting its commands, or was
    /// switched on or off (at most one notice per change).
    Safety = 7,
    /// The station's permissions refused the receiver's message: its key
    /// may not send that kind, or not on that channel (the text says
    /// which). Sent only to a sender whose message was signed and fresh,
    /// a few times a second at most.
    NotPermitted = 8,
}

/// Error or notice, any direction, for humans and logs.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Notice {
    pub level: Level,
    pub code: NoticeCode,
    pub text: String,
}

/// Ask the router to fan out telemetry (and notices) to the sender
/// (`telemetry = false` unsubscribes). Subscriptions lapse unless renewed
/// within the router's subscriber timeout (default 5 s).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Subscribe {
    pub telemetry: bool,
}

/// An externally measured position (motion capture, another tracker), sent to
/// the robot for its "external" position source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PositionFix {
    pub robot: String,
    pub pose: Pose,
    /// Fix quality in `[0, 1]`.
    pub quality: f64,
}

/// The sender is going away cleanly (agent shutdown, tool exit).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Bye {
    pub reason: String,
}

/// Any peer -> router: what is the station's time? Signed messages carry
/// station time, and a robot without a real-time clock (a Pi booted without
/// network time) asks before it signs anything else. The `nonce` is random,
/// so a replayed answer is recognised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TimeRequest {
    pub nonce: u64,
}

/// Router -> requester: the station's clock when it answered a
/// [`TimeRequest`], with the request's nonce.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    pub nonce: u64,
    /// Microseconds since the Unix epoch.
    pub station_us: u64,
}

crate::named_enum! {
    /// What an operator asks a robot's autopilot (PX4, ArduPilot) to do. The
    /// agent never arms, disarms or changes the autopilot's mode by itself:
    /// only on one of these.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize_repr, Deserialize_repr)]
    #[repr(u8)]
    pub enum AutopilotAction: "autopilot action" {
        /// Stop the motors (refused by the autopilot in flight).
        Disarm = 0 => "disarm",
        /// Start the motors.
        Arm = 1 => "arm",
        /// Hand control to the agent: PX4 OFFBOARD, ArduPilot GUIDED.
        Offboard = 2 => "offboard",
        /// The autopilot holds where it is on its own: PX4 Hold (AUTO.LOITER),
        /// ArduCopter LOITER, ArduRover HOLD.
        Hold = 3 => "hold",
        /// Land where it is: PX4 AUTO.LAND, ArduCopter LAND.
        Land = 4 => "land",
        /// Climb to `altitude` metres above home (MAV_CMD_NAV_TAKEOFF).
        Takeoff = 5 => "takeoff",
    }
}

impl AutopilotAction {
    /// Whether the action can start the vehicle moving, and so is refused
    /// while the robot is e-stopped.
    pub fn starts_motion(self) -> bool {
        matches!(
            self,
            AutopilotAction::Arm | AutopilotAction::Offboard | AutopilotAction::Takeoff
        )
    }
}

/// Operator -> router -> robot: a request to the robot's autopilot (arm,
/// disarm, mode change, land, take off). Only an operator may send it; the
/// router passes it to the named robot whatever its route, and the robot
/// answers with a [`Notice`] saying what the autopilot did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AutopilotRequest {
    pub robot: String,
    pub action: AutopilotAction,
    /// Metres above home for [`AutopilotAction::Takeoff`]; 0 otherwise.
    pub altitude: f64,
}

tagged_enum! {
    /// Every MECH message body; the number is the envelope's kind field.
    #[derive(Debug, Clone, PartialEq)]
    pub enum Body {
        Hello(Hello) = 1,
        Welcome(Welcome) = 2,
        Heartbeat(Heartbeat) = 3,
        Telemetry(Telemetry) = 4,
        Command(Command) = 5,
        FleetCommand(FleetCommand) = 6,
        Mission(Mission) = 7,
        MissionAck(MissionAck) = 8,
        Route(Route) = 9,
        RouteAck(RouteAck) = 10,
        EStop(EStop) = 11,
        EStopAck(EStopAck) = 12,
        ChannelsRequest(ChannelsRequest) = 13,
        Channels(Channels) = 14,
        Cluster(ClusterCommand) = 15,
        Notice(Notice) = 16,
        Subscribe(Subscribe) = 17,
        PositionFix(PositionFix) = 18,
        Bye(Bye) = 19,
        TimeRequest(TimeRequest) = 20,
        Time(Time) = 21,
        Autopilot(AutopilotRequest) = 22,
        Arena(Arena) = 23,
        ArenaAck(ArenaAck) = 24,
        Neighbours(Neighbours) = 25,
    }
}

fn text(v: &str, what: &str) -> Result<(), Error> {
    if v.len() > MAX_TEXT_LEN {
        return Err(Error::invalid(format!(
            "{what} is {} bytes long, at most {MAX_TEXT_LEN} allowed",
            v.len()
        )));
    }
    Ok(())
}

fn count(n: usize, max: usize, what: &str) -> Result<(), Error> {
    if n > max {
        return Err(Error::invalid(format!("{n} {what}, at most {max} allowed")));
    }
    Ok(())
}

fn fraction(v: f64, what: &str) -> Result<(), Error> {
    finite(v, what)?;
    if (0.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(Error::invalid(format!("{what} {v} is outside [0, 1]")))
    }
}

fn pose(p: &Pose) -> Result<(), Error> {
    finite(p.x, "pose x")?;
    finite(p.y, "pose y")?;
    finite(p.z, "pose z")?;
    finite(p.heading, "pose heading")
}

/// A robot name and the channel it is (or is to be) routed to; an empty
/// channel is routed to none.
fn robot_on_channel(robot: &str, channel: &str) -> Result<(), Error> {
    nonempty_name(robot, "robot name")?;
    name(channel, "channel")
}

impl Body {
    /// Checks every field against the protocol's ranges and limits: names,
    /// counts, finite numbers, fractions. Called by [`crate::encode`] and
    /// [`crate::decode`], so no invalid message is ever sent or accepted.
    pub fn validate(&self) -> Result<(), Error> {
        match self {
            Body::Hello(h) => h.validate(),
            Body::Welcome(w) => w.validate(),
            Body::Heartbeat(_) | Body::ChannelsRequest(_) | Body::Subscribe(_) => Ok(()),
            Body::Telemetry(t) => t.validate(),
            Body::Command(c) => c.validate(),
            Body::FleetCommand(f) => f.validate(),
            Body::Mission(m) => m.validate(),
            Body::MissionAck(a) => text(&a.reason, "mission ack reason"),
            Body::Route(r) => robot_on_channel(&r.robot, &r.channel),
            Body::RouteAck(r) => robot_on_channel(&r.robot, &r.channel),
            Body::EStop(_) | Body::EStopAck(_) => Ok(()),
            Body::Channels(c) => c.validate(),
            Body::Cluster(c) => c.validate(),
            Body::Notice(n) => text(&n.text, "notice text"),
            Body::PositionFix(p) => p.validate(),
            Body::Bye(b) => text(&b.reason, "bye reason"),
            Body::TimeRequest(_) | Body::Time(_) => Ok(()),
            Body::Autopilot(a) => a.validate(),
            Body::Arena(a) => a.validate(),
            Body::ArenaAck(a) => nonempty_name(&a.robot, "robot name"),
            Body::Neighbours(n) => n.validate(),
        }
    }
}

impl Hello {
    fn validate(&self) -> Result<(), Error> {
        nonempty_name(&self.name, "robot name")?;
        nonempty_name(&self.platform, "platform")?;
        count(
            self.capabilities.len(),
            CommandKind::ALL.len() * 4,
            "capabilities",
        )?;
        count(self.motors as usize, crate::MAX_MOTORS, "motors")?;
        finite(self.max_speed, "max speed")?;
        finite(self.max_yaw_rate, "max yaw rate")?;
        text(&self.agent_version, "agent version")
    }
}

impl Welcome {
    fn validate(&self) -> Result<(), Error> {
        robot_on_channel(&self.route.robot, &self.route.channel)?;
        text(&self.router_version, "router version")
    }
}

impl Telemetry {
    /// The checks a received telemetry passes (finite, in range, a valid
    /// channel name), for telemetry that arrives another way (a bridge).
    pub fn validate(&self) -> Result<(), Error> {
        pose(&self.pose)?;
        finite(self.velocity.vx, "velocity vx")?;
        finite(self.velocity.vy, "velocity vy")?;
        finite(self.velocity.vz, "velocity vz")?;
        finite(self.velocity.wz, "velocity wz")?;
        name(&self.channel, "channel")?;
        if let Some(b) = self.battery {
            fraction(b, "battery")?;
        }
        fraction(self.position_quality, "position quality")?;
        count(self.actuators.len(), crate::MAX_MOTORS, "actuator outputs")?;
        for a in &self.actuators {
            finite(*a, "actuator output")?;
        }
        if let Some(s) = &self.safety {
            s.validate()?;
        }
        Ok(())
    }
}

impl FleetCommand {
    fn validate(&self) -> Result<(), Error> {
        count(self.parts.len(), MAX_FLEET_PARTS, "fleet command parts")?;
        for p in &self.parts {
            nonempty_name(&p.robot, "robot name")?;
            p.command.validate()?;
        }
        Ok(())
    }
}

impl Mission {
    fn validate(&self) -> Result<(), Error> {
        count(self.waypoints.len(), MAX_WAYPOINTS, "waypoints")?;
        for w in &self.waypoints {
            w.validate()?;
        }
        finite(self.arrival_radius, "arrival radius")?;
        if self.arrival_radius <= 0.0 {
            return Err(Error::invalid("arrival radius must be positive"));
        }
        if self.start_index as usize > self.waypoints.len() {
            return Err(Error::invalid(format!(
                "start index {} is past the {} waypoints",
                self.start_index,
                self.waypoints.len()
            )));
        }
        Ok(())
    }
}

impl Waypoint {
    fn validate(&self) -> Result<(), Error> {
        finite(self.x, "waypoint x")?;
        finite(self.y, "waypoint y")?;
        finite(self.z, "waypoint z")?;
        if let Some(t) = self.time {
            finite(t, "waypoint time")?;
            if t < 0.0 {
                return Err(Error::invalid(format!("waypoint time {t} is negative")));
            }
            if t > MAX_WAYPOINT_TIME {
                return Err(Error::invalid(format!(
                    "waypoint time {t} s is more than {MAX_WAYPOINT_TIME} s (a day)"
                )));
            }
        }
        Ok(())
    }
}

impl Channels {
    fn validate(&self) -> Result<(), Error> {
        count(self.channels.len(), MAX_FLEET_PARTS, "channels")?;
        for ch in &self.channels {
            nonempty_name(&ch.name, "channel")?;
            name(&ch.publisher, "publisher")?;
            finite(ch.rate_hz, "channel rate")?;
            count(ch.robots.len(), MAX_FLEET_PARTS, "robots on a channel")?;
            for r in &ch.robots {
                nonempty_name(r, "robot name")?;
            }
        }
        Ok(())
    }
}

impl ClusterCommand {
    fn validate(&self) -> Result<(), Error> {
        nonempty_name(&self.cluster, "cluster name")?;
        count(self.members.len(), MAX_FLEET_PARTS, "cluster members")?;
        for m in &self.members {
            nonempty_name(m, "robot name")?;
        }
        self.goal.validate()?;
        if let Some(f) = &self.formation {
            f.validate()?;
        }
        Ok(())
    }
}

impl ClusterGoal {
    fn validate(&self) -> Result<(), Error> {
        match self {
            ClusterGoal::Velocity(v) => {
                finite(v.vx, "cluster vx")?;
                finite(v.vy, "cluster vy")?;
                finite(v.wz, "cluster wz")?;
                finite(v.scale_rate, "cluster scale rate")
            }
            ClusterGoal::Pose(p) => {
                finite(p.x, "cluster x")?;
                finite(p.y, "cluster y")?;
                finite(p.heading, "cluster heading")?;
                finite(p.scale, "cluster scale")
            }
        }
    }
}

impl Formation {
    fn validate(&self) -> Result<(), Error> {
        finite(self.spacing, "formation spacing")?;
        count(self.offsets.len(), MAX_FLEET_PARTS, "formation offsets")?;
        for o in &self.offsets {
            finite(o.x, "offset x")?;
            finite(o.y, "offset y")?;
        }
        Ok(())
    }
}

impl AutopilotRequest {
    fn validate(&self) -> Result<(), Error> {
        nonempty_name(&self.robot, "robot name")?;
        finite(self.altitude, "altitude")?;
        if self.action == AutopilotAction::Takeoff && self.altitude <= 0.0 {
            return Err(Error::invalid(format!(
                "takeoff altitude {} m must be positive",
                self.altitude
            )));
        }
        Ok(())
    }
}

impl PositionFix {
    fn validate(&self) -> Result<(), Error> {
        nonempty_name(&self.robot, "robot name")?;
        pose(&self.pose)?;
        fraction(self.quality, "fix quality")
    }
}

impl Route {
    /// The routed channel, or `None` when routed to none.
    pub fn channel(&self) -> Option<&str> {
        (!self.channel.is_empty()).then_some(self.channel.as_str())
    }
}
