//! What comes from ROS 2, checked before anything reaches the station:
//! cmd_vel becomes a MECH Twist command ([`cmd_vel`]), a goal pose a
//! one-waypoint mission ([`goal`]). Anything not finite, out of range or
//! in the wrong frame is refused with a [`Refusal`] the bridge counts.

pub mod cmd_vel;
pub mod goal;

mech_proto::named_enum! {
    /// Why a sample from ROS 2 was not forwarded; the bridge counts it as
    /// `refused_` and its name (`refused_not_finite`, ...).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
    pub enum Refusal: "refusal" {
        /// A component is NaN or infinite.
        NotFinite => "not_finite",
        /// A value is beyond the configured limits, or asks for motion MECH
        /// commands cannot carry (roll or pitch rates).
        OutOfRange => "out_of_range",
        /// The header's frame is not one the value can be taken in.
        WrongFrame => "wrong_frame",
        /// The topic names a robot the station has not reported.
        UnknownRobot => "unknown_robot",
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
