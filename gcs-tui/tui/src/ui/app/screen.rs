//! The screen as a whole: the terminal's size, which panel has the focus,
//! which panel the side column shows on a small terminal, whether the
//! robots are shown as cards beside the map or as the fleet table, and the
//! help overlay; the layout follows from them.

use ratatui::layout::Rect;

use crate::ui::help;
use crate::ui::layout::{Areas, SidePanel};

/// Which panel receives navigation keys.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Focus {
    #[default]
    Map,
    Cards,
    Waypoints,
    Routes,
}

impl Focus {
    pub(super) fn next(self) -> Focus {
        match self {
            Focus::Map => Focus::Cards,
            Focus::Cards => Focus::Waypoints,
            Focus::Waypoints => Focus::Routes,
            Focus::Routes => Focus::Map,
        }
    }

    pub(super) fn prev(self) -> Focus {
        match self {
            Focus::Map => Focus::Routes,
            Focus::Cards => Focus::Map,
            Focus::Waypoints => Focus::Cards,
            Focus::Routes => Focus::Waypoints,
        }
    }
}

/// How the robots are shown: cards beside the map, or the fleet table in
/// place of both (the side column stays).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum RobotsView {
    #[default]
    Cards,
    Table,
}

/// The `?` overlay: shown or not, and its first entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Help {
    pub shown: bool,
    /// First help entry shown.
    pub scroll: usize,
}

impl Help {
    /// Shows or hides the help, from its first entry.
    pub fn toggle(&mut self) {
        self.shown = !self.shown;
        self.scroll = 0;
    }
}

/// The terminal and what is on it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Screen {
    /// Terminal size (columns, rows), for the layout and click resolution.
    pub size: (u16, u16),
    pub focus: Focus,
    pub side: SidePanel,
    pub robots_view: RobotsView,
    pub help: Help,
}

impl Default for Screen {
    fn default() -> Self {
        Screen {
            size: (80, 24),
            focus: Focus::Map,
            side: SidePanel::Cards,
            robots_view: RobotsView::Cards,
            help: Help::default(),
        }
    }
}

impl Screen {
    /// The layout of the whole terminal.
    pub fn areas(&self) -> Areas {
        let table = self.robots_view == RobotsView::Table;
        Areas::compute(Rect::new(0, 0, self.size.0, self.size.1), self.side, table)
    }

    /// Gives `f` the focus; a side panel focused is the one the side column
    /// shows.
    pub fn set_focus(&mut self, f: Focus) {
        self.focus = f;
        self.side = match f {
            Focus::Cards => SidePanel::Cards,
            Focus::Waypoints => SidePanel::Waypoints,
            Focus::Routes => SidePanel::Routes,
            Focus::Map => self.side,
        };
    }

    /// The next (or previous) panel; the map is skipped while the table
    /// hides it.
    pub fn step_focus(&mut self, step: fn(Focus) -> Focus) {
        let mut f = step(self.focus);
        if f == Focus::Map && self.robots_view == RobotsView::Table {
            f = step(f);
        }
        self.set_focus(f);
    }

    /// Scrolls the help by `d` entries, keeping the last page full.
    pub fn scroll_help(&mut self, d: i32) {
        let rows = help::visible_entries(self.size.1);
        let max = help::KEYS.len().saturating_sub(rows);
        self.help.scroll = (self.help.scroll as i64 + i64::from(d)).clamp(0, max as i64) as usize;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn focus_cycles_skipping_the_map_under_the_table_and_moves_the_side_column() {
        let mut s = Screen::default();
        s.step_focus(Focus::prev);
        assert_eq!((s.focus, s.side), (Focus::Routes, SidePanel::Routes));
        s.step_focus(Focus::next);
        assert_eq!(s.focus, Focus::Map);
        assert_eq!(
            s.side,
            SidePanel::Routes,
            "the map leaves the side column be"
        );
        s.robots_view = RobotsView::Table;
        s.step_focus(Focus::prev);
        s.step_focus(Focus::next);
        assert_eq!(s.focus, Focus::Cards, "no map to focus under the table");
    }

    #[test]
    fn help_scrolls_within_its_entries_and_reopens_at_the_top() {
        let mut s = Screen {
            size: (80, 12),
            ..Screen::default()
        };
        s.help.toggle();
        s.scroll_help(-5);
        assert_eq!(s.help.scroll, 0);
        s.scroll_help(1000);
        assert_eq!(s.help.scroll, help::KEYS.len() - help::visible_entries(12));
        s.help.toggle();
        s.help.toggle();
        assert_eq!((s.help.shown, s.help.scroll), (true, 0));
    }
}
