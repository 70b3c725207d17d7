//! The waypoint panel: the list being edited (newest first), where it will
//! be sent, and the mission progress of the selected robots, or why one
//! holds a mission it does not run.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::style::Style;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph, Widget};

use super::app::{App, Focus, WAYPOINT_CHANNEL};
use super::theme::Theme;

/// The waypoint panel.
#[derive(Debug)]
pub struct WaypointPanel<'a> {
    pub app: &'a App,
    pub theme: Theme,
}

impl Widget for WaypointPanel<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let app = self.app;
        let t = self.theme;
        let border = if app.screen.focus == Focus::Waypoints || app.waypoints.placing {
            t.focused_border()
        } else {
            Style::new()
        };
        let mode = if app.waypoints.placing {
            " [placing]"
        } else {
            ""
        };
        let block = Block::bordered()
            .title(format!(" Waypoints {}{mode} ", app.waypoints.list.len()))
            .border_style(border);
        let inner = block.inner(area);
        block.render(area, buf);

        let mut lines: Vec<Line> = Vec::new();
        let targets: Vec<&str> = app
            .fleet
            .robots
            .iter()
            .filter(|r| app.cards.selection.contains(&r.name))
            .map(|r| r.name.as_str())
            .collect();
        let to = if targets.is_empty() {
            "select robots".to_string()
        } else {
            targets.join(" ")
        };
        lines.push(Line::from(vec![
            Span::styled("to ", t.dim()),
            Span::raw(to),
            Span::styled(format!(" on {WAYPOINT_CHANNEL}"), t.dim()),
        ]));
        lines.extend(mission_lines(app, t, inner.width));
        let n = app.waypoints.list.len();
        for (k, w) in app.waypoints.list.iter().enumerate().rev() {
            let time = w.time.map(|s| format!(" t {s:.1}s")).unwrap_or_default();
            lines.push(Line::from(vec![
                Span::styled(format!("⚑{:<3}", k + 1), Style::new().fg(t.waypoint())),
                Span::raw(format!("x{:7.2} y{:7.2}{time}", w.x, w.y)),
            ]));
            if lines.len() >= usize::from(inner.height).saturating_sub(1) && k > 0 {
                lines.push(Line::styled(format!("… {k} older"), t.dim()));
                break;
            }
        }
        if n == 0 {
            lines.push(Line::styled(
                "f: waypoint mode, click the map or e: type x,y[,t]",
                t.dim(),
            ));
        } else {
            lines.push(Line::styled(
                "Enter send  ⌫ remove last  Del clear  Esc done",
                t.dim(),
            ));
        }
        Paragraph::new(lines).render(inner, buf);
    }
}

/// The selected robots' missions: the progress of each one runs, and, for
/// one that stores the station's mission but is routed elsewhere, why it
/// stands still and the command that starts it (wrapped to `width`).
fn mission_lines(app: &App, t: Theme, width: u16) -> Vec<Line<'static>> {
    let mut lines = Vec::new();
    for r in app
        .fleet
        .robots
        .iter()
        .filter(|r| app.cards.selection.contains(&r.name))
    {
        if let Some(held) = &r.mission_held {
            let rows = wrap_words(held, usize::from(width).saturating_sub(1));
            lines.extend(
                rows.into_iter()
                    .map(|row| Line::styled(format!(" {row}"), t.warn())),
            );
        } else if let Some(m) = r.telemetry.mission {
            let state = if m.next >= m.total {
                Span::styled("arrived", t.ok())
            } else {
                Span::raw(format!("to wp {}/{}", m.next + 1, m.total))
            };
            lines.push(Line::from(vec![
                Span::raw(format!(" {} mission {} ", r.name, m.id)),
                state,
            ]));
        }
    }
    lines
}

/// `text` in rows of at most `width` characters, broken between words (a
/// word longer than a row is cut).
fn wrap_words(text: &str, width: usize) -> Vec<String> {
    let width = width.max(1);
    let mut rows: Vec<String> = Vec::new();
    let mut row = String::new();
    for word in text.split_whitespace() {
        let mut word: Vec<char> = word.chars().collect();
        let taken = row.chars().count();
        if taken > 0 && taken + 1 + word.len() <= width {
            row.push(' ');
            row.extend(word);
            continue;
        }
        if taken > 0 {
            rows.push(std::mem::take(&mut row));
        }
        while word.len() > width {
            rows.push(word.drain(..width).collect());
        }
        row.extend(word);
    }
    if !row.is_empty() {
        rows.push(row);
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_note_wraps_between_words_and_cuts_only_a_word_longer_than_a_row() {
        assert_eq!(
            wrap_words("robot_1 holds mission 3; it starts", 16),
            vec!["robot_1 holds", "mission 3; it", "starts"]
        );
        assert_eq!(wrap_words("abcdefgh ij", 3), vec!["abc", "def", "gh", "ij"]);
        assert!(wrap_words("", 10).is_empty());
    }
}
