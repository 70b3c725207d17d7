//! Robots of other stations, shown here read-only. A bridge between
//! stations (`mech-zenoh`) hears what another station says about its robots
//! and records it here; this station's router never sees them, so nothing
//! here can drive them. Each is kept under `ROBOT@STATION`
//! ([`remote_name`]) with [`Robot::remote`] naming its station, so it never
//! takes the place of a robot of this station.

use std::net::SocketAddr;
use std::time::Duration;

use mech_proto::{Hello, Telemetry};

use super::{Fleet, Robot, RouteState, Severity};
use crate::event::{LinkAddr, LinkState};

/// The name a robot of another station is shown under: `robot@station`.
pub fn remote_name(robot: &str, station: &str) -> String {
    format!("{robot}@{station}")
}

impl Fleet {
    /// The entry of `robot` of `station`, made on the first word of it;
    /// `None` if one of this station's robots has that name already.
    fn remote_entry(&mut self, station: &str, robot: &str) -> Option<&mut Robot> {
        let name = remote_name(robot, station);
        let nowhere = LinkAddr::Udp(SocketAddr::from(([0, 0, 0, 0], 0)));
        let r = self.robots.entry(name.clone()).or_insert_with(|| {
            let mut r = Robot::new(&name, 0, nowhere);
            r.remote = Some(station.to_string());
            r.link = LinkState::Lost;
            r
        });
        (r.remote.as_deref() == Some(station)).then_some(r)
    }

    /// Records a remote robot's registration: the id its station's router
    /// gave it and its [`Hello`] as that station publishes it. Returns
    /// `false` (nothing changed) when its name belongs to one of this
    /// station's robots.
    pub fn remote_info(&mut self, station: &str, robot: &str, id: u16, hello: &Hello) -> bool {
        let Some(r) = self.remote_entry(station, robot) else {
            return false;
        };
        r.registration.id = id;
        r.registration.hello.clone_from(hello);
        true
    }

    /// Records a remote robot's telemetry, received at router time `at`
    /// (pose, state and trail as for this station's robots).
    pub fn remote_telemetry(
        &mut self,
        station: &str,
        robot: &str,
        telemetry: &Telemetry,
        at: Duration,
    ) -> bool {
        if self.remote_entry(station, robot).is_none() {
            return false;
        }
        self.now = self.now.max(at);
        self.telemetry(&remote_name(robot, station), telemetry, at);
        true
    }

    /// Records a remote robot's link state as its station reports it (or
    /// `Lost` when it, or its station, left the network); a change is
    /// logged.
    pub fn remote_link(&mut self, station: &str, robot: &str, state: LinkState) -> bool {
        let Some(r) = self.remote_entry(station, robot) else {
            return false;
        };
        let changed = r.link != state;
        r.link = state;
        if changed {
            let severity = if state == LinkState::Lost {
                Severity::Warn
            } else {
                Severity::Info
            };
            let name = remote_name(robot, station);
            self.log(severity, format!("{name} link {} (remote)", state.as_str()));
        }
        true
    }

    /// Records a remote robot's route as its station reports it.
    pub fn remote_route(&mut self, station: &str, robot: &str, route: RouteState) -> bool {
        let Some(r) = self.remote_entry(station, robot) else {
            return false;
        };
        r.route = route;
        true
    }

    /// Records whether another station is on the network; when it is lost,
    /// so is every robot of it. A change is logged.
    pub fn remote_station(&mut self, station: &str, state: LinkState) {
        let before = self.stations.insert(station.to_string(), state);
        if state == LinkState::Lost {
            let robots: Vec<String> = self
                .robots
                .values()
                .filter(|r| r.remote.as_deref() == Some(station) && r.link != LinkState::Lost)
                .map(|r| r.name.clone())
                .collect();
            for name in robots {
                if let Some(r) = self.robots.get_mut(&name) {
                    r.link = LinkState::Lost;
                }
            }
        }
        if before != Some(state) {
            let severity = if state == LinkState::Lost {
                Severity::Warn
            } else {
                Severity::Info
            };
            self.log(severity, format!("station {station} {}", state.as_str()));
        }
    }

    /// Robots of `station` shown here.
    pub fn robots_of(&self, station: &str) -> impl Iterator<Item = &Robot> {
        self.robots
            .values()
            .filter(move |r| r.remote.as_deref() == Some(station))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fleet::FleetConfig;

    fn info() -> Hello {
        Hello {
            name: "robot_1".into(),
            platform: "kiwi".into(),
            capabilities: vec![mech_proto::CommandKind::Twist],
            motors: 3,
            max_speed: 1.0,
            max_yaw_rate: 2.0,
            agent_version: String::new(),
        }
    }

    #[test]
    fn remote_robots_are_kept_apart_and_left_out_of_all() {
        let mut f = Fleet::new(FleetConfig::default());
        assert!(f.remote_info("site-b", "robot_1", 3, &info()));
        assert!(f.remote_link("site-b", "robot_1", LinkState::Connected));
        let r = f.robot("robot_1@site-b").unwrap();
        assert_eq!(r.remote.as_deref(), Some("site-b"));
        assert_eq!(
            (r.registration.hello.platform.as_str(), r.registration.id),
            ("kiwi", 3)
        );
        assert!(!r.is_local());
        assert_eq!(f.resolve("all").unwrap(), Vec::<String>::new());
        assert_eq!(
            f.resolve("robot_1@site-b").unwrap(),
            vec!["robot_1@site-b".to_string()]
        );
        assert_eq!(f.robots_of("site-b").count(), 1);
    }

    #[test]
    fn a_local_robot_keeps_its_name() {
        let mut f = Fleet::new(FleetConfig::default());
        let addr = SocketAddr::from(([127, 0, 0, 1], 9000));
        f.robots
            .insert("a@b".into(), Robot::new("a@b", 1, LinkAddr::Udp(addr)));
        assert!(!f.remote_info("b", "a", 3, &info()));
        assert!(f.robot("a@b").unwrap().is_local());
        assert_eq!(f.robot("a@b").unwrap().registration.hello.platform, "");
    }

    #[test]
    fn a_lost_station_loses_its_robots_and_says_so_once() {
        let mut f = Fleet::new(FleetConfig::default());
        f.remote_station("site-b", LinkState::Connected);
        for r in ["r1", "r2"] {
            f.remote_link("site-b", r, LinkState::Connected);
        }
        f.remote_link("site-c", "r1", LinkState::Connected);
        let lines = f.log.len();
        f.remote_station("site-b", LinkState::Lost);
        f.remote_station("site-b", LinkState::Lost);
        assert_eq!(f.log.len(), lines + 1, "one line for the change");
        assert!(f.log.back().unwrap().text.contains("site-b lost"));
        assert!(f.robots_of("site-b").all(|r| r.link == LinkState::Lost));
        assert_eq!(
            f.robot("r1@site-c").unwrap().link,
            LinkState::Connected,
            "another station's robots are not touched"
        );
        assert_eq!(f.stations["site-b"], LinkState::Lost);
    }

    #[test]
    fn remote_telemetry_moves_the_robot_and_its_trail() {
        let mut f = Fleet::new(FleetConfig::default());
        let t = Telemetry {
            pose: mech_proto::Pose {
                x: 2.0,
                y: 1.0,
                z: 0.0,
                heading: 0.3,
            },
            velocity: Default::default(),
            velocity_source: Default::default(),
            safety: None,
            mode: mech_proto::ControlMode::Twist,
            channel: "ext/x".into(),
            computation: Default::default(),
            failsafe: Default::default(),
            health: Default::default(),
            battery: None,
            position_quality: 1.0,
            actuators: vec![],
            mission: None,
            stale: 0,
        };
        assert!(f.remote_telemetry("site-b", "r1", &t, Duration::from_secs(2)));
        let r = f.robot("r1@site-b").unwrap();
        assert_eq!((r.telemetry.pose.x, r.telemetry.pose.y), (2.0, 1.0));
        assert_eq!(r.reported_channel(), Some("ext/x"));
        assert_eq!(r.path.len(), 1);
        assert_eq!(r.last_telemetry, Some(Duration::from_secs(2)));
    }
}
