//! From words to [`Statement`]s: the verb table and one small parse function
//! per verb, over an argument cursor that reports errors at the offending
//! word's line and column.

use std::time::Duration;

use mech_proto::{CommandKind, FailsafeState, Waypoint};

use super::ast::{Command, Expectation, Statement, Target, WaitFor};
use super::control;
use super::lexer::{Line, Word, lex};
use super::{LangError, Span};
use mech_core::LinkState;

/// Default timeout of `wait` when none is written.
pub const DEFAULT_WAIT: Duration = Duration::from_secs(10);

/// One verb of the language: its name, usage line and help text (shown by
/// `help` and in `docs/commands.md`), and its parser.
#[derive(Debug)]
pub struct Verb {
    pub name: &'static str,
    pub usage: &'static str,
    pub help: &'static str,
    parse: fn(&mut Args<'_>) -> Result<Command, LangError>,
}

/// Every verb, in the order `help` lists them.
pub static VERBS: &[Verb] = &[
    Verb {
        name: "route",
        usage: "route TARGET CHANNEL|none",
        help: "route robots to a channel (takes effect for the next message)",
        parse: parse_route,
    },
    Verb {
        name: "mode",
        usage: "mode TARGET MODE",
        help: "control mode `drive` uses: actuators, steering-throttle, velocity-heading, twist, stop",
        parse: parse_mode,
    },
    Verb {
        name: "drive",
        usage: "drive TARGET NUMBER...",
        help: "publish one command in the robots' mode on the GCS command channel",
        parse: parse_drive,
    },
    Verb {
        name: "waypoint",
        usage: "waypoint ROBOT X,Y[,Z][@T]... [loop] | waypoint ROBOT clear",
        help: "set a robot's waypoint list (T = arrival time, e.g. @15s)",
        parse: parse_waypoint,
    },
    Verb {
        name: "send",
        usage: "send TARGET [CHANNEL]",
        help: "send each robot's waypoint list as a mission (default channel wp/gcs)",
        parse: parse_send,
    },
    Verb {
        name: "cluster",
        usage: "cluster NAME ROBOT...",
        help: "define a named set of robots",
        parse: parse_cluster,
    },
    Verb {
        name: "stop",
        usage: "stop TARGET",
        help: "controlled stop on each robot's current channel (not latched)",
        parse: parse_stop,
    },
    Verb {
        name: "estop",
        usage: "estop",
        help: "emergency stop every robot (latched until release)",
        parse: |_| Ok(Command::EStop),
    },
    Verb {
        name: "release",
        usage: "release",
        help: "release the emergency stop",
        parse: |_| Ok(Command::Release),
    },
    Verb {
        name: "wait",
        usage: "wait connected|lost|arrived TARGET [TIMEOUT] | wait robots N [TIMEOUT] | wait route TARGET CHANNEL|none [TIMEOUT] | wait near TARGET X,Y TOLERANCE [TIMEOUT] | wait estop [TIMEOUT]",
        help: "wait until a condition holds (default timeout 10s)",
        parse: parse_wait,
    },
    Verb {
        name: "expect",
        usage: "expect near TARGET X,Y TOLERANCE | expect route TARGET CHANNEL|none | expect link TARGET connected|stale|lost | expect failsafe TARGET ok|channel-silent|router-lost|estopped|fault | expect dropped CHANNEL N",
        help: "check a condition now; a script fails if it does not hold",
        parse: parse_expect,
    },
    Verb {
        name: "sleep",
        usage: "sleep DURATION",
        help: "pause the script",
        parse: parse_sleep,
    },
    Verb {
        name: "log",
        usage: "log TEXT...",
        help: "write a line to the event log and output",
        parse: parse_log,
    },
    Verb {
        name: "spawn",
        usage: "spawn N",
        help: "start N simulated agents",
        parse: parse_spawn,
    },
    Verb {
        name: "channels",
        usage: "channels",
        help: "list live channels, their publisher and rate",
        parse: |_| Ok(Command::Channels),
    },
    Verb {
        name: "status",
        usage: "status [TARGET]",
        help: "one line per robot",
        parse: parse_status,
    },
    Verb {
        name: "formation",
        usage: "formation CLUSTER line|column|wedge|circle [SPACING] | formation CLUSTER custom X,Y...",
        help: "set a cluster's formation (slots re-assigned to minimise travel)",
        parse: control::parse_formation_verb,
    },
    Verb {
        name: "cluster-move",
        usage: "cluster-move CLUSTER VX VY WZ [SCALE_RATE]",
        help: "move a cluster at a cluster-frame velocity (route its members to fleet/CLUSTER)",
        parse: control::parse_cluster_move,
    },
    Verb {
        name: "cluster-hold",
        usage: "cluster-hold CLUSTER",
        help: "stop a cluster where it is",
        parse: control::parse_cluster_hold,
    },
    Verb {
        name: "cluster-status",
        usage: "cluster-status CLUSTER",
        help: "cluster pose (desired and measured), slot targets and tracking errors",
        parse: control::parse_cluster_status,
    },
    Verb {
        name: "cluster-waypoint",
        usage: "cluster-waypoint CLUSTER X,Y[,HEADING]... [loop]",
        help: "set a cluster's waypoints (heading in rad, or deg suffix); start with `send CLUSTER`",
        parse: control::parse_cluster_waypoint_verb,
    },
    Verb {
        name: "cluster-wait",
        usage: "cluster-wait CLUSTER [TIMEOUT] | cluster-wait CLUSTER settled TOLERANCE [TIMEOUT]",
        help: "wait until a cluster has done its waypoints, or every member is routed to it, reporting, and within TOLERANCE m of its slot (default 60s)",
        parse: control::parse_cluster_wait,
    },
    Verb {
        name: "cluster-expect",
        usage: "cluster-expect CLUSTER max-error|rms-error METRES",
        help: "check a cluster's slot tracking error since its waypoints were sent",
        parse: control::parse_cluster_expect,
    },
    Verb {
        name: "follow",
        usage: "follow ROBOT LEADER DX,DY | follow ROBOT none",
        help: "keep an offset in the leader's frame (route ROBOT to follow/LEADER)",
        parse: control::parse_follow,
    },
    Verb {
        name: "nav",
        usage: "nav ROBOT offboard|onboard",
        help: "switch waypoint navigation between the GCS loop and the robot, keeping progress",
        parse: control::parse_nav,
    },
    Verb {
        name: "nav-wait",
        usage: "nav-wait ROBOT NEXT [TIMEOUT]",
        help: "wait until a robot's next waypoint index reaches NEXT (default 60s)",
        parse: control::parse_nav_wait,
    },
    Verb {
        name: "help",
        usage: "help",
        help: "list commands",
        parse: |_| Ok(Command::Help),
    },
];

/// Parses a whole script. Fails at the first error (lexing or parsing).
pub fn parse_script(source: &str) -> Result<Vec<Statement>, LangError> {
    lex(source, 1)?.iter().map(parse_words).collect()
}

/// Parses one command line (the TUI command line). `Ok(None)` for a blank or
/// comment-only line.
pub fn parse_line(text: &str) -> Result<Option<Statement>, LangError> {
    let lines = lex(text, 1)?;
    match lines.as_slice() {
        [] => Ok(None),
        [line] => parse_words(line).map(Some),
        [_, second, ..] => Err(LangError::new(second.words[0].span, "one command per line")),
    }
}

fn parse_words(line: &Line) -> Result<Statement, LangError> {
    let verb = &line.words[0];
    let spec = VERBS
        .iter()
        .find(|v| v.name == verb.text && !verb.quoted)
        .ok_or_else(|| {
            let known: Vec<&str> = VERBS.iter().map(|v| v.name).collect();
            LangError::new(
                verb.span,
                format!(
                    "unknown command {:?}; commands are: {}",
                    verb.text,
                    known.join(", ")
                ),
            )
        })?;
    let end = line.words.last().map_or(verb.span, |w| Span {
        line: w.span.line,
        column: w.span.column + w.text.chars().count() + if w.quoted { 2 } else { 0 },
    });
    let mut args = Args {
        words: &line.words[1..],
        pos: 0,
        end,
        usage: spec.usage,
    };
    let command = (spec.parse)(&mut args)?;
    args.finish()?;
    Ok(Statement {
        span: verb.span,
        text: line.text.clone(),
        command,
    })
}

/// A cursor over a command's arguments.
#[derive(Debug)]
pub struct Args<'a> {
    words: &'a [Word],
    pos: usize,
    /// Just past the last word, where "missing argument" errors point.
    end: Span,
    usage: &'static str,
}

impl<'a> Args<'a> {
    /// The next word, or an error naming what was expected.
    pub fn next(&mut self, what: &str) -> Result<&'a Word, LangError> {
        let w = self.words.get(self.pos).ok_or_else(|| {
            LangError::new(self.end, format!("missing {what} (usage: {})", self.usage))
        })?;
        self.pos += 1;
        Ok(w)
    }

    pub fn peek(&self) -> Option<&'a Word> {
        self.words.get(self.pos)
    }

    pub fn is_empty(&self) -> bool {
        self.pos >= self.words.len()
    }

    fn finish(&self) -> Result<(), LangError> {
        match self.peek() {
            None => Ok(()),
            Some(w) => Err(LangError::new(
                w.span,
                format!("unexpected {:?} (usage: {})", w.text, self.usage),
            )),
        }
    }

    pub fn target(&mut self) -> Result<Target, LangError> {
        let w = self.next("robot, cluster or `all`")?;
        Ok(Target {
            name: w.text.clone(),
            span: w.span,
        })
    }

    /// A channel name, or `none`.
    pub fn channel(&mut self) -> Result<Option<String>, LangError> {
        let w = self.next("channel (or none)")?;
        if w.text == "none" && !w.quoted {
            return Ok(None);
        }
        if w.text.is_empty()
            || w.text.len() > mech_proto::MAX_NAME_LEN
            || w.text.chars().any(|c| c.is_whitespace() || c.is_control())
        {
            return Err(LangError::new(
                w.span,
                format!("{:?} is not a channel name", w.text),
            ));
        }
        Ok(Some(w.text.clone()))
    }

    pub fn number(&mut self, what: &str) -> Result<f64, LangError> {
        let w = self.next(what)?;
        number(&w.text).ok_or_else(|| {
            LangError::new(
                w.span,
                format!("expected {what} (a number), found {:?}", w.text),
            )
        })
    }

    pub fn count(&mut self, what: &str) -> Result<u64, LangError> {
        let w = self.next(what)?;
        w.text.parse().map_err(|_| {
            LangError::new(
                w.span,
                format!("expected {what} (a whole number), found {:?}", w.text),
            )
        })
    }

    pub fn duration(&mut self) -> Result<Duration, LangError> {
        let w = self.next("duration")?;
        duration(&w.text).ok_or_else(|| {
            LangError::new(
                w.span,
                format!(
                    "expected a duration like 500ms, 2s or 1m, found {:?}",
                    w.text
                ),
            )
        })
    }

    /// A trailing optional duration.
    pub fn timeout(&mut self) -> Result<Duration, LangError> {
        if self.is_empty() {
            Ok(DEFAULT_WAIT)
        } else {
            self.duration()
        }
    }

    /// `x,y`, `x,y,z`, each optionally followed by `@T` (arrival time).
    pub fn point(&mut self) -> Result<(Waypoint, Span), LangError> {
        let w = self.next("point x,y")?;
        point(&w.text).map(|p| (p, w.span)).ok_or_else(|| {
            LangError::new(
                w.span,
                format!(
                    "expected a point like 1.0,2.0 or 1,2@15s, found {:?}",
                    w.text
                ),
            )
        })
    }
}

fn number(s: &str) -> Option<f64> {
    s.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// `500ms`, `2s`, `1.5s`, `1m`, `100us`.
pub fn duration(s: &str) -> Option<Duration> {
    let (value, scale) = if let Some(v) = s.strip_suffix("ms") {
        (v, 1e-3)
    } else if let Some(v) = s.strip_suffix("us") {
        (v, 1e-6)
    } else if let Some(v) = s.strip_suffix('s') {
        (v, 1.0)
    } else if let Some(v) = s.strip_suffix('m') {
        (v, 60.0)
    } else {
        return None;
    };
    let v = number(value)?;
    if v < 0.0 {
        return None;
    }
    Duration::try_from_secs_f64(v * scale).ok()
}

/// `x,y[,z][@T]`.
pub fn point(s: &str) -> Option<Waypoint> {
    let (coords, time) = match s.split_once('@') {
        Some((c, t)) => (
            c,
            Some(
                duration(t)
                    .or_else(|| number(t).filter(|v| *v >= 0.0).map(Duration::from_secs_f64))?,
            ),
        ),
        None => (s, None),
    };
    let parts: Vec<f64> = coords.split(',').map(number).collect::<Option<_>>()?;
    let (x, y, z) = match parts.as_slice() {
        [x, y] => (*x, *y, 0.0),
        [x, y, z] => (*x, *y, *z),
        _ => return None,
    };
    Some(Waypoint {
        x,
        y,
        z,
        time: time.map(|t| t.as_secs_f64()),
    })
}

fn parse_route(a: &mut Args<'_>) -> Result<Command, LangError> {
    Ok(Command::Route {
        target: a.target()?,
        channel: a.channel()?,
    })
}

fn parse_mode(a: &mut Args<'_>) -> Result<Command, LangError> {
    let target = a.target()?;
    let w = a.next("mode")?;
    let mode = CommandKind::parse(&w.text).filter(|k| *k != CommandKind::Waypoints).ok_or_else(|| {
        LangError::new(
            w.span,
            format!("unknown mode {:?}; modes are actuators, steering-throttle, velocity-heading, twist, stop (waypoints: use `waypoint` and `send`)", w.text),
        )
    })?;
    Ok(Command::Mode { target, mode })
}

fn parse_drive(a: &mut Args<'_>) -> Result<Command, LangError> {
    let target = a.target()?;
    let mut values = Vec::new();
    while !a.is_empty() {
        values.push(a.number("value")?);
    }
    Ok(Command::Drive { target, values })
}

fn parse_waypoint(a: &mut Args<'_>) -> Result<Command, LangError> {
    let target = a.target()?;
    if a.peek().is_some_and(|w| w.text == "clear" && !w.quoted) {
        a.next("clear")?;
        return Ok(Command::Waypoint {
            target,
            points: Vec::new(),
            looped: false,
        });
    }
    let mut points = Vec::new();
    let mut looped = false;
    while let Some(w) = a.peek() {
        if w.text == "loop" && !w.quoted {
            a.next("loop")?;
            looped = true;
            break;
        }
        points.push(a.point()?.0);
    }
    if points.is_empty() {
        return Err(LangError::new(
            a.end,
            format!("missing point x,y (usage: {})", a.usage),
        ));
    }
    if points.len() > mech_proto::MAX_WAYPOINTS {
        return Err(LangError::new(
            target.span,
            format!("at most {} waypoints", mech_proto::MAX_WAYPOINTS),
        ));
    }
    Ok(Command::Waypoint {
        target,
        points,
        looped,
    })
}

fn parse_send(a: &mut Args<'_>) -> Result<Command, LangError> {
    let target = a.target()?;
    let channel = if a.is_empty() { None } else { a.channel()? };
    Ok(Command::Send { target, channel })
}

fn parse_cluster(a: &mut Args<'_>) -> Result<Command, LangError> {
    let name = a.next("cluster name")?;
    if name.text == "all" {
        return Err(LangError::new(
            name.span,
            "`all` is reserved for every robot",
        ));
    }
    let mut members = Vec::new();
    while !a.is_empty() {
        members.push(a.target()?);
    }
    if members.is_empty() {
        return Err(LangError::new(
            a.end,
            format!("missing robot (usage: {})", a.usage),
        ));
    }
    Ok(Command::Cluster {
        name: name.text.clone(),
        members,
    })
}

fn parse_stop(a: &mut Args<'_>) -> Result<Command, LangError> {
    Ok(Command::Stop {
        target: a.target()?,
    })
}

fn parse_wait(a: &mut Args<'_>) -> Result<Command, LangError> {
    let what = a.next("condition (connected, lost, robots, arrived, route, near, estop)")?;
    let condition = match what.text.as_str() {
        "connected" => WaitFor::Connected(a.target()?),
        "lost" => WaitFor::Lost(a.target()?),
        "arrived" => WaitFor::Arrived(a.target()?),
        "robots" => WaitFor::Robots(a.count("number of robots")? as usize),
        "route" => {
            let target = a.target()?;
            WaitFor::Route(target, a.channel()?)
        }
        "near" => {
            let target = a.target()?;
            let (p, _) = a.point()?;
            let tolerance = a.number("tolerance in metres")?;
            WaitFor::Near {
                target,
                x: p.x,
                y: p.y,
                tolerance,
            }
        }
        "estop" => WaitFor::EStopAcked,
        other => {
            return Err(LangError::new(
                what.span,
                format!(
                    "unknown wait condition {other:?}; use connected, lost, robots, arrived, route, near or estop"
                ),
            ));
        }
    };
    Ok(Command::Wait {
        condition,
        timeout: a.timeout()?,
    })
}

fn parse_expect(a: &mut Args<'_>) -> Result<Command, LangError> {
    let what = a.next("check (near, route, link, failsafe, dropped)")?;
    let e = match what.text.as_str() {
        "near" => {
            let target = a.target()?;
            let (p, _) = a.point()?;
            let tolerance = a.number("tolerance in metres")?;
            Expectation::Near {
                target,
                x: p.x,
                y: p.y,
                tolerance,
            }
        }
        "route" => {
            let target = a.target()?;
            Expectation::Route(target, a.channel()?)
        }
        "link" => {
            let target = a.target()?;
            let w = a.next("link state")?;
            let state = LinkState::parse(&w.text).ok_or_else(|| {
                LangError::new(
                    w.span,
                    format!(
                        "unknown link state {:?}; use connected, stale or lost",
                        w.text
                    ),
                )
            })?;
            Expectation::Link(target, state)
        }
        "failsafe" => {
            let target = a.target()?;
            let w = a.next("failsafe state")?;
            let state = failsafe(&w.text).ok_or_else(|| {
                LangError::new(w.span, format!("unknown failsafe state {:?}; use ok, channel-silent, router-lost, estopped or fault", w.text))
            })?;
            Expectation::Failsafe(target, state)
        }
        "dropped" => {
            let channel = a
                .channel()?
                .ok_or_else(|| LangError::new(what.span, "`expect dropped` needs a channel"))?;
            Expectation::DroppedAtLeast {
                channel,
                min: a.count("minimum count")?,
            }
        }
        other => {
            return Err(LangError::new(
                what.span,
                format!("unknown check {other:?}; use near, route, link, failsafe or dropped"),
            ));
        }
    };
    Ok(Command::Expect(e))
}

/// Failsafe state names, as the language and the UI write them.
pub fn failsafe(s: &str) -> Option<FailsafeState> {
    Some(match s {
        "ok" => FailsafeState::Ok,
        "channel-silent" => FailsafeState::ChannelSilent,
        "router-lost" => FailsafeState::RouterLost,
        "estopped" => FailsafeState::EStopped,
        "fault" => FailsafeState::Fault,
        _ => return None,
    })
}

/// The name [`failsafe`] parses.
pub fn failsafe_name(s: FailsafeState) -> &'static str {
    match s {
        FailsafeState::Ok => "ok",
        FailsafeState::ChannelSilent => "channel-silent",
        FailsafeState::RouterLost => "router-lost",
        FailsafeState::EStopped => "estopped",
        FailsafeState::Fault => "fault",
    }
}

fn parse_sleep(a: &mut Args<'_>) -> Result<Command, LangError> {
    Ok(Command::Sleep(a.duration()?))
}

fn parse_log(a: &mut Args<'_>) -> Result<Command, LangError> {
    let mut parts = Vec::new();
    while !a.is_empty() {
        parts.push(a.next("text")?.text.clone());
    }
    Ok(Command::Log(parts.join(" ")))
}

fn parse_spawn(a: &mut Args<'_>) -> Result<Command, LangError> {
    let w = a.peek();
    let n = a.count("number of simulated agents")?;
    if n == 0 || n > 10_000 {
        let span = w.map_or(a.end, |w| w.span);
        return Err(LangError::new(span, "spawn between 1 and 10000 agents"));
    }
    Ok(Command::Spawn(n as usize))
}

fn parse_status(a: &mut Args<'_>) -> Result<Command, LangError> {
    Ok(Command::Status(if a.is_empty() {
        None
    } else {
        Some(a.target()?)
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(s: &str) -> Command {
        parse_line(s).unwrap().unwrap().command
    }

    #[test]
    fn examples_from_the_issue_parse() {
        let script = "route robot_1 joy/0\nroute robot_1 none\nmode robot_1 velocity-heading\n\
            waypoint robot_1 1.0,2.0 3.0,2.0@15s\nsend robot_1\ncluster c1 robot_1 robot_2\nstop all\n\
            estop\nrelease\nwait connected robot_1 5s\nwait arrived robot_1 30s\n\
            expect near robot_1 3.0,2.0 0.1\nsleep 2s\nlog \"text\"\nspawn 4\n";
        let stmts = parse_script(script).unwrap();
        assert_eq!(stmts.len(), 15);
        assert_eq!(
            stmts[1].command,
            Command::Route {
                target: Target {
                    name: "robot_1".into(),
                    span: Span { line: 2, column: 7 }
                },
                channel: None
            }
        );
        match &stmts[3].command {
            Command::Waypoint { points, looped, .. } => {
                assert_eq!(points.len(), 2);
                assert_eq!(points[1].time, Some(15.0));
                assert!(!looped);
            }
            other => panic!("{other:?}"),
        }
        match &stmts[9].command {
            Command::Wait {
                condition: WaitFor::Connected(t),
                timeout,
            } => {
                assert_eq!(t.name, "robot_1");
                assert_eq!(*timeout, Duration::from_secs(5));
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(stmts[13].command, Command::Log("text".into()));
    }

    #[test]
    fn errors_point_at_line_and_column() {
        let e = parse_script("estop\nwait connected robot_1 5x\n").unwrap_err();
        assert_eq!(
            e.span,
            Span {
                line: 2,
                column: 24
            }
        );
        assert!(e.message.contains("duration"), "{e}");
        let e = parse_script("  fly robot_1\n").unwrap_err();
        assert_eq!(e.span, Span { line: 1, column: 3 });
        let e = parse_script("route robot_1\n").unwrap_err();
        assert_eq!(
            e.span,
            Span {
                line: 1,
                column: 14
            }
        );
        assert!(e.message.contains("missing channel"), "{e}");
        let e = parse_script("estop now\n").unwrap_err();
        assert_eq!(e.span, Span { line: 1, column: 7 });
    }

    #[test]
    fn durations_and_points() {
        assert_eq!(duration("500ms"), Some(Duration::from_millis(500)));
        assert_eq!(duration("1.5s"), Some(Duration::from_millis(1500)));
        assert_eq!(duration("1m"), Some(Duration::from_secs(60)));
        assert_eq!(duration("-1s"), None);
        assert_eq!(duration("5"), None);
        let p = point("1,-2.5,3@2s").unwrap();
        assert_eq!((p.x, p.y, p.z, p.time), (1.0, -2.5, 3.0, Some(2.0)));
        assert!(point("1").is_none());
        assert!(point("1,nan").is_none());
    }

    #[test]
    fn wait_defaults_its_timeout_and_waypoints_loop() {
        assert_eq!(
            one("wait robots 3"),
            Command::Wait {
                condition: WaitFor::Robots(3),
                timeout: DEFAULT_WAIT
            }
        );
        match one("waypoint r 0,0 1,1 loop") {
            Command::Waypoint { looped, points, .. } => assert!(looped && points.len() == 2),
            other => panic!("{other:?}"),
        }
        assert!(parse_line("waypoint r loop").is_err());
        assert!(parse_line("mode r waypoints").is_err());
        assert_eq!(parse_line("   # nothing").unwrap(), None);
    }
}
