//! The one-line prompt on the App: the `:` command line with its history
//! and the results the core sends back, `x,y[,t]` waypoint entry, and the
//! fleet table's `/` filter (applied as it is typed).

use mech_proto::Waypoint;

use super::{App, HISTORY_LINES, LogLevel, Prompt, PromptError, Request};

impl App {
    pub(super) fn open_command_line(&mut self) {
        self.prompt = Some(Prompt::Command(String::new()));
        self.history_pos = None;
    }

    /// Changes the text of the open prompt, if any; a filter applies at
    /// once.
    pub(super) fn edit_prompt(&mut self, edit: impl FnOnce(&mut String)) {
        match &mut self.prompt {
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
        if let Some(Prompt::Filter(_)) = self.prompt.take() {
            self.set_filter(String::new());
        }
    }

    pub(super) fn submit_prompt(&mut self) {
        match self.prompt.take() {
            Some(Prompt::Command(line)) => {
                let line = line.trim().to_string();
                if line.is_empty() {
                    return;
                }
                if self.history.last() != Some(&line) {
                    self.history.push(line.clone());
                    if self.history.len() > HISTORY_LINES {
                        self.history.remove(0);
                    }
                }
                self.history_pos = None;
                self.prompt_error = None;
                self.outbox.push(Request::Exec(line));
            }
            // The filter is already applied: Enter keeps it.
            Some(Prompt::Filter(_)) => {}
            Some(Prompt::Waypoint(text)) => match parse_waypoint(&text) {
                Ok(w) => {
                    self.prompt_error = None;
                    self.add_waypoint(w);
                }
                Err((message, column)) => {
                    self.prompt_error = Some(PromptError {
                        line: text.clone(),
                        message,
                        column: Some(column),
                    });
                    self.prompt = Some(Prompt::Waypoint(text));
                }
            },
            None => {}
        }
    }

    pub(super) fn history_step(&mut self, dir: i32) {
        let Some(Prompt::Command(s)) = &mut self.prompt else {
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

    /// Logs what a command line printed, or its error (kept for the error
    /// box).
    pub(super) fn command_result(&mut self, r: Result<String, PromptError>) {
        match r {
            Ok(text) => {
                self.prompt_error = None;
                for line in text.lines().filter(|l| !l.is_empty()) {
                    self.log(LogLevel::Info, line.to_string());
                }
            }
            Err(e) => {
                self.log(LogLevel::Error, format!("{}: {}", e.line, e.message));
                self.prompt_error = Some(e);
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
}
