//! The recording's topics and the JSON Schemas of their messages: MECH's
//! own (`mech.*`) and Foxglove's well-known ones (`foxglove.*`, written in
//! their JSON form), which Foxglove and Lichtblick draw without plugins.

use serde_json::{Value, json};

/// Every router message as received (MessagePack bytes, no schema).
pub const RAW: &str = "/mech/raw";
/// The router's decision on each message (except accepted telemetry).
pub const DECISIONS: &str = "/mech/decisions";
/// Station events as they happened.
pub const EVENTS: &str = "/mech/events";
/// The state at the start of a file, as events (not things that happened
/// then: a replay applies them, `replay --script` does not print them).
pub const SNAPSHOT: &str = "/mech/snapshot";
/// Operator commands and how they went.
pub const OPERATOR: &str = "/mech/operator";
/// Cluster definitions, whenever they change.
pub const CLUSTERS: &str = "/mech/clusters";
/// The event log, as the operator saw it (`foxglove.Log`).
pub const LOG: &str = "/mech/log";
/// The fleet drawn in 3D (`foxglove.SceneUpdate`).
pub const SCENE: &str = "/mech/scene";

/// A robot's telemetry topic.
pub fn telemetry_topic(robot: &str) -> String {
    format!("/robots/{robot}/telemetry")
}

/// A robot's pose topic (`foxglove.PoseInFrame`).
pub fn pose_topic(robot: &str) -> String {
    format!("/robots/{robot}/pose")
}

/// The robot a `/robots/NAME/telemetry` topic belongs to.
pub fn telemetry_robot(topic: &str) -> Option<&str> {
    topic.strip_prefix("/robots/")?.strip_suffix("/telemetry")
}

/// Message encoding of the raw channel (MECH's MessagePack envelope;
/// `docs/protocol.md`). Foxglove and Lichtblick list it but cannot show it.
pub const RAW_ENCODING: &str = "x-mech-msgpack";

/// Schema names, as the channels declare them.
pub const POSE_IN_FRAME: &str = "foxglove.PoseInFrame";
pub const SCENE_UPDATE: &str = "foxglove.SceneUpdate";
pub const FOXGLOVE_LOG: &str = "foxglove.Log";
pub const MECH_EVENT: &str = "mech.Event";
pub const MECH_DECISION: &str = "mech.Decision";
pub const MECH_OPERATOR: &str = "mech.OperatorCommand";
pub const MECH_CLUSTERS: &str = "mech.Clusters";
pub const MECH_TELEMETRY: &str = "mech.Telemetry";

/// The JSON Schema of a named schema.
pub fn schema(name: &str) -> Value {
    match name {
        POSE_IN_FRAME => pose_in_frame(),
        SCENE_UPDATE => scene_update(),
        FOXGLOVE_LOG => log(),
        MECH_EVENT => event(),
        MECH_DECISION => decision(),
        MECH_OPERATOR => operator(),
        MECH_CLUSTERS => clusters(),
        _ => telemetry(),
    }
}

fn object(title: &str, description: &str, properties: Value) -> Value {
    json!({"title": title, "description": description, "type": "object", "properties": properties})
}

fn number() -> Value {
    json!({"type": "number"})
}

fn integer() -> Value {
    json!({"type": "integer"})
}

fn string() -> Value {
    json!({"type": "string"})
}

fn time() -> Value {
    json!({"type": "object", "title": "time", "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}})
}

fn duration() -> Value {
    json!({"type": "object", "title": "duration", "properties": {
        "sec": {"type": "integer"},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}})
}

fn vector3() -> Value {
    object(
        "foxglove.Vector3",
        "A vector in 3D space",
        json!({"x": number(), "y": number(), "z": number()}),
    )
}

fn pose() -> Value {
    let quaternion = object(
        "foxglove.Quaternion",
        "A quaternion",
        json!({"x": number(), "y": number(), "z": number(), "w": number()}),
    );
    object(
        "foxglove.Pose",
        "A position and orientation",
        json!({"position": vector3(), "orientation": quaternion}),
    )
}

fn color() -> Value {
    object(
        "foxglove.Color",
        "A color in RGBA, each in [0, 1]",
        json!({"r": number(), "g": number(), "b": number(), "a": number()}),
    )
}

fn array(items: Value) -> Value {
    json!({"type": "array", "items": items})
}

/// Enum values documented as Foxglove does (`oneOf` of titled constants),
/// so its message panels show the names.
fn one_of(title: &str, values: &[(&str, u64)]) -> Value {
    let cases: Vec<Value> = values
        .iter()
        .map(|(t, v)| json!({"title": t, "const": v}))
        .collect();
    json!({"title": title, "oneOf": cases})
}

fn pose_in_frame() -> Value {
    object(
        POSE_IN_FRAME,
        "A robot's pose in the world frame (REP 103: x forward, heading counter-clockwise)",
        json!({"timestamp": time(), "frame_id": string(), "pose": pose()}),
    )
}

fn log() -> Value {
    let level = one_of(
        "foxglove.LogLevel",
        &[
            ("UNKNOWN", 0),
            ("DEBUG", 1),
            ("INFO", 2),
            ("WARNING", 3),
            ("ERROR", 4),
            ("FATAL", 5),
        ],
    );
    object(
        FOXGLOVE_LOG,
        "A line of the station's event log",
        json!({"timestamp": time(), "level": level, "message": string(), "name": string(),
               "file": string(), "line": integer()}),
    )
}

fn scene_update() -> Value {
    let deletion = object(
        "foxglove.SceneEntityDeletion",
        "Entities to remove",
        json!({"timestamp": time(), "type": one_of("foxglove.SceneEntityDeletionType",
                &[("MATCHING_ID", 0), ("ALL", 1)]), "id": string()}),
    );
    let posed = |title: &str, extra: Value| {
        let mut p = json!({"pose": pose(), "color": color()});
        if let (Value::Object(m), Value::Object(e)) = (&mut p, extra) {
            m.extend(e);
        }
        object(title, title, p)
    };
    let arrow = posed(
        "foxglove.ArrowPrimitive",
        json!({"shaft_length": number(), "shaft_diameter": number(),
               "head_length": number(), "head_diameter": number()}),
    );
    let sphere = posed("foxglove.SpherePrimitive", json!({"size": vector3()}));
    let text = posed(
        "foxglove.TextPrimitive",
        json!({"billboard": {"type": "boolean"}, "font_size": number(),
               "scale_invariant": {"type": "boolean"}, "text": string()}),
    );
    let line = posed(
        "foxglove.LinePrimitive",
        json!({"type": one_of("foxglove.LineType", &[("LINE_STRIP", 0), ("LINE_LOOP", 1), ("LINE_LIST", 2)]),
               "thickness": number(), "scale_invariant": {"type": "boolean"},
               "points": array(vector3()), "colors": array(color()), "indices": array(integer())}),
    );
    let entity = object(
        "foxglove.SceneEntity",
        "A robot, a waypoint list or a cluster",
        json!({"timestamp": time(), "frame_id": string(), "id": string(), "lifetime": duration(),
               "frame_locked": {"type": "boolean"}, "metadata": array(json!({"type": "object"})),
               "arrows": array(arrow), "cubes": array(json!({"type": "object"})),
               "spheres": array(sphere), "cylinders": array(json!({"type": "object"})),
               "lines": array(line), "triangles": array(json!({"type": "object"})),
               "texts": array(text), "models": array(json!({"type": "object"}))}),
    );
    object(
        SCENE_UPDATE,
        "The fleet: robots with headings, mission waypoints, cluster centres",
        json!({"deletions": array(deletion), "entities": array(entity)}),
    )
}

fn event() -> Value {
    object(
        MECH_EVENT,
        "A station event (mech_core::Event); `event` names it, `t` is seconds since the router started. The other fields depend on the event.",
        json!({"t": number(), "event": {"type": "string", "enum": EVENT_NAMES}}),
    )
}

/// Names of every event, as [`crate::Event::name`] gives them.
pub const EVENT_NAMES: &[&str] = &[
    "listening",
    "registered",
    "link",
    "links",
    "radio",
    "telemetry",
    "link_quality",
    "route_changed",
    "route_acked",
    "mission_sent",
    "mission_acked",
    "mission_failed",
    "estop",
    "estop_acked",
    "estop_complete",
    "channel_publisher",
    "cluster_command",
    "bye",
    "notice",
    "bad_packet",
    "rejected",
];

fn decision() -> Value {
    object(
        MECH_DECISION,
        "What the router did with one message it received. `n` numbers messages as the router counts them (and is the sequence of the same message on /mech/raw).",
        json!({"t": number(), "n": integer(), "from": string(), "kind": string(),
               "sender": string(), "destination": string(), "channel": string(),
               "seq": integer(), "stamp_us": integer(),
               "outcome": {"type": "string", "enum": ["forwarded", "dropped", "consumed"]},
               "forwarded": integer(), "reason": string(), "detail": string(),
               "body": {"description": "the decoded body (MessagePack form as JSON)"}}),
    )
}

fn operator() -> Value {
    object(
        MECH_OPERATOR,
        "A command the operator gave (command line, script, key) and its outcome",
        json!({"t": number(), "source": string(), "line": integer(), "text": string(),
               "ok": {"type": "boolean"}, "summary": string()}),
    )
}

fn clusters() -> Value {
    object(
        MECH_CLUSTERS,
        "Every cluster defined at the station, by name, with its members",
        json!({"t": number(), "clusters": {"type": "object",
               "additionalProperties": array(string())}}),
    )
}

fn telemetry() -> Value {
    let pose = object(
        "mech.Pose",
        "m, rad",
        json!({"x": number(), "y": number(), "z": number(), "heading": number()}),
    );
    let velocity = object(
        "mech.Velocity",
        "m/s, rad/s",
        json!({"vx": number(), "vy": number(), "vz": number(), "wz": number()}),
    );
    let mode = one_of(
        "mech.ControlMode",
        &[
            ("IDLE", 0),
            ("ACTUATORS", 1),
            ("STEERING_THROTTLE", 2),
            ("VELOCITY_HEADING", 3),
            ("TWIST", 4),
            ("WAYPOINTS", 5),
            ("STOPPED", 6),
        ],
    );
    let failsafe = one_of(
        "mech.FailsafeState",
        &[
            ("OK", 0),
            ("CHANNEL_SILENT", 1),
            ("ROUTER_LOST", 2),
            ("ESTOPPED", 3),
            ("FAULT", 4),
        ],
    );
    let mission = object(
        "mech.MissionProgress",
        "the mission held",
        json!({"id": integer(), "next": integer(), "total": integer()}),
    );
    object(
        MECH_TELEMETRY,
        "A robot's telemetry as it sent it (docs/protocol.md)",
        json!({"pose": pose, "velocity": velocity, "mode": mode, "channel": string(),
               "computation": one_of("mech.Computation", &[("ONBOARD", 0), ("OFFBOARD", 1)]),
               "failsafe": failsafe,
               "health": one_of("mech.Health", &[("OK", 0), ("DEGRADED", 1), ("FAULT", 2)]),
               "battery": {"type": ["number", "null"]}, "position_quality": number(),
               "actuators": array(number()), "mission": {"anyOf": [mission, {"type": "null"}]},
               "stale": integer()}),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_event_name_is_listed_and_topics_name_their_robot() {
        let names: Vec<&str> = EVENT_NAMES.to_vec();
        assert!(names.contains(&"estop_complete") && names.len() == 21);
        assert_eq!(
            telemetry_robot(&telemetry_topic("robot_1")),
            Some("robot_1")
        );
        assert_eq!(telemetry_robot(&pose_topic("robot_1")), None);
        for name in [
            POSE_IN_FRAME,
            SCENE_UPDATE,
            FOXGLOVE_LOG,
            MECH_EVENT,
            MECH_TELEMETRY,
        ] {
            assert_eq!(schema(name)["title"], name);
        }
    }

    #[test]
    fn events_are_tagged_with_their_names_and_read_back() {
        use crate::counters::RejectReason;
        use crate::event::{Event, LinkState};
        let events = [
            Event::Link {
                robot: "r".into(),
                state: LinkState::Stale,
            },
            Event::RouteChanged {
                robot: "r".into(),
                channel: None,
                epoch: 2,
            },
            Event::EStop {
                engage: true,
                id: 7,
            },
            Event::EStopAcked {
                robot: "r".into(),
                engage: false,
                id: 7,
            },
            Event::EStopComplete {
                engage: true,
                id: 7,
            },
            Event::Rejected {
                from: "udp:1.2.3.4:5".into(),
                reason: RejectReason::UnknownKey,
                detail: "x".into(),
            },
            Event::BadPacket {
                from: "gcs".into(),
                error: "e".into(),
            },
        ];
        for e in events {
            let v = serde_json::to_value(&e).unwrap();
            assert_eq!(v["event"], e.name());
            assert!(EVENT_NAMES.contains(&e.name()));
            assert_eq!(serde_json::from_value::<Event>(v).unwrap(), e);
        }
    }
}
