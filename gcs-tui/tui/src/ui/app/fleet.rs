//! The fleet as this screen holds it: the robots (in natural name order:
//! `robot_2` before `robot_10`), the live channels, the clusters (as the
//! station reports them, and those made here until it does) with the one a
//! pad in cluster mode drives, the fleet e-stop, the station's security and
//! refusals, its arena, and a replay's clock. Taking a station's snapshot, making a
//! cluster from the selection and switching the selected robots'
//! navigation are here too.

use super::{App, LogLevel, Request};
use crate::ui::view::{
    ArenaBounds, ArenaShape, ChannelView, ClusterOnScreen, FleetSnapshot, ReplayClock, RobotView,
    Security,
};
use mech_core::names::natural_cmp;

/// What the station last reported, as the screen shows it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FleetState {
    pub robots: Vec<RobotView>,
    pub channels: Vec<ChannelView>,
    pub clusters: Vec<ClusterOnScreen>,
    /// Cluster a pad in cluster mode drives (the last one made or selected).
    pub active_cluster: Option<String>,
    /// Fleet-wide e-stop engaged (requested here or reported by the core).
    pub estop: bool,
    /// Whether the station checks signatures (shown in the status bar).
    pub security: Security,
    /// Messages the station refused, as last reported.
    pub rejected: u64,
    /// A replay's clock, when the TUI shows a recording.
    pub replay: Option<ReplayClock>,
    /// The station's arena (boundary, keep-outs, slow zones, obstacles),
    /// when it has one.
    pub arena: Option<ArenaShape>,
}

impl FleetState {
    pub fn robot(&self, name: &str) -> Option<&RobotView> {
        self.index_of(name).map(|i| &self.robots[i])
    }

    /// Robot `name`'s place in the fleet (its colour, its card). The robots
    /// are in natural name order ([`FleetState::apply`]), an order that
    /// agrees with equality, so a binary search finds it (a cluster of a
    /// thousand members is drawn without a thousand scans of the fleet);
    /// a list put in another order is scanned.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        match self.robots.binary_search_by(|r| natural_cmp(&r.name, name)) {
            Ok(i) => Some(i),
            Err(_) => self.robots.iter().position(|r| r.name == name),
        }
    }

    /// The robots named `names`, in that order (names not in the fleet
    /// left out). Each name is tried first just after the robot found
    /// before it: a cluster made from a selection lists its members in
    /// fleet order, so a thousand members cost a thousand comparisons,
    /// not a thousand searches (the map draws every cluster each frame).
    /// Any other order falls back to [`FleetState::index_of`].
    pub fn robots_named<'a, I>(&'a self, names: I) -> impl Iterator<Item = &'a RobotView> + 'a
    where
        I: IntoIterator<Item = &'a String>,
        I::IntoIter: 'a,
    {
        let mut next = 0;
        names.into_iter().filter_map(move |name| {
            let i = match self.robots.get(next) {
                Some(r) if r.name == *name => next,
                _ => self.index_of(name)?,
            };
            next = i + 1;
            Some(&self.robots[i])
        })
    }

    /// Takes the station's state as it is: the e-stop, robots (sorted),
    /// channels, the arena and (when the source keeps them) clusters.
    pub fn apply(&mut self, s: FleetSnapshot) {
        self.estop = s.estop;
        self.arena = s.arena;
        self.security = s.security;
        self.rejected = s.rejected;
        self.replay = s.replay;
        self.robots = s.robots;
        // Already in order from the station: a stable sort then costs one
        // comparison per robot.
        self.robots.sort_by(|a, b| natural_cmp(&a.name, &b.name));
        self.channels = s.channels;
        if let Some(c) = s.clusters {
            self.clusters = c;
        }
    }

    /// The first free cluster name: `c1`, `c2`...
    fn next_cluster_name(&self) -> String {
        let mut n = self.clusters.len() + 1;
        while self.clusters.iter().any(|c| c.name == format!("c{n}")) {
            n += 1;
        }
        format!("c{n}")
    }
}

impl App {
    /// Takes the station's state (and a sample of it for the plots, on the
    /// replay's clock in a replay); keeps only the selected robots that are
    /// still there, and fits the map once, to the first robots that
    /// reported where they are (a robot that registered has no position
    /// until its first telemetry, and reads as the origin).
    pub(super) fn apply_snapshot(&mut self, s: FleetSnapshot) {
        let placed = s
            .robots
            .iter()
            .any(|r| r.telemetry.pose.x != 0.0 || r.telemetry.pose.y != 0.0);
        let t = match s.replay {
            Some(clock) => clock.at,
            None => self.history.live_time(self.manual.now),
        };
        self.fleet.apply(s);
        self.history.record(t, &self.fleet.robots);
        // The station's arena is the map's outline (and what it fits to).
        if let Some([min_x, min_y, max_x, max_y]) =
            self.fleet.arena.as_ref().and_then(|a| a.bounds())
        {
            self.map.arena = Some(ArenaBounds {
                min_x,
                min_y,
                max_x,
                max_y,
            });
        }
        let fleet = &self.fleet;
        self.cards
            .selection
            .retain(|n| fleet.robots.iter().any(|r| &r.name == n));
        self.refresh_rows();
        if placed && self.map.first_fit() {
            self.fit_fleet();
        }
    }

    /// A cluster of the selected robots (two at least), named `c<n>`, made
    /// the active one and asked of the station.
    pub(super) fn make_cluster(&mut self) {
        let members = self.selected_robots();
        if members.len() < 2 {
            self.log(
                LogLevel::Warn,
                "select at least two robots to make a cluster",
            );
            return;
        }
        let name = self.fleet.next_cluster_name();
        self.log(
            LogLevel::Info,
            format!("cluster {name}: {}", members.join(" ")),
        );
        self.outbox.push(Request::DefineCluster {
            name: name.clone(),
            members: members.clone(),
        });
        self.fleet.clusters.push(ClusterOnScreen {
            name: name.clone(),
            members,
            control: None,
        });
        self.fleet.active_cluster = Some(name);
    }

    /// Asks the station to move the selected robots' waypoint navigation
    /// to the other side (onboard <-> offboard).
    pub(super) fn toggle_nav(&mut self) {
        let robots = self.selected_robots();
        if robots.is_empty() {
            self.log(
                LogLevel::Warn,
                "select a robot to switch onboard/offboard navigation",
            );
            return;
        }
        self.log(
            LogLevel::Info,
            format!("navigation onboard/offboard switch: {}", robots.join(" ")),
        );
        self.outbox.push(Request::ToggleNav { robots });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn snapshot(names: &[&str]) -> FleetSnapshot {
        FleetSnapshot {
            robots: names
                .iter()
                .map(|n| RobotView::at(n, 1, "kiwi", 0.0, 0.0, 0.0))
                .collect(),
            ..FleetSnapshot::default()
        }
    }

    #[test]
    fn robots_are_kept_in_natural_name_order_and_clusters_only_when_reported() {
        let mut f = FleetState::default();
        f.clusters.push(ClusterOnScreen {
            name: "c1".into(),
            members: vec!["robot_2".into()],
            control: None,
        });
        f.apply(snapshot(&["robot_10", "robot_2", "robot_1"]));
        let names: Vec<&str> = f.robots.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(names, ["robot_1", "robot_2", "robot_10"]);
        assert_eq!(f.index_of("robot_10"), Some(2));
        assert_eq!(f.clusters.len(), 1, "a source without clusters keeps ours");
        assert_eq!(f.next_cluster_name(), "c2");
        f.apply(FleetSnapshot {
            clusters: Some(Vec::new()),
            ..snapshot(&[])
        });
        assert!(f.clusters.is_empty());
        assert_eq!(f.next_cluster_name(), "c1");
    }

    /// A fleet of `robot_1`..`robot_n`, and their names in fleet order.
    fn fleet_of(n: usize) -> (FleetState, Vec<String>) {
        let mut f = FleetState::default();
        let names: Vec<String> = (1..=n).map(|i| format!("robot_{i}")).collect();
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        f.apply(snapshot(&refs));
        (f, names)
    }

    #[test]
    fn a_robot_is_found_by_name_in_order_or_out_of_it() {
        let (mut f, names) = fleet_of(300);
        for (i, n) in names.iter().enumerate() {
            assert_eq!(f.index_of(n), Some(i));
            assert_eq!(f.robot(n).map(|r| r.name.as_str()), Some(n.as_str()));
        }
        assert_eq!(f.index_of("robot_0"), None);
        assert_eq!(
            f.index_of("robot_01"),
            None,
            "equal by value is not the name"
        );
        // A list someone put out of order is still searched in full.
        f.robots.reverse();
        assert_eq!(f.index_of("robot_1"), Some(299));
        assert_eq!(f.index_of("robot_150"), Some(150));
        assert_eq!(f.index_of("robot_301"), None);
    }

    #[test]
    fn cluster_members_are_found_in_their_order_whatever_it_is() {
        let (f, names) = fleet_of(12);
        let found = |members: &[&str]| -> Vec<String> {
            let members: Vec<String> = members.iter().map(|m| m.to_string()).collect();
            f.robots_named(&members).map(|r| r.name.clone()).collect()
        };
        // In fleet order, with gaps, out of order, repeated, and missing.
        let cases: [&[&str]; 4] = [
            &["robot_1", "robot_2", "robot_3"],
            &["robot_2", "robot_9", "robot_10", "robot_12"],
            &["robot_12", "robot_1", "robot_7", "robot_7", "robot_3"],
            &["robot_5", "robot_13", "robot_01", "robot_6"],
        ];
        for members in cases {
            let expected: Vec<&str> = members
                .iter()
                .copied()
                .filter(|m| names.iter().any(|n| n == m))
                .collect();
            assert_eq!(found(members), expected);
        }
    }
}
