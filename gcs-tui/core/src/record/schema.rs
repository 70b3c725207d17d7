//! The recording's topics and the JSON Schemas of their messages: MECH's
//! own (`mech.*`) and Foxglove's well-known ones (`foxglove.*`, written in
//! their JSON form), which Foxglove and Lichtblick draw without plugins.

use serde_json::{Value, json};

use crate::event::Event;

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

/// The fields of each event beside `t` and `event`, every one required,
/// by the event's name ([`Event::names`], in its order): the data is
/// `mech_core::Event` as serde writes it, and a test records every variant
/// and validates it against this schema.
const EVENT_FIELDS: &[(&str, &[&str])] = &[
    ("listening", &["udp", "tcp"]),
    ("registered", &["hello", "id", "addr", "known"]),
    ("links", &["robot", "links"]),
    ("radio", &["port", "up", "reason"]),
    ("link", &["robot", "state"]),
    ("telemetry", &["robot", "telemetry"]),
    ("link_quality", &["robot", "quality"]),
    ("route_changed", &["robot", "channel", "epoch"]),
    ("route_acked", &["robot", "channel", "epoch"]),
    (
        "mission_sent",
        &["robot", "channel", "id", "waypoints", "looped"],
    ),
    ("mission_acked", &["robot", "id", "accepted", "reason"]),
    ("mission_failed", &["robot", "id", "reason"]),
    ("estop", &["engage", "id"]),
    ("estop_acked", &["robot", "engage", "id"]),
    ("estop_complete", &["engage", "id"]),
    ("channel_publisher", &["channel", "publisher"]),
    ("cluster_command", &["channel", "command"]),
    ("bye", &["robot", "reason"]),
    ("notice", &["from", "notice"]),
    ("bad_packet", &["from", "error"]),
    ("rejected", &["from", "reason", "detail"]),
    (
        "refused",
        &["count", "sources", "by_reason", "from", "detail"],
    ),
    ("arena", &["arena"]),
    ("safety_switched", &["robot", "enabled", "id"]),
    ("arena_acked", &["robot", "id", "enabled"]),
    ("safety", &["robot", "safety_state", "intervention"]),
];

fn nullable(type_name: &str) -> Value {
    json!({"type": [type_name, "null"]})
}

fn boolean() -> Value {
    json!({"type": "boolean"})
}

/// An object whose every listed property is required and nothing else is
/// allowed: MECH's own messages, so a field added to the data and not to
/// the schema fails the recording test.
fn strict(title: &str, description: &str, properties: Value) -> Value {
    let required: Vec<String> = properties
        .as_object()
        .map(|m| m.keys().cloned().collect())
        .unwrap_or_default();
    let mut v = object(title, description, properties);
    if let Value::Object(m) = &mut v {
        m.insert("required".into(), json!(required));
        m.insert("additionalProperties".into(), json!(false));
    }
    v
}

/// The schema of an event field, by name (one meaning per name across
/// events).
fn event_field(name: &str) -> Value {
    match name {
        "robot" | "publisher" | "from" | "reason" | "error" | "detail" | "udp" | "port" => string(),
        "tcp" | "channel" => nullable("string"),
        "id" | "epoch" | "count" | "sources" => integer(),
        "by_reason" => json!({"description": "messages refused for each reason",
            "type": "object", "additionalProperties": integer()}),
        "known" | "looped" | "accepted" | "engage" | "enabled" | "up" => boolean(),
        "safety_state" => json!({"description": "the robot's safety layer",
            "type": "string", "enum": ["no-arena", "on", "off"]}),
        "intervention" => json!({"description": "what the safety layer limits now",
            "type": "string",
            "enum": mech_proto::Intervention::ALL.map(|i| i.as_str())}),
        "arena" => arena(),
        "state" => json!({"type": "string", "enum": ["connected", "stale", "lost"]}),
        "hello" => strict(
            "mech.Hello",
            "the registration as the robot sent it",
            json!({"name": string(), "platform": string(),
                   "capabilities": {"description": "command kinds it obeys (docs/protocol.md numbers)",
                                    "type": "array", "items": integer()},
                   "motors": integer(), "max_speed": number(), "max_yaw_rate": number(),
                   "agent_version": string()}),
        ),
        "addr" => json!({"title": "mech.LinkAddr", "description": "where the robot was heard from",
            "oneOf": [
                {"type": "object", "properties": {"udp": string()}, "required": ["udp"], "additionalProperties": false},
                {"type": "object", "properties": {"radio": string()}, "required": ["radio"], "additionalProperties": false}]}),
        "links" => strict(
            "mech.RobotLinks",
            "the robot's live links and the one commands go out on",
            json!({"udp": boolean(), "radio": nullable("string"),
                   "active": {"type": "string", "enum": ["udp", "radio", ""]},
                   "radio_budget_hz": nullable("number"),
                   "down": {"description": "links heard once but silent now: wifi, radio",
                            "type": "array", "items": string()}}),
        ),
        "telemetry" => telemetry(),
        "quality" => link_quality(),
        "waypoints" => array(strict(
            "mech.Waypoint",
            "m; time: s after the mission starts",
            json!({"x": number(), "y": number(), "z": number(), "time": nullable("number")}),
        )),
        "command" => strict(
            "mech.ClusterCommand",
            "a cluster command (docs/protocol.md)",
            json!({"cluster": string(), "members": array(string()),
                   "goal": {"description": "velocity or pose goal, as [kind, fields]"},
                   "formation": {"description": "the formation, or null"}}),
        ),
        "notice" => strict(
            "mech.Notice",
            "a notice from a robot or controller",
            json!({"level": one_of("mech.Level", &[("DEBUG", 0), ("INFO", 1), ("WARN", 2), ("ERROR", 3)]),
                   "code": integer(), "text": string()}),
        ),
        _ => json!({}),
    }
}

/// The station's arena (`mech_core::ArenaShape`), or null when it has
/// none: polygons as lists of points, m.
fn arena() -> Value {
    let point = strict(
        "mech.Point",
        "m, map frame",
        json!({"x": number(), "y": number()}),
    );
    let polygon = array(point);
    let mut shape = strict(
        "mech.Arena",
        "the arena robots are kept inside (docs/safety.md), or null: none",
        json!({"boundary": polygon.clone(), "keep_out": array(polygon.clone()),
               "slow_zones": array(strict("mech.SlowZone", "a polygon and its speed cap, m/s",
                   json!({"polygon": polygon, "max_speed": number()}))),
               "obstacles": array(strict("mech.Disc", "a static obstacle disc, m",
                   json!({"x": number(), "y": number(), "radius": number()}))),
               "margin": number()}),
    );
    if let Value::Object(m) = &mut shape {
        m.insert("type".into(), json!(["object", "null"]));
    }
    shape
}

/// A robot's link as the router measures it (`mech_core::LinkQuality`):
/// rates in messages per second, loss a fraction, times in seconds.
fn link_quality() -> Value {
    strict(
        "mech.LinkQuality",
        "the link as the router measures it over its last seconds; rtt and window in seconds",
        json!({"rx_hz": number(), "tx_hz": number(), "loss": nullable("number"),
               "rtt": {"description": "mean round trip, s (null: not measured)", "type": ["number", "null"]},
               "window": {"description": "the time the figures cover, s", "type": "number"},
               "received": integer(), "sent": integer(), "lost": integer()}),
    )
}

/// Every event's fields at the top level (so Foxglove's message paths
/// offer them: `/mech/events{event=="link_quality"}.quality.rtt`), and
/// for each event which of them it has, all of them, and no other.
fn event() -> Value {
    let mut properties = serde_json::Map::new();
    properties.insert("t".into(), number());
    properties.insert(
        "event".into(),
        json!({"type": "string", "enum": Event::names()}),
    );
    let mut cases = Vec::new();
    for (name, fields) in EVENT_FIELDS {
        for f in *fields {
            properties.insert((*f).to_string(), event_field(f));
        }
        let mut allowed = vec!["t", "event"];
        allowed.extend_from_slice(fields);
        cases.push(json!({
            "if": {"properties": {"event": {"const": name}}, "required": ["event"]},
            "then": {"required": fields, "propertyNames": {"enum": allowed}}}));
    }
    let mut v = object(
        MECH_EVENT,
        "A station event (mech_core::Event); `event` names it, `t` is seconds since the router started. The other fields depend on the event.",
        Value::Object(properties),
    );
    if let Value::Object(m) = &mut v {
        m.insert("required".into(), json!(["t", "event"]));
        m.insert("allOf".into(), Value::Array(cases));
    }
    v
}

fn decision() -> Value {
    let mut v = object(
        MECH_DECISION,
        "What the router did with one message it received. `n` numbers messages as the router counts them (and is the sequence of the same message on /mech/raw).",
        json!({"t": number(), "n": integer(), "from": string(), "kind": string(),
               "sender": string(), "destination": string(), "channel": string(),
               "seq": integer(), "stamp_us": integer(),
               "outcome": {"type": "string", "enum": ["forwarded", "dropped", "consumed"]},
               "forwarded": integer(), "reason": string(), "detail": string(),
               "body": {"description": "the decoded body (MessagePack form as JSON)"}}),
    );
    // An unreadable message has no header fields; a kept one no reason.
    if let Value::Object(m) = &mut v {
        m.insert(
            "required".into(),
            json!(["t", "n", "from", "kind", "outcome", "forwarded"]),
        );
        m.insert("additionalProperties".into(), json!(false));
    }
    v
}

fn operator() -> Value {
    strict(
        MECH_OPERATOR,
        "A command the operator gave (command line, script, key) and its outcome; a script's end is a record with line 0 and no text",
        json!({"t": number(), "source": string(), "line": integer(), "text": string(),
               "ok": {"type": "boolean"}, "summary": string(), "details": array(string())}),
    )
}

fn clusters() -> Value {
    strict(
        MECH_CLUSTERS,
        "Every cluster defined at the station, by name, with its members",
        json!({"t": number(), "clusters": {"type": "object",
               "additionalProperties": array(string())}}),
    )
}

fn telemetry() -> Value {
    let pose = strict(
        "mech.Pose",
        "m, rad",
        json!({"x": number(), "y": number(), "z": number(), "heading": number()}),
    );
    let velocity = strict(
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
    let mission = strict(
        "mech.MissionProgress",
        "the mission held",
        json!({"id": integer(), "next": integer(), "total": integer()}),
    );
    let mut v = strict(
        MECH_TELEMETRY,
        "A robot's telemetry as it sent it (docs/protocol.md); `safety` only from robots with a safety layer",
        json!({"pose": pose, "velocity": velocity, "mode": mode, "channel": string(),
               "computation": one_of("mech.Computation", &[("ONBOARD", 0), ("OFFBOARD", 1)]),
               "failsafe": failsafe,
               "health": one_of("mech.Health", &[("OK", 0), ("DEGRADED", 1), ("FAULT", 2)]),
               "battery": {"type": ["number", "null"]}, "position_quality": number(),
               "actuators": array(number()), "mission": {"anyOf": [mission, {"type": "null"}]},
               "stale": integer(),
               "velocity_source": one_of("mech.VelocitySource", &[("COMMANDED", 0), ("MEASURED", 1)]),
               "safety": safety_report()}),
    );
    if let Some(Value::Array(required)) = v.get_mut("required") {
        required.retain(|f| f != "safety");
    }
    v
}

/// A robot's safety layer as its telemetry reports it
/// (`mech_proto::SafetyReport`, `docs/safety.md`).
fn safety_report() -> Value {
    let counts = strict(
        "mech.InterventionCounts",
        "how many times each intervention began since the robot started",
        json!({"fence": integer(), "keep_out": integer(), "separation": integer(),
               "stale_neighbours": integer(), "slow_zone": integer(), "returning": integer()}),
    );
    strict(
        "mech.SafetyReport",
        "the robot's safety layer: its state, the arena in force, what it does to the command now",
        json!({"state": one_of("mech.SafetyState", &[("NO_ARENA", 0), ("ON", 1), ("OFF", 2)]),
               "arena": integer(),
               "intervention": one_of("mech.Intervention", &[("NONE", 0), ("FENCE", 1), ("KEEP_OUT", 2),
                   ("SEPARATION", 3), ("STALE_NEIGHBOURS", 4), ("SLOW_ZONE", 5), ("RETURNING", 6)]),
               "counts": counts,
               "radius": {"description": "m", "type": "number"},
               "position_error": {"description": "m: how far the position estimate may be from the truth (the layer keeps its distances from a disc of radius + position_error)", "type": "number"}}),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_event_name_is_listed_and_topics_name_their_robot() {
        let names = Event::names();
        assert!(names.contains(&"estop_complete") && names.len() == 26);
        let described: Vec<&str> = EVENT_FIELDS.iter().map(|(n, _)| *n).collect();
        assert_eq!(described, names, "every event has its fields described");
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
            Event::Refused {
                count: 3,
                sources: 2,
                by_reason: [("bad-tag".to_string(), 2), ("shed".to_string(), 1)]
                    .into_iter()
                    .collect(),
                from: "udp:1.2.3.4:5".into(),
                detail: "x".into(),
            },
        ];
        for e in events {
            let v = serde_json::to_value(&e).unwrap();
            let name = v["event"].as_str().unwrap_or_default();
            assert!(Event::names().contains(&name), "{name}");
            assert_eq!(serde_json::from_value::<Event>(v).unwrap(), e);
        }
    }

    /// One of every event, as the recorder writes it.
    fn every_event() -> Vec<crate::event::Event> {
        use crate::counters::{LinkQuality, RejectReason};
        use crate::event::{Event, LinkAddr, LinkState, RobotLinks};
        use mech_proto::{
            ClusterCommand, ClusterGoal, ClusterVelocity, CommandKind, Formation, FormationKind,
            Hello, Level, Notice, NoticeCode, Offset, Waypoint,
        };
        let robot = || "robot_1".to_string();
        let telemetry = sample_telemetry();
        vec![
            Event::Listening {
                udp: "127.0.0.1:7400".parse().unwrap(),
                tcp: None,
            },
            Event::Registered {
                hello: Hello {
                    name: robot(),
                    platform: "diff-drive".into(),
                    capabilities: vec![CommandKind::Twist, CommandKind::Actuators],
                    motors: 2,
                    max_speed: 0.5,
                    max_yaw_rate: 2.0,
                    agent_version: "0.1.0".into(),
                },
                id: 1,
                addr: LinkAddr::Udp("127.0.0.1:40000".parse().unwrap()),
                known: false,
            },
            Event::Registered {
                hello: Hello {
                    name: "robot_2".into(),
                    platform: "kiwi".into(),
                    capabilities: vec![],
                    motors: 3,
                    max_speed: 0.5,
                    max_yaw_rate: 2.0,
                    agent_version: "0.1.0".into(),
                },
                id: 2,
                addr: LinkAddr::Radio("/dev/ttyUSB0".into()),
                known: true,
            },
            Event::Links {
                robot: robot(),
                links: RobotLinks {
                    udp: true,
                    radio: Some("/dev/ttyUSB0".into()),
                    active: "udp",
                    radio_budget_hz: Some(14.0),
                    down: vec!["radio".into()],
                },
            },
            Event::Radio {
                port: "/dev/ttyUSB0".into(),
                up: false,
                reason: "Broken pipe".into(),
            },
            Event::Link {
                robot: robot(),
                state: LinkState::Stale,
            },
            Event::Telemetry {
                robot: robot(),
                telemetry,
            },
            Event::LinkQuality {
                robot: robot(),
                quality: LinkQuality {
                    rx_hz: 21.0,
                    tx_hz: 4.0,
                    loss: Some(0.01),
                    rtt: Some(std::time::Duration::from_micros(420)),
                    window: std::time::Duration::from_secs(5),
                    received: 100,
                    sent: 20,
                    lost: 1,
                },
            },
            Event::LinkQuality {
                robot: robot(),
                quality: LinkQuality::default(),
            },
            Event::RouteChanged {
                robot: robot(),
                channel: None,
                epoch: 2,
            },
            Event::RouteAcked {
                robot: robot(),
                channel: Some("wp/gcs".into()),
                epoch: 2,
            },
            Event::MissionSent {
                robot: robot(),
                channel: "wp/gcs".into(),
                id: 3,
                waypoints: vec![
                    Waypoint {
                        x: 1.0,
                        y: 2.0,
                        z: 0.0,
                        time: None,
                    },
                    Waypoint {
                        x: 2.0,
                        y: 2.0,
                        z: 0.0,
                        time: Some(10.0),
                    },
                ],
                looped: true,
            },
            Event::MissionAcked {
                robot: robot(),
                id: 3,
                accepted: true,
                reason: String::new(),
            },
            Event::MissionFailed {
                robot: robot(),
                id: 3,
                reason: "no acknowledgement".into(),
            },
            Event::EStop {
                engage: true,
                id: 7,
            },
            Event::EStopAcked {
                robot: robot(),
                engage: true,
                id: 7,
            },
            Event::EStopComplete {
                engage: false,
                id: 8,
            },
            Event::ChannelPublisher {
                channel: "joy/0".into(),
                publisher: "gcs".into(),
            },
            Event::ClusterCommand {
                channel: "fleet/c1".into(),
                command: ClusterCommand {
                    cluster: "c1".into(),
                    members: vec![robot()],
                    goal: ClusterGoal::Velocity(ClusterVelocity {
                        vx: 0.1,
                        vy: 0.0,
                        wz: 0.0,
                        scale_rate: 0.0,
                    }),
                    formation: Some(Formation {
                        kind: FormationKind::Custom,
                        spacing: 1.0,
                        offsets: vec![Offset { x: 1.0, y: 0.0 }],
                    }),
                },
            },
            Event::Bye {
                robot: robot(),
                reason: "shutdown".into(),
            },
            Event::Notice {
                from: robot(),
                notice: Notice {
                    level: Level::Warn,
                    code: NoticeCode::DriverFault,
                    text: "left wheel stalled".into(),
                },
            },
            Event::BadPacket {
                from: "udp:127.0.0.1:5".into(),
                error: "truncated".into(),
            },
            Event::Rejected {
                from: "udp:1.2.3.4:5".into(),
                reason: RejectReason::Replay,
                detail: "stamp seen".into(),
            },
            Event::Refused {
                count: 1200,
                sources: 16,
                by_reason: [("bad-tag".to_string(), 1000), ("shed".to_string(), 200)]
                    .into_iter()
                    .collect(),
                from: "udp:1.2.3.4:5".into(),
                detail: "bad tag".into(),
            },
            Event::Arena {
                arena: Some(crate::ArenaConfig::demo().shape()),
            },
            Event::Arena {
                arena: Some(crate::ArenaShape {
                    keep_out: vec![vec![
                        mech_proto::Point { x: 1.0, y: 1.0 },
                        mech_proto::Point { x: 2.0, y: 1.0 },
                        mech_proto::Point { x: 2.0, y: 2.0 },
                    ]],
                    slow_zones: vec![mech_proto::SlowZone {
                        polygon: vec![
                            mech_proto::Point { x: 0.0, y: 0.0 },
                            mech_proto::Point { x: 1.0, y: 0.0 },
                            mech_proto::Point { x: 1.0, y: 1.0 },
                        ],
                        max_speed: 0.1,
                    }],
                    obstacles: vec![mech_proto::Disc {
                        x: 3.0,
                        y: 0.5,
                        radius: 0.2,
                    }],
                    ..crate::ArenaConfig::demo().shape()
                }),
            },
            Event::Arena { arena: None },
            Event::SafetySwitched {
                robot: robot(),
                enabled: false,
                id: 4,
            },
            Event::ArenaAcked {
                robot: robot(),
                id: 4,
                enabled: false,
            },
            Event::Safety {
                robot: robot(),
                state: mech_proto::SafetyState::On,
                intervention: mech_proto::Intervention::Fence,
            },
        ]
    }

    fn sample_telemetry() -> mech_proto::Telemetry {
        use mech_proto::{
            Computation, ControlMode, FailsafeState, Health, MissionProgress, Pose, Telemetry,
            Velocity, VelocitySource,
        };
        Telemetry {
            pose: Pose {
                x: 1.0,
                y: 2.0,
                z: 0.0,
                heading: 0.5,
            },
            velocity: Velocity::default(),
            mode: ControlMode::Twist,
            channel: "joy/0".into(),
            computation: Computation::Onboard,
            failsafe: FailsafeState::Ok,
            health: Health::Ok,
            battery: Some(0.8),
            position_quality: 1.0,
            actuators: vec![0.1, -0.1],
            mission: Some(MissionProgress {
                id: 3,
                next: 1,
                total: 2,
            }),
            stale: 0,
            velocity_source: VelocitySource::Measured,
            safety: Some(mech_proto::SafetyReport {
                state: mech_proto::SafetyState::On,
                arena: 2,
                intervention: mech_proto::Intervention::Separation,
                counts: mech_proto::InterventionCounts {
                    separation: 3,
                    ..Default::default()
                },
                radius: 0.15,
                position_error: 0.03,
            }),
        }
    }

    /// What `tests/scripts/validate_recording.py` (Python's `jsonschema`
    /// and `mcap`) says of `file`; `None` where Python or its packages are
    /// missing outside CI (`scripts/deps.sh` installs them; CI must run it).
    fn python_validates(file: &std::path::Path) -> Option<Value> {
        let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../tests/scripts/validate_recording.py");
        let out = std::process::Command::new("python3")
            .arg(script)
            .arg(file)
            .output();
        let missing = |why: &str| {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI must validate recordings: {why}"
            );
            println!("skipped the schema validation: {why} (bash scripts/deps.sh)");
            None
        };
        let out = match out {
            Ok(out) => out,
            Err(e) => return missing(&e.to_string()),
        };
        let stderr = String::from_utf8_lossy(&out.stderr);
        if stderr.contains("No module named") {
            return missing(&stderr);
        }
        assert!(out.status.success(), "validator: {stderr}");
        Some(serde_json::from_slice(&out.stdout).expect("one JSON object"))
    }

    #[test]
    fn every_event_validates_against_the_schema_the_file_embeds() {
        use crate::event::Stamped;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("events.mcap");
        let mut file =
            super::super::file::McapFile::create(&path, false, true, Default::default()).unwrap();
        let events = file.channel(EVENTS, Some(MECH_EVENT)).unwrap();
        let wrong = file.channel("/wrong", Some(MECH_EVENT)).unwrap();
        let all = every_event();
        let written = all.len() as u64;
        let mut names: Vec<String> = all
            .iter()
            .map(|e| serde_json::to_value(e).unwrap()["event"].to_string())
            .map(|tag| tag.trim_matches('"').to_string())
            .collect();
        names.dedup();
        assert_eq!(names, Event::names(), "one of every event, in order");
        for (i, e) in all.into_iter().enumerate() {
            let stamped = Stamped {
                at: std::time::Duration::from_millis(i as u64),
                event: e,
            };
            let json = super::super::encode::event(&stamped);
            file.write(events, None, i as u64, &json).unwrap();
        }
        // What the schema must refuse: a field it does not describe, a
        // round trip in serde's Duration form, an event it does not know.
        for bad in [
            json!({"t": 0.0, "event": "link", "robot": "r", "state": "stale", "extra": 1}),
            json!({"t": 0.0, "event": "link_quality", "robot": "r", "quality": {
                "rx_hz": 1.0, "tx_hz": 1.0, "loss": null, "rtt": {"secs": 0, "nanos": 5},
                "window": 5.0, "received": 1, "sent": 1, "lost": 0}}),
            json!({"t": 0.0, "event": "unheard_of"}),
        ] {
            file.write(wrong, None, 0, &serde_json::to_vec(&bad).unwrap())
                .unwrap();
        }
        file.finish(Default::default()).unwrap();
        let Some(read) = python_validates(&path) else {
            return;
        };
        assert_eq!(read["validated"][EVENTS].as_u64(), Some(written), "{read}");
        let errors = read["errors"].as_array().unwrap();
        assert!(
            errors.iter().all(|e| e["topic"] == "/wrong"),
            "every event validates: {read:#}"
        );
        assert_eq!(read["validated"]["/wrong"], 3, "{read}");
        assert!(errors.len() >= 3, "each wrong message refused: {read:#}");
    }
}
