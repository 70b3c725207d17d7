//! The routing table: robots x channels, the active route marked
//! acknowledged (●) or pending (◌), a cursor to re-route with Enter, and the
//! live channels with their publisher and rate.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::style::Style;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph, Widget};

use super::app::{App, Focus};
use super::layout::{ROUTE_COL_W, ROUTE_NAME_W, TableWindow};
use super::theme::Theme;
use super::view::{ClusterControlView, RouteView};

/// The routing-table panel.
#[derive(Debug)]
pub struct RoutesPanel<'a> {
    pub app: &'a App,
    pub theme: Theme,
}

fn clip(s: &str, w: usize) -> String {
    if s.chars().count() <= w {
        format!("{s:<w$}")
    } else {
        let mut out: String = s.chars().take(w.saturating_sub(1)).collect();
        out.push('…');
        out
    }
}

impl Widget for RoutesPanel<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let app = self.app;
        let t = self.theme;
        let focused = app.screen.focus == Focus::Routes;
        let border = if focused {
            t.focused_border()
        } else {
            Style::new()
        };
        let block = Block::bordered().title(" Routes ").border_style(border);
        let inner = block.inner(area);
        block.render(area, buf);

        let mut lines = table_lines(app, &t, inner, focused);
        channel_lines(app, &t, &mut lines);
        controller_lines(app, &t, &mut lines);
        cluster_lines(app, &t, &mut lines);
        if focused {
            lines.push(Line::styled("↑↓ robot  ←→ channel  Enter route", t.dim()));
        }
        Paragraph::new(lines).render(inner, buf);
    }
}

/// The visible window of the robots x channels table: a header of channel
/// names, then one row of route marks per robot, the cursor highlighted
/// when the panel has focus.
fn table_lines(app: &App, t: &Theme, inner: Rect, focused: bool) -> Vec<Line<'static>> {
    let cols = app.route_columns();
    let w = TableWindow::new(app.routes.cursor, inner, cols.len());
    let (first, fit, first_row, rows_fit) = (w.first_col, w.cols, w.first_row, w.rows);
    let shown = &cols[first..(first + fit).min(cols.len())];

    let mut lines: Vec<Line> = Vec::new();
    let mut head = vec![Span::raw(" ".repeat(ROUTE_NAME_W + 1))];
    for c in shown {
        let name = if c.is_empty() { "none" } else { c };
        head.push(Span::styled(clip(name, ROUTE_COL_W), t.title()));
    }
    lines.push(Line::from(head));
    for (ri, r) in app
        .fleet
        .robots
        .iter()
        .enumerate()
        .skip(first_row)
        .take(rows_fit)
    {
        let mut spans = vec![Span::styled(
            format!("{} ", clip(&r.name, ROUTE_NAME_W)),
            Style::new().fg(t.robot(ri)),
        )];
        for (k, c) in shown.iter().enumerate() {
            let cursor = focused && app.routes.cursor == (ri, first + k);
            spans.push(route_mark(&r.route, c, cursor, t));
        }
        lines.push(Line::from(spans));
    }
    if app.fleet.robots.is_empty() {
        lines.push(Line::styled("no robots", t.dim()));
    }
    lines
}

/// One cell of the table: whether `route` is on `channel`, and acknowledged.
fn route_mark(route: &RouteView, channel: &str, cursor: bool, t: &Theme) -> Span<'static> {
    let active = route.channel == channel;
    let mark = match (active, route.acknowledged) {
        (true, true) => "●ack",
        (true, false) => "◌pend",
        _ => "·",
    };
    let mut style = if active && route.acknowledged {
        t.ok()
    } else if active {
        t.warn()
    } else {
        t.dim()
    };
    if cursor {
        style = style.patch(t.selected());
    }
    Span::styled(clip(mark, ROUTE_COL_W), style)
}

/// The live channels, with their last publisher and rate.
fn channel_lines(app: &App, t: &Theme, lines: &mut Vec<Line<'_>>) {
    if app.fleet.channels.is_empty() {
        return;
    }
    lines.push(Line::styled("live channels", t.title()));
    for c in &app.fleet.channels {
        lines.push(Line::raw(format!(
            " {:<10} {:<8}{:>6.1}Hz",
            c.name, c.publisher, c.rate_hz
        )));
    }
}

/// Connected pads (channel, mode, dead-man) and keyboard teleop when on.
fn controller_lines(app: &App, t: &Theme, lines: &mut Vec<Line<'_>>) {
    let pads = app.pads();
    if pads.is_empty() && !app.manual.keys_on {
        return;
    }
    lines.push(Line::styled("controllers", t.title()));
    for p in pads {
        let state = if p.enabled {
            Span::styled("driving", t.warn())
        } else {
            Span::styled("hold LB", t.dim())
        };
        lines.push(Line::from(vec![
            Span::raw(format!(" {:<6} {:<8} ", p.channel(), p.mode.label())),
            state,
            Span::styled(format!(" {}", p.name), t.dim()),
        ]));
    }
    if app.manual.keys_on {
        lines.push(Line::from(vec![
            Span::raw(format!(" {:<6} {:<8} ", app.manual.key_channel, "twist")),
            Span::styled("keys", t.warn()),
        ]));
    }
}

/// Clusters, numbered for their keys, the active one highlighted, with
/// each member's slot tracking error once a controller runs the cluster.
fn cluster_lines(app: &App, t: &Theme, lines: &mut Vec<Line<'_>>) {
    if app.fleet.clusters.is_empty() {
        return;
    }
    lines.push(Line::styled("clusters", t.title()));
    for (k, c) in app.fleet.clusters.iter().enumerate() {
        let active = app.fleet.active_cluster.as_deref() == Some(c.name.as_str());
        let style = if active { t.title() } else { Style::new() };
        let mut spans = vec![Span::styled(format!(" {} {:<4}", k + 1, c.name), style)];
        match &c.control {
            Some(ctl) => spans.extend(c.members.iter().map(|m| member_mark(m, ctl, t))),
            None => spans.push(Span::raw(c.members.join(" "))),
        }
        lines.push(Line::from(spans));
    }
}

/// A member's slot tracking error in cm (warned above 15 cm), or that it
/// is lost or absent (–).
fn member_mark(m: &str, ctl: &ClusterControlView, t: &Theme) -> Span<'static> {
    let (text, style) = if let Some(s) = ctl.slots.iter().find(|s| s.robot == m) {
        let cm = (s.error * 100.0).round();
        let style = if s.error > 0.15 {
            t.warn()
        } else {
            Style::new()
        };
        (format!("{m} {cm:.0}cm "), style)
    } else if ctl.lost.iter().any(|l| l == m) {
        (format!("{m} lost "), t.warn())
    } else {
        (format!("{m} – "), t.dim())
    };
    Span::styled(text, style)
}
