//! What travels on each key, as JSON (`application/json`): a program on
//! the Zenoh network (ROS 2 through a bridge, Python, a dashboard) reads it
//! with any JSON library and the schema in `docs/zenoh.md`, without MECH's
//! code. Units are the protocol's: SI, REP 103 frames, heading
//! counter-clockwise from +x. Every state payload carries `v` (the schema
//! version), its station and robot, so a sample stands on its own.
//!
//! Readers of state ignore fields they do not know (a later version may add
//! some); commands refuse them, since a misspelt field must not become a
//! zero on a motor.

mod command;
mod names;
mod route;

use mech_core::fleet::{Registration, RouteState};
use mech_proto::{
    CommandKind, Computation, ControlMode, FailsafeState, Health, Hello, MissionProgress, Pose,
    SafetyReport, Telemetry, Velocity, VelocitySource,
};
use serde::{Deserialize, Serialize};

pub use command::CommandMsg;
pub use route::{RouteReply, RouteRequest};

use mech_core::LinkState;

/// The schema version every payload carries as `v`.
pub const VERSION: u32 = 1;

/// A payload that could not be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PayloadError {
    #[error("not a JSON {what}: {detail}")]
    Json { what: &'static str, detail: String },
    #[error("{what} of schema version {found}; this station reads version {VERSION}")]
    Version { what: &'static str, found: u32 },
    #[error("{what} names {found:?} but was published under {key:?}")]
    Mismatch {
        what: &'static str,
        found: String,
        key: String,
    },
    #[error("invalid {what}: {detail}")]
    Invalid { what: &'static str, detail: String },
}

/// Reads a JSON payload of kind `what`.
pub(crate) fn from_json<'a, T: Deserialize<'a>>(
    what: &'static str,
    bytes: &'a [u8],
) -> Result<T, PayloadError> {
    serde_json::from_slice(bytes).map_err(|e| PayloadError::Json {
        what,
        detail: e.to_string(),
    })
}

/// Encodes a payload (these types always encode).
pub(crate) fn to_json<T: Serialize>(value: &T) -> Vec<u8> {
    serde_json::to_vec(value).unwrap_or_default()
}

/// Who a state payload is about, checked against the key it came under.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Origin {
    pub v: u32,
    pub station: String,
    pub robot: String,
}

impl Origin {
    pub fn new(station: &str, robot: &str) -> Origin {
        Origin {
            v: VERSION,
            station: station.to_string(),
            robot: robot.to_string(),
        }
    }

    /// Refuses a payload of another version, or naming another station or
    /// robot than its key.
    pub fn check(
        &self,
        what: &'static str,
        station: &str,
        robot: &str,
    ) -> Result<(), PayloadError> {
        if self.v != VERSION {
            return Err(PayloadError::Version {
                what,
                found: self.v,
            });
        }
        if self.station != station || self.robot != robot {
            return Err(PayloadError::Mismatch {
                what,
                found: format!("{}/{}", self.station, self.robot),
                key: format!("{station}/{robot}"),
            });
        }
        Ok(())
    }
}

/// `mech/<station>/<robot>/telemetry`: the robot's state as its station
/// received it: the protocol's [`Telemetry`] as it is, written as JSON by
/// [`TelemetryJson`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TelemetryMsg {
    #[serde(flatten)]
    pub origin: Origin,
    /// When the station received it: Unix time, microseconds.
    pub stamp_us: u64,
    #[serde(flatten, with = "TelemetryJson")]
    pub telemetry: Telemetry,
}

/// How [`Telemetry`] is written on Zenoh (serde's mirror of a type of
/// another crate: the compiler checks every field of `Telemetry` is named
/// here). Enums are names, not wire numbers; the channel is `null` for
/// none; the safety report is not carried.
#[derive(Serialize, Deserialize)]
#[serde(remote = "Telemetry")]
struct TelemetryJson {
    /// m, m, m, rad.
    pose: Pose,
    /// World frame m/s; `wz` rad/s.
    velocity: Velocity,
    /// `measured` (wheel encoders) or `commanded` (what the outputs should
    /// give); `commanded` when absent.
    #[serde(default, with = "mech_proto::named::by_name")]
    velocity_source: VelocitySource,
    #[serde(with = "mech_proto::named::by_name")]
    mode: ControlMode,
    /// The channel the robot obeys; `null` = none.
    #[serde(default, with = "names::channel")]
    channel: String,
    #[serde(with = "mech_proto::named::by_name")]
    computation: Computation,
    #[serde(with = "mech_proto::named::by_name")]
    failsafe: FailsafeState,
    #[serde(with = "mech_proto::named::by_name")]
    health: Health,
    /// Fraction in [0, 1].
    battery: Option<f64>,
    position_quality: f64,
    actuators: Vec<f64>,
    mission: Option<MissionProgress>,
    #[serde(default)]
    stale: u32,
    #[serde(skip)]
    safety: Option<SafetyReport>,
}

impl TelemetryMsg {
    pub fn new(station: &str, robot: &str, t: &Telemetry, stamp_us: u64) -> TelemetryMsg {
        TelemetryMsg {
            origin: Origin::new(station, robot),
            stamp_us,
            telemetry: t.clone(),
        }
    }

    /// Refuses telemetry the protocol would refuse from a robot.
    pub fn check(&self) -> Result<(), PayloadError> {
        self.telemetry
            .validate()
            .map_err(|e| PayloadError::Invalid {
                what: "telemetry",
                detail: e.to_string(),
            })
    }
}

/// `mech/<station>/<robot>/info`: the robot's registration, its
/// [`Hello`] as it is (written by [`HelloJson`]) with the id its station's
/// router gave it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InfoMsg {
    #[serde(flatten)]
    pub origin: Origin,
    /// The id its station's router gave it.
    pub id: u16,
    #[serde(flatten, with = "HelloJson")]
    pub hello: Hello,
}

/// How [`Hello`] is written on Zenoh: the robot's name is the key's
/// (`robot`), capabilities are names (`actuators`, `steering-throttle`,
/// `velocity-heading`, `twist`, `waypoints`, `stop`; one this version does
/// not know is left out), the agent's version is not carried.
#[derive(Serialize, Deserialize)]
#[serde(remote = "Hello")]
struct HelloJson {
    #[serde(skip)]
    name: String,
    platform: String,
    #[serde(with = "names::capabilities")]
    capabilities: Vec<CommandKind>,
    motors: u8,
    /// m/s
    max_speed: f64,
    /// rad/s
    max_yaw_rate: f64,
    #[serde(skip)]
    agent_version: String,
}

impl InfoMsg {
    pub fn new(station: &str, robot: &str, r: &Registration) -> InfoMsg {
        InfoMsg {
            origin: Origin::new(station, robot),
            id: r.id,
            hello: r.hello.clone(),
        }
    }

    /// Refuses a registration the protocol would refuse from a robot.
    pub fn check(&self) -> Result<(), PayloadError> {
        let bad = |detail: String| PayloadError::Invalid {
            what: "info",
            detail,
        };
        let h = &self.hello;
        // A platform name obeys the protocol's rule for names.
        if !mech_core::config::is_channel_name(&h.platform) {
            return Err(bad(format!("{:?} is not a platform name", h.platform)));
        }
        if usize::from(h.motors) > mech_proto::MAX_MOTORS {
            return Err(bad(format!("{} motors", h.motors)));
        }
        if !(h.max_speed.is_finite() && h.max_yaw_rate.is_finite()) {
            return Err(bad("limits must be finite".into()));
        }
        Ok(())
    }
}

/// `mech/<station>/<robot>/link`: how recently its station heard from it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinkMsg {
    #[serde(flatten)]
    pub origin: Origin,
    pub state: LinkState,
}

/// `mech/<station>/<robot>/route`: the channel its station forwards to it,
/// and the one it acknowledged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RouteMsg {
    #[serde(flatten)]
    pub origin: Origin,
    /// `null` = none.
    pub requested: Option<String>,
    pub epoch: u32,
    pub acknowledged: Option<String>,
    pub acked_epoch: u32,
}

impl RouteMsg {
    pub fn new(station: &str, robot: &str, route: &RouteState) -> RouteMsg {
        RouteMsg {
            origin: Origin::new(station, robot),
            requested: route.requested.clone(),
            epoch: route.epoch,
            acknowledged: route.acknowledged.clone(),
            acked_epoch: route.acked_epoch,
        }
    }

    pub fn route(&self) -> Result<RouteState, PayloadError> {
        for c in [&self.requested, &self.acknowledged].into_iter().flatten() {
            if !mech_core::config::is_channel_name(c) {
                return Err(PayloadError::Invalid {
                    what: "route",
                    detail: format!("{c:?} is not a channel name"),
                });
            }
        }
        Ok(RouteState {
            requested: self.requested.clone(),
            epoch: self.epoch,
            acknowledged: self.acknowledged.clone(),
            acked_epoch: self.acked_epoch,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn telemetry() -> Telemetry {
        Telemetry {
            pose: Pose {
                x: 1.5,
                y: -2.0,
                z: 0.0,
                heading: 0.25,
            },
            velocity: Velocity {
                vx: 0.1,
                vy: 0.0,
                vz: 0.0,
                wz: 0.5,
            },
            velocity_source: VelocitySource::Measured,
            safety: None,
            mode: ControlMode::SteeringThrottle,
            channel: "joy/0".into(),
            computation: Computation::Offboard,
            failsafe: FailsafeState::ChannelSilent,
            health: Health::Degraded,
            battery: Some(0.75),
            position_quality: 0.9,
            actuators: vec![0.5, -0.5],
            mission: Some(MissionProgress {
                id: 9,
                next: 1,
                total: 4,
            }),
            stale: 2,
        }
    }

    #[test]
    fn telemetry_json_reads_without_mech_and_back() {
        let msg = TelemetryMsg::new("site-a", "robot_1", &telemetry(), 1_700_000_000_000_000);
        let json: serde_json::Value = serde_json::from_slice(&to_json(&msg)).unwrap();
        assert_eq!(json["v"], 1);
        assert_eq!(json["station"], "site-a");
        assert_eq!(json["robot"], "robot_1");
        assert_eq!(json["pose"]["x"], 1.5);
        assert_eq!(json["velocity"]["wz"], 0.5);
        assert_eq!(json["mode"], "steering-throttle");
        assert_eq!(json["computation"], "offboard");
        assert_eq!(json["failsafe"], "channel-silent");
        assert_eq!(json["health"], "degraded");
        assert_eq!(json["channel"], "joy/0");
        assert_eq!(json["mission"]["total"], 4);
        let back: TelemetryMsg = from_json("telemetry", &to_json(&msg)).unwrap();
        back.check().unwrap();
        assert_eq!(back.telemetry, telemetry());
    }

    #[test]
    fn telemetry_json_is_byte_for_byte_the_documented_shape() {
        let msg = TelemetryMsg::new("site-a", "robot_1", &telemetry(), 17);
        let json = String::from_utf8(to_json(&msg)).unwrap();
        assert_eq!(
            json,
            concat!(
                r#"{"v":1,"station":"site-a","robot":"robot_1","stamp_us":17,"#,
                r#""pose":{"x":1.5,"y":-2.0,"z":0.0,"heading":0.25},"#,
                r#""velocity":{"vx":0.1,"vy":0.0,"vz":0.0,"wz":0.5},"#,
                r#""velocity_source":"measured","mode":"steering-throttle","#,
                r#""channel":"joy/0","computation":"offboard","failsafe":"channel-silent","#,
                r#""health":"degraded","battery":0.75,"position_quality":0.9,"#,
                r#""actuators":[0.5,-0.5],"mission":{"id":9,"next":1,"total":4},"stale":2}"#
            )
        );
        let none = Telemetry {
            channel: String::new(),
            safety: Some(mech_proto::SafetyReport::default()),
            ..telemetry()
        };
        let json: serde_json::Value =
            serde_json::from_slice(&to_json(&TelemetryMsg::new("s", "r", &none, 1))).unwrap();
        assert_eq!(json["channel"], serde_json::Value::Null, "none is null");
        assert!(
            json.get("safety").is_none(),
            "the safety report is not carried"
        );
        let back: TelemetryMsg = from_json("telemetry", json.to_string().as_bytes()).unwrap();
        assert_eq!(back.telemetry.channel, "");
        assert_eq!(back.telemetry.safety, None);
    }

    #[test]
    fn telemetry_of_an_older_station_reads_with_defaults() {
        let json = concat!(
            r#"{"v":1,"station":"s","robot":"r","stamp_us":1,"#,
            r#""pose":{"x":0.0,"y":0.0,"z":0.0,"heading":0.0},"#,
            r#""velocity":{"vx":0.0,"vy":0.0,"vz":0.0,"wz":0.0},"#,
            r#""mode":"twist","computation":"onboard","failsafe":"ok","health":"ok","#,
            r#""battery":null,"position_quality":1.0,"actuators":[],"mission":null}"#
        );
        let msg: TelemetryMsg = from_json("telemetry", json.as_bytes()).unwrap();
        msg.check().unwrap();
        assert_eq!(msg.telemetry.velocity_source, VelocitySource::Commanded);
        assert_eq!(
            (msg.telemetry.channel.as_str(), msg.telemetry.stale),
            ("", 0)
        );
    }

    fn registration() -> Registration {
        Registration {
            id: 3,
            hello: Hello {
                name: "robot_1".into(),
                platform: "kiwi".into(),
                capabilities: vec![CommandKind::Twist, CommandKind::Waypoints],
                motors: 3,
                max_speed: 1.5,
                max_yaw_rate: 2.0,
                agent_version: "0.1.0".into(),
            },
            addr: mech_core::LinkAddr::Udp(([127, 0, 0, 1], 9000).into()),
            count: 1,
        }
    }

    #[test]
    fn info_json_is_the_hello_without_name_or_version() {
        let msg = InfoMsg::new("site-a", "robot_1", &registration());
        let json = String::from_utf8(to_json(&msg)).unwrap();
        assert_eq!(
            json,
            concat!(
                r#"{"v":1,"station":"site-a","robot":"robot_1","id":3,"platform":"kiwi","#,
                r#""capabilities":["twist","waypoints"],"motors":3,"max_speed":1.5,"#,
                r#""max_yaw_rate":2.0}"#
            )
        );
        let mut value: serde_json::Value = serde_json::from_str(&json).unwrap();
        value["capabilities"] = serde_json::json!(["twist", "teleport"]);
        let back: InfoMsg = from_json("info", value.to_string().as_bytes()).unwrap();
        back.check().unwrap();
        assert_eq!(back.id, 3);
        assert_eq!(
            back.hello.capabilities,
            vec![CommandKind::Twist],
            "unknown left out"
        );
        assert_eq!((back.hello.name.as_str(), back.hello.motors), ("", 3));
        value["motors"] = serde_json::json!(200);
        let bad: InfoMsg = from_json("info", value.to_string().as_bytes()).unwrap();
        assert!(matches!(bad.check(), Err(PayloadError::Invalid { .. })));
    }

    #[test]
    fn unknown_fields_in_state_are_ignored_bad_values_are_not() {
        let mut json: serde_json::Value =
            serde_json::from_slice(&to_json(&TelemetryMsg::new("s", "r", &telemetry(), 1)))
                .unwrap();
        json["added_later"] = serde_json::json!(true);
        let msg: TelemetryMsg = from_json("telemetry", json.to_string().as_bytes()).unwrap();
        msg.check().unwrap();
        json["battery"] = serde_json::json!(2.0);
        let msg: TelemetryMsg = from_json("telemetry", json.to_string().as_bytes()).unwrap();
        assert!(matches!(msg.check(), Err(PayloadError::Invalid { .. })));
        json["mode"] = serde_json::json!("warp");
        let e = from_json::<TelemetryMsg>("telemetry", json.to_string().as_bytes()).unwrap_err();
        assert!(e.to_string().contains("warp"), "{e}");
    }

    #[test]
    fn origin_must_match_the_key_and_version() {
        let o = Origin::new("s", "r");
        o.check("link", "s", "r").unwrap();
        assert!(matches!(
            o.check("link", "s", "other"),
            Err(PayloadError::Mismatch { .. })
        ));
        let old = Origin { v: 7, ..o };
        assert!(matches!(
            old.check("link", "s", "r"),
            Err(PayloadError::Version { found: 7, .. })
        ));
    }

    #[test]
    fn link_and_route_payloads() {
        let l = LinkMsg {
            origin: Origin::new("s", "r"),
            state: LinkState::Stale,
        };
        let json = String::from_utf8(to_json(&l)).unwrap();
        assert_eq!(json, r#"{"v":1,"station":"s","robot":"r","state":"stale"}"#);
        let route = RouteState {
            requested: Some("ext/x".into()),
            epoch: 3,
            acknowledged: None,
            acked_epoch: 2,
        };
        let msg = RouteMsg::new("s", "r", &route);
        let back: RouteMsg = from_json("route", &to_json(&msg)).unwrap();
        assert_eq!(back.route().unwrap(), route);
        let bad = RouteMsg {
            requested: Some("two words".into()),
            ..msg
        };
        assert!(bad.route().is_err());
    }
}
