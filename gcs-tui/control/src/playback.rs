//! A recording printed as the JSON lines of `--script` (`mech-gcs replay
//! FILE --script`), for analysis with the same tools: one `event` line per
//! station event (telemetry left out, as `--script` does; the router's
//! binding from the file's snapshot first), one `result` line per operator
//! command, and a closing `summary`. Nothing is sent anywhere: this reads
//! the file only.

use serde_json::{Value, json};

use crate::script::{Sink, emit, event_json, secs};
use mech_core::replay::{Entry, Replay};
use mech_core::{Event, Stamped};

/// The line `--script` would print for `entry`, if any.
pub fn entry_json(entry: &Entry) -> Option<Value> {
    match entry {
        Entry::Event(s) if matches!(s.event, Event::Telemetry { .. }) => None,
        Entry::Event(s) => Some(event_json(s)),
        Entry::Snapshot(
            s @ Stamped {
                event: Event::Listening { .. },
                ..
            },
        ) => Some(event_json(s)),
        Entry::Snapshot(_) | Entry::Clusters { .. } => None,
        Entry::Operator(o) => {
            let mut v = json!({
                "type": "result", "t": secs(o.at), "line": o.line, "command": o.text, "ok": o.ok,
            });
            if let Value::Object(m) = &mut v {
                let key = if o.ok { "summary" } else { "error" };
                m.insert(key.into(), json!(o.summary));
                if o.source != "script" {
                    m.insert("source".into(), json!(o.source));
                }
            }
            Some(v)
        }
    }
}

/// Prints `replay` to `sink`; returns whether the file was whole (a
/// damaged one prints what could be read, and says what is wrong in the
/// summary).
pub fn print(replay: &Replay, sink: &Sink) -> bool {
    let (mut events, mut commands) = (0u64, 0u64);
    for entry in replay.entries() {
        let Some(line) = entry_json(&entry) else {
            continue;
        };
        match entry {
            Entry::Operator(_) => commands += 1,
            _ => events += 1,
        }
        emit(sink, &line);
    }
    let damage = replay.damage();
    emit(
        sink,
        &json!({
            "type": "summary", "ok": damage.is_none(), "replay": replay.path().display().to_string(),
            "events": events, "commands": commands, "duration": secs(replay.duration()),
            "damage": damage,
        }),
    );
    damage.is_none()
}
