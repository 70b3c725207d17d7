//! The fleet table's state (its order, filter, rows, cursor, scroll and
//! whether the cursor's robot is shown in detail), and on the App:
//! switching to it and back, keeping its rows (filtered and sorted)
//! current, sorting, the `/` filter, moving the cursor (which selects, as
//! the cards' arrows do) and the detail view.

use super::{App, Focus, Prompt, RobotsView, Select};
use crate::ui::columns::{Column, sorted_rows};

/// The fleet table: its order, filter, rows, cursor and whether the
/// cursor's robot is shown in detail.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct TableState {
    pub sort: Column,
    pub descending: bool,
    /// Text the rows must contain (name, route or state), any case.
    pub filter: String,
    /// Indices into the fleet's robots ([`super::FleetState::robots`]),
    /// filtered and sorted: kept up to date by `update`, so drawing only
    /// reads them.
    pub rows: Vec<usize>,
    /// The robot the keys act on, by name, so it stays put when rows
    /// re-sort (a speed column re-sorts every frame).
    pub cursor: Option<String>,
    /// First row shown.
    pub scroll: usize,
    /// The cursor's robot in detail (card, events, counters) in place of
    /// the table.
    pub detail: bool,
}

impl App {
    /// The table in place of the cards and the map, or back. The table
    /// takes the keys of the robots panel.
    pub(super) fn toggle_table(&mut self) {
        self.screen.robots_view = match self.screen.robots_view {
            RobotsView::Cards => RobotsView::Table,
            RobotsView::Table => RobotsView::Cards,
        };
        self.table.detail = false;
        if self.screen.robots_view == RobotsView::Table {
            self.screen.set_focus(Focus::Cards);
            if self.table.cursor.is_none() {
                self.table.cursor = self.cards.selection.iter().next().cloned();
            }
            self.refresh_rows();
            self.keep_cursor_visible();
        }
    }

    /// Recomputes the rows from the robots, the filter and the order.
    pub(super) fn refresh_rows(&mut self) {
        let t = &self.table;
        self.table.rows = sorted_rows(&self.fleet.robots, t.sort, t.descending, &t.filter);
        let max = self.table.rows.len().saturating_sub(self.table_page());
        self.table.scroll = self.table.scroll.min(max);
    }

    /// Sorts by `column`; by the same column again, the other way.
    pub(super) fn sort_by(&mut self, column: Column) {
        if self.table.sort == column {
            self.table.descending = !self.table.descending;
        } else {
            self.table.sort = column;
            self.table.descending = false;
        }
        self.refresh_rows();
        self.keep_cursor_visible();
    }

    /// Shows the table and starts typing its filter (what was typed before
    /// is kept, to edit).
    pub(super) fn open_filter(&mut self) {
        if self.screen.robots_view != RobotsView::Table {
            self.toggle_table();
        }
        self.table.detail = false;
        self.prompt.open = Some(Prompt::Filter(self.table.filter.clone()));
    }

    pub(super) fn set_filter(&mut self, filter: String) {
        self.table.filter = filter;
        self.table.scroll = 0;
        self.refresh_rows();
        self.keep_cursor_visible();
    }

    /// Moves the cursor `n` rows (clamped to the table) and selects only
    /// that robot; with no cursor in the rows, starts at the first.
    pub(super) fn table_move(&mut self, n: i32) {
        let rows = &self.table.rows;
        let Some(last) = rows.len().checked_sub(1) else {
            return;
        };
        let at = self
            .table
            .cursor
            .as_ref()
            .and_then(|c| rows.iter().position(|&i| &self.fleet.robots[i].name == c));
        let to = match at {
            Some(i) => (i as i64 + i64::from(n)).clamp(0, last as i64) as usize,
            None => 0,
        };
        let name = self.fleet.robots[rows[to]].name.clone();
        self.select(Select::Only(name));
    }

    /// Rows the table shows at once (inside its border, under the header).
    pub fn table_page(&self) -> usize {
        self.areas()
            .table
            .map_or(1, |a| usize::from(a.height.saturating_sub(3)).max(1))
    }

    /// The cursor's row, if it is among the rows.
    pub fn cursor_row(&self) -> Option<usize> {
        let c = self.table.cursor.as_ref()?;
        self.table
            .rows
            .iter()
            .position(|&i| &self.fleet.robots[i].name == c)
    }

    /// Scrolls so that the cursor's row is on screen.
    pub(super) fn keep_cursor_visible(&mut self) {
        let Some(row) = self.cursor_row() else {
            return;
        };
        let page = self.table_page();
        if row < self.table.scroll {
            self.table.scroll = row;
        } else if row >= self.table.scroll + page {
            self.table.scroll = row + 1 - page;
        }
    }

    /// Scrolls the rows by `n` without moving the cursor (the wheel).
    pub(super) fn scroll_table(&mut self, n: i32) {
        let max = self.table.rows.len().saturating_sub(self.table_page()) as i64;
        self.table.scroll = (self.table.scroll as i64 + i64::from(n)).clamp(0, max) as usize;
    }

    /// The robot the detail view shows: the cursor's.
    pub fn detail_robot(&self) -> Option<&crate::ui::view::RobotView> {
        self.table.cursor.as_deref().and_then(|n| self.robot(n))
    }
}
