//! Headless script runs (`mech-gcs --script FILE`): parse the whole script,
//! run it statement by statement with the shared [`Executor`], and print one
//! JSON object per line for every router event (telemetry excluded) and
//! every command result. The run succeeds only if every command and
//! expectation does.
//!
//! Output lines (`t` = seconds since the router started):
//! - `{"type":"event","t":0.12,"event":"registered","robot":"robot_1",...}`
//! - `{"type":"result","t":0.5,"line":3,"command":"route robot_1 joy/0","ok":true,"summary":"..."}`
//! - `{"type":"result",...,"ok":false,"error":"line 3, column 7: ..."}`
//! - last: `{"type":"summary","ok":true,"commands":12,"failed":0}`

use std::io::Write;
use std::sync::{Arc, Mutex};

use serde_json::{Map, Value, json};

use crate::lang::{Executor, LangError, Outcome, Statement, parse_script};
use mech_core::router::Subscription;
use mech_core::{ArenaShape, Event, Gcs, LinkState, Stamped};

/// How a script run ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScriptOutcome {
    /// Every command and expectation succeeded.
    Passed { commands: usize },
    /// The script did not parse; nothing ran.
    Invalid(LangError),
    /// This command failed; the rest did not run.
    Failed { error: LangError, commands: usize },
}

impl ScriptOutcome {
    /// Process exit code: 0 passed, 1 a command failed, 2 invalid script.
    pub fn exit_code(&self) -> i32 {
        match self {
            ScriptOutcome::Passed { .. } => 0,
            ScriptOutcome::Failed { .. } => 1,
            ScriptOutcome::Invalid(_) => 2,
        }
    }
}

/// A line-oriented JSON sink shared by the event printer and the runner.
pub type Sink = Arc<Mutex<Box<dyn Write + Send>>>;

pub(crate) fn emit(sink: &Sink, value: &Value) {
    let mut w = mech_core::sync::lock(sink);
    // Output is best effort: a closed stdout must not stop the robots' script.
    let _ = writeln!(w, "{value}");
    let _ = w.flush();
}

/// Seconds, rounded to the microsecond, as the JSON lines print them.
pub fn secs(d: std::time::Duration) -> f64 {
    (d.as_secs_f64() * 1e6).round() / 1e6
}

/// The JSON line of an event: its serde form, as recordings hold it
/// (tagged with its name in `event`), with the line's `type` and `t`,
/// changed only where [`script_fields`] says.
pub fn event_json(s: &Stamped) -> Value {
    let mut v = serde_json::to_value(&s.event).unwrap_or_default();
    if let Value::Object(m) = &mut v {
        script_fields(&s.event, m);
        m.insert("type".into(), json!("event"));
        m.insert("t".into(), json!(secs(s.at)));
    }
    v
}

/// Where an event's line is not its serde form, the fields the line has
/// always had instead (`docs/commands.md`, *Script output*): a robot's
/// registration and links at the top level (its name as `robot`, its
/// address as text), a route to none as `"none"`, a mission's length, a
/// cluster command's cluster, a notice's level by name, an arena's size
/// and bounds, a safety layer's state as `state`. Telemetry and link
/// quality, which no script line shows, print as recorded.
fn script_fields(event: &Event, m: &mut Map<String, Value>) {
    let mut put = |key: &str, value: Value| m.insert(key.into(), value);
    match event {
        Event::Registered { hello, addr, .. } => {
            let capabilities: Vec<&str> = hello.capabilities.iter().map(|c| c.as_str()).collect();
            put("robot", json!(hello.name));
            put("platform", json!(hello.platform));
            put("capabilities", json!(capabilities));
            put("addr", json!(addr.to_string()));
            m.remove("hello");
        }
        Event::Links { .. } => {
            if let Some(Value::Object(links)) = m.remove("links") {
                m.extend(links);
            }
        }
        Event::RouteChanged { channel, .. } | Event::RouteAcked { channel, .. } => {
            put("channel", json!(channel.as_deref().unwrap_or("none")));
        }
        Event::MissionSent { waypoints, .. } => {
            put("waypoints", json!(waypoints.len()));
        }
        Event::ClusterCommand { command, .. } => {
            put("cluster", json!(command.cluster));
            m.remove("command");
        }
        Event::Notice { notice, .. } => {
            put("level", json!(format!("{:?}", notice.level)));
            put("text", json!(notice.text));
            m.remove("notice");
        }
        Event::Arena { arena } => {
            if let Value::Object(fields) = arena_json(arena.as_ref()) {
                m.extend(fields);
            }
        }
        Event::Safety { .. } => {
            if let Some(state) = m.remove("safety_state") {
                m.insert("state".into(), state);
            }
        }
        _ => {}
    }
}

/// An arena as a script line gives it: whether there is one, how many
/// vertices, keep-outs, slow zones and obstacles it has, its margin and
/// bounds.
fn arena_json(arena: Option<&ArenaShape>) -> Value {
    match arena {
        Some(a) => json!({
            "arena": true, "vertices": a.boundary.len(), "keep_out": a.keep_out.len(),
            "slow_zones": a.slow_zones.len(), "obstacles": a.obstacles.len(),
            "margin": a.margin, "bounds": a.bounds(),
        }),
        None => json!({"arena": false}),
    }
}

fn result_json(gcs: &Gcs, stmt: &Statement, outcome: Result<&Outcome, &LangError>) -> Value {
    result_json_at(secs(gcs.router().elapsed()), stmt, outcome)
}

/// The JSON line of a command's result at `t` seconds of station time.
pub fn result_json_at(t: f64, stmt: &Statement, outcome: Result<&Outcome, &LangError>) -> Value {
    let mut v = json!({
        "type": "result",
        "t": t,
        "line": stmt.span.line,
        "command": stmt.text,
        "ok": outcome.is_ok(),
    });
    if let Value::Object(m) = &mut v {
        match outcome {
            Ok(o) => {
                m.insert("summary".into(), json!(o.summary));
                if !o.details.is_empty() {
                    m.insert("details".into(), json!(o.details));
                }
            }
            Err(e) => {
                m.insert("error".into(), json!(e.to_string()));
            }
        }
    }
    v
}

/// Runs `stmt`, handing `on_event` every event of `events` that arrives
/// meanwhile and then those it caused synchronously (route changes,
/// e-stops), so they come before its result.
pub async fn execute_with_events(
    executor: &mut Executor,
    stmt: &Statement,
    events: &mut Subscription,
    mut on_event: impl FnMut(&Stamped),
) -> Result<Outcome, LangError> {
    let result = {
        let run = executor.execute(stmt);
        tokio::pin!(run);
        loop {
            tokio::select! {
                biased;
                r = &mut run => break r,
                Some(ev) = events.recv() => on_event(&ev),
            }
        }
    };
    while let Some(ev) = events.try_recv() {
        on_event(&ev);
    }
    result
}

/// Rejections by reason, and their total.
fn rejected_json(r: &mech_core::counters::Rejections) -> Value {
    let mut v = json!({"total": r.total()});
    if let Value::Object(m) = &mut v {
        for (reason, n) in r.by_reason() {
            m.insert(reason.as_str().into(), json!(n));
        }
    }
    v
}

/// Fleet safety at the end of a run: whether there is an arena, the robots
/// whose layer is off (an alarm), and how many times each intervention
/// began, over every robot.
fn safety_json(f: &mech_core::Fleet) -> Value {
    let off: Vec<&str> = f
        .local_robots()
        .filter(|r| r.safety_alarm())
        .map(|r| r.name.as_str())
        .collect();
    let mut interventions = serde_json::Map::new();
    for i in mech_proto::Intervention::ALL {
        let n: u64 = f
            .local_robots()
            .filter_map(|r| r.telemetry.safety)
            .map(|s| u64::from(s.counts.get(i)))
            .sum();
        if i != mech_proto::Intervention::None {
            interventions.insert(i.as_str().into(), json!(n));
        }
    }
    json!({"arena": f.arena.is_some(), "off": off, "interventions": interventions})
}

/// A recording's file and what it lost so far.
fn recording_json(r: &mech_core::RecordingStatus) -> Value {
    json!({
        "file": r.file.display().to_string(), "messages": r.messages,
        "queued": r.queued, "dropped": r.dropped,
        "refused_unrecorded": r.refused_unrecorded, "error": r.error,
    })
}

/// Marks the script's end in the recording, if one is being made: a
/// `script` record with line 0 and no text, so `replay --script` stops
/// where the run printed its summary (what the recording holds after it,
/// the robots' goodbyes as the station stops, the run never printed).
fn record_end(gcs: &Gcs, ok: bool, commands: usize, error: Option<&str>) {
    let summary = match error {
        None => format!("script passed: {commands} commands"),
        Some(e) => format!("script failed after {commands} commands: {e}"),
    };
    gcs.router()
        .record_operator(mech_core::router::OperatorRecord {
            at: std::time::Duration::ZERO,
            source: SCRIPT_SOURCE.into(),
            line: 0,
            text: String::new(),
            ok,
            summary,
        });
}

/// The recorded source of a script's commands (and of its end).
pub const SCRIPT_SOURCE: &str = "script";

/// Whether a recorded operator command is a script's end
/// ([`record_end`]): no command has an empty text.
pub fn is_script_end(o: &mech_core::router::OperatorRecord) -> bool {
    o.source == SCRIPT_SOURCE && o.line == 0 && o.text.is_empty()
}

/// Runs `source` against `gcs` with `executor`, writing JSON lines to `sink`.
pub async fn run(gcs: &Gcs, executor: &mut Executor, source: &str, sink: Sink) -> ScriptOutcome {
    let statements = match parse_script(source) {
        Ok(s) => s,
        Err(e) => {
            emit(
                &sink,
                &json!({"type": "summary", "ok": false, "commands": 0, "error": e.to_string()}),
            );
            return ScriptOutcome::Invalid(e);
        }
    };
    let mut events = gcs.router().subscribe_default(false);
    // Events that happened before the script started (the router binding).
    gcs.with_fleet(|f| {
        if let Some(udp) = f.udp {
            let s = Stamped {
                at: std::time::Duration::ZERO,
                event: Event::Listening { udp, tcp: f.tcp },
            };
            emit(&sink, &event_json(&s));
        }
    });
    let mut outcome = ScriptOutcome::Passed {
        commands: statements.len(),
    };
    for (i, stmt) in statements.iter().enumerate() {
        let result = execute_with_events(executor, stmt, &mut events, |ev| {
            emit(&sink, &event_json(ev))
        })
        .await;
        emit(&sink, &result_json(gcs, stmt, result.as_ref()));
        if let Err(error) = result {
            outcome = ScriptOutcome::Failed {
                error,
                commands: i + 1,
            };
            break;
        }
    }
    while let Some(ev) = events.try_recv() {
        emit(&sink, &event_json(&ev));
    }
    let (ok, ran, error) = match &outcome {
        ScriptOutcome::Passed { commands } => (true, *commands, None),
        ScriptOutcome::Failed { error, commands } => (false, *commands, Some(error.to_string())),
        ScriptOutcome::Invalid(e) => (false, 0, Some(e.to_string())),
    };
    record_end(gcs, ok, ran, error.as_deref());
    let (robots, remote, safety) = gcs.with_fleet(|f| {
        let connected = |r: &&mech_core::fleet::Robot| r.link == LinkState::Connected;
        let remote = f
            .robots
            .values()
            .filter(|r| !r.is_local())
            .filter(connected);
        (
            f.local_robots().filter(connected).count(),
            remote.count(),
            safety_json(f),
        )
    });
    let counters = gcs.router().counters();
    let mut summary = json!({
        "type": "summary", "ok": ok, "commands": ran, "error": error,
        "connected_robots": robots, "connected_remote_robots": remote,
        "received": counters.received, "forwarded": counters.forwarded,
        "bad_packets": counters.dropped.bad_packet,
        "authenticated": gcs.router().authenticated(),
        "rejected": rejected_json(&counters.rejected),
        "safety": safety,
    });
    if let (Some(r), Value::Object(m)) = (gcs.recording(), &mut summary) {
        m.insert("recording".into(), recording_json(&r));
    }
    emit(&sink, &summary);
    outcome
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_core::counters::RejectReason;
    use mech_core::{LinkAddr, RobotLinks};
    use mech_proto::{
        ClusterCommand, ClusterGoal, ClusterVelocity, CommandKind, Hello, Intervention, Level,
        Notice, NoticeCode, SafetyState, Waypoint,
    };
    use std::time::Duration;

    fn line(event: Event) -> Value {
        event_json(&Stamped {
            at: Duration::from_millis(1500),
            event,
        })
    }

    fn hello() -> Hello {
        Hello {
            name: "robot_1".into(),
            platform: "diff-drive".into(),
            capabilities: vec![CommandKind::Twist, CommandKind::Actuators],
            motors: 2,
            max_speed: 0.5,
            max_yaw_rate: 2.0,
            agent_version: "0.1.0".into(),
        }
    }

    /// Each event's line: the fields given, with `type`, `t` and the
    /// event's name.
    fn prints_as_documented<const N: usize>(cases: [(Event, Value); N]) {
        for (event, fields) in cases {
            let mut want = json!({"type": "event", "t": 1.5});
            if let (Value::Object(w), Value::Object(f)) = (&mut want, fields) {
                w.extend(f);
            }
            want["event"] = serde_json::to_value(&event).unwrap()["event"].clone();
            assert_eq!(line(event), want);
        }
    }

    /// The events whose script line is not their serde form, and the lines
    /// `docs/commands.md` and the end-to-end tests read: a registration,
    /// links.
    #[test]
    fn a_registration_and_links_print_at_the_top_level() {
        prints_as_documented([
            (
                Event::Registered {
                    hello: hello(),
                    id: 1,
                    addr: LinkAddr::Udp("127.0.0.1:40000".parse().unwrap()),
                    known: false,
                },
                json!({"robot": "robot_1", "id": 1, "addr": "127.0.0.1:40000",
                       "platform": "diff-drive", "capabilities": ["twist", "actuators"],
                       "known": false}),
            ),
            (
                Event::Registered {
                    hello: Hello {
                        capabilities: vec![],
                        ..hello()
                    },
                    id: 2,
                    addr: LinkAddr::Radio("/dev/ttyUSB0".into()),
                    known: true,
                },
                json!({"robot": "robot_1", "id": 2, "addr": "radio /dev/ttyUSB0",
                       "platform": "diff-drive", "capabilities": [], "known": true}),
            ),
            (
                Event::Links {
                    robot: "robot_1".into(),
                    links: RobotLinks {
                        udp: true,
                        radio: Some("/dev/ttyUSB0".into()),
                        active: "radio",
                        radio_budget_hz: Some(14.0),
                        down: vec!["wifi".into()],
                    },
                },
                json!({"robot": "robot_1", "udp": true, "radio": "/dev/ttyUSB0",
                       "active": "radio", "radio_budget_hz": 14.0, "down": ["wifi"]}),
            ),
        ]);
    }

    /// A route to none, a mission's length, a cluster command, a notice.
    #[test]
    fn routes_missions_clusters_and_notices_print_as_documented() {
        let waypoint = Waypoint {
            x: 1.0,
            y: 2.0,
            z: 0.0,
            time: None,
        };
        prints_as_documented([
            (
                Event::RouteChanged {
                    robot: "robot_1".into(),
                    channel: None,
                    epoch: 2,
                },
                json!({"robot": "robot_1", "channel": "none", "epoch": 2}),
            ),
            (
                Event::RouteAcked {
                    robot: "robot_1".into(),
                    channel: Some("wp/gcs".into()),
                    epoch: 3,
                },
                json!({"robot": "robot_1", "channel": "wp/gcs", "epoch": 3}),
            ),
            (
                Event::MissionSent {
                    robot: "robot_1".into(),
                    channel: "wp/gcs".into(),
                    id: 3,
                    waypoints: vec![waypoint, waypoint],
                    looped: true,
                },
                json!({"robot": "robot_1", "channel": "wp/gcs", "id": 3, "waypoints": 2,
                       "looped": true}),
            ),
            (
                Event::ClusterCommand {
                    channel: "fleet/c1".into(),
                    command: ClusterCommand {
                        cluster: "c1".into(),
                        members: vec!["robot_1".into()],
                        goal: ClusterGoal::Velocity(ClusterVelocity {
                            vx: 0.1,
                            vy: 0.0,
                            wz: 0.0,
                            scale_rate: 0.0,
                        }),
                        formation: None,
                    },
                },
                json!({"channel": "fleet/c1", "cluster": "c1"}),
            ),
            (
                Event::Notice {
                    from: "robot_1".into(),
                    notice: Notice {
                        level: Level::Warn,
                        code: NoticeCode::DriverFault,
                        text: "left wheel stalled".into(),
                    },
                },
                json!({"from": "robot_1", "level": "Warn", "text": "left wheel stalled"}),
            ),
        ]);
    }

    /// An arena's size and bounds, none, a safety layer's state.
    #[test]
    fn arenas_and_safety_print_as_documented() {
        prints_as_documented([
            (
                Event::Arena {
                    arena: Some(mech_core::ArenaConfig::demo().shape()),
                },
                json!({"arena": true, "vertices": 4, "keep_out": 0, "slow_zones": 0,
                       "obstacles": 0, "margin": 0.1, "bounds": [0.0, 0.0, 3.9, 2.8]}),
            ),
            (Event::Arena { arena: None }, json!({"arena": false})),
            (
                Event::Safety {
                    robot: "robot_1".into(),
                    state: SafetyState::On,
                    intervention: Intervention::Fence,
                },
                json!({"robot": "robot_1", "state": "on", "intervention": "fence"}),
            ),
        ]);
    }

    /// One of every event a script line prints as it is recorded.
    fn recorded_as_is() -> Vec<Event> {
        let robot = || "robot_1".to_string();
        vec![
            Event::Listening {
                udp: "127.0.0.1:7400".parse().unwrap(),
                tcp: Some("127.0.0.1:7401".parse().unwrap()),
            },
            Event::Link {
                robot: robot(),
                state: mech_core::LinkState::Stale,
            },
            Event::Radio {
                port: "/dev/ttyUSB0".into(),
                up: false,
                reason: "Broken pipe".into(),
            },
            Event::MissionAcked {
                robot: robot(),
                id: 3,
                accepted: false,
                reason: "too far".into(),
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
            Event::Bye {
                robot: robot(),
                reason: "shutdown".into(),
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
                by_reason: [("bad-tag".to_string(), 1000)].into_iter().collect(),
                from: "udp:1.2.3.4:5".into(),
                detail: "bad tag".into(),
            },
            Event::SafetySwitched {
                robot: robot(),
                enabled: false,
                id: 4,
            },
            Event::ArenaAcked {
                robot: robot(),
                id: 4,
                enabled: true,
            },
        ]
    }

    /// Every other event prints as it is recorded, with the line's `type`
    /// and `t`.
    #[test]
    fn other_events_print_their_serde_form() {
        for event in recorded_as_is() {
            let mut want = serde_json::to_value(&event).unwrap();
            want["type"] = json!("event");
            want["t"] = json!(1.5);
            assert_eq!(line(event), want);
        }
    }
}
