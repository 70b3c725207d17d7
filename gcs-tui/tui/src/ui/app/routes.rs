//! The routing table's state: its cursor (robot row, channel column); its
//! channel columns, and re-routing a robot from it or from a request.

use super::{App, LogLevel, Request, WAYPOINT_CHANNEL};

/// The routing-table panel's state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RoutesState {
    /// Robot row, channel column.
    pub cursor: (usize, usize),
}

impl RoutesState {
    /// Moves the cursor by rows and columns in a table of `rows` x `cols`,
    /// wrapping around at the edges.
    pub fn move_cursor(&mut self, dr: i32, dc: i32, rows: usize, cols: usize) {
        let rows = rows.max(1) as i64;
        let cols = cols.max(1) as i64;
        let r = (self.cursor.0 as i64 + i64::from(dr)).rem_euclid(rows);
        let c = (self.cursor.1 as i64 + i64::from(dc)).rem_euclid(cols);
        self.cursor = (r as usize, c as usize);
    }
}

impl App {
    /// Channel columns of the routing table: none, every live channel, the
    /// waypoint and keyboard channels, and any channel a robot is routed to.
    pub fn route_columns(&self) -> Vec<String> {
        let mut cols: Vec<String> = vec![String::new()];
        let mut push = |c: &str| {
            if !cols.iter().any(|x| x == c) {
                cols.push(c.to_string());
            }
        };
        push(WAYPOINT_CHANNEL);
        push(&self.manual.key_channel);
        for p in self.manual.pads.pads() {
            push(&p.channel());
        }
        for c in &self.fleet.channels {
            push(&c.name);
        }
        for r in &self.fleet.robots {
            if !r.route.channel.is_empty() {
                push(&r.route.channel);
            }
        }
        cols
    }

    pub(super) fn move_route_cursor(&mut self, dr: i32, dc: i32) {
        let (rows, cols) = (self.fleet.robots.len(), self.route_columns().len());
        self.routes.move_cursor(dr, dc, rows, cols);
    }

    /// Routes the robot under the cursor to the channel under it.
    pub(super) fn apply_route_cursor(&mut self) {
        let cols = self.route_columns();
        let (row, col) = self.routes.cursor;
        if let (Some(r), Some(c)) = (self.fleet.robots.get(row), cols.get(col)) {
            let (robot, channel) = (r.name.clone(), c.clone());
            self.route(robot, channel);
        }
    }

    /// Shows `robot` routed to `channel` at once (not acknowledged yet) and
    /// asks the station to route it.
    pub(super) fn route(&mut self, robot: String, channel: String) {
        let Some(i) = self.fleet.index_of(&robot) else {
            self.log(LogLevel::Error, format!("no robot named {robot}"));
            return;
        };
        let shown = if channel.is_empty() { "none" } else { &channel };
        self.log(LogLevel::Info, format!("route {robot} -> {shown}"));
        let r = &mut self.fleet.robots[i];
        r.route.channel = channel.clone();
        r.route.acknowledged = false;
        self.outbox.push(Request::Route { robot, channel });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cursor_wraps_around_both_ways() {
        let mut r = RoutesState::default();
        r.move_cursor(-1, -1, 3, 4);
        assert_eq!(r.cursor, (2, 3));
        r.move_cursor(1, 2, 3, 4);
        assert_eq!(r.cursor, (0, 1));
        r.move_cursor(5, 0, 0, 0);
        assert_eq!(r.cursor, (0, 0), "an empty table keeps the cursor home");
    }
}
