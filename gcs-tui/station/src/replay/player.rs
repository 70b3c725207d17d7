//! The TUI's replay: a recording played back as a station the TUI attaches
//! to. It speaks the attach protocol's messages (snapshots, log lines,
//! command results), so the TUI draws a replay with the code that draws a
//! live fleet; but there is no router and no socket behind it, so nothing
//! an operator does can reach a robot. It obeys only `pause`, `play`,
//! `speed X` and `seek T`; every other command and every teleop message is
//! refused.

use std::time::Duration;

use mech_core::replay::{Cursor, Replay};
use tokio::sync::mpsc;

use crate::client::Attached;
use crate::feed::{LogCursor, snapshot};
use crate::view::{FleetSnapshot, ReplayClock, Security};
use crate::wire::{FromStation, LineResult, PROTOCOL, ToStation, Welcome};

/// Snapshots per second while playing (and the clock's resolution).
const RATE_HZ: u64 = 20;

/// Event-log lines shown when the replay starts or jumps.
const LOG_HISTORY: usize = 50;

/// The slowest and fastest playback.
const SPEEDS: std::ops::RangeInclusive<f64> = 0.1..=10.0;

/// What the replay answers to anything else.
const USAGE: &str =
    "a replay sends nothing to robots; it obeys: pause, play, speed 0.1..10, seek [+|-]SECONDS";

/// A recording being played: where it is, how fast, and the log lines the
/// TUI has been sent.
#[derive(Debug)]
pub struct Player<'a> {
    cursor: Cursor<'a>,
    start: Duration,
    end: Duration,
    speed: f64,
    paused: bool,
    log: LogCursor,
}

impl<'a> Player<'a> {
    /// At the start of `replay`, playing at 1x.
    pub fn new(replay: &'a Replay) -> Player<'a> {
        let mut cursor = replay.cursor();
        cursor.seek(replay.start());
        let log = LogCursor::recent(cursor.fleet(), LOG_HISTORY);
        Player {
            cursor,
            start: replay.start(),
            end: replay.end(),
            speed: 1.0,
            paused: false,
            log,
        }
    }

    /// Where the replay is, in seconds from the recording's start.
    pub fn clock(&self) -> ReplayClock {
        ReplayClock {
            at: self.offset(self.cursor.at()),
            start: self.start.as_secs_f64(),
            end: self.offset(self.end),
            speed: self.speed,
            paused: self.paused,
        }
    }

    fn offset(&self, t: Duration) -> f64 {
        t.saturating_sub(self.start).as_secs_f64()
    }

    /// Moves on by `wall` of real time at the current speed (nothing while
    /// paused); stops, paused, at the end.
    pub fn advance(&mut self, wall: Duration) {
        if self.paused {
            return;
        }
        let t = self.cursor.at() + wall.mul_f64(self.speed);
        if t >= self.end {
            self.cursor.advance_to(self.end);
            self.paused = true;
        } else {
            self.cursor.advance_to(t);
        }
    }

    /// Obeys one command line; `Err` says why it was refused.
    pub fn command(&mut self, line: &str) -> Result<String, String> {
        let mut words = line.split_whitespace();
        let (verb, arg) = (words.next().unwrap_or(""), words.next());
        if words.next().is_some() {
            return Err(USAGE.to_string());
        }
        match (verb, arg) {
            ("pause", None) => self.paused = true,
            ("play", None) => {
                if self.cursor.at() >= self.end {
                    self.jump(self.start);
                }
                self.paused = false;
            }
            ("speed", Some(x)) => self.speed = speed(x)?,
            ("seek", Some(t)) => {
                let to = self.seek_target(t)?;
                self.jump(to);
            }
            _ => return Err(USAGE.to_string()),
        }
        Ok(self.clock().label())
    }

    /// The router time `seek` names: seconds from the start, or `+S`/`-S`
    /// from here; clamped to the recording.
    fn seek_target(&self, text: &str) -> Result<Duration, String> {
        let bad = || format!("seek wants seconds (30, +10, -5), not {text:?}");
        let secs: f64 = text.trim_end_matches('s').parse().map_err(|_| bad())?;
        if !secs.is_finite() {
            return Err(bad());
        }
        let here = self.offset(self.cursor.at());
        let offset = if text.starts_with(['+', '-']) {
            here + secs
        } else {
            secs
        };
        let span = self.offset(self.end);
        Ok(self.start + Duration::from_secs_f64(offset.clamp(0.0, span)))
    }

    fn jump(&mut self, to: Duration) {
        self.cursor.seek(to);
        // The log restarts from what the fleet model logged by then.
        self.log = LogCursor::recent(self.cursor.fleet(), 0);
    }

    /// The fleet as the TUI draws it, with the replay's clock.
    pub fn snapshot(&self) -> FleetSnapshot {
        let mut s = snapshot(self.cursor.fleet(), Vec::new());
        s.security = Security::Authenticated;
        s.replay = Some(self.clock());
        s
    }

    /// Event-log lines logged since the last call.
    pub fn log_lines(&mut self) -> Vec<FromStation> {
        self.log.messages(self.cursor.fleet())
    }

    /// The answer to a client's message.
    fn receive(&mut self, m: ToStation) -> FromStation {
        match m {
            ToStation::Line { id, text } => {
                let outcome = self.command(&text);
                FromStation::Result(LineResult {
                    id,
                    t: self.clock().at,
                    ok: outcome.is_ok(),
                    summary: outcome.clone().unwrap_or_default(),
                    details: Vec::new(),
                    error: outcome.err(),
                    column: None,
                })
            }
            _ => FromStation::Refused {
                reason: USAGE.to_string(),
            },
        }
    }
}

/// `2`, `0.5x`: a playback speed within [`SPEEDS`].
fn speed(text: &str) -> Result<f64, String> {
    let x: f64 = text
        .trim_end_matches('x')
        .parse()
        .map_err(|_| format!("speed wants a number, not {text:?}"))?;
    if SPEEDS.contains(&x) {
        Ok(x)
    } else {
        Err(format!(
            "speed {x} is outside {}..{}",
            SPEEDS.start(),
            SPEEDS.end()
        ))
    }
}

/// A replay the TUI attaches to as it would to a station.
pub fn attach(replay: Replay) -> Attached {
    let (to, requests) = mpsc::unbounded_channel();
    let (replies, from) = mpsc::channel(64);
    let welcome = Welcome {
        protocol: PROTOCOL,
        operator: "replay".into(),
        router: replay.path().display().to_string(),
        security: Security::Authenticated,
        pads: String::new(),
        keys: String::new(),
        arena: None,
    };
    tokio::spawn(play(replay, requests, replies));
    Attached { welcome, to, from }
}

/// Plays until the TUI leaves.
async fn play(
    replay: Replay,
    mut requests: mpsc::UnboundedReceiver<ToStation>,
    replies: mpsc::Sender<FromStation>,
) {
    let mut player = Player::new(&replay);
    let mut tick = tokio::time::interval(Duration::from_millis(1000 / RATE_HZ));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut last = tokio::time::Instant::now();
    let mut seq = 0;
    loop {
        let mut out = Vec::new();
        tokio::select! {
            now = tick.tick() => {
                player.advance(now - last);
                last = now;
            }
            m = requests.recv() => match m {
                None | Some(ToStation::Bye) => return,
                Some(m) => out.push(player.receive(m)),
            }
        }
        out.extend(player.log_lines());
        seq += 1;
        out.push(FromStation::Snapshot {
            seq,
            fleet: player.snapshot(),
        });
        for m in out {
            if replies.send(m).await.is_err() {
                return;
            }
        }
    }
}
