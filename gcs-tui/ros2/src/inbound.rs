//! What comes from ROS 2, checked before anything reaches the station:
//! cmd_vel becomes a MECH Twist command ([`cmd_vel`]), a goal pose a
//! one-waypoint mission ([`goal`]). Anything not finite, out of range or
//! in the wrong frame is refused with a [`Refusal`] the bridge counts.

pub mod cmd_vel;
pub mod goal;

use std::fmt;

/// Why a sample from ROS 2 was not forwarded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Refusal {
    /// A component is NaN or infinite.
    NotFinite,
    /// A value is beyond the configured limits, or asks for motion MECH
    /// commands cannot carry (roll or pitch rates).
    OutOfRange,
    /// The header's frame is not one the value can be taken in.
    WrongFrame,
    /// The topic names a robot the station has not reported.
    UnknownRobot,
}

impl Refusal {
    /// Every reason, in counter order.
    pub const ALL: [Refusal; 4] = [
        Refusal::NotFinite,
        Refusal::OutOfRange,
        Refusal::WrongFrame,
        Refusal::UnknownRobot,
    ];

    /// The counter's name: `not_finite`, `out_of_range`, ...
    pub fn key(self) -> &'static str {
        match self {
            Refusal::NotFinite => "not_finite",
            Refusal::OutOfRange => "out_of_range",
            Refusal::WrongFrame => "wrong_frame",
            Refusal::UnknownRobot => "unknown_robot",
        }
    }
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.key())
    }
}

/// A refused sample: the reason to count, and what to log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refused {
    pub reason: Refusal,
    pub detail: String,
}

impl Refused {
    pub(crate) fn new(reason: Refusal, detail: impl Into<String>) -> Refused {
        Refused {
            reason,
            detail: detail.into(),
        }
    }
}

/// Strips one leading `/` (`/map` is `map` to tf2).
pub(crate) fn frame(name: &str) -> &str {
    name.strip_prefix('/').unwrap_or(name)
}
