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

use mech_core::fleet::{RemoteInfo, Robot, RouteState};
use mech_proto::{
    CommandKind, Computation, ControlMode, FailsafeState, Health, MissionProgress, Pose, Telemetry,
    Velocity, VelocitySource,
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
/// received it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TelemetryMsg {
    #[serde(flatten)]
    pub origin: Origin,
    /// When the station received it: Unix time, microseconds.
    pub stamp_us: u64,
    /// m, m, m, rad.
    pub pose: Pose,
    /// World frame m/s; `wz` rad/s.
    pub velocity: Velocity,
    /// `measured` (wheel encoders) or `commanded` (what the outputs should
    /// give); `commanded` when absent.
    #[serde(default, with = "names::velocity_source")]
    pub velocity_source: VelocitySource,
    #[serde(with = "names::mode")]
    pub mode: ControlMode,
    /// The channel the robot obeys; `null` = none.
    pub channel: Option<String>,
    #[serde(with = "names::computation")]
    pub computation: Computation,
    #[serde(with = "names::failsafe")]
    pub failsafe: FailsafeState,
    #[serde(with = "names::health")]
    pub health: Health,
    /// Fraction in [0, 1].
    pub battery: Option<f64>,
    pub position_quality: f64,
    pub actuators: Vec<f64>,
    pub mission: Option<MissionProgress>,
    #[serde(default)]
    pub stale: u32,
}

impl TelemetryMsg {
    pub fn new(station: &str, robot: &str, t: &Telemetry, stamp_us: u64) -> TelemetryMsg {
        TelemetryMsg {
            origin: Origin::new(station, robot),
            stamp_us,
            pose: t.pose,
            velocity: t.velocity,
            velocity_source: t.velocity_source,
            mode: t.mode,
            channel: (!t.channel.is_empty()).then(|| t.channel.clone()),
            computation: t.computation,
            failsafe: t.failsafe,
            health: t.health,
            battery: t.battery,
            position_quality: t.position_quality,
            actuators: t.actuators.clone(),
            mission: t.mission,
            stale: t.stale,
        }
    }

    /// The telemetry, checked as the protocol checks a received one.
    pub fn telemetry(&self) -> Result<Telemetry, PayloadError> {
        let t = Telemetry {
            pose: self.pose,
            velocity: self.velocity,
            velocity_source: self.velocity_source,
            safety: None,
            mode: self.mode,
            channel: self.channel.clone().unwrap_or_default(),
            computation: self.computation,
            failsafe: self.failsafe,
            health: self.health,
            battery: self.battery,
            position_quality: self.position_quality,
            actuators: self.actuators.clone(),
            mission: self.mission,
            stale: self.stale,
        };
        let body = mech_proto::Body::Telemetry(t);
        body.validate().map_err(|e| PayloadError::Invalid {
            what: "telemetry",
            detail: e.to_string(),
        })?;
        match body {
            mech_proto::Body::Telemetry(t) => Ok(t),
            _ => unreachable!("built as telemetry above"),
        }
    }
}

/// `mech/<station>/<robot>/info`: the robot's registration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InfoMsg {
    #[serde(flatten)]
    pub origin: Origin,
    /// The id its station's router gave it.
    pub id: u16,
    pub platform: String,
    /// Command kinds it obeys: `actuators`, `steering-throttle`,
    /// `velocity-heading`, `twist`, `waypoints`, `stop`.
    pub capabilities: Vec<String>,
    pub motors: u8,
    /// m/s
    pub max_speed: f64,
    /// rad/s
    pub max_yaw_rate: f64,
}

impl InfoMsg {
    pub fn new(station: &str, r: &Robot, robot: &str) -> InfoMsg {
        InfoMsg {
            origin: Origin::new(station, robot),
            id: r.id,
            platform: r.platform.clone(),
            capabilities: r
                .capabilities
                .iter()
                .map(|c| c.as_str().to_string())
                .collect(),
            motors: r.motors,
            max_speed: r.max_speed,
            max_yaw_rate: r.max_yaw_rate,
        }
    }

    /// The registration as the fleet model keeps it; a capability this
    /// version does not know is left out.
    pub fn info(&self) -> Result<RemoteInfo, PayloadError> {
        let bad = |detail: String| PayloadError::Invalid {
            what: "info",
            detail,
        };
        // A platform name obeys the protocol's rule for names.
        if !mech_core::config::is_channel_name(&self.platform) {
            return Err(bad(format!("{:?} is not a platform name", self.platform)));
        }
        if usize::from(self.motors) > mech_proto::MAX_MOTORS {
            return Err(bad(format!("{} motors", self.motors)));
        }
        if !(self.max_speed.is_finite() && self.max_yaw_rate.is_finite()) {
            return Err(bad("limits must be finite".into()));
        }
        Ok(RemoteInfo {
            id: self.id,
            platform: self.platform.clone(),
            capabilities: self
                .capabilities
                .iter()
                .filter_map(|c| CommandKind::parse(c))
                .collect(),
            motors: self.motors,
            max_speed: self.max_speed,
            max_yaw_rate: self.max_yaw_rate,
        })
    }
}

/// `mech/<station>/<robot>/link`: how recently its station heard from it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LinkMsg {
    #[serde(flatten)]
    pub origin: Origin,
    #[serde(with = "names::link")]
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
        assert_eq!(back.telemetry().unwrap(), telemetry());
    }

    #[test]
    fn unknown_fields_in_state_are_ignored_bad_values_are_not() {
        let mut json: serde_json::Value =
            serde_json::from_slice(&to_json(&TelemetryMsg::new("s", "r", &telemetry(), 1)))
                .unwrap();
        json["added_later"] = serde_json::json!(true);
        let msg: TelemetryMsg = from_json("telemetry", json.to_string().as_bytes()).unwrap();
        msg.telemetry().unwrap();
        json["battery"] = serde_json::json!(2.0);
        let msg: TelemetryMsg = from_json("telemetry", json.to_string().as_bytes()).unwrap();
        assert!(matches!(msg.telemetry(), Err(PayloadError::Invalid { .. })));
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
