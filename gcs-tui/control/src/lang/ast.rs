//! The parsed form of commands: what each verb means, independent of how it
//! was written.

use std::time::Duration;

use mech_proto::{CommandKind, FailsafeState, Waypoint};

use super::Span;
use mech_core::LinkState;

/// Robots a command applies to: a robot name, a cluster name, or `all`.
/// Resolved against the fleet model when the command runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Target {
    pub name: String,
    pub span: Span,
}

/// A condition `wait` polls for until it holds or its timeout passes.
#[derive(Debug, Clone, PartialEq)]
pub enum WaitFor {
    /// Every robot of the target is registered and connected.
    Connected(Target),
    /// Every robot of the target is lost.
    Lost(Target),
    /// At least this many robots are connected.
    Robots(usize),
    /// Every robot of the target finished its last mission.
    Arrived(Target),
    /// Every robot of the target acknowledged this route.
    Route(Target, Option<String>),
    /// Every robot of the target is within `tolerance` m of the point.
    Near {
        target: Target,
        x: f64,
        y: f64,
        tolerance: f64,
    },
    /// Every robot acknowledged the current e-stop or release.
    EStopAcked,
}

/// A check that must hold now.
#[derive(Debug, Clone, PartialEq)]
pub enum Expectation {
    /// Within `tolerance` metres of `(x, y)`.
    Near {
        target: Target,
        x: f64,
        y: f64,
        tolerance: f64,
    },
    /// Acknowledged route.
    Route(Target, Option<String>),
    Link(Target, LinkState),
    Failsafe(Target, FailsafeState),
    /// At least `min` commands on `channel` were dropped as not routed.
    DroppedAtLeast {
        channel: String,
        min: u64,
    },
}

/// One command of the language.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// `route TARGET CHANNEL|none`
    Route {
        target: Target,
        channel: Option<String>,
    },
    /// `mode TARGET MODE`: the mode `drive` uses for these robots.
    Mode { target: Target, mode: CommandKind },
    /// `drive TARGET NUMBER...`: one command in the robots' mode on the GCS
    /// command channel.
    Drive { target: Target, values: Vec<f64> },
    /// `waypoint ROBOT POINT... [loop]` or `waypoint ROBOT clear`: sets the
    /// robot's waypoint draft.
    Waypoint {
        target: Target,
        points: Vec<Waypoint>,
        looped: bool,
    },
    /// `send TARGET [CHANNEL]`: sends each robot's draft as a mission.
    Send {
        target: Target,
        channel: Option<String>,
    },
    /// `cluster NAME ROBOT...`
    Cluster { name: String, members: Vec<Target> },
    /// `stop TARGET`: a controlled (unlatched) stop on each robot's channel.
    Stop { target: Target },
    /// `estop`
    EStop,
    /// `release`
    Release,
    /// `wait CONDITION [TIMEOUT]`
    Wait {
        condition: WaitFor,
        timeout: Duration,
    },
    /// `expect CHECK`
    Expect(Expectation),
    /// `sleep DURATION`
    Sleep(Duration),
    /// `log TEXT...`
    Log(String),
    /// `spawn N`: start N simulated agents.
    Spawn(usize),
    /// `channels`: list live channels.
    Channels,
    /// `status [TARGET]`: one line per robot.
    Status(Option<Target>),
    /// `help`
    Help,
    /// Fleet and offboard control: `formation`, `cluster-move`,
    /// `cluster-waypoint`, `follow`, `nav`... (see [`crate::control`]).
    Control(super::control::ControlCommand),
}

/// A command with where it was written.
#[derive(Debug, Clone, PartialEq)]
pub struct Statement {
    pub span: Span,
    /// The line as written (trimmed), for output.
    pub text: String,
    pub command: Command,
}
