//! The mouse on the App: a click, drag, wheel or hover resolved against
//! the same layout the screen was drawn with (map, cards, fleet table,
//! waypoints, routing table).

use mech_proto::Waypoint;
use ratatui::layout::Position;

use super::{App, Focus, Select};
use crate::ui::columns;
use crate::ui::layout::{TableWindow, inner};
use crate::ui::view::RobotView;

impl App {
    /// The robot drawn at (or next to) an absolute terminal cell of the map.
    pub fn robot_at_cell(&self, col: u16, row: u16) -> Option<&RobotView> {
        let inner = self.areas().map_inner();
        if !inner.contains(Position::new(col, row)) {
            return None;
        }
        let p = self.map.viewport.project(inner.width, inner.height);
        let (cx, cy) = (col - inner.x, row - inner.y);
        let (wx, wy) = p.cell_to_world(cx, cy);
        self.fleet
            .robots
            .iter()
            .filter_map(|r| {
                let (rc, rr) = p.world_to_cell(r.telemetry.pose.x, r.telemetry.pose.y)?;
                (rc.abs_diff(cx) <= 1 && rr.abs_diff(cy) <= 1)
                    .then(|| ((r.telemetry.pose.x - wx).hypot(r.telemetry.pose.y - wy), r))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, r)| r)
    }

    /// World point (m) under an absolute terminal cell of the map.
    pub fn map_point(&self, col: u16, row: u16) -> Option<(f64, f64)> {
        let inner = self.areas().map_inner();
        if !inner.contains(Position::new(col, row)) {
            return None;
        }
        let p = self.map.viewport.project(inner.width, inner.height);
        Some(p.cell_to_world(col - inner.x, row - inner.y))
    }

    pub(super) fn click(&mut self, col: u16, row: u16, add: bool) {
        let areas = self.areas();
        let pos = Position::new(col, row);
        if areas.map_inner().contains(pos) {
            self.screen.focus = Focus::Map;
            if self.waypoints.placing {
                if let Some((x, y)) = self.map_point(col, row) {
                    self.add_waypoint(Waypoint {
                        x,
                        y,
                        z: 0.0,
                        time: None,
                    });
                }
                return;
            }
            match self.robot_at_cell(col, row).map(|r| r.name.clone()) {
                Some(name) if add => self.select(Select::Toggle(name)),
                Some(name) => self.select(Select::Only(name)),
                None if !add => self.map.start_drag(col, row),
                None => {}
            }
            return;
        }
        if let Some(table) = areas.table.filter(|a| a.contains(pos)) {
            self.screen.set_focus(Focus::Cards);
            self.click_table(inner(table), col, row, add);
            return;
        }
        if let Some(cards) = areas.cards.filter(|a| a.contains(pos)) {
            self.screen.focus = Focus::Cards;
            let inner = inner(cards);
            if row < inner.y {
                return;
            }
            let i = self.cards.scroll + usize::from(row - inner.y) / self.card_height();
            if let Some(name) = self.fleet.robots.get(i).map(|r| r.name.clone()) {
                self.select(if add {
                    Select::Toggle(name)
                } else {
                    Select::Only(name)
                });
            }
            return;
        }
        if areas.waypoints.is_some_and(|a| a.contains(pos)) {
            self.screen.set_focus(Focus::Waypoints);
        } else if let Some(routes) = areas.routes.filter(|a| a.contains(pos)) {
            self.screen.set_focus(Focus::Routes);
            let inner = inner(routes);
            let cols = self.route_columns().len();
            let w = TableWindow::new(self.routes.cursor, inner, cols);
            if let Some((r, c)) = w.cell_at(inner, col, row) {
                if r < self.fleet.robots.len() && c < cols {
                    // A click picks the cell; a click on the picked cell routes.
                    if self.routes.cursor == (r, c) {
                        self.apply_route_cursor();
                    } else {
                        self.routes.cursor = (r, c);
                    }
                }
            }
        }
    }

    /// A click in the table: on the header, sorts by that column; on a row,
    /// selects its robot (`add`: adds or removes it).
    fn click_table(&mut self, inner: ratatui::layout::Rect, col: u16, row: u16, add: bool) {
        if self.table.detail || row < inner.y || col < inner.x {
            return;
        }
        let (shown, trend) = columns::layout(usize::from(inner.width), self.table.sort);
        if row == inner.y {
            if let Some(c) = columns::column_at(&shown, trend, usize::from(col - inner.x)) {
                self.sort_by(c);
            }
            return;
        }
        let at = self.table.scroll + usize::from(row - inner.y - 1);
        if let Some(name) = self
            .table
            .rows
            .get(at)
            .map(|&i| self.fleet.robots[i].name.clone())
        {
            self.select(if add {
                Select::Toggle(name)
            } else {
                Select::Only(name)
            });
        }
    }

    /// The pointer over the map: the robot under it is labelled whatever
    /// the crowd around it.
    pub(super) fn hover(&mut self, col: u16, row: u16) {
        self.map.hover = self.robot_at_cell(col, row).map(|r| r.name.clone());
    }

    pub(super) fn scroll(&mut self, col: u16, row: u16, steps: i32) {
        let factor = 1.25f64.powi(steps);
        let over_table = self
            .areas()
            .table
            .is_some_and(|a| a.contains(Position::new(col, row)));
        if over_table {
            self.scroll_table(-3 * steps);
            return;
        }
        match self.map_point(col, row) {
            Some((x, y)) => self.map.viewport.zoom_about(factor, x, y),
            None => {
                let over_cards = self
                    .areas()
                    .cards
                    .is_some_and(|a| a.contains(Position::new(col, row)));
                if over_cards {
                    self.cards.wheel(steps, self.fleet.robots.len());
                }
            }
        }
    }
}
