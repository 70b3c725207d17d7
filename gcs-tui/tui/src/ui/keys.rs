//! Terminal input -> [`Action`]s: the key bindings listed in
//! [`super::help::KEYS`] and the mouse.
//!
//! E-stop (`X`, and `Ctrl+X` even while typing) is checked before anything
//! else, so no mode or overlay can swallow it.

use crossterm::event::{
    Event, KeyCode, KeyEvent, KeyEventKind, KeyModifiers, MouseButton, MouseEvent, MouseEventKind,
};

use super::app::{Action, App, Focus, Prompt, Select};
use crate::gamepad::DriveKey;

/// Actions for one terminal event.
pub fn on_event(app: &App, ev: &Event) -> Vec<Action> {
    match ev {
        Event::Key(k) => on_key(app, k),
        Event::Mouse(m) if app.mouse => on_mouse(app, m).into_iter().collect(),
        Event::Resize(w, h) => vec![Action::Resize(*w, *h)],
        _ => Vec::new(),
    }
}

/// Actions for one key.
pub fn on_key(app: &App, key: &KeyEvent) -> Vec<Action> {
    if key.kind == KeyEventKind::Release {
        return Vec::new();
    }
    let ctrl = key.modifiers.contains(KeyModifiers::CONTROL);
    // Safety keys first: nothing may shadow them.
    match key.code {
        KeyCode::Char('x') | KeyCode::Char('X') if ctrl => return vec![Action::EStop],
        KeyCode::Char('X') if app.prompt.is_none() => return vec![Action::EStop],
        KeyCode::Char('r') | KeyCode::Char('R') if ctrl => return vec![Action::Release],
        KeyCode::Char('c') if ctrl => return vec![Action::Quit],
        _ => {}
    }
    if app.show_help {
        return vec![match key.code {
            KeyCode::Up | KeyCode::Char('k') => Action::HelpScroll(-1),
            KeyCode::Down | KeyCode::Char('j') => Action::HelpScroll(1),
            KeyCode::PageUp => Action::HelpScroll(-10),
            KeyCode::PageDown | KeyCode::Char(' ') => Action::HelpScroll(10),
            _ => Action::ToggleHelp,
        }];
    }
    if app.prompt.is_some() {
        return prompt_key(app, key);
    }
    if app.key_teleop_on {
        let drive = match key.code {
            KeyCode::Up | KeyCode::Char('w') => Some(DriveKey::Forward),
            KeyCode::Down | KeyCode::Char('s') => Some(DriveKey::Back),
            KeyCode::Left | KeyCode::Char('a') => Some(DriveKey::TurnLeft),
            KeyCode::Right | KeyCode::Char('d') => Some(DriveKey::TurnRight),
            KeyCode::Char('q') => Some(DriveKey::StrafeLeft),
            KeyCode::Char('e') => Some(DriveKey::StrafeRight),
            _ => None,
        };
        if let Some(d) = drive {
            return vec![Action::Drive(d)];
        }
        match key.code {
            KeyCode::Char(' ') => return vec![Action::DriveStop],
            KeyCode::Char('t') | KeyCode::Esc => return vec![Action::ToggleKeyTeleop],
            _ => {}
        }
    }
    if app.waypoint_mode {
        match key.code {
            KeyCode::Esc => return vec![Action::WaypointMode(false)],
            KeyCode::Backspace => return vec![Action::RemoveLastWaypoint],
            KeyCode::Delete => return vec![Action::ClearWaypoints],
            KeyCode::Enter | KeyCode::Char('s') => return vec![Action::SendWaypoints],
            KeyCode::Char('e') => return vec![Action::OpenWaypointEntry],
            _ => {}
        }
    }
    if app.focus == Focus::Routes {
        match key.code {
            KeyCode::Up => return vec![Action::RouteCursor(-1, 0)],
            KeyCode::Down => return vec![Action::RouteCursor(1, 0)],
            KeyCode::Left => return vec![Action::RouteCursor(0, -1)],
            KeyCode::Right => return vec![Action::RouteCursor(0, 1)],
            KeyCode::Enter => return vec![Action::ApplyRouteCursor],
            _ => {}
        }
    }
    if app.focus == Focus::Cards {
        match key.code {
            KeyCode::Up => return vec![Action::Select(Select::Prev)],
            KeyCode::Down => return vec![Action::Select(Select::Next)],
            _ => {}
        }
    }
    if app.focus == Focus::Waypoints {
        match key.code {
            KeyCode::Backspace => return vec![Action::RemoveLastWaypoint],
            KeyCode::Delete => return vec![Action::ClearWaypoints],
            KeyCode::Enter => return vec![Action::SendWaypoints],
            _ => {}
        }
    }
    let a = match key.code {
        KeyCode::Char('q') => Action::Quit,
        KeyCode::Char('?') => Action::ToggleHelp,
        KeyCode::Char(':') => Action::OpenCommandLine,
        KeyCode::Tab => Action::FocusNext,
        KeyCode::BackTab => Action::FocusPrev,
        KeyCode::Char('n') => Action::Select(Select::Next),
        KeyCode::Char('p') => Action::Select(Select::Prev),
        KeyCode::Char('N') => Action::Select(Select::AddNext),
        KeyCode::Char('a') => Action::Select(Select::All),
        KeyCode::Esc => Action::Select(Select::Clear),
        KeyCode::Char('c') => Action::MakeCluster,
        KeyCode::Char(d @ '1'..='9') => Action::Select(Select::Cluster(format!("c{d}"))),
        KeyCode::Char('f') => Action::WaypointMode(!app.waypoint_mode),
        KeyCode::Char('e') => Action::OpenWaypointEntry,
        KeyCode::Char('s') => Action::SendWaypoints,
        KeyCode::Char('+') | KeyCode::Char('=') => Action::Zoom(1.25),
        KeyCode::Char('-') => Action::Zoom(0.8),
        KeyCode::Char('0') | KeyCode::Char('z') => Action::FitFleet,
        KeyCode::Char('t') => Action::ToggleKeyTeleop,
        KeyCode::Char('o') => Action::ToggleNav,
        KeyCode::Left => Action::Pan(-4.0, 0.0),
        KeyCode::Right => Action::Pan(4.0, 0.0),
        KeyCode::Up => Action::Pan(0.0, 2.0),
        KeyCode::Down => Action::Pan(0.0, -2.0),
        _ => return Vec::new(),
    };
    vec![a]
}

fn prompt_key(app: &App, key: &KeyEvent) -> Vec<Action> {
    let command = matches!(app.prompt, Some(Prompt::Command(_)));
    match key.code {
        KeyCode::Esc => vec![Action::PromptCancel],
        KeyCode::Enter => vec![Action::PromptSubmit],
        KeyCode::Backspace => vec![Action::PromptBackspace],
        KeyCode::Up if command => vec![Action::HistoryPrev],
        KeyCode::Down if command => vec![Action::HistoryNext],
        KeyCode::Char(c) => vec![Action::PromptChar(c)],
        _ => Vec::new(),
    }
}

/// Action for one mouse event.
pub fn on_mouse(app: &App, m: &MouseEvent) -> Option<Action> {
    let add = m
        .modifiers
        .intersects(KeyModifiers::SHIFT | KeyModifiers::CONTROL);
    match m.kind {
        MouseEventKind::Down(MouseButton::Left) => Some(Action::Click {
            col: m.column,
            row: m.row,
            add,
        }),
        MouseEventKind::Drag(MouseButton::Left) if !app.waypoint_mode => Some(Action::Drag {
            col: m.column,
            row: m.row,
        }),
        MouseEventKind::Up(_) => Some(Action::MouseUp),
        MouseEventKind::ScrollUp => Some(Action::Scroll {
            col: m.column,
            row: m.row,
            steps: 1,
        }),
        MouseEventKind::ScrollDown => Some(Action::Scroll {
            col: m.column,
            row: m.row,
            steps: -1,
        }),
        _ => None,
    }
}
