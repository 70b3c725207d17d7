//! Traffic counters: per robot, per channel and router-wide, with drops by
//! reason, each robot's link quality, and the live-channel listing. Updated
//! on the routing path under the router's table lock (plain integer
//! increments) and copied out for the fleet model, displays and `--script`.

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

mech_proto::named_enum! {
    /// Why a message was not forwarded.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum DropReason: "drop reason" {
        /// The destination robot is routed to another channel (or to none).
        NotRouted => "not-routed",
        /// The destination names no registered robot.
        UnknownRobot => "unknown-robot",
        /// The operating system refused the datagram (buffer full, unreachable).
        SendFailed => "send-failed",
        /// The message could not be decoded.
        BadPacket => "bad-packet",
        /// The router has shut down.
        Stopped => "router-stopped",
        /// Refused by the authenticated control plane (see [`Rejections`]).
        Rejected => "rejected",
        /// Not read at all: the router was behind and the datagram's source
        /// address had been refused many times in the last second (and is
        /// not a peer it knows).
        Shed => "shed",
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
    pub shed: u64,
}

impl Drops {
    pub fn total(&self) -> u64 {
        self.not_routed
            + self.unknown_robot
            + self.send_failed
            + self.bad_packet
            + self.stopped
            + self.rejected
            + self.shed
    }

    pub(crate) fn count(&mut self, reason: DropReason) {
        match reason {
            DropReason::NotRouted => self.not_routed += 1,
            DropReason::UnknownRobot => self.unknown_robot += 1,
            DropReason::SendFailed => self.send_failed += 1,
            DropReason::BadPacket => self.bad_packet += 1,
            DropReason::Stopped => self.stopped += 1,
            DropReason::Rejected => self.rejected += 1,
            DropReason::Shed => self.shed += 1,
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
            DropReason::Shed => self.shed,
        }
    }
}

mech_proto::named_enum! {
    /// Rejection reasons, as counted.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
    pub enum RejectReason: "rejection reason" {
        Unsigned => "unsigned",
        UnknownKey => "unknown-key",
        BadTag => "bad-tag",
        Replay => "replay",
        NotPermitted => "not-permitted",
    }
}

mech_proto::serde_by_name!(RejectReason);

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

/// How well the link to one robot works, as the router measures it over
/// its last few seconds (`docs/protocol.md`, *Link quality*): the 2017
/// thesis's "usable packets" figure, live. In JSON (recordings, the live
/// view, the attach protocol) `rtt` and `window` are seconds as numbers, so
/// a plot can draw them.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct LinkQuality {
    /// Messages per second received from the robot.
    pub rx_hz: f64,
    /// Messages per second the router sent the robot (commands forwarded
    /// to it, and the router's own heartbeats, routes, missions...).
    pub tx_hz: f64,
    /// Fraction, in `[0, 1]`, of the robot's messages that did not reach
    /// the router, from the gaps in their sequence numbers; `None` when the
    /// robot sent nothing in the window.
    pub loss: Option<f64>,
    /// Mean round-trip time of the robot's heartbeat echoes in the window;
    /// `None` without one (an agent that does not echo, or all echoes lost).
    #[serde(with = "seconds::optional")]
    pub rtt: Option<Duration>,
    /// The time these figures cover (up to the last five seconds).
    #[serde(with = "seconds")]
    pub window: Duration,
    /// Since the robot registered: messages received from it.
    pub received: u64,
    /// Since the robot registered: messages sent to it.
    pub sent: u64,
    /// Since the robot registered: its messages lost on the way.
    pub lost: u64,
}

/// A [`Duration`] in JSON as seconds (a number). Reads the number, or the
/// `{"secs", "nanos"}` object that serde's own form of a `Duration` is (so
/// recordings made before link quality was written in seconds still
/// replay).
mod seconds {
    use std::time::Duration;

    use serde::{Deserialize, Deserializer, Serializer};

    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Form {
        Seconds(f64),
        Serde { secs: u64, nanos: u32 },
    }

    impl Form {
        /// `None` for a `secs`/`nanos` pair no `Duration` holds.
        fn duration(self) -> Option<Duration> {
            match self {
                Form::Seconds(s) => Some(Duration::try_from_secs_f64(s).unwrap_or_default()),
                Form::Serde { secs, nanos } => {
                    Duration::from_secs(secs).checked_add(Duration::from_nanos(u64::from(nanos)))
                }
            }
        }
    }

    pub fn serialize<S: Serializer>(d: &Duration, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_f64(d.as_secs_f64())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Duration, D::Error> {
        Form::deserialize(d)?
            .duration()
            .ok_or_else(|| serde::de::Error::custom("a duration longer than any clock holds"))
    }

    pub mod optional {
        use super::*;

        pub fn serialize<S: Serializer>(d: &Option<Duration>, s: S) -> Result<S::Ok, S::Error> {
            match d {
                Some(d) => s.serialize_f64(d.as_secs_f64()),
                None => s.serialize_none(),
            }
        }

        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Duration>, D::Error> {
            Option::<Form>::deserialize(d)?
                .map(|f| {
                    f.duration().ok_or_else(|| {
                        serde::de::Error::custom("a duration longer than any clock holds")
                    })
                })
                .transpose()
        }
    }
}

impl LinkQuality {
    /// Whether anything has been measured yet.
    pub fn measured(&self) -> bool {
        !self.window.is_zero()
    }

    /// Loss as a percentage with one decimal (`19.8%`), `–` unknown.
    pub fn loss_text(&self) -> String {
        match self.loss {
            Some(l) => format!("{:.1}%", l * 100.0),
            None => "–".into(),
        }
    }

    /// Round-trip time in milliseconds, to three significant figures at
    /// most (`0.42ms`, `12.5ms`, `230ms`), `–` unknown.
    pub fn rtt_text(&self) -> String {
        match self.rtt {
            Some(d) => {
                let ms = d.as_secs_f64() * 1e3;
                if ms < 10.0 {
                    format!("{ms:.2}ms")
                } else if ms < 100.0 {
                    format!("{ms:.1}ms")
                } else {
                    format!("{ms:.0}ms")
                }
            }
            None => "–".into(),
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_quality_times_are_seconds_in_json_and_old_recordings_still_read() {
        let q = LinkQuality {
            rx_hz: 20.0,
            rtt: Some(Duration::from_micros(420)),
            window: Duration::from_secs(5),
            ..LinkQuality::default()
        };
        let v = serde_json::to_value(q).unwrap();
        assert_eq!(v["rtt"], serde_json::json!(0.00042));
        assert_eq!(v["window"], serde_json::json!(5.0));
        assert_eq!(serde_json::from_value::<LinkQuality>(v).unwrap(), q);
        let unmeasured = serde_json::to_value(LinkQuality::default()).unwrap();
        assert!(unmeasured["rtt"].is_null(), "{unmeasured}");
        let old = serde_json::json!({"rx_hz": 20.0, "rtt": {"secs": 0, "nanos": 420_000},
                                     "window": {"secs": 5, "nanos": 0}});
        assert_eq!(serde_json::from_value::<LinkQuality>(old).unwrap(), q);
        // A pair no `Duration` holds (from a damaged recording or a hostile
        // station) is an error, not a panic.
        for field in ["window", "rtt"] {
            let mut bad = serde_json::to_value(q).unwrap();
            bad[field] = serde_json::json!({"secs": u64::MAX, "nanos": 1_000_000_000u32});
            let e = serde_json::from_value::<LinkQuality>(bad).unwrap_err();
            assert!(e.to_string().contains("longer than any clock"), "{e}");
        }
    }
}
