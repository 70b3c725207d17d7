//! What the plots and the fleet table's trends can draw of a robot's last
//! minute: a name for each series, shared by the history that keeps them
//! (`app::History`), the charts (`plots`) and the table's columns.

/// One series of a robot's last minute.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Series {
    /// The speed the robot reports (measured by encoders, or following
    /// from its commands).
    Speed,
    /// The speed its positions show: distance over the last second.
    GroundSpeed,
    /// Heading, degrees.
    Heading,
    /// Battery, %.
    Battery,
    /// Link loss, %.
    Loss,
    /// Round trip, ms.
    Rtt,
    /// Messages per second from the robot.
    Rx,
    /// Messages per second to the robot.
    Tx,
    /// Distance from the leg of a mission sent from this TUI, m.
    CrossTrack,
}
