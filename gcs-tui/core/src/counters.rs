//! Traffic counters: per robot, per channel and router-wide, with drops by
//! reason, and the live-channel listing. Updated on the routing path under
//! the router's table lock (plain integer increments) and copied out for the
//! fleet model, displays and `--script`.

use std::collections::BTreeMap;
use std::time::Duration;

/// A live channel as the router sees it (the 2017 "requestDTconfig").
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelStatus {
    pub name: String,
    /// Sender name of the last publisher.
    pub publisher: String,
    /// Messages per second over the last second.
    pub rate_hz: f64,
    /// Robots routed to this channel now.
    pub robots: Vec<String>,
    /// Time since the last message on it.
    pub idle: Duration,
}

/// Why a message was not forwarded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DropReason {
    /// The destination robot is routed to another channel (or to none).
    NotRouted,
    /// The destination names no registered robot.
    UnknownRobot,
    /// The operating system refused the datagram (buffer full, unreachable).
    SendFailed,
    /// The message could not be decoded.
    BadPacket,
    /// The router has shut down.
    Stopped,
    /// Refused by the authenticated control plane (see [`Rejections`]).
    Rejected,
}

impl DropReason {
    pub fn as_str(self) -> &'static str {
        match self {
            DropReason::NotRouted => "not-routed",
            DropReason::UnknownRobot => "unknown-robot",
            DropReason::SendFailed => "send-failed",
            DropReason::BadPacket => "bad-packet",
            DropReason::Stopped => "router-stopped",
            DropReason::Rejected => "rejected",
        }
    }
}

/// Messages dropped, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Drops {
    pub not_routed: u64,
    pub unknown_robot: u64,
    pub send_failed: u64,
    pub bad_packet: u64,
    pub stopped: u64,
    pub rejected: u64,
}

impl Drops {
    pub fn total(&self) -> u64 {
        self.not_routed
            + self.unknown_robot
            + self.send_failed
            + self.bad_packet
            + self.stopped
            + self.rejected
    }

    pub(crate) fn count(&mut self, reason: DropReason) {
        match reason {
            DropReason::NotRouted => self.not_routed += 1,
            DropReason::UnknownRobot => self.unknown_robot += 1,
            DropReason::SendFailed => self.send_failed += 1,
            DropReason::BadPacket => self.bad_packet += 1,
            DropReason::Stopped => self.stopped += 1,
            DropReason::Rejected => self.rejected += 1,
        }
    }

    /// Count for one reason.
    pub fn get(&self, reason: DropReason) -> u64 {
        match reason {
            DropReason::NotRouted => self.not_routed,
            DropReason::UnknownRobot => self.unknown_robot,
            DropReason::SendFailed => self.send_failed,
            DropReason::BadPacket => self.bad_packet,
            DropReason::Stopped => self.stopped,
            DropReason::Rejected => self.rejected,
        }
    }
}

/// Rejection reasons, as counted.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum RejectReason {
    Unsigned,
    UnknownKey,
    BadTag,
    Replay,
    NotPermitted,
}

impl RejectReason {
    pub fn as_str(self) -> &'static str {
        match self {
            RejectReason::Unsigned => "unsigned",
            RejectReason::UnknownKey => "unknown-key",
            RejectReason::BadTag => "bad-tag",
            RejectReason::Replay => "replay",
            RejectReason::NotPermitted => "not-permitted",
        }
    }
}

/// Messages refused, by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Rejections {
    pub unsigned: u64,
    pub unknown_key: u64,
    pub bad_tag: u64,
    pub replay: u64,
    pub not_permitted: u64,
}

impl Rejections {
    pub fn total(&self) -> u64 {
        self.unsigned + self.unknown_key + self.bad_tag + self.replay + self.not_permitted
    }

    pub fn count(&mut self, reason: RejectReason) {
        match reason {
            RejectReason::Unsigned => self.unsigned += 1,
            RejectReason::UnknownKey => self.unknown_key += 1,
            RejectReason::BadTag => self.bad_tag += 1,
            RejectReason::Replay => self.replay += 1,
            RejectReason::NotPermitted => self.not_permitted += 1,
        }
    }

    /// `(reason, count)` for every reason.
    pub fn by_reason(&self) -> [(RejectReason, u64); 5] {
        [
            (RejectReason::Unsigned, self.unsigned),
            (RejectReason::UnknownKey, self.unknown_key),
            (RejectReason::BadTag, self.bad_tag),
            (RejectReason::Replay, self.replay),
            (RejectReason::NotPermitted, self.not_permitted),
        ]
    }
}

/// Traffic through one robot or channel.
///
/// For a channel: `received` = messages published on it, `forwarded` = parts
/// delivered to robots. For a robot: `received` = messages from the robot
/// (telemetry, heartbeats, acks), `forwarded` = commands delivered to it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Traffic {
    pub received: u64,
    pub forwarded: u64,
    pub dropped: Drops,
}

/// Every counter of the router.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Counters {
    pub robots: BTreeMap<String, Traffic>,
    pub channels: BTreeMap<String, Traffic>,
    /// Everything received, from every peer.
    pub received: u64,
    /// Every message sent on to a robot or subscriber.
    pub forwarded: u64,
    /// Drops not attributable to a robot or channel (garbage, unknown robot).
    pub dropped: Drops,
    /// Telemetry copies not delivered to external subscribers.
    pub fanout_dropped: u64,
    /// Messages refused by the authenticated control plane, by reason.
    pub rejected: Rejections,
}
