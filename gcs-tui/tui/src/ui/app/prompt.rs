//! The one-line prompt: the `:` command line with its history and the
//! results the station sends back, `x,y[,t]` waypoint entry, and the fleet
//! table's `/` filter (applied as it is typed); the last error, shown under
//! the line that caused it.

use mech_proto::Waypoint;

use super::{App, LogLevel, Request};

/// Command lines the history keeps.
const HISTORY_LINES: usize = 100;

/// A one-line text entry in progress.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Prompt {
    /// `:` command line, run by the shared command language.
    Command(String),
    /// `x,y[,t]` waypoint entry.
    Waypoint(String),
    /// `/` the fleet table's filter, applied as it is typed.
    Filter(String),
}

/// The last command-line error, with the column it points at.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PromptError {
    pub line: String,
    pub message: String,
    /// Byte offset in `line` of the mistake, if known.
    pub column: Option<usize>,
}

/// The prompt's state.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct PromptLine {
    /// The entry being typed, if any.
    pub open: Option<Prompt>,
    pub error: Option<PromptError>,
    /// Command lines run, oldest first.
    pub history: Vec<String>,
    /// Where ↑↓ are in the history; None: a new line.
    history_pos: Option<usize>,
}

impl PromptLine {
    /// Opens an empty command line, at the end of the history.
    pub fn open_command_line(&mut self) {
        self.open = Some(Prompt::Command(String::new()));
        self.history_pos = None;
    }

    /// Offers `line` without taking the keyboard: it becomes the newest
    /// line of the history, so `:` then ↑ brings it back to run with Enter.
    pub fn offer_command(&mut self, line: &str) {
        self.remember(line);
    }

    /// Keeps a command line run in the history (not twice in a row, at
    /// most [`HISTORY_LINES`]).
    fn remember(&mut self, line: &str) {
        if self.history.last().map(String::as_str) != Some(line) {
            self.history.push(line.to_string());
            if self.history.len() > HISTORY_LINES {
                self.history.remove(0);
            }
        }
        self.history_pos = None;
    }

    /// ↑ (`dir` < 0) or ↓ on an open command line: an earlier or later line
    /// from the history, or a blank one past its end.
    pub fn history_step(&mut self, dir: i32) {
        let Some(Prompt::Command(s)) = &mut self.open else {
            return;
        };
        if self.history.is_empty() {
            return;
        }
        let last = self.history.len() - 1;
        let pos = match (self.history_pos, dir < 0) {
            (None, true) => Some(last),
            (None, false) => None,
            (Some(p), true) => Some(p.saturating_sub(1)),
            (Some(p), false) => (p < last).then_some(p + 1),
        };
        self.history_pos = pos;
        *s = pos.map(|p| self.history[p].clone()).unwrap_or_default();
    }
}

impl App {
    /// Changes the text of the open prompt, if any; a filter applies at
    /// once.
    pub(super) fn edit_prompt(&mut self, edit: impl FnOnce(&mut String)) {
        match &mut self.prompt.open {
            Some(Prompt::Command(s) | Prompt::Waypoint(s)) => edit(s),
            Some(Prompt::Filter(s)) => {
                edit(s);
                let filter = s.clone();
                self.set_filter(filter);
            }
            None => {}
        }
    }

    /// Esc on a prompt: closes it; on the filter, also clears the filter.
    pub(super) fn cancel_prompt(&mut self) {
        if let Some(Prompt::Filter(_)) = self.prompt.open.take() {
            self.set_filter(String::new());
        }
    }

    /// Enter: a command line goes to the station, a waypoint is added (or
    /// its error shown, the entry kept open to fix), a filter is kept.
    pub(super) fn submit_prompt(&mut self) {
        match self.prompt.open.take() {
            Some(Prompt::Command(line)) => {
                let line = line.trim().to_string();
                if line.is_empty() {
                    return;
                }
                self.prompt.remember(&line);
                self.prompt.error = None;
                self.outbox.push(Request::Exec(line));
            }
            // The filter is already applied: Enter keeps it.
            Some(Prompt::Filter(_)) => {}
            Some(Prompt::Waypoint(text)) => match parse_waypoint(&text) {
                Ok(w) => {
                    self.prompt.error = None;
                    self.add_waypoint(w);
                }
                Err((message, column)) => {
                    self.prompt.error = Some(PromptError {
                        line: text.clone(),
                        message,
                        column: Some(column),
                    });
                    self.prompt.open = Some(Prompt::Waypoint(text));
                }
            },
            None => {}
        }
    }

    /// Logs what a command line printed, or its error (kept for the error
    /// box).
    pub(super) fn command_result(&mut self, r: Result<String, PromptError>) {
        match r {
            Ok(text) => {
                self.prompt.error = None;
                for line in text.lines().filter(|l| !l.is_empty()) {
                    self.log(LogLevel::Info, line.to_string());
                }
            }
            Err(e) => {
                self.log(LogLevel::Error, format!("{}: {}", e.line, e.message));
                self.prompt.error = Some(e);
            }
        }
    }
}

/// Parses `x,y[,t]` (commas or spaces) into a waypoint; on error, the
/// message and the byte column of the offending field.
pub fn parse_waypoint(text: &str) -> Result<Waypoint, (String, usize)> {
    let mut fields: Vec<(usize, &str)> = Vec::new();
    let mut start = None;
    for (i, ch) in text.char_indices() {
        let sep = ch == ',' || ch.is_whitespace();
        match (sep, start) {
            (false, None) => start = Some(i),
            (true, Some(s)) => {
                fields.push((s, &text[s..i]));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        fields.push((s, &text[s..]));
    }
    if fields.len() < 2 {
        return Err((
            "expected x,y[,t] in metres (and seconds)".into(),
            text.len(),
        ));
    }
    if fields.len() > 3 {
        return Err(("too many numbers: x,y[,t]".into(), fields[3].0));
    }
    let mut nums = [0.0f64; 3];
    for (k, (col, f)) in fields.iter().enumerate() {
        let v: f64 = f
            .parse()
            .map_err(|_| (format!("{f:?} is not a number"), *col))?;
        if !v.is_finite() {
            return Err((format!("{f:?} is not a finite number"), *col));
        }
        nums[k] = v;
    }
    let time = if fields.len() == 3 {
        if nums[2] < 0.0 {
            return Err(("arrival time must not be negative".into(), fields[2].0));
        }
        Some(nums[2])
    } else {
        None
    };
    Ok(Waypoint {
        x: nums[0],
        y: nums[1],
        z: 0.0,
        time,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn waypoint_text_parses_with_optional_time() {
        assert_eq!(
            parse_waypoint("1.5, -2"),
            Ok(Waypoint {
                x: 1.5,
                y: -2.0,
                z: 0.0,
                time: None
            })
        );
        assert_eq!(parse_waypoint("1 2 30").map(|w| w.time), Ok(Some(30.0)));
    }

    #[test]
    fn waypoint_errors_point_at_the_field() {
        assert_eq!(parse_waypoint("1,abc").map_err(|e| e.1), Err(2));
        assert_eq!(parse_waypoint("1,2,-3").map_err(|e| e.1), Err(4));
        assert!(parse_waypoint("7").is_err());
    }

    #[test]
    fn the_history_keeps_distinct_lines_and_steps_back_and_forth() {
        let mut p = PromptLine::default();
        for line in ["status", "status", "route a none"] {
            p.remember(line);
        }
        assert_eq!(p.history, ["status", "route a none"]);
        p.history_step(-1);
        assert!(p.open.is_none(), "no line open: nothing recalled");
        p.open_command_line();
        let shown = |p: &PromptLine| match &p.open {
            Some(Prompt::Command(s)) => s.clone(),
            other => panic!("{other:?}"),
        };
        p.history_step(-1);
        assert_eq!(shown(&p), "route a none");
        p.history_step(-1);
        p.history_step(-1);
        assert_eq!(shown(&p), "status", "stays at the oldest");
        p.history_step(1);
        p.history_step(1);
        assert_eq!(shown(&p), "", "past the newest: a blank line");
        for i in 0..HISTORY_LINES + 3 {
            p.remember(&format!("line {i}"));
        }
        assert_eq!(p.history.len(), HISTORY_LINES);
        assert_eq!(p.history[0], "line 3");
    }
}
