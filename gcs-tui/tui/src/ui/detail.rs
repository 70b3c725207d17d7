//! One robot in detail, in place of the fleet table (Enter on a row): its
//! card, its last minute in charts ([`super::plots`]), and, where the
//! height allows, its link and counters as the router measures them and
//! the recent events that name it.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::style::Style;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph, Widget};

use super::app::{App, LogLevel};
use super::cards::{card, loss_style};
use super::plots::{MIN_HEIGHT, PlotGrid};
use super::theme::Theme;

/// From this inner height the link's counters and the robot's events are
/// shown beside the charts (at 80x24 and 120x36 the charts take the room).
const ROOMY: u16 = 30;

/// The detail panel.
#[derive(Debug)]
pub struct DetailPanel<'a> {
    pub app: &'a App,
    pub theme: Theme,
}

/// Whether a log line names `robot` (as a whole word: `robot_1` is not
/// named by a line about `robot_10`).
pub fn names(text: &str, robot: &str) -> bool {
    let word = |c: char| c.is_alphanumeric() || c == '_' || c == '-';
    text.match_indices(robot).any(|(at, _)| {
        let before = text[..at].chars().next_back();
        let after = text[at + robot.len()..].chars().next();
        !before.is_some_and(word) && !after.is_some_and(word)
    })
}

impl Widget for DetailPanel<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let app = self.app;
        let t = self.theme;
        let Some(r) = app.detail_robot() else {
            let block = Block::bordered().title(" Robot │ Esc back ");
            let inner = block.inner(area);
            block.render(area, buf);
            Paragraph::new(Line::styled("select a robot first", t.dim())).render(inner, buf);
            return;
        };
        let block = Block::bordered()
            .title(format!(" {} #{} │ Enter/Esc back ", r.name, r.id))
            .border_style(t.focused_border());
        let inner = block.inner(area);
        block.render(area, buf);
        let i = app
            .fleet
            .robots
            .iter()
            .position(|x| x.name == r.name)
            .unwrap_or(0);
        let mut lines = Vec::new();
        card(r, i, app.cards.selection.contains(&r.name), &t, &mut lines);
        let roomy = inner.height >= ROOMY;
        if roomy {
            lines.push(Line::raw(""));
            link_lines(r, &t, &mut lines);
        }
        let top = (lines.len() as u16).min(inner.height);
        Paragraph::new(lines).render(
            Rect {
                height: top,
                ..inner
            },
            buf,
        );
        let rest = inner.height - top;
        let events_height = if roomy { (rest / 4).max(3) } else { 0 };
        let charts = Rect {
            y: inner.y + top,
            height: rest - events_height,
            ..inner
        };
        if charts.height >= MIN_HEIGHT {
            PlotGrid {
                history: &app.history,
                robot: &r.name,
                theme: t,
            }
            .render(charts, buf);
        }
        let events = Rect {
            y: charts.y + charts.height,
            height: rest - charts.height,
            ..inner
        };
        if events.height > 0 {
            event_lines(app, &r.name, &t, events, buf);
        }
    }
}

/// The link, as the router measures it: rates, loss, round trip, totals.
fn link_lines<'a>(r: &super::view::RobotView, t: &Theme, lines: &mut Vec<Line<'a>>) {
    let q = &r.quality;
    lines.push(Line::styled("link, as the router measures it", t.title()));
    if q.measured() {
        lines.push(Line::raw(format!(
            " rx {:.1}/s from the robot, tx {:.1}/s to it, over the last {:.0} s",
            q.rx_hz,
            q.tx_hz,
            q.window.as_secs_f64()
        )));
        lines.push(Line::from(vec![
            Span::raw(" loss "),
            Span::styled(q.loss_text(), loss_style(q, t)),
            Span::raw(format!(" of its messages, round trip {}", q.rtt_text())),
        ]));
        lines.push(Line::raw(format!(
            " since it registered: received {}, sent {}, lost {}",
            q.received, q.sent, q.lost
        )));
    } else {
        lines.push(Line::styled(" not measured yet", t.dim()));
    }
}

/// The recent events that name `robot`, newest last, in `area`.
fn event_lines(app: &App, robot: &str, t: &Theme, area: Rect, buf: &mut Buffer) {
    let mut lines = vec![Line::styled("recent events", t.title())];
    let room = usize::from(area.height).saturating_sub(1);
    let events: Vec<_> = app
        .events
        .iter()
        .filter(|l| names(&l.text, robot))
        .collect();
    if events.is_empty() {
        lines.push(Line::styled(" none kept", t.dim()));
    }
    for l in events.iter().skip(events.len().saturating_sub(room)) {
        let style = match l.level {
            LogLevel::Info => Style::new(),
            LogLevel::Warn => t.warn(),
            LogLevel::Error => t.alarm(),
        };
        lines.push(Line::styled(format!(" {}", l.text), style));
    }
    Paragraph::new(lines).render(area, buf);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_names_a_robot_as_a_whole_word() {
        assert!(names("robot_1 link stale", "robot_1"));
        assert!(names("route robot_1 -> joy/0", "robot_1"));
        assert!(!names("robot_10 link stale", "robot_1"));
        assert!(!names("offboard/robot_12 up", "robot_1"));
        assert!(names("cluster c1: robot_2 robot_1", "robot_1"));
    }
}
