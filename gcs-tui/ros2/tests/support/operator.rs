//! An operator attached to the station's control socket
//! (`docs/control-protocol.md`): command-language lines in, their results,
//! the router's events, the event log and fleet snapshots out, each kept
//! with the wall-clock time it arrived (as the fake base stamps its
//! samples, so the two can be compared); and teleop, a twist published on
//! a channel 10 times a second while a [`Pad`] lives.

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

use crate::rig::WAIT;

/// Wall-clock seconds since the Unix epoch (Python's `time.time()`).
pub fn now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// Snapshots kept: a minute and more at the station's 20 a second.
const SNAPSHOTS: usize = 4000;

/// What the station has sent, as it came.
#[derive(Debug, Default)]
struct Heard {
    /// (arrival, fleet) with the robots' trails left out.
    snapshots: std::collections::VecDeque<(f64, Value)>,
    /// Router events and event-log lines, with their arrival.
    events: Vec<(f64, Value)>,
    results: HashMap<u64, Value>,
}

/// One attached session; the station's messages are read by a thread.
#[derive(Debug)]
pub struct Operator {
    stream: Arc<Mutex<UnixStream>>,
    heard: Arc<Mutex<Heard>>,
    next_id: AtomicU64,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl Operator {
    /// Attaches to `socket` asking for snapshots, events and the log.
    pub fn attach(socket: &Path) -> Operator {
        let deadline = Instant::now() + WAIT;
        let stream = loop {
            match UnixStream::connect(socket) {
                Ok(s) => break s,
                Err(e) if Instant::now() > deadline => {
                    panic!("attaching to {}: {e}", socket.display())
                }
                Err(_) => std::thread::sleep(Duration::from_millis(100)),
            }
        };
        let mut reader = BufReader::new(stream.try_clone().expect("socket clone"));
        let op = Operator {
            stream: Arc::new(Mutex::new(stream)),
            heard: Arc::new(Mutex::new(Heard::default())),
            next_id: AtomicU64::new(1),
        };
        op.send(&json!({"type": "hello", "protocol": 1, "operator": "test",
            "stream": {"snapshots": true, "events": true, "log": true}}));
        let mut line = String::new();
        reader
            .read_line(&mut line)
            .expect("the station answers hello");
        let welcome: Value = serde_json::from_str(&line).expect("JSON");
        assert_eq!(welcome["type"], "welcome", "{welcome}");
        let heard = op.heard.clone();
        std::thread::spawn(move || {
            for line in reader.lines().map_while(Result::ok) {
                let Ok(mut m) = serde_json::from_str::<Value>(&line) else {
                    continue;
                };
                let t = now();
                let mut h = lock(&heard);
                match m["type"].as_str() {
                    Some("snapshot") => {
                        let mut fleet = m["fleet"].take();
                        if let Some(robots) = fleet["robots"].as_array_mut() {
                            for r in robots {
                                r.as_object_mut().map(|o| o.remove("trail"));
                            }
                        }
                        if h.snapshots.len() == SNAPSHOTS {
                            h.snapshots.pop_front();
                        }
                        h.snapshots.push_back((t, fleet));
                    }
                    Some("result") => {
                        let id = m["id"].as_u64().unwrap_or(0);
                        h.results.insert(id, m);
                    }
                    Some("event" | "log") => h.events.push((t, m)),
                    _ => {}
                }
            }
        });
        op
    }

    fn send(&self, message: &Value) {
        let mut s = lock(&self.stream);
        // A station killed on purpose leaves a broken pipe: the tests
        // that kill it stop sending.
        let _ = writeln!(s, "{message}");
        let _ = s.flush();
    }

    /// Runs one command-language line; returns its result, panicking if
    /// it failed or never came.
    pub fn run(&self, text: &str) -> Value {
        let result = self.try_run(text);
        assert_eq!(result["ok"], true, "`{text}` failed: {result}");
        result
    }

    /// Runs one line; returns its result, failed or not.
    pub fn try_run(&self, text: &str) -> Value {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        self.send(&json!({"type": "line", "id": id, "text": text}));
        let deadline = Instant::now() + WAIT * 2;
        while Instant::now() < deadline {
            if let Some(r) = lock(&self.heard).results.remove(&id) {
                return r;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        panic!("no result for `{text}` within {:?}", WAIT * 2);
    }

    /// Publishes a body-frame twist on `channel` for `robot`, once.
    pub fn twist(&self, channel: &str, robot: &str, vx: f64, wz: f64) {
        self.send(
            &json!({"type": "publish", "channel": channel, "robots": [robot],
            "command": [4, {"vx": vx, "vy": 0.0, "vz": 0.0, "wz": wz}]}),
        );
    }

    /// The newest snapshot's robot `name`, with its arrival time.
    pub fn robot(&self, name: &str) -> Option<(f64, Value)> {
        let h = lock(&self.heard);
        let (t, fleet) = h.snapshots.back()?;
        let r = fleet["robots"]
            .as_array()?
            .iter()
            .find(|r| r["name"] == name)?;
        Some((*t, r.clone()))
    }

    /// Every snapshot that arrived after `since`, oldest first.
    pub fn snapshots_since(&self, since: f64) -> Vec<(f64, Value)> {
        lock(&self.heard)
            .snapshots
            .iter()
            .filter(|(t, _)| *t > since)
            .cloned()
            .collect()
    }

    /// The events and log lines that arrived after `since`.
    pub fn events_since(&self, since: f64) -> Vec<(f64, Value)> {
        lock(&self.heard)
            .events
            .iter()
            .filter(|(t, _)| *t > since)
            .cloned()
            .collect()
    }

    /// The events and log lines after `since` whose text (any of their
    /// string fields) has every word of `words`, ignoring case.
    pub fn heard_all(&self, since: f64, words: &[&str]) -> Vec<(f64, Value)> {
        self.events_since(since)
            .into_iter()
            .filter(|(_, m)| texts(m).iter().any(|t| has_all(t, words)))
            .collect()
    }

    /// The first of [`Operator::heard_all`].
    pub fn heard(&self, since: f64, words: &[&str]) -> Option<(f64, Value)> {
        self.heard_all(since, words).into_iter().next()
    }

    /// The last events and log lines, for failure messages.
    pub fn tail(&self, n: usize) -> String {
        let h = lock(&self.heard);
        let from = h.events.len().saturating_sub(n);
        h.events[from..]
            .iter()
            .map(|(t, m)| format!("{t:.3} {m}"))
            .collect::<Vec<_>>()
            .join("\n")
    }
}

/// Every string in a message (a notice's text, a log line's).
fn texts(m: &Value) -> Vec<String> {
    match m {
        Value::String(s) => vec![s.clone()],
        Value::Array(a) => a.iter().flat_map(texts).collect(),
        Value::Object(o) => o.values().flat_map(texts).collect(),
        _ => Vec::new(),
    }
}

fn has_all(text: &str, words: &[&str]) -> bool {
    let text = text.to_lowercase();
    words.iter().all(|w| text.contains(&w.to_lowercase()))
}

/// A controller on `channel` driving `robot` with a twist 10 times a
/// second until dropped.
#[derive(Debug)]
pub struct Pad {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Pad {
    pub fn start(op: &Arc<Operator>, channel: &str, robot: &str, vx: f64, wz: f64) -> Pad {
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (op, stop) = (op.clone(), stop.clone());
            let (channel, robot) = (channel.to_string(), robot.to_string());
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    op.twist(&channel, &robot, vx, wz);
                    std::thread::sleep(Duration::from_millis(100));
                }
            })
        };
        Pad {
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for Pad {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
