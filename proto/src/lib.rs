//! `mech-proto`: the MECH wire protocol.
//!
//! Every message is an [`Envelope`]: a fixed header (protocol version, message
//! kind, sequence number, timestamp, sender, destination, channel), a [`Body`]
//! and an optional authentication tag. Envelopes are encoded as compact
//! MessagePack arrays ([`encode`] / [`decode`]) and carried one per UDP
//! datagram, length-prefixed on TCP streams ([`framing::StreamDecoder`]) or
//! COBS-framed with a CRC-32 on serial radios ([`framing::SerialDecoder`]).
//!
//! Units are SI and frames follow ROS REP 103: metres, metres per second,
//! radians, x forward / y left / z up in the body frame, heading measured
//! counter-clockwise from the world +x axis.
//!
//! This crate does no I/O and never panics on input: truncated, oversized,
//! corrupt, wrong-version and unknown-kind bytes all return a typed [`Error`].
//! The byte-level format is specified in `docs/protocol.md`.

pub mod auth;
mod autopilot;
mod body;
mod command;
mod envelope;
mod error;
pub mod framing;
pub mod named;
mod names;
mod safety;
mod tagged;
mod units;

pub use autopilot::AutopilotNews;
pub use body::Body;
pub use body::{
    AutopilotAction, AutopilotRequest, Bye, Channel as ChannelInfo, Channels, ChannelsRequest,
    ClusterCommand, ClusterGoal, ClusterPose, ClusterVelocity, Computation, ControlMode, EStop,
    EStopAck, Echo, FailsafeState, FleetCommand, Formation, FormationKind, Health, Heartbeat,
    Hello, Level, MAX_WAYPOINT_TIME, Mission, MissionAck, MissionProgress, Notice, NoticeCode,
    Offset, Pose, PositionFix, RobotCommand, Route, RouteAck, Subscribe, Telemetry, Time,
    TimeRequest, Velocity, VelocitySource, Waypoint, Welcome,
};
pub use command::{
    Actuators, Command, CommandKind, SteeringThrottle, Stop, Twist, VelocityHeading,
};
pub use envelope::{
    AuthTag, COMMAND_KIND, Envelope, Header, Peek, check_command, decode, encode, encode_into,
    peek, signed_region,
};
pub use error::{Error, ErrorKind};
pub use named::Named;
pub use safety::{
    Arena, ArenaAck, Disc, Intervention, InterventionCounts, MAX_BOUNDARY_VERTICES, MAX_EXTENT,
    MAX_KEEP_OUTS, MAX_NEIGHBOURS, MAX_OBSTACLES, MAX_POLYGON_VERTICES, MAX_SLOW_ZONES, Neighbour,
    Neighbours, Obstacle, Point, SafetyReport, SafetyState, SlowZone, check_polygon,
};
pub use units::{unix_micros, wrap_angle};

/// Protocol version this build speaks. A message with another version is
/// rejected with [`Error::Version`] before its body is looked at.
pub const PROTOCOL_VERSION: u8 = 1;

/// Largest encoded message, in bytes. Fits one UDP datagram on any IPv4 path
/// (65,507 bytes) with room to spare; larger input is rejected unread.
pub const MAX_MESSAGE_LEN: usize = 60_000;

/// Longest robot, sender, destination or channel name, in bytes of UTF-8.
pub const MAX_NAME_LEN: usize = 64;

/// Most actuator outputs in one [`Actuators`] command.
pub const MAX_MOTORS: usize = 32;

/// Most waypoints in one [`Mission`].
pub const MAX_WAYPOINTS: usize = 1024;

/// Most per-robot parts in one [`FleetCommand`] (and members in a cluster).
pub const MAX_FLEET_PARTS: usize = 1024;

/// Longest free text ([`Notice`] text, version strings), in bytes.
pub const MAX_TEXT_LEN: usize = 1024;

/// Longest authentication tag, in bytes (enough for HMAC-SHA-512 or Ed25519).
pub const MAX_AUTH_LEN: usize = 64;

/// Destination that means "every robot" (used by e-stop and release).
pub const BROADCAST: &str = "*";

/// Destination that means "the router itself" (registration, discovery,
/// subscriptions). An empty destination means the same.
pub const ROUTER: &str = "router";
