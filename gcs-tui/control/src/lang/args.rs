//! The cursor over a command's arguments and the small word parsers the
//! verbs share (target, channel, number, count, duration, point, a named
//! value such as a failsafe state), each reporting errors at the offending
//! word's line and column.

use std::time::Duration;

use mech_proto::{Named, Waypoint};

use super::lexer::Word;
use super::{LangError, Span};

/// Robots a command applies to: a robot name, a cluster name, or `all`.
/// Resolved against the fleet model when the command runs, so a script may
/// name robots that register later.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Target {
    pub name: String,
    pub span: Span,
}

/// A cursor over a command's arguments.
#[derive(Debug)]
pub struct Args<'a> {
    words: &'a [Word],
    pos: usize,
    /// Just past the last word, where "missing argument" errors point.
    end: Span,
    /// The verb's usage line, quoted by every "missing" or "unexpected" error.
    usage: &'static str,
}

impl<'a> Args<'a> {
    /// A cursor over `words` (the words after the verb); `end` is just past
    /// the line's last word.
    pub fn new(words: &'a [Word], end: Span, usage: &'static str) -> Args<'a> {
        Args {
            words,
            pos: 0,
            end,
            usage,
        }
    }

    /// The next word, or an error naming what was expected.
    pub fn next(&mut self, what: &str) -> Result<&'a Word, LangError> {
        let w = self.words.get(self.pos).ok_or_else(|| self.missing(what))?;
        self.pos += 1;
        Ok(w)
    }

    /// The error for an argument that is not there: at the end of the line,
    /// with the verb's usage.
    pub fn missing(&self, what: &str) -> LangError {
        LangError::new(self.end, format!("missing {what} (usage: {})", self.usage))
    }

    /// The next word as one of `T`'s written names ([`Named`]); an
    /// unknown word is an error at it that lists the names.
    pub fn named<T: Named>(&mut self) -> Result<T, LangError> {
        let w = self.next(T::WHAT)?;
        T::from_name(&w.text).ok_or_else(|| {
            LangError::new(
                w.span,
                format!("unknown {} {:?}; use {}", T::WHAT, w.text, T::names()),
            )
        })
    }

    /// The next word, left in place (for optional arguments).
    pub fn peek(&self) -> Option<&'a Word> {
        self.words.get(self.pos)
    }

    /// Just past the line's last word.
    pub fn end(&self) -> Span {
        self.end
    }

    /// Whether every word was taken.
    pub fn is_empty(&self) -> bool {
        self.pos >= self.words.len()
    }

    /// Takes the next word if it is the unquoted keyword `word` (a quoted
    /// word is never a keyword, so `"loop"` can name a robot).
    pub fn keyword(&mut self, word: &str) -> bool {
        let found = self.peek().is_some_and(|w| w.text == word && !w.quoted);
        if found {
            self.pos += 1;
        }
        found
    }

    /// Fails at the first word no parser took.
    pub fn finish(&self) -> Result<(), LangError> {
        match self.peek() {
            None => Ok(()),
            Some(w) => Err(LangError::new(
                w.span,
                format!("unexpected {:?} (usage: {})", w.text, self.usage),
            )),
        }
    }

    /// A robot, cluster or `all`, resolved only when the command runs.
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

    /// A finite number; `what` names it in errors.
    pub fn number(&mut self, what: &str) -> Result<f64, LangError> {
        let w = self.next(what)?;
        number(&w.text).ok_or_else(|| {
            LangError::new(
                w.span,
                format!("expected {what} (a number), found {:?}", w.text),
            )
        })
    }

    /// A whole, non-negative number; `what` names it in errors.
    pub fn count(&mut self, what: &str) -> Result<u64, LangError> {
        let w = self.next(what)?;
        w.text.parse().map_err(|_| {
            LangError::new(
                w.span,
                format!("expected {what} (a whole number), found {:?}", w.text),
            )
        })
    }

    /// A duration: `500ms`, `2s`, `1.5s`, `1m`, `100us`.
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

    /// A trailing optional duration; `default` when none is written.
    pub fn timeout(&mut self, default: Duration) -> Result<Duration, LangError> {
        if self.is_empty() {
            Ok(default)
        } else {
            self.duration()
        }
    }

    /// `x,y`, `x,y,z`, each optionally followed by `@T` (arrival time).
    pub fn point(&mut self) -> Result<(Waypoint, Span), LangError> {
        self.point_z().map(|(p, _, span)| (p, span))
    }

    /// Like [`Args::point`], and whether the point gave its height (`x,y,z`):
    /// one without it reads as `z = 0`.
    pub fn point_z(&mut self) -> Result<(Waypoint, bool, Span), LangError> {
        let w = self.next("point x,y")?;
        point_z(&w.text)
            .map(|(p, z)| (p, z, w.span))
            .ok_or_else(|| {
                LangError::new(
                    w.span,
                    format!(
                        "expected a point like 1.0,2.0 or 1,2@15s (due within a day), found {:?}",
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
    point_z(s).map(|(p, _)| p)
}

/// `x,y[,z][@T]`, and whether `z` was given.
pub fn point_z(s: &str) -> Option<(Waypoint, bool)> {
    let (coords, time) = match s.split_once('@') {
        Some((c, t)) => (
            c,
            Some(
                duration(t)
                    .or_else(|| {
                        number(t)
                            .filter(|v| *v >= 0.0)
                            .and_then(|v| Duration::try_from_secs_f64(v).ok())
                    })
                    .filter(|d| d.as_secs_f64() <= mech_proto::MAX_WAYPOINT_TIME)?,
            ),
        ),
        None => (s, None),
    };
    let parts: Vec<f64> = coords.split(',').map(number).collect::<Option<_>>()?;
    let (x, y, z) = match parts.as_slice() {
        [x, y] => (*x, *y, None),
        [x, y, z] => (*x, *y, Some(*z)),
        _ => return None,
    };
    let waypoint = Waypoint {
        x,
        y,
        z: z.unwrap_or(0.0),
        time: time.map(|t| t.as_secs_f64()),
    };
    Some((waypoint, z.is_some()))
}

/// A safety layer's state as the language writes it: `on`, `off`,
/// `no-arena`.
pub fn safety_state(s: &str) -> Option<mech_proto::SafetyState> {
    use mech_proto::SafetyState;
    [SafetyState::On, SafetyState::Off, SafetyState::NoArena]
        .into_iter()
        .find(|st| mech_core::event::safety_state_str(*st) == s)
}

#[cfg(test)]
mod tests {
    use super::*;

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
        // Due a day after the start at most, like every waypoint sent; a
        // time no clock holds is no point (it used to end the session).
        assert_eq!(point("1,2@86400").unwrap().time, Some(86_400.0));
        assert!(point("1,2@86401").is_none());
        assert!(point("1,2@1e20").is_none());
    }
}
