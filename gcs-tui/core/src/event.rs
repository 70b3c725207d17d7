//! What the station saw happen: a robot registered, a route was
//! acknowledged, telemetry arrived... Each [`Event`] is stamped with router
//! time ([`Stamped`]). The router makes them; the fleet model and every
//! subscriber consume them through an [`EventSink`] or a subscription. This
//! module depends on nothing else in the station but the leaves it names
//! (counters, the arena's shape), so producers and consumers never depend
//! on each other.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::Duration;

use mech_proto::{ClusterCommand, Hello, Intervention, Notice, SafetyState, Telemetry, Waypoint};
use serde::{Deserialize, Serialize};

use crate::arena::ArenaShape;
use crate::counters::{LinkQuality, RejectReason};

mod names;

mech_proto::named_enum! {
    /// How recently the router heard from a robot.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
    pub enum LinkState: "link state" {
        /// Heard within `stale_after`.
        #[default]
        Connected => "connected",
        /// Silent longer than `stale_after` (0.5 s by default).
        Stale => "stale",
        /// Silent longer than `lost_after` (1 s by default), or said goodbye.
        Lost => "lost",
    }
}

mech_proto::serde_by_name!(LinkState);

/// Where a robot was heard from: a UDP address, or a serial radio (the
/// router's serial endpoint, by port). Recorded as `{"udp": "ADDR"}` or
/// `{"radio": "PORT"}`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LinkAddr {
    Udp(SocketAddr),
    /// A radio on the station's serial port with this path.
    Radio(String),
}

impl std::fmt::Display for LinkAddr {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinkAddr::Udp(a) => write!(f, "{a}"),
            LinkAddr::Radio(port) => write!(f, "radio {port}"),
        }
    }
}

/// Which of a robot's links the router hears now, which one it sends on,
/// and the robot's share of its radio.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct RobotLinks {
    /// Heard over UDP (Wi-Fi, Ethernet) within the router's link timeout.
    pub udp: bool,
    /// The radio (serial port) the robot is heard on within the link
    /// timeout.
    pub radio: Option<String>,
    /// The link commands go out on now: `"udp"`, `"radio"`, or `""` when
    /// the robot is heard on neither.
    pub active: &'static str,
    /// Telemetry messages per second this robot may send over its radio:
    /// its share of the radio's bandwidth (`None` without a radio).
    pub radio_budget_hz: Option<f64>,
    /// The links the robot was heard on once but not within the link
    /// timeout: `"wifi"`, `"radio"` (a radio unplugged at either end, Wi-Fi
    /// out of range). Absent from a recording that predates it: none.
    pub down: Vec<String>,
}

/// [`RobotLinks`] as a recording holds it (the active link's name owned).
#[derive(Deserialize)]
struct RecordedLinks {
    udp: bool,
    radio: Option<String>,
    active: String,
    radio_budget_hz: Option<f64>,
    #[serde(default)]
    down: Vec<String>,
}

impl<'de> Deserialize<'de> for RobotLinks {
    /// An active link the router never names reads as none.
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let r = RecordedLinks::deserialize(d)?;
        Ok(RobotLinks {
            udp: r.udp,
            radio: r.radio,
            active: ["udp", "radio"]
                .into_iter()
                .find(|l| *l == r.active)
                .unwrap_or(""),
            radio_budget_hz: r.radio_budget_hz,
            down: r.down,
        })
    }
}

impl RobotLinks {
    /// How a card or a status line names the links: the live ones
    /// (`wifi+radio`, `radio`, `wifi`, or `none`; the active one starred
    /// when both live), then each link that went silent (`wifi, radio
    /// down`, `radio, wifi down`, `wifi down, radio down`).
    pub fn label(&self) -> String {
        let live = match (self.udp, self.radio.is_some()) {
            (true, true) if self.active == "radio" => "wifi+radio*",
            (true, true) => "wifi*+radio",
            (true, false) => "wifi",
            (false, true) => "radio",
            (false, false) => "none",
        };
        let mut parts: Vec<String> = self.down.iter().map(|l| format!("{l} down")).collect();
        if live != "none" || parts.is_empty() {
            parts.insert(0, live.to_string());
        }
        parts.join(", ")
    }
}

/// Distinct sources an [`Event::Refused`] counts; a flood from more is
/// reported as coming from at least this many.
pub const REFUSED_SOURCES_COUNTED: usize = 4096;

/// Something the router did or saw. Subscribers receive them in order, each
/// wrapped in a [`Stamped`]. Recordings and script output store them as
/// JSON objects in serde's form below, tagged with their `event` name
/// ([`Event::names`] lists them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    /// The router is bound and running.
    Listening {
        udp: SocketAddr,
        tcp: Option<SocketAddr>,
    },
    /// A robot's `Hello` was accepted (first time, or again after a restart
    /// or from a new address: `known` says which).
    Registered {
        /// The registration as the robot sent it: its name, platform,
        /// capabilities and limits.
        hello: Hello,
        id: u16,
        addr: LinkAddr,
        known: bool,
    },
    /// A robot's live links changed (or its radio budget did).
    Links { robot: String, links: RobotLinks },
    /// One of the station's radios failed (`up` false, `reason` says why;
    /// the router keeps opening it again) or was opened again (`up` true).
    /// Each outage is reported once when it begins and once when it ends.
    Radio {
        port: String,
        up: bool,
        reason: String,
    },
    /// A robot's link state changed.
    Link { robot: String, state: LinkState },
    /// A robot sent telemetry.
    Telemetry { robot: String, telemetry: Telemetry },
    /// A robot's link quality over the last seconds, once a second. Like
    /// telemetry, it reaches only subscribers that asked for telemetry.
    LinkQuality { robot: String, quality: LinkQuality },
    /// The routing table changed; the robot has not acknowledged yet.
    RouteChanged {
        robot: String,
        channel: Option<String>,
        epoch: u32,
    },
    /// The robot acknowledged the route with this epoch.
    RouteAcked {
        robot: String,
        channel: Option<String>,
        epoch: u32,
    },
    /// A mission is on its way to a robot (retried until acknowledged).
    MissionSent {
        robot: String,
        channel: String,
        id: u32,
        waypoints: Vec<Waypoint>,
        looped: bool,
    },
    /// The robot acknowledged (or refused) the mission.
    MissionAcked {
        robot: String,
        id: u32,
        accepted: bool,
        reason: String,
    },
    /// The mission was not acknowledged in time.
    MissionFailed {
        robot: String,
        id: u32,
        reason: String,
    },
    /// E-stop engaged (`engage`) or released, for every robot.
    #[serde(rename = "estop")]
    EStop { engage: bool, id: u32 },
    /// One robot acknowledged the e-stop or release `id`.
    #[serde(rename = "estop_acked")]
    EStopAcked {
        robot: String,
        engage: bool,
        id: u32,
    },
    /// Every robot known when it was sent acknowledged e-stop/release `id`.
    #[serde(rename = "estop_complete")]
    EStopComplete { engage: bool, id: u32 },
    /// A channel published for the first time, or got a new publisher.
    ChannelPublisher { channel: String, publisher: String },
    /// A cluster command published on a channel, for the fleet controller
    /// that serves it.
    ClusterCommand {
        channel: String,
        command: ClusterCommand,
    },
    /// A robot said goodbye.
    Bye { robot: String, reason: String },
    /// A notice from a robot or controller.
    Notice { from: String, notice: Notice },
    /// A datagram or frame that could not be used: the first refused
    /// message after a second in which none was reported. Those that follow
    /// within the second are reported together in [`Event::Refused`].
    BadPacket { from: String, error: String },
    /// A message the authenticated control plane refused: the first refused
    /// message after a second in which none was reported, as
    /// [`Event::BadPacket`]. Every one is counted.
    Rejected {
        from: String,
        reason: RejectReason,
        detail: String,
    },
    /// The messages refused since the last report, reported at most once a
    /// second while refusals go on: a flood reaches the event log and the
    /// operators as one summary a second, never as a line per datagram.
    Refused {
        /// Messages refused.
        count: u64,
        /// Distinct sources among them (counted up to
        /// [`REFUSED_SOURCES_COUNTED`]).
        sources: u64,
        /// How many for each reason: `bad-packet`, `shed` (not read: the
        /// router was behind and the source kept failing), or a rejection
        /// reason (`unsigned`, `unknown-key`, `bad-tag`, `replay`,
        /// `not-permitted`).
        by_reason: BTreeMap<String, u64>,
        /// One of them: where it came from, and why it was refused.
        from: String,
        detail: String,
    },
    /// The station's arena changed (configured at start, loaded, cleared):
    /// every robot is sent it anew.
    Arena { arena: Option<ArenaShape> },
    /// An operator switched a robot's safety layer on or off; its arena
    /// `id` goes out until the robot acknowledges it.
    SafetySwitched {
        robot: String,
        enabled: bool,
        id: u32,
    },
    /// A robot acknowledged arena `id` (its layer `enabled` or not).
    ArenaAcked {
        robot: String,
        id: u32,
        enabled: bool,
    },
    /// A robot's telemetry reported a new state of its safety layer or a
    /// new intervention (one event per change, not per telemetry).
    Safety {
        robot: String,
        /// Recorded as `safety_state` (a link event's `state` is another
        /// thing).
        #[serde(with = "safety_state_name", rename = "safety_state")]
        state: SafetyState,
        #[serde(with = "intervention_name")]
        intervention: Intervention,
    },
}

/// How events and scripts name a safety layer's state.
pub fn safety_state_str(s: SafetyState) -> &'static str {
    match s {
        SafetyState::NoArena => "no-arena",
        SafetyState::On => "on",
        SafetyState::Off => "off",
    }
}

/// A safety state as its name in recordings.
mod safety_state_name {
    use mech_proto::SafetyState;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(s: &SafetyState, ser: S) -> Result<S::Ok, S::Error> {
        ser.serialize_str(super::safety_state_str(*s))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<SafetyState, D::Error> {
        let name = String::deserialize(d)?;
        [SafetyState::NoArena, SafetyState::On, SafetyState::Off]
            .into_iter()
            .find(|s| super::safety_state_str(*s) == name)
            .ok_or_else(|| serde::de::Error::custom(format!("no safety state {name:?}")))
    }
}

/// An intervention as its name in recordings (`fence`, `separation`...).
mod intervention_name {
    use mech_proto::Intervention;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(i: &Intervention, ser: S) -> Result<S::Ok, S::Error> {
        ser.serialize_str(i.as_str())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Intervention, D::Error> {
        let name = String::deserialize(d)?;
        Intervention::ALL
            .into_iter()
            .find(|i| i.as_str() == name)
            .ok_or_else(|| serde::de::Error::custom(format!("no intervention {name:?}")))
    }
}

impl Event {
    /// Every event's name, in the order of the variants: the `event` tag
    /// serde writes, as recordings and script output carry it (read from
    /// the type, so a new variant is named here as it is in them).
    pub fn names() -> &'static [&'static str] {
        names::all()
    }
}

/// An event with the router time it happened at (tokio time, so tests with a
/// paused clock see exact times).
#[derive(Debug, Clone, PartialEq)]
pub struct Stamped {
    /// Time since the router started.
    pub at: Duration,
    pub event: Event,
}

/// Where the router delivers every event, in the order its tables made
/// them, before any subscriber sees it: the fleet model implements it, so
/// the model never misses a route or link change even when a subscriber
/// lags. Keep [`EventSink::apply`] short: the router calls it after it has
/// released its tables, holding its delivery lock, so other events wait
/// for it. It may read the router (counters, channels) but must not make it
/// act (route, publish, e-stop), which would wait for that same lock.
pub trait EventSink: Send + Sync + std::fmt::Debug {
    fn apply(&self, event: &Stamped);
}
