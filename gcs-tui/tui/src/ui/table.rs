//! The fleet table: one row per robot (name, platform, link, route, mode,
//! failsafe, pose, speed, battery, mission, and the link's rates, loss and
//! round trip), sorted by any column and filtered with `/`, the columns
//! that fit the width; sorted by a number that moves (speed, battery,
//! rates, loss, round trip), that column's last minute as a sparkline
//! beside it. Only the rows on screen are drawn, from the rows the App
//! keeps sorted.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::style::Style;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph, Widget};

use super::app::{App, Focus};
use super::cards::{link_style, loss_style};
use super::columns::{self, Column, GUTTER, TREND_WIDTH};
use super::plots;
use super::theme::Theme;
use super::view::RobotView;
use mech_proto::FailsafeState;

/// The fleet table panel.
#[derive(Debug)]
pub struct TablePanel<'a> {
    pub app: &'a App,
    pub theme: Theme,
}

/// `text` cut or padded to exactly `width` cells (numbers right-aligned).
fn fit(text: &str, width: usize, right: bool) -> String {
    let n = text.chars().count();
    if n > width {
        let mut s: String = text.chars().take(width.saturating_sub(1)).collect();
        s.push('…');
        s
    } else if right {
        format!("{text:>width$}")
    } else {
        format!("{text:<width$}")
    }
}

fn right_aligned(c: Column) -> bool {
    matches!(
        c,
        Column::Speed
            | Column::Battery
            | Column::Rx
            | Column::Tx
            | Column::Loss
            | Column::Rtt
            | Column::Pose
    )
}

impl Widget for TablePanel<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let app = self.app;
        let t = self.theme;
        let focused = app.screen.focus == Focus::Cards;
        let border = if focused {
            t.focused_border()
        } else {
            Style::new()
        };
        let block = Block::bordered().title(title(app)).border_style(border);
        let inner = block.inner(area);
        block.render(area, buf);
        let (shown, trend) = columns::layout(usize::from(inner.width), app.table.sort);
        let mut lines = Vec::with_capacity(usize::from(inner.height));
        lines.push(header(app, &shown, trend, &t));
        let cursor = app.cursor_row();
        let rows = usize::from(inner.height.saturating_sub(1));
        for (k, &i) in app
            .table
            .rows
            .iter()
            .enumerate()
            .skip(app.table.scroll)
            .take(rows)
        {
            let r = &app.fleet.robots[i];
            let selected = app.cards.selection.contains(&r.name);
            let mut line = row(r, i, selected, &shown, &t);
            if let Some((after, (series, span))) = trend.and_then(|c| Some((c, c.trend()?))) {
                let spark = plots::trend(&app.history, &r.name, series, TREND_WIDTH, span);
                insert_after(&mut line, &shown, after, spark);
            }
            if cursor == Some(k) {
                line = line.patch_style(if focused { t.selected() } else { t.title() });
            }
            lines.push(line);
        }
        if app.table.rows.is_empty() {
            let why = if app.fleet.robots.is_empty() {
                "no robots yet".to_string()
            } else {
                format!("no robot matches /{}", app.table.filter)
            };
            lines.push(Line::styled(why, t.dim()));
        }
        Paragraph::new(lines).render(inner, buf);
    }
}

/// ` Fleet 11/100 │ sort loss ▼ │ /robot_9 `.
fn title(app: &App) -> String {
    let arrow = if app.table.descending { "▼" } else { "▲" };
    let mut s = format!(
        " Fleet {}/{} │ sort {} {arrow} ",
        app.table.rows.len(),
        app.fleet.robots.len(),
        app.table.sort.header().trim().to_lowercase(),
    );
    if !app.table.filter.is_empty() {
        s.push_str(&format!("│ /{} ", app.table.filter));
    }
    s
}

/// Puts `text` (the trend) after the cells of column `after` in `line`
/// (a row or the header: a gutter span, then per column a separator and
/// its cell).
fn insert_after(line: &mut Line<'static>, shown: &[Column], after: Column, text: String) {
    if let Some(k) = shown.iter().position(|c| *c == after) {
        // The gutter, then for column k its cell at 2k+1 (after k separators).
        let at = (2 * k + 2).min(line.spans.len());
        line.spans.insert(at, Span::raw(text));
        line.spans.insert(at, Span::raw(" "));
    }
}

fn header(app: &App, shown: &[Column], trend: Option<Column>, t: &Theme) -> Line<'static> {
    let mut spans = vec![Span::raw(" ".repeat(GUTTER))];
    for (k, c) in shown.iter().enumerate() {
        if k > 0 {
            spans.push(Span::raw(" "));
        }
        let mut text = c.header().to_string();
        if *c == app.table.sort {
            text.push(if app.table.descending { '▼' } else { '▲' });
        }
        spans.push(Span::styled(
            fit(&text, c.width(), right_aligned(*c) && *c != Column::Pose),
            t.title(),
        ));
    }
    let mut line = Line::from(spans);
    if let Some(after) = trend {
        insert_after(&mut line, shown, after, fit("1 MIN", TREND_WIDTH, false));
    }
    line
}

/// One robot's row; `i` is its place in the fleet (its colour).
fn row(r: &RobotView, i: usize, selected: bool, shown: &[Column], t: &Theme) -> Line<'static> {
    let mark = if selected { "▶ " } else { "  " };
    let mut spans = vec![Span::styled(mark, Style::new().fg(t.robot(i)))];
    for (k, c) in shown.iter().enumerate() {
        if k > 0 {
            spans.push(Span::raw(" "));
        }
        let style = match c {
            Column::Name if selected => Style::new().fg(t.robot(i)).patch(t.title()),
            Column::Name => Style::new().fg(t.robot(i)),
            Column::Link => link_style(r.link, t),
            Column::Failsafe => match r.telemetry.failsafe {
                FailsafeState::Ok => t.ok(),
                FailsafeState::ChannelSilent => t.dim(),
                _ => t.alarm(),
            },
            Column::Loss => loss_style(&r.quality, t),
            _ => Style::new(),
        };
        spans.push(Span::styled(
            fit(&c.text(r), c.width(), right_aligned(*c)),
            style,
        ));
    }
    Line::from(spans)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_are_cut_with_an_ellipsis_or_padded() {
        assert_eq!(fit("offboard/robot_12✓", 16, false), "offboard/robot_…");
        assert_eq!(fit("ok", 4, false), "ok  ");
        assert_eq!(fit("6.0%", 6, true), "  6.0%");
    }
}
