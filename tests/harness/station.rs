//! The station as a process: `mech-gcs --config FILE --script -`, its
//! script given on stdin, its JSON lines (events and command results)
//! collected with the time each arrived.

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::Value;

use super::{Killed, poll, unix_us};

/// One line the station printed.
#[derive(Debug, Clone)]
pub struct Line {
    /// When it was read, µs since the Unix epoch.
    pub at_us: u64,
    pub json: Value,
}

impl Line {
    /// `"event"` or `"result"` lines' `event` or `command` field.
    pub fn is_event(&self, name: &str) -> bool {
        self.json["type"] == "event" && self.json["event"] == name
    }

    pub fn robot(&self) -> &str {
        self.json["robot"].as_str().unwrap_or("")
    }

    /// Router time of an event, s.
    pub fn t(&self) -> f64 {
        self.json["t"].as_f64().unwrap_or(f64::NAN)
    }
}

/// The station's standard error, in its log directory.
const STDERR: &str = "station.stderr";

/// A running station; killed (SIGKILL) when dropped.
#[derive(Debug)]
pub struct Station {
    process: Mutex<Killed>,
    lines: Arc<Mutex<Vec<Line>>>,
    /// When it was started, µs since the Unix epoch.
    pub started_us: u64,
    /// Where its standard error goes.
    stderr: std::path::PathBuf,
}

impl Station {
    /// Starts `mech-gcs` with `config` and runs `script`.
    pub fn start(config: &Path, script: &str, logs: &Path) -> Station {
        let started_us = unix_us();
        let mut child = Command::new(crate::binary("mech-gcs"))
            .arg("--config")
            .arg(config)
            .args(["--script", "-"])
            .env("XDG_STATE_HOME", logs)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(
                std::fs::File::create(logs.join(STDERR))
                    .map_or_else(|_| Stdio::null(), Stdio::from),
            )
            .spawn()
            .expect("mech-gcs starts (the test command builds it first)");
        let mut stdin = child.stdin.take().expect("stdin");
        stdin.write_all(script.as_bytes()).expect("script written");
        drop(stdin);
        let stdout = child.stdout.take().expect("stdout");
        let lines = Arc::new(Mutex::new(Vec::new()));
        let sink = lines.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                let Ok(json) = serde_json::from_str(&line) else {
                    continue;
                };
                let l = Line {
                    at_us: unix_us(),
                    json,
                };
                sink.lock().unwrap_or_else(|e| e.into_inner()).push(l);
            }
        });
        Station {
            process: Mutex::new(Killed(Some(child))),
            lines,
            started_us,
            stderr: logs.join(STDERR),
        }
    }

    /// Every line so far.
    pub fn lines(&self) -> Vec<Line> {
        self.lines.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Waits for a line matching `want`.
    pub fn wait(&self, timeout: Duration, want: impl Fn(&Line) -> bool) -> Option<Line> {
        poll(timeout, || self.lines().into_iter().find(|l| want(l)))
    }

    /// Waits for the script's `log TEXT` line; panics with the output so
    /// far if it does not come.
    pub fn wait_log(&self, text: &str, timeout: Duration) -> Line {
        self.wait(timeout, |l| {
            l.json["type"] == "result" && l.json["summary"].as_str() == Some(text)
        })
        .unwrap_or_else(|| {
            panic!(
                "no `log {text}` within {timeout:?} ({} lines, station {}): {:#?}\nits stderr ends:\n{}",
                self.lines().len(),
                self.process
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .state(),
                self.tail(),
                self.stderr_tail()
            )
        })
    }

    /// The end of the station's standard error, for failure messages.
    pub fn stderr_tail(&self) -> String {
        let text = std::fs::read_to_string(&self.stderr).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        lines[lines.len().saturating_sub(20)..].join("\n")
    }

    /// The last lines, for failure messages.
    pub fn tail(&self) -> Vec<String> {
        let lines = self.lines();
        let from = lines.len().saturating_sub(30);
        lines[from..].iter().map(|l| l.json.to_string()).collect()
    }

    /// The station's process id, while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.process.lock().unwrap_or_else(|e| e.into_inner()).pid()
    }

    /// Kills the station (SIGKILL, as `kill -9`).
    pub fn kill(&mut self) {
        self.process
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .kill();
    }
}

/// A `[router]` section for a station on loopback `port`, unauthenticated,
/// with `extra` lines (radios, timeouts) appended to the section.
pub fn config(dir: &Path, port: u16, extra: &str) -> std::path::PathBuf {
    let path = dir.join("gcs.toml");
    std::fs::write(
        &path,
        format!(
            "[router]\nudp = \"127.0.0.1:{port}\"\ntcp = \"127.0.0.1:0\"\n{extra}\n\
             [auth]\nmode = \"off\"\n"
        ),
    )
    .expect("config written");
    path
}

/// A free UDP port on loopback.
pub fn free_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}
