//! The `?` overlay: every key, in one table that the key handler follows.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Clear, Paragraph, Widget};

use super::theme::Theme;

/// Every key binding: (keys, what it does).
pub const KEYS: &[(&str, &str)] = &[
    (
        "X  Ctrl+X",
        "E-STOP every robot, in every mode (Ctrl+X while typing)",
    ),
    ("Ctrl+R / :release", "release the e-stop"),
    ("?", "this help (↑↓ PgUp PgDn scroll, any other key closes)"),
    ("q  Ctrl+C", "quit"),
    (":", "command line (↑↓ history, Enter run, Esc cancel)"),
    (
        "Tab Shift+Tab",
        "next / previous panel: map, robots, waypoints, routes",
    ),
    ("n p", "select next / previous robot"),
    ("N", "add the next robot to the selection"),
    ("a", "select all robots"),
    (
        "Esc",
        "leave a mode, detail or filter; else clear selection",
    ),
    (
        "click",
        "select a robot (map or card); Shift/Ctrl+click adds",
    ),
    ("c", "make a cluster from the selection"),
    (
        "1-9",
        "select cluster c1..c9 (a pad in cluster mode drives it)",
    ),
    ("f", "waypoint mode: click the map to place a waypoint"),
    ("e", "type a waypoint x,y[,t] (metres, seconds)"),
    ("Backspace", "remove the last waypoint"),
    ("Delete", "clear the waypoints"),
    (
        "Enter / s",
        "send the waypoints to the selected robots (wp/gcs)",
    ),
    ("+ - wheel", "zoom (wheel zooms about the pointer)"),
    ("arrows, drag", "pan the map (map panel focused)"),
    ("0  z", "fit the fleet in view"),
    (
        "pointer on a robot",
        "name it on the map, even where a crowd hides names",
    ),
    (
        "Routes: ↑↓ ←→",
        "move the cursor: robot row, channel column",
    ),
    ("Routes: Enter", "route that robot to that channel"),
    ("Routes: click", "pick a cell; click it again to route"),
    ("v", "fleet table in place of cards and map, and back"),
    ("/", "filter the table: name, route or state (Esc clears)"),
    (
        "table: ↑↓",
        "select the previous / next row (Shift+↑↓ adds it)",
    ),
    (
        "table: PgUp PgDn",
        "a page up / down (Home End: first / last row)",
    ),
    (
        "table: < > r",
        "sort by the previous / next column; r reverses",
    ),
    (
        "table: Space",
        "add or remove the cursor's robot from the selection",
    ),
    (
        "table: Enter Esc",
        "the robot's detail (card, events, counters); back",
    ),
    (
        "table: click",
        "header: sort by it (again: reverse); row: select",
    ),
    (
        "o",
        "selected robots: waypoint navigation onboard <-> offboard",
    ),
    ("t", "keyboard teleop on key/0 on/off"),
    ("R", "record to the recording directory on/off"),
    (
        "teleop: arrows WASD",
        "drive/turn; q e strafe; r f climb; Space stop; t Esc off",
    ),
    (
        "gamepad",
        "hold LB to drive; Select cycles mode; Start = E-STOP",
    ),
];

/// The help overlay, drawn centred over the screen; scrolls when the
/// terminal is too short for every key.
#[derive(Debug)]
pub struct HelpOverlay {
    pub theme: Theme,
    /// First entry shown.
    pub scroll: usize,
}

/// Entries that fit in a terminal of `height` rows.
pub fn visible_entries(height: u16) -> usize {
    usize::from(height.saturating_sub(2)).max(1)
}

impl Widget for HelpOverlay {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let w = if area.width > 84 { 80 } else { area.width };
        let rows = visible_entries(area.height).min(KEYS.len());
        let h = (rows as u16 + 2).min(area.height);
        let r = Rect {
            x: area.x + (area.width - w) / 2,
            y: area.y + (area.height - h) / 2,
            width: w,
            height: h,
        };
        Clear.render(r, buf);
        let first = self.scroll.min(KEYS.len() - rows);
        let title = if rows < KEYS.len() {
            format!(
                " Keys {}-{} of {} (↑↓ scroll) ",
                first + 1,
                first + rows,
                KEYS.len()
            )
        } else {
            " Keys (any key closes) ".to_string()
        };
        let block = Block::bordered()
            .title(title)
            .border_style(self.theme.focused_border());
        let key_w = KEYS
            .iter()
            .map(|(k, _)| k.chars().count())
            .max()
            .unwrap_or(0);
        let lines: Vec<Line> = KEYS
            .iter()
            .skip(first)
            .take(rows)
            .map(|(k, d)| {
                Line::from(vec![
                    Span::styled(format!("{k:<key_w$} "), self.theme.title()),
                    Span::raw(*d),
                ])
            })
            .collect();
        Paragraph::new(lines).block(block).render(r, buf);
    }
}
