//! The events pane's state: the most recent log lines, oldest first, at
//! most `LOG_LINES` of them.

use std::collections::VecDeque;

/// Lines the events pane keeps; older ones are dropped.
const LOG_LINES: usize = 200;

/// Severity of a log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LogLevel {
    Info,
    Warn,
    Error,
}

/// One line of the events pane.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogLine {
    pub level: LogLevel,
    pub text: String,
}

/// The events pane's lines.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct EventLog {
    lines: VecDeque<LogLine>,
}

impl EventLog {
    /// Adds a line, dropping the oldest beyond `LOG_LINES`.
    pub fn push(&mut self, level: LogLevel, text: impl Into<String>) {
        self.lines.push_back(LogLine {
            level,
            text: text.into(),
        });
        while self.lines.len() > LOG_LINES {
            self.lines.pop_front();
        }
    }

    /// The lines, oldest first.
    pub fn iter(&self) -> impl DoubleEndedIterator<Item = &LogLine> + ExactSizeIterator {
        self.lines.iter()
    }

    /// The newest line.
    pub fn last(&self) -> Option<&LogLine> {
        self.lines.back()
    }

    pub fn len(&self) -> usize {
        self.lines.len()
    }

    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_keeps_the_newest_lines() {
        let mut log = EventLog::default();
        for i in 0..LOG_LINES + 5 {
            log.push(LogLevel::Info, format!("line {i}"));
        }
        assert_eq!(log.len(), LOG_LINES);
        assert_eq!(log.iter().next().map(|l| l.text.as_str()), Some("line 5"));
        let last = format!("line {}", LOG_LINES + 4);
        assert_eq!(log.iter().last().map(|l| l.text.clone()), Some(last));
    }
}
