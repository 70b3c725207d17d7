//! Terminal input -> [`Action`]s: the key bindings listed in
//! [`super::help::KEYS`] and the mouse.
//!
//! E-stop (`X`, and `Ctrl+X` even while typing) is checked before anything
//! else, so no mode or overlay can swallow it.

use crossterm::event::{
    Event, KeyCode, KeyEvent, KeyEventKind, KeyModifiers, MouseButton, MouseEvent, MouseEventKind,
};

use super::app::{Action, App, Focus, Prompt, RobotsView, Select};
use crate::gamepad::DriveKey;

/// Actions for one terminal event.
pub fn on_event(app: &App, ev: &Event) -> Vec<Action> {
    match ev {
        Event::Key(k) => on_key(app, k),
        Event::Mouse(m) if app.session.mouse => on_mouse(app, m).into_iter().collect(),
        Event::Resize(w, h) => vec![Action::Resize(*w, *h)],
        _ => Vec::new(),
    }
}

/// Actions for one key. Safety keys come first, so nothing may shadow
/// them; then the help overlay and an open prompt take every key; then
/// keyboard teleop, waypoint mode, the focused panel and last the keys that
/// work everywhere.
pub fn on_key(app: &App, key: &KeyEvent) -> Vec<Action> {
    if key.kind == KeyEventKind::Release {
        return Vec::new();
    }
    if let Some(a) = safety_key(app, key) {
        return vec![a];
    }
    if app.screen.help.shown {
        return vec![help_key(key.code)];
    }
    if app.prompt.open.is_some() {
        return prompt_key(app, key);
    }
    teleop_key(app, key.code)
        .or_else(|| waypoint_mode_key(app, key.code))
        .or_else(|| table_key(app, key))
        .or_else(|| panel_key(app, key.code))
        .or_else(|| global_key(app, key.code))
        .into_iter()
        .collect()
}

/// E-stop (`X`, or `Ctrl+X` even while typing), release and quit.
fn safety_key(app: &App, key: &KeyEvent) -> Option<Action> {
    let ctrl = key.modifiers.contains(KeyModifiers::CONTROL);
    match key.code {
        KeyCode::Char('x') | KeyCode::Char('X') if ctrl => Some(Action::EStop),
        KeyCode::Char('X') if app.prompt.open.is_none() => Some(Action::EStop),
        KeyCode::Char('r') | KeyCode::Char('R') if ctrl => Some(Action::Release),
        KeyCode::Char('c') if ctrl => Some(Action::Quit),
        _ => None,
    }
}

/// While the help is shown: scroll it, any other key closes it.
fn help_key(code: KeyCode) -> Action {
    match code {
        KeyCode::Up | KeyCode::Char('k') => Action::HelpScroll(-1),
        KeyCode::Down | KeyCode::Char('j') => Action::HelpScroll(1),
        KeyCode::PageUp => Action::HelpScroll(-10),
        KeyCode::PageDown | KeyCode::Char(' ') => Action::HelpScroll(10),
        _ => Action::ToggleHelp,
    }
}

/// Keyboard teleop, when on: arrows/WASD drive, Q/E strafe, R/F (or
/// PageUp/PageDown) climb and descend, Space stops, `t` or Esc turns it
/// off.
fn teleop_key(app: &App, code: KeyCode) -> Option<Action> {
    if !app.manual.keys_on {
        return None;
    }
    let drive = match code {
        KeyCode::Up | KeyCode::Char('w') => DriveKey::Forward,
        KeyCode::Down | KeyCode::Char('s') => DriveKey::Back,
        KeyCode::Left | KeyCode::Char('a') => DriveKey::TurnLeft,
        KeyCode::Right | KeyCode::Char('d') => DriveKey::TurnRight,
        KeyCode::Char('q') => DriveKey::StrafeLeft,
        KeyCode::Char('e') => DriveKey::StrafeRight,
        KeyCode::Char('r') | KeyCode::PageUp => DriveKey::Climb,
        KeyCode::Char('f') | KeyCode::PageDown => DriveKey::Descend,
        KeyCode::Char(' ') => return Some(Action::DriveStop),
        KeyCode::Char('t') | KeyCode::Esc => return Some(Action::ToggleKeyTeleop),
        _ => return None,
    };
    Some(Action::Drive(drive))
}

/// Waypoint mode, when on: leave, edit, send or type a waypoint.
fn waypoint_mode_key(app: &App, code: KeyCode) -> Option<Action> {
    if !app.waypoints.placing {
        return None;
    }
    match code {
        KeyCode::Esc => Some(Action::WaypointMode(false)),
        KeyCode::Backspace => Some(Action::RemoveLastWaypoint),
        KeyCode::Delete => Some(Action::ClearWaypoints),
        KeyCode::Enter | KeyCode::Char('s') => Some(Action::SendWaypoints),
        KeyCode::Char('e') => Some(Action::OpenWaypointEntry),
        _ => None,
    }
}

/// Keys of the fleet table, when it has the focus: rows select as the
/// cards' arrows do (Shift adds), a page or the ends, Space marks, Enter
/// shows the robot in detail, `<` `>` `r` sort, Esc leaves the detail,
/// then clears the filter (then falls through to clearing the selection).
fn table_key(app: &App, key: &KeyEvent) -> Option<Action> {
    if app.screen.robots_view != RobotsView::Table || app.screen.focus != Focus::Cards {
        return None;
    }
    let shift = key.modifiers.contains(KeyModifiers::SHIFT);
    let page = app.table_page() as i32;
    let a = match key.code {
        KeyCode::Up if shift => Action::Select(Select::AddPrev),
        KeyCode::Down if shift => Action::Select(Select::AddNext),
        KeyCode::Up => Action::TableMove(-1),
        KeyCode::Down => Action::TableMove(1),
        KeyCode::PageUp => Action::TableMove(-page),
        KeyCode::PageDown => Action::TableMove(page),
        KeyCode::Home => Action::TableMove(i32::MIN),
        KeyCode::End => Action::TableMove(i32::MAX),
        KeyCode::Char(' ') => Action::Select(Select::Toggle(app.table.cursor.clone()?)),
        KeyCode::Enter => Action::ToggleDetail,
        KeyCode::Char('<') => Action::SortStep(-1),
        KeyCode::Char('>') => Action::SortStep(1),
        KeyCode::Char('r') => Action::SortReverse,
        KeyCode::Esc if app.table.detail => Action::CloseDetail,
        KeyCode::Esc if !app.table.filter.is_empty() => Action::ClearFilter,
        _ => return None,
    };
    Some(a)
}

/// Keys of the focused panel: the routing-table cursor, the card
/// selection, the waypoint list (its keys also on the map and the cards).
fn panel_key(app: &App, code: KeyCode) -> Option<Action> {
    match (app.screen.focus, code) {
        (Focus::Routes, KeyCode::Up) => Some(Action::RouteCursor(-1, 0)),
        (Focus::Routes, KeyCode::Down) => Some(Action::RouteCursor(1, 0)),
        (Focus::Routes, KeyCode::Left) => Some(Action::RouteCursor(0, -1)),
        (Focus::Routes, KeyCode::Right) => Some(Action::RouteCursor(0, 1)),
        (Focus::Routes, KeyCode::Enter) => Some(Action::ApplyRouteCursor),
        (Focus::Cards, KeyCode::Up) => Some(Action::Select(Select::Prev)),
        (Focus::Cards, KeyCode::Down) => Some(Action::Select(Select::Next)),
        // The waypoint keys, wherever they mean nothing else (the routing
        // table takes Enter for itself).
        (Focus::Map | Focus::Cards | Focus::Waypoints, KeyCode::Backspace) => {
            Some(Action::RemoveLastWaypoint)
        }
        (Focus::Map | Focus::Cards | Focus::Waypoints, KeyCode::Delete) => {
            Some(Action::ClearWaypoints)
        }
        (Focus::Map | Focus::Cards | Focus::Waypoints, KeyCode::Enter) => {
            Some(Action::SendWaypoints)
        }
        _ => None,
    }
}

/// Keys that work whatever the mode and the focus.
fn global_key(app: &App, code: KeyCode) -> Option<Action> {
    let a = match code {
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
        KeyCode::Char('f') => Action::WaypointMode(!app.waypoints.placing),
        KeyCode::Char('e') => Action::OpenWaypointEntry,
        KeyCode::Char('s') => Action::SendWaypoints,
        KeyCode::Char('+') | KeyCode::Char('=') => Action::Zoom(1.25),
        KeyCode::Char('-') => Action::Zoom(0.8),
        KeyCode::Char('0') | KeyCode::Char('z') => Action::FitFleet,
        KeyCode::Char('t') => Action::ToggleKeyTeleop,
        KeyCode::Char('o') => Action::ToggleNav,
        KeyCode::Char('R') => Action::ToggleRecording,
        KeyCode::Char('v') => Action::ToggleTable,
        KeyCode::Char('/') => Action::OpenFilter,
        KeyCode::Left => Action::Pan(-4.0, 0.0),
        KeyCode::Right => Action::Pan(4.0, 0.0),
        KeyCode::Up => Action::Pan(0.0, 2.0),
        KeyCode::Down => Action::Pan(0.0, -2.0),
        _ => return None,
    };
    Some(a)
}

fn prompt_key(app: &App, key: &KeyEvent) -> Vec<Action> {
    let command = matches!(app.prompt.open, Some(Prompt::Command(_)));
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
        MouseEventKind::Drag(MouseButton::Left) if !app.waypoints.placing => Some(Action::Drag {
            col: m.column,
            row: m.row,
        }),
        MouseEventKind::Up(_) => Some(Action::MouseUp),
        MouseEventKind::Moved => Some(Action::Hover {
            col: m.column,
            row: m.row,
        }),
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
