//! The agent core's settings: the parts of the robot's config it uses.

use std::time::Duration;

use crate::control::Gains;
use crate::failsafe::FailsafeConfig;
use crate::fusion::FusionSettings;
use crate::safety::SafetyConfig;
use crate::wheels::WheelSettings;

/// Settings of the agent core (the parts of the robot config it uses).
#[derive(Debug, Clone, PartialEq)]
pub struct AgentSettings {
    /// Robot name: `robot_1`, `rover-a`...
    pub name: String,
    pub failsafe: FailsafeConfig,
    /// Telemetry period (default 50 ms = 20 Hz).
    pub telemetry_period: Duration,
    /// Period of the agent's `Heartbeat`.
    pub hello_period: Duration,
    /// Period of `Hello` while unregistered: short, so a robot is back
    /// within a fraction of a second of its station.
    pub hello_retry: Duration,
    /// Answer a rejected command with `Notice{NotRouted}` (at most one a
    /// second), so a controller learns why it is ignored.
    pub notify_not_routed: bool,
    /// Moving-median window for position samples.
    pub filter_window: usize,
    /// Whether `PositionFix` messages (external positioning relayed by the
    /// GCS) are the position source.
    pub external_position: bool,
    /// Whether the robot has any position source; without one, modes that
    /// need a position are not offered.
    pub has_position: bool,
    /// A position older than this marks health `Degraded`.
    pub position_stale_after: Duration,
    pub gains: Gains,
    /// Wheel encoders (`[encoders]`): measured velocity, closed-loop wheel
    /// speed, stall detection, and odometry fused with the position source.
    /// `None`: velocity is reported from the commanded outputs and the
    /// outputs are open loop.
    pub wheels: Option<WheelSettings>,
    /// Noise figures of the odometry + position fusion (used with `wheels`
    /// and a position source).
    pub fusion: FusionSettings,
    /// Whether an autopilot (PX4, ArduPilot) flies the vehicle: operators'
    /// autopilot requests are then queued for it
    /// ([`super::Agent::take_autopilot_requests`]); without one they are answered
    /// as unsupported.
    pub autopilot: bool,
    /// The robot's footprint and braking for the fleet safety layer
    /// (`[safety]`), which the station's arena switches on.
    pub safety: SafetyConfig,
}

impl AgentSettings {
    pub fn new(name: impl Into<String>) -> AgentSettings {
        AgentSettings {
            name: name.into(),
            failsafe: FailsafeConfig::default(),
            telemetry_period: Duration::from_millis(50),
            hello_period: Duration::from_secs(1),
            hello_retry: Duration::from_millis(250),
            notify_not_routed: true,
            filter_window: 9,
            external_position: false,
            has_position: true,
            position_stale_after: Duration::from_secs(1),
            gains: Gains::default(),
            wheels: None,
            fusion: FusionSettings::default(),
            autopilot: false,
            safety: SafetyConfig::default(),
        }
    }
}
