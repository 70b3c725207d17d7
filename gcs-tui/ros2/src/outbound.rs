//! What the bridge publishes on ROS 2, made from the station's telemetry:
//! odometry and transforms ([`odom`]), battery state ([`battery`]),
//! `/diagnostics` ([`diagnostics`]) and rviz2 markers ([`markers`]). Pure
//! functions of the telemetry, the bridge's fleet view and its counters.

pub mod battery;
pub mod diagnostics;
pub mod markers;
pub mod odom;

/// The frames of one robot (REP 105, one namespace per robot).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frames {
    /// The world frame, `map`.
    pub map: String,
    /// `<robot>/base_link`.
    pub base: String,
}

impl Frames {
    pub fn new(map: &str, robot: &str) -> Frames {
        Frames {
            map: map.to_string(),
            base: format!("{robot}/base_link"),
        }
    }
}
