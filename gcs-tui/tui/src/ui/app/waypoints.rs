//! The waypoint list being edited (in mission order) and placing mode, in
//! which clicks on the map add waypoints; adding (at most a mission's
//! worth), and sending the list to the selected robots, saying which of
//! them will not follow it until routed to the mission's channel (and
//! offering the command that routes them in the command line's history).

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
            robots: robots.clone(),
            waypoints: self.waypoints.list.clone(),
        });
        let views: Vec<_> = robots
            .iter()
            .filter_map(|r| self.robot(r).cloned())
            .collect();
        self.history.mission_sent(&views, &self.waypoints.list);
        self.offer_mission_route(&robots);
    }

    /// A robot runs a mission only while routed to its channel: for those
    /// of `robots` routed elsewhere (or to none) the event log says so, and
    /// the route that makes them follow it waits in the command line's
    /// history (`:` then ↑, Enter), without taking the keyboard.
    fn offer_mission_route(&mut self, robots: &[String]) {
        let elsewhere: Vec<(String, String)> = robots
            .iter()
            .filter_map(|name| {
                let r = self.robot(name)?;
                (r.route.channel != WAYPOINT_CHANNEL).then(|| {
                    let now = match r.route.channel.as_str() {
                        "" => "none".to_string(),
                        c => c.to_string(),
                    };
                    (name.clone(), now)
                })
            })
            .collect();
        if elsewhere.is_empty() {
            return;
        }
        for (name, now) in &elsewhere {
            self.log(
                LogLevel::Warn,
                format!(
                    "{name} is routed to {now}: it follows these waypoints only once \
                     routed to {WAYPOINT_CHANNEL} (:route {name} {WAYPOINT_CHANNEL})"
                ),
            );
        }
        let names: Vec<&str> = elsewhere.iter().map(|(n, _)| n.as_str()).collect();
        let line = format!("route {} {WAYPOINT_CHANNEL}", self.route_target(&names));
        self.log(
            LogLevel::Info,
            format!("`:` then ↑ brings `{line}`: Enter runs it"),
        );
        self.prompt.offer_command(&line);
    }

    /// One target naming exactly `robots`: the robot, a cluster whose
    /// members they are, `all` for the whole fleet; else the first robot
    /// (the log names every one).
    fn route_target(&self, robots: &[&str]) -> String {
        if let [one] = robots {
            return (*one).to_string();
        }
        let same = |members: &[String]| {
            members.len() == robots.len() && robots.iter().all(|r| members.iter().any(|m| m == r))
        };
        if let Some(c) = self.fleet.clusters.iter().find(|c| same(&c.members)) {
            return c.name.clone();
        }
        let fleet: Vec<String> = self.fleet.robots.iter().map(|r| r.name.clone()).collect();
        if same(&fleet) {
            return "all".into();
        }
        robots.first().map(|r| (*r).to_string()).unwrap_or_default()
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
