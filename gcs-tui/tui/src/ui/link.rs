//! The TUI's link to its station: the App's [`Request`]s carried as
//! attach-protocol messages (command-language lines, and teleop at the
//! pads' rate), and what the station sends back turned into [`Action`]s
//! (snapshots, log lines, the results of typed lines).

use std::collections::HashMap;

use mech_proto::Waypoint;
use tokio::sync::mpsc;

use super::app::{Action, App, LogLevel, PromptError, Request, WAYPOINT_CHANNEL};
use mech_control::lang::quote;
use mech_station::wire::{FromStation, LineResult, LogLevel as WireLevel, ToStation};

/// Byte offset of character `chars` in `s` (its end when shorter).
fn char_to_byte(s: &str, chars: usize) -> usize {
    s.char_indices().nth(chars).map_or(s.len(), |(i, _)| i)
}

/// Carries the App's [`Request`]s to the station as attach-protocol
/// messages (command-language lines, and teleop at the pads' rate), and
/// what the station sends back to the App.
#[derive(Debug)]
pub struct StationLink {
    to: mpsc::UnboundedSender<ToStation>,
    next_id: u64,
    /// Lines typed at the prompt waiting for their result, by id: their
    /// results go to the prompt; those of lines made from clicks and keys
    /// are logged when they fail.
    typed: HashMap<u64, String>,
}

impl StationLink {
    pub fn new(to: mpsc::UnboundedSender<ToStation>) -> StationLink {
        StationLink {
            to,
            next_id: 0,
            typed: HashMap::new(),
        }
    }

    /// One message from the station into the App.
    pub fn receive(&mut self, m: FromStation, app: &mut App) {
        match m {
            FromStation::Snapshot { fleet, .. } => app.update(Action::Fleet(fleet)),
            FromStation::Log { level, text, .. } => app.update(Action::Log(level.into(), text)),
            FromStation::Result(r) => self.result(r, app),
            FromStation::Refused { reason } => app.log(LogLevel::Warn, reason),
            FromStation::Bye { reason } => {
                app.log(LogLevel::Error, format!("the station said bye: {reason}"));
            }
            FromStation::Welcome(_) | FromStation::Challenge { .. } | FromStation::Event(_) => {}
        }
    }

    fn result(&mut self, r: LineResult, app: &mut App) {
        match self.typed.remove(&r.id) {
            Some(line) => {
                let result = if r.ok {
                    let mut text = r.summary;
                    for d in r.details {
                        text.push('\n');
                        text.push_str(&d);
                    }
                    Ok(text)
                } else {
                    Err(PromptError {
                        message: r.error.unwrap_or_default(),
                        column: r.column.map(|c| char_to_byte(&line, c.saturating_sub(1))),
                        line,
                    })
                };
                app.update(Action::CommandResult(result));
            }
            None if !r.ok => app.log(LogLevel::Error, r.error.unwrap_or_default()),
            None => {}
        }
    }

    /// Carries one request.
    pub fn carry(&mut self, req: Request, app: &mut App) {
        match req {
            Request::Route { robot, channel } => {
                let channel = if channel.is_empty() {
                    "none".into()
                } else {
                    quote(&channel)
                };
                self.line(format!("route {} {channel}", quote(&robot)));
            }
            Request::Mission { robots, waypoints } => self.mission(&robots, &waypoints),
            Request::EStop { engage } => {
                self.line(if engage { "estop" } else { "release" }.into());
            }
            Request::Publish {
                channel,
                robots,
                command,
            } => self.send(ToStation::Publish {
                channel,
                robots,
                command,
            }),
            Request::ClusterVelocity { cluster, velocity } => {
                self.send(ToStation::DriveCluster { cluster, velocity });
            }
            Request::ToggleNav { robots } => {
                for r in robots {
                    self.line(format!("nav {} toggle", quote(&r)));
                }
            }
            Request::DefineCluster { name, members } => {
                let members: Vec<_> = members.iter().map(|m| quote(m)).collect();
                self.line(format!("cluster {} {}", quote(&name), members.join(" ")));
            }
            Request::Exec(line) => self.exec(line),
            Request::Quit => {}
        }
        if self.to.is_closed() {
            app.log(LogLevel::Error, "not attached to a station");
        }
    }

    /// Each robot's waypoint list, then the send, on [`WAYPOINT_CHANNEL`].
    fn mission(&mut self, robots: &[String], waypoints: &[Waypoint]) {
        let points: Vec<String> = waypoints.iter().map(point).collect();
        for robot in robots {
            let r = quote(robot);
            self.line(format!("waypoint {r} {}", points.join(" ")));
            self.line(format!("send {r} {WAYPOINT_CHANNEL}"));
        }
    }

    /// A line typed at the prompt: its result goes back to the prompt.
    pub fn exec(&mut self, line: String) {
        let id = self.line(line.clone());
        self.typed.insert(id, line);
    }

    /// A line made from a click or a key; returns its id.
    fn line(&mut self, text: String) -> u64 {
        self.next_id += 1;
        let id = self.next_id;
        self.send(ToStation::Line { id, text });
        id
    }

    fn send(&self, m: ToStation) {
        // A closed link is reported by `carry`.
        let _ = self.to.send(m);
    }
}

/// A waypoint as the command language writes it: `x,y[,z][@t]`.
fn point(w: &Waypoint) -> String {
    let mut p = format!("{},{}", w.x, w.y);
    if w.z != 0.0 {
        p.push_str(&format!(",{}", w.z));
    }
    if let Some(t) = w.time {
        p.push_str(&format!("@{t}"));
    }
    p
}

impl From<WireLevel> for LogLevel {
    fn from(l: WireLevel) -> LogLevel {
        match l {
            WireLevel::Info => LogLevel::Info,
            WireLevel::Warn => LogLevel::Warn,
            WireLevel::Error => LogLevel::Error,
        }
    }
}
