//! Ground-side closed-loop controllers: cluster-space (fleet) control with
//! formations and slot assignment, follow-the-leader, and offboard waypoint
//! navigation; [`ControlHub`] runs them against the router on the channels
//! `fleet/<cluster>`, `follow/<leader>` and `offboard/<robot>`, and the
//! verbs of [`lang`] (`formation`, `cluster-move`, `follow`, `nav`...) drive
//! them.
//!
//! Every controller here is a pure state machine over plain inputs: each
//! member's last [`MemberState`] (pose, velocity and platform limits taken from
//! telemetry and registration) and an injected time `now` in seconds. A step
//! returns the vehicle-level [`mech_proto::Command`] for every member the
//! controller still commands, together with a status snapshot (slot targets,
//! tracking errors, lost members) that displays can read. Nothing in this
//! controller does I/O or reads a clock, so every timeout is tested with
//! stepped time.
//!
//! Safety rules shared by all controllers:
//! - a member whose telemetry is older than its controller's `telemetry_timeout`
//!   is *lost*: it receives no command at all (its channel falls silent and its
//!   agent's failsafe stops it) and the step reports it;
//! - a member missing from the step's input (for instance routed away from the
//!   controller's channel) is dropped from the outputs in that same step.

mod assignment;
mod cluster;
pub mod files;
mod follow;
mod formation;
mod geometry;
mod hub;
pub mod lang;
pub mod mission_file;
mod offboard;
pub mod playback;
pub mod script;
mod spec;
mod tracking;

pub use assignment::{assign_slots, total_distance};
pub use cluster::{
    ClusterConfig, ClusterController, ClusterMotion, ClusterOutput, ClusterStatus, ClusterWaypoint,
    SlotTarget,
};
pub use follow::{FollowConfig, FollowOutput, FollowTarget, FollowTheLeader, Follower};
pub use formation::{FormationError, slot_offsets};
pub use geometry::wrap_angle;
pub use hub::{
    ClusterView, ControlError, ControlHub, ControlSnapshot, FollowView, HubConfig, NavView,
    TrackingStats, cluster_channel, follow_channel, offboard_channel,
};
pub use lang::verbs::cluster_expect::ErrorMetric;
pub use lang::verbs::cluster_wait::ClusterUntil;
pub use lang::verbs::nav::NavSide;
pub use offboard::{NavConfig, NavOutput, OffboardNavigator};
pub use spec::{
    ClusterSpec, ClusterStickRates, ClusterSticks, DEFAULT_SPACING, SpecError,
    cluster_velocity_from_sticks, formation_kind, parse_cluster_waypoint, parse_formation,
    parse_offset,
};
pub use tracking::{Reference, TrackingGains, track};

use std::collections::BTreeSet;

use mech_proto::{CommandKind, Hello, Pose, Velocity};

/// How a platform can move in the plane, which decides the tracking law.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kinematics {
    /// Can translate in any direction while turning (kiwi, quadcopter,
    /// mecanum): tracked with a body twist.
    Holonomic,
    /// Can only drive along its heading (differential drive, skid steer,
    /// car-like): tracked with point-offset feedback linearisation.
    NonHolonomic,
}

impl Kinematics {
    /// Kinematics of a platform from its registered name. Platforms that name
    /// a wheeled base without lateral wheels are non-holonomic; everything
    /// else that accepts a twist is treated as holonomic.
    pub fn of_platform(platform: &str, capabilities: &[CommandKind]) -> Kinematics {
        let name = platform.to_ascii_lowercase();
        let wheeled = [
            "diff",
            "differential",
            "skid",
            "tank",
            "unicycle",
            "ackermann",
            "car",
        ]
        .iter()
        .any(|w| name.contains(w));
        if wheeled || !capabilities.contains(&CommandKind::Twist) {
            Kinematics::NonHolonomic
        } else {
            Kinematics::Holonomic
        }
    }
}

/// What a controller needs to know about a member's platform, from its
/// [`Hello`]: how it moves, which commands it obeys and its limits.
#[derive(Debug, Clone, PartialEq)]
pub struct PlatformLimits {
    pub kinematics: Kinematics,
    pub capabilities: Vec<CommandKind>,
    /// Top speed, m/s.
    pub max_speed: f64,
    /// Top yaw rate, rad/s.
    pub max_yaw_rate: f64,
}

impl PlatformLimits {
    /// Limits of a registered platform; a missing or invalid limit falls back
    /// to a cautious value (0.5 m/s, 2 rad/s).
    pub fn new(
        platform: &str,
        capabilities: &[CommandKind],
        max_speed: f64,
        max_yaw_rate: f64,
    ) -> PlatformLimits {
        PlatformLimits {
            kinematics: Kinematics::of_platform(platform, capabilities),
            capabilities: capabilities.to_vec(),
            max_speed: positive_or(max_speed, 0.5),
            max_yaw_rate: positive_or(max_yaw_rate, 2.0),
        }
    }

    /// Limits announced in a registration.
    pub fn from_hello(hello: &Hello) -> PlatformLimits {
        PlatformLimits::new(
            &hello.platform,
            &hello.capabilities,
            hello.max_speed,
            hello.max_yaw_rate,
        )
    }

    /// Whether the platform obeys `kind`.
    pub fn accepts(&self, kind: CommandKind) -> bool {
        self.capabilities.contains(&kind)
    }
}

fn positive_or(v: f64, fallback: f64) -> f64 {
    if v.is_finite() && v > 0.0 {
        v
    } else {
        fallback
    }
}

/// One member as a controller sees it: identity, platform, and the latest
/// telemetry with the time it was received.
#[derive(Debug, Clone, PartialEq)]
pub struct MemberState {
    pub robot: String,
    pub platform: PlatformLimits,
    pub pose: Pose,
    /// World-frame linear velocity and yaw rate.
    pub velocity: Velocity,
    /// When the telemetry was received, seconds on the controller's clock.
    pub stamp: f64,
}

impl MemberState {
    /// Whether this telemetry is too old to close a loop on at `now`.
    pub fn is_stale(&self, now: f64, timeout: f64) -> bool {
        let age = now - self.stamp;
        age.is_nan() || age > timeout
    }
}

/// Something a controller wants the operator to know about.
#[derive(Debug, Clone, PartialEq)]
pub enum ControlEvent {
    /// The member's telemetry went stale: it is no longer commanded.
    MemberLost { robot: String },
    /// Fresh telemetry is back: the member is commanded again.
    MemberRecovered { robot: String },
    /// A waypoint (cluster or vehicle) was reached; `index` is its position in
    /// the list.
    WaypointReached { index: usize },
    /// The last waypoint of a non-looped list was reached.
    Finished,
}

/// The time between a controller's steps, from the `now` each step is given.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct StepClock {
    last: Option<f64>,
}

impl StepClock {
    /// Seconds since the previous step, capped at 0.5 s so a stall does not
    /// turn into one long integration step; 0 at the first step and when time
    /// does not move forward.
    pub(crate) fn interval(&mut self, now: f64) -> f64 {
        let dt = match self.last {
            Some(t) if now > t => (now - t).min(0.5),
            _ => 0.0,
        };
        self.last = Some(now);
        dt
    }
}

/// Keeps `lost` (the members with stale telemetry) up to date for `robot`,
/// with an event when the robot is lost or recovered, so every controller
/// reports the change once.
pub(crate) fn note_staleness(
    lost: &mut BTreeSet<String>,
    robot: &str,
    stale: bool,
    events: &mut Vec<ControlEvent>,
) {
    if stale {
        if lost.insert(robot.to_string()) {
            events.push(ControlEvent::MemberLost {
                robot: robot.to_string(),
            });
        }
    } else if lost.remove(robot) {
        events.push(ControlEvent::MemberRecovered {
            robot: robot.to_string(),
        });
    }
}
