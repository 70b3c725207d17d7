//! A recording printed as the JSON lines of `--script` (`mech-gcs replay
//! FILE --script`), for analysis with the same tools: one `event` line per
//! station event (the periodic telemetry and link quality left out, as
//! `--script` does; the router's binding from the file's snapshot first, at
//! t 0 as the run prints it), one `result` line per operator command (with
//! its detail lines), up to a recorded script's end, and a closing
//! `summary`. Nothing is sent anywhere: this reads the file only.

use serde_json::{Value, json};

use crate::script::{Sink, emit, event_json, is_script_end, secs};
use mech_core::replay::{Entry, Replay};
use mech_core::{Event, Stamped};

/// The line `--script` would print for `entry`, if any.
pub fn entry_json(entry: &Entry) -> Option<Value> {
    match entry {
        Entry::Event(s)
            if matches!(s.event, Event::Telemetry { .. } | Event::LinkQuality { .. }) =>
        {
            None
        }
        Entry::Event(s) => Some(event_json(s)),
        // The run prints the router's binding first, at t 0 (it binds as
        // the router starts); the snapshot holds it at the file's start.
        Entry::Snapshot(Stamped {
            event: e @ Event::Listening { .. },
            ..
        }) => Some(event_json(&Stamped {
            at: std::time::Duration::ZERO,
            event: e.clone(),
        })),
        Entry::Snapshot(_) | Entry::Clusters { .. } => None,
        Entry::Operator(o) if is_script_end(o) => None,
        Entry::Operator(o) => {
            let mut v = json!({
                "type": "result", "t": secs(o.at), "line": o.line, "command": o.text, "ok": o.ok,
            });
            if let Value::Object(m) = &mut v {
                let mut lines = o.summary.split('\n');
                let first = lines.next().unwrap_or_default();
                let details: Vec<&str> = lines.collect();
                if o.ok {
                    m.insert("summary".into(), json!(first));
                    if !details.is_empty() {
                        m.insert("details".into(), json!(details));
                    }
                } else {
                    m.insert("error".into(), json!(o.summary));
                }
                if o.source != crate::script::SCRIPT_SOURCE {
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
    // After a script's end the run printed nothing more; the rest is still
    // read, so damage anywhere in the file is found and reported.
    let mut ended = false;
    for entry in replay.entries() {
        ended |= matches!(&entry, Entry::Operator(o) if is_script_end(o));
        if ended {
            continue;
        }
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
