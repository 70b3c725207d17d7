//! Commands of the control hierarchy below fleet level: per-motor actuator
//! outputs, steering-throttle, velocity-heading, body twist and stop.
//!
//! The control mode travels inside each command (as the 2017 system's control
//! field did), so one controller can switch mode message by message. Waypoint
//! lists are not a [`Command`] but a [`crate::Mission`], because they are
//! delivered reliably and acknowledged.

use serde::{Deserialize, Serialize};
use serde_repr::{Deserialize_repr, Serialize_repr};

use crate::error::Error;
use crate::tagged::tagged_enum;

/// Normalised outputs for each actuator, in motor order, each in `[-1, 1]`
/// (fraction of full forward / reverse). Any number of motors up to
/// [`crate::MAX_MOTORS`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Actuators {
    pub outputs: Vec<f64>,
}

/// Car-style input, both in `[-1, 1]`. `steering` > 0 turns left
/// (counter-clockwise); `throttle` > 0 drives forward. The platform scales
/// them to its own limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SteeringThrottle {
    pub steering: f64,
    pub throttle: f64,
}

/// Drive at `speed` (m/s, negative reverses) while holding the world-frame
/// `heading` (rad, counter-clockwise from +x).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VelocityHeading {
    pub speed: f64,
    pub heading: f64,
}

/// Body-frame velocity (REP 103: x forward, y left, z up): `vx`, `vy`, `vz` in
/// m/s and yaw rate `wz` in rad/s (counter-clockwise positive). A platform
/// that cannot move sideways ignores `vy`; ground robots ignore `vz`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Twist {
    pub vx: f64,
    pub vy: f64,
    pub vz: f64,
    pub wz: f64,
}

/// Controlled stop: zero velocity, actuators to zero, mission paused. Unlike
/// [`crate::EStop`] it is not latched; the next command resumes motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Stop {}

tagged_enum! {
    /// A vehicle- or actuator-level command; see the payload types for units.
    #[derive(Debug, Clone, PartialEq)]
    pub enum Command {
        Actuators(Actuators) = 1,
        SteeringThrottle(SteeringThrottle) = 2,
        VelocityHeading(VelocityHeading) = 3,
        Twist(Twist) = 4,
        Stop(Stop) = 6,
    }
}

crate::named_enum! {
    /// The kinds of command a robot can accept; a robot lists its capabilities in
    /// [`crate::Hello`]. The numbers equal the [`Command`] kinds, plus
    /// `Waypoints` for [`crate::Mission`].
    #[derive(
        Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize_repr, Deserialize_repr,
    )]
    #[repr(u8)]
    pub enum CommandKind: "command kind" {
        Actuators = 1 => "actuators",
        SteeringThrottle = 2 => "steering-throttle",
        VelocityHeading = 3 => "velocity-heading",
        Twist = 4 => "twist",
        Waypoints = 5 => "waypoints",
        Stop = 6 => "stop",
    }
}

impl Command {
    /// The capability a robot needs to obey this command.
    pub fn command_kind(&self) -> CommandKind {
        match self {
            Command::Actuators(_) => CommandKind::Actuators,
            Command::SteeringThrottle(_) => CommandKind::SteeringThrottle,
            Command::VelocityHeading(_) => CommandKind::VelocityHeading,
            Command::Twist(_) => CommandKind::Twist,
            Command::Stop(_) => CommandKind::Stop,
        }
    }

    /// Checks ranges: every number finite, normalised inputs within `[-1, 1]`,
    /// at most [`crate::MAX_MOTORS`] outputs.
    pub fn validate(&self) -> Result<(), Error> {
        match self {
            Command::Actuators(a) => {
                if a.outputs.len() > crate::MAX_MOTORS {
                    return Err(Error::invalid(format!(
                        "{} actuator outputs, at most {} allowed",
                        a.outputs.len(),
                        crate::MAX_MOTORS
                    )));
                }
                for (i, &o) in a.outputs.iter().enumerate() {
                    unit_range(o, &format!("actuator output {i}"))?;
                }
                Ok(())
            }
            Command::SteeringThrottle(s) => {
                unit_range(s.steering, "steering")?;
                unit_range(s.throttle, "throttle")
            }
            Command::VelocityHeading(v) => {
                finite(v.speed, "speed")?;
                finite(v.heading, "heading")
            }
            Command::Twist(t) => {
                finite(t.vx, "vx")?;
                finite(t.vy, "vy")?;
                finite(t.vz, "vz")?;
                finite(t.wz, "wz")
            }
            Command::Stop(_) => Ok(()),
        }
    }
}

/// Rejects NaN and infinities, which would otherwise reach a motor.
pub(crate) fn finite(v: f64, what: &str) -> Result<(), Error> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::invalid(format!("{what} is not a finite number")))
    }
}

fn unit_range(v: f64, what: &str) -> Result<(), Error> {
    finite(v, what)?;
    if (-1.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(Error::invalid(format!("{what} {v} is outside [-1, 1]")))
    }
}
