//! The `?` overlay: every key, in one table that the key handler follows.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Clear, Paragraph, Widget, Wrap};

use super::theme::Theme;

/// Every key binding: (keys, what it does).
pub const KEYS: &[(&str, &str)] = &[
    (
        "X  or Ctrl+X",
        "E-STOP every robot (works in every mode, Ctrl+X while typing)",
    ),
    ("Ctrl+R / :release", "release the e-stop"),
    ("?", "this help (any key closes)"),
    ("q  Ctrl+C", "quit"),
    (":", "command line (↑↓ history, Enter run, Esc cancel)"),
    (
        "Tab Shift+Tab",
        "next / previous panel: map, robots, waypoints, routes",
    ),
    ("n p", "select next / previous robot"),
    ("N", "add the next robot to the selection"),
    ("a", "select all robots"),
    ("Esc", "leave waypoint mode, else clear the selection"),
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
        "Routes: ↑↓ ←→",
        "move the cursor: robot row, channel column",
    ),
    ("Routes: Enter", "route that robot to that channel"),
    ("Routes: click", "pick a cell; click it again to route"),
    ("t", "keyboard teleop on key/0 on/off"),
    (
        "teleop: arrows WASD",
        "drive / turn; Q E strafe; Space stop",
    ),
    (
        "gamepad",
        "hold LB to drive; Select cycles mode; Start = E-STOP",
    ),
];

/// The help overlay, drawn centred over the screen.
#[derive(Debug)]
pub struct HelpOverlay {
    pub theme: Theme,
}

impl Widget for HelpOverlay {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let w = area.width.saturating_sub(4).min(90);
        let h = area.height.saturating_sub(2).min(KEYS.len() as u16 + 2);
        let r = Rect {
            x: area.x + (area.width - w) / 2,
            y: area.y + (area.height - h) / 2,
            width: w,
            height: h,
        };
        Clear.render(r, buf);
        let block = Block::bordered()
            .title(" Keys (? or Esc closes) ")
            .border_style(self.theme.focused_border());
        let key_w = KEYS
            .iter()
            .map(|(k, _)| k.chars().count())
            .max()
            .unwrap_or(0);
        let lines: Vec<Line> = KEYS
            .iter()
            .map(|(k, d)| {
                Line::from(vec![
                    Span::styled(format!("{k:<key_w$}  "), self.theme.title()),
                    Span::raw(*d),
                ])
            })
            .collect();
        Paragraph::new(lines)
            .block(block)
            .wrap(Wrap { trim: false })
            .render(r, buf);
    }
}
