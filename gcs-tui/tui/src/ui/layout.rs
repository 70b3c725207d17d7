//! Screen layout as a pure function of the terminal size, shared by the
//! renderer and by click handling (so a click is resolved against exactly
//! the rectangles that were drawn): the panel rectangles, the height of a
//! robot card and the visible window of the routing table.

use ratatui::layout::{Constraint, Layout, Rect};

/// Width and height from which every panel is shown at once.
pub const WIDE_MIN: (u16, u16) = (120, 36);

/// Lines per robot card, so scrolling and clicks land on the card drawn.
pub const CARD_HEIGHT: usize = 4;

/// Width of the routing table's robot-name column (a space follows it).
pub const ROUTE_NAME_W: usize = 9;
/// Width of one routing-table channel column.
pub const ROUTE_COL_W: usize = 7;

/// Panels that share the side column on small terminals.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SidePanel {
    #[default]
    Cards,
    Waypoints,
    Routes,
}

/// Where each panel goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Areas {
    pub status: Rect,
    pub cards: Option<Rect>,
    pub waypoints: Option<Rect>,
    pub routes: Option<Rect>,
    /// The fleet table, in the table view: where the cards and the map
    /// are otherwise.
    pub table: Option<Rect>,
    /// The map including its border; empty in the table view.
    pub map: Rect,
    pub log: Rect,
    /// Key hints or the command line.
    pub bottom: Rect,
    /// All panels visible at once.
    pub wide: bool,
}

impl Areas {
    /// Lays out `area`; on a small terminal the side column shows `side`.
    /// With `table`, the fleet table takes the place of the cards and the
    /// map (on a small terminal, of the map only when the side column
    /// shows another panel).
    pub fn compute(area: Rect, side: SidePanel, table: bool) -> Areas {
        let wide = area.width >= WIDE_MIN.0 && area.height >= WIDE_MIN.1;
        let log_h = if wide { 7 } else { 2 };
        let [status, body, log, bottom] = Layout::vertical([
            Constraint::Length(1),
            Constraint::Min(3),
            Constraint::Length(log_h),
            Constraint::Length(1),
        ])
        .areas(area);
        let frame = Areas {
            status,
            cards: None,
            waypoints: None,
            routes: None,
            table: None,
            map: Rect::default(),
            log,
            bottom,
            wide,
        };
        if wide {
            frame.with_wide_body(body, table)
        } else if table {
            frame.with_small_table_body(body, side)
        } else {
            frame.with_small_body(body, side)
        }
    }

    /// Everything at once: the cards (or the table, over the map too), the
    /// map, and the waypoints over the routing table on the right.
    fn with_wide_body(self, body: Rect, table: bool) -> Areas {
        let right_w = (body.width / 4).clamp(36, 56);
        let left_w = (body.width / 4).clamp(40, 56);
        let [left, map, right] = Layout::horizontal([
            Constraint::Length(left_w),
            Constraint::Min(10),
            Constraint::Length(right_w),
        ])
        .areas(body);
        let [waypoints, routes] =
            Layout::vertical([Constraint::Percentage(40), Constraint::Percentage(60)]).areas(right);
        let (cards, table, map) = if table {
            let [both, _] =
                Layout::horizontal([Constraint::Min(10), Constraint::Length(right_w)]).areas(body);
            (None, Some(both), Rect::default())
        } else {
            (Some(left), None, map)
        };
        Areas {
            cards,
            waypoints: Some(waypoints),
            routes: Some(routes),
            table,
            map,
            ..self
        }
    }

    /// A small terminal in the table view: the table alone, or beside the
    /// side column when it shows the waypoints or the routing table.
    fn with_small_table_body(self, body: Rect, side: SidePanel) -> Areas {
        let (waypoints, routes, table) = match side {
            SidePanel::Cards => (None, None, body),
            other => {
                let [left, rest] = Layout::horizontal([
                    Constraint::Length(side_width(body.width, other)),
                    Constraint::Min(10),
                ])
                .areas(body);
                if other == SidePanel::Routes {
                    (None, Some(left), rest)
                } else {
                    (Some(left), None, rest)
                }
            }
        };
        Areas {
            waypoints,
            routes,
            table: Some(table),
            ..self
        }
    }

    /// A small terminal: the side column (one panel) beside the map.
    fn with_small_body(self, body: Rect, side: SidePanel) -> Areas {
        let [left, map] = Layout::horizontal([
            Constraint::Length(side_width(body.width, side)),
            Constraint::Min(10),
        ])
        .areas(body);
        let (cards, waypoints, routes) = match side {
            SidePanel::Cards => (Some(left), None, None),
            SidePanel::Waypoints => (None, Some(left), None),
            SidePanel::Routes => (None, None, Some(left)),
        };
        Areas {
            cards,
            waypoints,
            routes,
            map,
            ..self
        }
    }

    /// The map's drawing area (inside its border).
    pub fn map_inner(&self) -> Rect {
        inner(self.map)
    }
}

/// The side column's width on a small terminal `width` columns wide: the
/// routing table needs more, for its channel columns.
fn side_width(width: u16, side: SidePanel) -> u16 {
    if side == SidePanel::Routes {
        (width / 2).clamp(20, 44)
    } else {
        (width * 2 / 5).clamp(20, 40)
    }
}

/// A rectangle minus a one-cell border.
pub fn inner(r: Rect) -> Rect {
    Rect {
        x: r.x.saturating_add(1),
        y: r.y.saturating_add(1),
        width: r.width.saturating_sub(2),
        height: r.height.saturating_sub(2),
    }
}

/// Which part of the routing table is visible: the cursor is always in
/// view. Shared by drawing and click handling.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TableWindow {
    pub first_col: usize,
    pub cols: usize,
    pub first_row: usize,
    pub rows: usize,
}

impl TableWindow {
    /// The window for a table of `n_cols` channel columns in `inner`, with
    /// the cursor at (robot row, channel column) `cursor`.
    pub fn new(cursor: (usize, usize), inner: Rect, n_cols: usize) -> TableWindow {
        let cols = (usize::from(inner.width).saturating_sub(ROUTE_NAME_W + 1) / ROUTE_COL_W).max(1);
        let first_col = cursor
            .1
            .saturating_sub(cols - 1)
            .min(n_cols.saturating_sub(1));
        let rows = usize::from(inner.height).saturating_sub(1 + 2).max(1);
        let first_row = cursor.0.saturating_sub(rows - 1);
        TableWindow {
            first_col,
            cols,
            first_row,
            rows,
        }
    }

    /// The (robot row, channel column) under a cell of `inner`, if any.
    pub fn cell_at(&self, inner: Rect, col: u16, row: u16) -> Option<(usize, usize)> {
        let dy = usize::from(row.checked_sub(inner.y)?);
        let dx = usize::from(col.checked_sub(inner.x)?);
        if dy == 0 || dy > self.rows || dx < ROUTE_NAME_W + 1 {
            return None;
        }
        let c = (dx - ROUTE_NAME_W - 1) / ROUTE_COL_W;
        (c < self.cols).then_some((self.first_row + dy - 1, self.first_col + c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_terminal_shares_the_side_column() {
        let a = Areas::compute(Rect::new(0, 0, 80, 24), SidePanel::Routes, false);
        assert!(!a.wide);
        assert!(a.cards.is_none() && a.waypoints.is_none());
        assert!(a.routes.is_some());
        assert!(a.map.width >= 40 && a.map.height >= 18);
    }

    #[test]
    fn large_terminal_shows_everything() {
        let a = Areas::compute(Rect::new(0, 0, 160, 48), SidePanel::Cards, false);
        assert!(a.wide);
        assert!(a.cards.is_some() && a.waypoints.is_some() && a.routes.is_some());
        assert!(a.table.is_none());
    }

    #[test]
    fn the_table_takes_the_cards_and_the_map() {
        let body = |a: &Areas| a.table.expect("the table shown");
        let a = Areas::compute(Rect::new(0, 0, 200, 50), SidePanel::Cards, true);
        assert!(a.cards.is_none() && a.map.is_empty());
        assert_eq!((body(&a).x, body(&a).width), (0, 150));
        assert!(a.routes.is_some() && a.waypoints.is_some(), "routing stays");
        let a = Areas::compute(Rect::new(0, 0, 80, 24), SidePanel::Cards, true);
        assert_eq!(body(&a).width, 80, "small: the whole width");
        let a = Areas::compute(Rect::new(0, 0, 80, 24), SidePanel::Routes, true);
        assert!(a.routes.is_some());
        assert_eq!(body(&a).width, 40, "small: beside the routing table");
    }
}
