//! The JSON form of each recorded message: station events, telemetry,
//! poses, router decisions, operator commands, log lines and clusters.
//! Times inside messages are Foxglove `{sec, nsec}` since the Unix epoch;
//! `t` fields are seconds since the router started.

use std::collections::BTreeMap;
use std::time::Duration;

use mech_proto::{Pose, Telemetry};
use serde::Serialize;
use serde_json::{Value, json};

use crate::event::Stamped;
use crate::fleet::{Cluster, Severity};
use crate::router::{Delivery, OperatorRecord, TappedMessage};

/// Seconds, rounded to the microsecond (as `--script` prints them).
pub(crate) fn secs(d: Duration) -> f64 {
    (d.as_secs_f64() * 1e6).round() / 1e6
}

/// A Foxglove time.
#[derive(Debug, Clone, Copy, Serialize)]
pub(super) struct Time {
    sec: u64,
    nsec: u32,
}

impl Time {
    pub(super) fn from_unix_ns(ns: u64) -> Time {
        Time {
            sec: ns / 1_000_000_000,
            nsec: (ns % 1_000_000_000) as u32,
        }
    }
}

fn bytes(v: &Value) -> Vec<u8> {
    // A Value always serialises.
    serde_json::to_vec(v).unwrap_or_default()
}

/// A station event: `{"t": .., "event": "name", ..its fields}`.
pub fn event(s: &Stamped) -> Vec<u8> {
    let mut v = serde_json::to_value(&s.event).unwrap_or(Value::Null);
    if let Value::Object(m) = &mut v {
        m.insert("t".into(), json!(secs(s.at)));
    }
    bytes(&v)
}

/// A robot's telemetry, field for field.
pub fn telemetry(t: &Telemetry) -> Vec<u8> {
    serde_json::to_vec(t).unwrap_or_default()
}

#[derive(Serialize)]
struct Vector3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Serialize)]
struct Quaternion {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

#[derive(Serialize)]
pub(super) struct FoxglovePose {
    position: Vector3,
    orientation: Quaternion,
}

/// A pose in the plane as Foxglove's position and orientation (a yaw of
/// `heading` about +z).
pub(super) fn foxglove_pose(x: f64, y: f64, z: f64, heading: f64) -> FoxglovePose {
    let half = heading / 2.0;
    FoxglovePose {
        position: Vector3 { x, y, z },
        orientation: Quaternion {
            x: 0.0,
            y: 0.0,
            z: half.sin(),
            w: half.cos(),
        },
    }
}

#[derive(Serialize)]
struct PoseInFrame<'a> {
    timestamp: Time,
    frame_id: &'a str,
    pose: FoxglovePose,
}

/// Frame every pose and scene entity is in.
pub(super) const WORLD: &str = "world";

/// A robot's pose as `foxglove.PoseInFrame`.
pub fn pose(unix_ns: u64, p: &Pose) -> Vec<u8> {
    let msg = PoseInFrame {
        timestamp: Time::from_unix_ns(unix_ns),
        frame_id: WORLD,
        pose: foxglove_pose(p.x, p.y, p.z, p.heading),
    };
    serde_json::to_vec(&msg).unwrap_or_default()
}

/// Whether a message's decision goes on the decisions channel: all but
/// accepted telemetry (its decision is always the same, and its content is
/// on the robot's telemetry topic).
pub(super) fn has_decision(m: &TappedMessage) -> bool {
    let telemetry = mech_proto::peek(&m.bytes).is_ok_and(|h| h.kind == TELEMETRY_KIND);
    !(telemetry && m.delivery == Delivery::Consumed)
}

/// Wire kind of a telemetry body.
const TELEMETRY_KIND: u8 = 4;

/// What the router did with a message, with the message decoded as far as
/// it can be.
pub(super) fn decision(m: &TappedMessage) -> Vec<u8> {
    let (outcome, forwarded, reason) = match m.delivery {
        Delivery::Forwarded(n) => ("forwarded", n, None),
        Delivery::Dropped(r) => ("dropped", 0, Some(r.as_str())),
        Delivery::Consumed => ("consumed", 0, None),
    };
    let mut v = json!({
        "t": secs(m.at), "n": m.number, "from": m.from.to_string(),
        "outcome": outcome, "forwarded": forwarded,
    });
    let Value::Object(map) = &mut v else {
        return bytes(&v);
    };
    if let Some(r) = reason {
        map.insert("reason".into(), json!(r));
    }
    if let Some(d) = &m.detail {
        map.insert("detail".into(), json!(d));
    }
    match mech_proto::decode(&m.bytes) {
        Ok(env) => {
            let h = &env.header;
            map.insert("kind".into(), json!(env.body.name()));
            map.insert("sender".into(), json!(h.sender));
            map.insert("destination".into(), json!(h.destination));
            map.insert("channel".into(), json!(h.channel));
            map.insert("seq".into(), json!(h.seq));
            map.insert("stamp_us".into(), json!(h.stamp_us));
            map.insert(
                "body".into(),
                serde_json::to_value(&env.body).unwrap_or_default(),
            );
        }
        Err(e) => {
            map.insert("kind".into(), json!("unreadable"));
            map.entry("detail").or_insert_with(|| json!(e.to_string()));
        }
    }
    bytes(&v)
}

/// An operator command and its outcome: the record's first line is the
/// summary, any further lines the details (`status`'s robots).
pub(super) fn operator(o: &OperatorRecord) -> Vec<u8> {
    let mut lines = o.summary.split('\n');
    let summary = lines.next().unwrap_or_default();
    let details: Vec<&str> = lines.collect();
    bytes(&json!({
        "t": secs(o.at), "source": o.source, "line": o.line, "text": o.text,
        "ok": o.ok, "summary": summary, "details": details,
    }))
}

/// A line of the event log as `foxglove.Log`.
pub fn log_line(unix_ns: u64, severity: Severity, text: &str, name: &str) -> Vec<u8> {
    let level = match severity {
        Severity::Debug => 1,
        Severity::Info => 2,
        Severity::Warn => 3,
        Severity::Error => 4,
    };
    bytes(&json!({
        "timestamp": Time::from_unix_ns(unix_ns), "level": level, "message": text,
        "name": name, "file": "", "line": 0,
    }))
}

/// Every cluster, by name, with its members.
pub fn clusters(at: Duration, clusters: &BTreeMap<String, Cluster>) -> Vec<u8> {
    let by_name: BTreeMap<&str, &[String]> = clusters
        .iter()
        .map(|(n, c)| (n.as_str(), c.members.as_slice()))
        .collect();
    bytes(&json!({"t": secs(at), "clusters": by_name}))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_heading_is_a_yaw_about_z() {
        let p = foxglove_pose(1.0, 2.0, 0.0, std::f64::consts::FRAC_PI_2);
        let v = serde_json::to_value(&p).unwrap();
        assert!((v["orientation"]["z"].as_f64().unwrap() - 0.5f64.sqrt()).abs() < 1e-12);
        assert!((v["orientation"]["w"].as_f64().unwrap() - 0.5f64.sqrt()).abs() < 1e-12);
        let t = serde_json::to_value(Time::from_unix_ns(1_500_000_001)).unwrap();
        assert_eq!(t, json!({"sec": 1, "nsec": 500_000_001}));
    }
}
