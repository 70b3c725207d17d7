//! The waypoint list being edited (in mission order) and placing mode, in
//! which clicks on the map add waypoints; adding (at most a mission's
//! worth), and sending the list to the selected robots.

use mech_proto::Waypoint;

use super::{App, Focus, LogLevel, Request, RobotsView, WAYPOINT_CHANNEL};

/// The waypoint panel's state.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WaypointsState {
    /// Clicks on the map place waypoints.
    pub placing: bool,
    /// Waypoints being edited, in mission order.
    pub list: Vec<Waypoint>,
}

impl WaypointsState {
    /// Adds `w` at the end, unless the list holds a whole mission already;
    /// then why not.
    pub fn add(&mut self, w: Waypoint) -> Result<(), String> {
        if self.list.len() >= mech_proto::MAX_WAYPOINTS {
            return Err(format!(
                "a mission holds at most {} waypoints: ({:.2}, {:.2}) not added",
                mech_proto::MAX_WAYPOINTS,
                w.x,
                w.y
            ));
        }
        self.list.push(w);
        Ok(())
    }

    pub fn remove_last(&mut self) {
        self.list.pop();
    }
}

impl App {
    /// Waypoint mode places waypoints with clicks on the map, so it brings
    /// the map back from the table.
    pub(super) fn set_waypoint_mode(&mut self, on: bool) {
        self.waypoints.placing = on;
        if on {
            self.screen.robots_view = RobotsView::Cards;
            self.screen.set_focus(Focus::Waypoints);
        }
    }

    pub(super) fn add_waypoint(&mut self, w: Waypoint) {
        if let Err(why) = self.waypoints.add(w) {
            self.log(LogLevel::Warn, why);
        }
    }

    /// Asks the station to send the list to each selected robot.
    pub(super) fn send_waypoints(&mut self) {
        if self.waypoints.list.is_empty() {
            self.log(LogLevel::Warn, "no waypoints to send");
            return;
        }
        let robots = self.selected_robots();
        if robots.is_empty() {
            self.log(
                LogLevel::Warn,
                "select a robot or a cluster to send waypoints to",
            );
            return;
        }
        self.log(
            LogLevel::Info,
            format!(
                "mission of {} waypoint(s) -> {} on {WAYPOINT_CHANNEL}",
                self.waypoints.list.len(),
                robots.join(" ")
            ),
        );
        self.outbox.push(Request::Mission {
            robots,
            waypoints: self.waypoints.list.clone(),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_list_holds_at_most_one_mission() {
        let mut w = WaypointsState::default();
        let at = |x| Waypoint {
            x,
            y: 0.0,
            z: 0.0,
            time: None,
        };
        for i in 0..mech_proto::MAX_WAYPOINTS {
            assert!(w.add(at(i as f64)).is_ok());
        }
        let refused = w.add(at(-1.0)).expect_err("one too many");
        assert!(refused.contains("(-1.00, 0.00) not added"), "{refused}");
        assert_eq!(w.list.len(), mech_proto::MAX_WAYPOINTS);
        w.remove_last();
        assert_eq!(
            w.list.last().map(|p| p.x),
            Some((mech_proto::MAX_WAYPOINTS - 2) as f64)
        );
    }
}
