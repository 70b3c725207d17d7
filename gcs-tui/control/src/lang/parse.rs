//! From words to [`Statement`]s: finds the verb in [`VERBS`] and runs its
//! parser over an argument cursor that reports errors at the offending
//! word's line and column.

use super::args::Args;
use super::lexer::{Line, lex};
use super::verbs::{Command, VERBS};
use super::{LangError, Span};

/// A command with where it was written.
#[derive(Debug, Clone, PartialEq)]
pub struct Statement {
    pub span: Span,
    /// The line as written (trimmed), for output.
    pub text: String,
    pub command: Command,
}

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
    let mut args = Args::new(&line.words[1..], end, spec.usage);
    let command = (spec.parse)(&mut args)?;
    args.finish()?;
    Ok(Statement {
        span: verb.span,
        text: line.text.clone(),
        command,
    })
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::lang::Target;
    use crate::lang::verbs::WAIT_TIMEOUT;
    use crate::lang::verbs::log::Log;
    use crate::lang::verbs::route::Route;
    use crate::lang::verbs::wait::{Wait, WaitFor};
    use crate::lang::verbs::waypoint::SetWaypoints;

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
            Command::Route(Route {
                target: Target {
                    name: "robot_1".into(),
                    span: Span { line: 2, column: 7 }
                },
                channel: None
            })
        );
        match &stmts[3].command {
            Command::SetWaypoints(SetWaypoints { points, looped, .. }) => {
                assert_eq!(points.len(), 2);
                assert_eq!(points[1].time, Some(15.0));
                assert!(!looped);
            }
            other => panic!("{other:?}"),
        }
        match &stmts[9].command {
            Command::Wait(Wait {
                condition: WaitFor::Connected(t),
                timeout,
            }) => {
                assert_eq!(t.name, "robot_1");
                assert_eq!(*timeout, Duration::from_secs(5));
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            stmts[13].command,
            Command::Log(Log {
                text: "text".into()
            })
        );
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
    fn wait_defaults_its_timeout_and_waypoints_loop() {
        assert_eq!(
            one("wait robots 3"),
            Command::Wait(Wait {
                condition: WaitFor::Robots(3),
                timeout: WAIT_TIMEOUT
            })
        );
        match one("waypoint r 0,0 1,1 loop") {
            Command::SetWaypoints(SetWaypoints { looped, points, .. }) => {
                assert!(looped && points.len() == 2)
            }
            other => panic!("{other:?}"),
        }
        assert!(parse_line("waypoint r loop").is_err());
        assert!(parse_line("mode r waypoints").is_err());
        assert_eq!(parse_line("   # nothing").unwrap(), None);
    }
}
