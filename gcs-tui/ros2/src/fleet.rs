//! The robots as the bridge sees them through the station's telemetry
//! fan-out: the latest sample of each, how often samples arrive, and the
//! goal the bridge last sent it. The bridge knows a robot once its
//! telemetry has arrived; a command for any other name is refused.

use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

use mech_proto::{FailsafeState, Mission, Telemetry, Waypoint};

/// Whether `name` can be a ROS 2 namespace token, so `/<name>/odom` is a
/// topic: letters, digits and underscores, not starting with a digit, no
/// `__` (ROS 2 reserves it). MECH names allow more (`px4-1`); such robots
/// are not bridged.
pub fn ros_name_ok(name: &str) -> bool {
    let mut chars = name.chars();
    let Some(first) = chars.next() else {
        return false;
    };
    (first.is_ascii_alphabetic() || first == '_')
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !name.contains("__")
}

/// A goal sent as a mission: resent until its robot acknowledges it.
#[derive(Debug, Clone, PartialEq)]
pub struct Goal {
    pub mission: Mission,
    pub channel: String,
    pub first_sent: Instant,
    pub last_sent: Instant,
    /// The robot answered MissionAck: accepted or not, with its reason.
    pub ack: Option<(bool, String)>,
    /// Given up: no acknowledgement in time.
    pub unacked: bool,
}

impl Goal {
    /// The goal's only waypoint.
    pub fn waypoint(&self) -> Option<Waypoint> {
        self.mission.waypoints.first().copied()
    }
}

/// One robot.
#[derive(Debug, Clone)]
pub struct Robot {
    pub telemetry: Telemetry,
    /// The robot's own stamp on its latest sample (µs, station time).
    pub stamp_us: u64,
    pub received: Instant,
    /// When the last samples arrived (the last second's), for the rate.
    arrivals: VecDeque<Instant>,
    pub goal: Option<Goal>,
    /// cmd_vel samples forwarded for it.
    pub cmd_forwarded: u64,
}

impl Robot {
    /// Samples that arrived in the last second (the one that arrived a
    /// second ago exactly is not counted).
    pub fn rate_hz(&self, now: Instant) -> usize {
        self.arrivals
            .iter()
            .filter(|t| now.saturating_duration_since(**t) < Duration::from_secs(1))
            .count()
    }

    /// Whether no sample arrived for `after`.
    pub fn stale(&self, now: Instant, after: Duration) -> bool {
        now.saturating_duration_since(self.received) > after
    }
}

/// Goals to send again, and goals given up, at one moment.
#[derive(Debug, Default, PartialEq)]
pub struct GoalsDue {
    /// (robot, channel, mission) to resend.
    pub resend: Vec<(String, String, Mission)>,
    /// (robot, mission id) no longer waited for.
    pub given_up: Vec<(String, u32)>,
}

/// Every robot the bridge has heard of, by name.
#[derive(Debug, Default)]
pub struct Fleet {
    robots: BTreeMap<String, Robot>,
}

impl Fleet {
    /// Takes in a sample; true if the robot is new.
    pub fn update(&mut self, name: &str, t: Telemetry, stamp_us: u64, now: Instant) -> bool {
        if let Some(r) = self.robots.get_mut(name) {
            r.telemetry = t;
            r.stamp_us = stamp_us;
            r.received = now;
            r.arrivals.push_back(now);
            while r
                .arrivals
                .front()
                .is_some_and(|a| now.saturating_duration_since(*a) >= Duration::from_secs(1))
            {
                r.arrivals.pop_front();
            }
            return false;
        }
        self.robots.insert(
            name.to_string(),
            Robot {
                telemetry: t,
                stamp_us,
                received: now,
                arrivals: VecDeque::from([now]),
                goal: None,
                cmd_forwarded: 0,
            },
        );
        true
    }

    pub fn get(&self, name: &str) -> Option<&Robot> {
        self.robots.get(name)
    }

    pub fn get_mut(&mut self, name: &str) -> Option<&mut Robot> {
        self.robots.get_mut(name)
    }

    pub fn knows(&self, name: &str) -> bool {
        self.robots.contains_key(name)
    }

    /// Every robot, in name order.
    pub fn iter(&self) -> impl Iterator<Item = (&String, &Robot)> {
        self.robots.iter()
    }

    /// Every robot, mutably.
    pub fn iter_mut(&mut self) -> impl Iterator<Item = (&String, &mut Robot)> {
        self.robots.iter_mut()
    }

    pub fn len(&self) -> usize {
        self.robots.len()
    }

    /// Whether every robot's latest telemetry says it is e-stopped.
    pub fn all_estopped(&self) -> bool {
        self.robots
            .values()
            .all(|r| r.telemetry.failsafe == FailsafeState::EStopped)
    }

    /// The goals not yet acknowledged: those last sent `retry` ago or more
    /// are due again (and marked sent `now`); those first sent more than
    /// `give_up` ago are given up (and marked so, never due again).
    pub fn goals_due(&mut self, now: Instant, retry: Duration, give_up: Duration) -> GoalsDue {
        let mut due = GoalsDue::default();
        for (name, r) in &mut self.robots {
            let Some(g) = r.goal.as_mut() else { continue };
            if g.ack.is_some() || g.unacked {
                continue;
            }
            if now.saturating_duration_since(g.first_sent) > give_up {
                g.unacked = true;
                due.given_up.push((name.clone(), g.mission.id));
            } else if now.saturating_duration_since(g.last_sent) >= retry {
                g.last_sent = now;
                due.resend
                    .push((name.clone(), g.channel.clone(), g.mission.clone()));
            }
        }
        due
    }

    pub fn is_empty(&self) -> bool {
        self.robots.is_empty()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use mech_proto::{
        Computation, ControlMode, FailsafeState, Health, Pose, Velocity, VelocitySource,
    };

    pub(crate) fn telemetry(x: f64, heading: f64) -> Telemetry {
        Telemetry {
            pose: Pose {
                x,
                y: 0.0,
                z: 0.0,
                heading,
            },
            velocity: Velocity {
                vx: 0.0,
                vy: 0.0,
                vz: 0.0,
                wz: 0.0,
            },
            mode: ControlMode::Idle,
            channel: String::new(),
            computation: Computation::Onboard,
            failsafe: FailsafeState::Ok,
            health: Health::Ok,
            battery: Some(0.8),
            position_quality: 1.0,
            actuators: vec![],
            mission: None,
            stale: 0,
            velocity_source: VelocitySource::Commanded,
            safety: None,
        }
    }

    fn goal(now: Instant) -> Goal {
        Goal {
            mission: Mission {
                id: 5,
                waypoints: vec![Waypoint {
                    x: 1.0,
                    y: 2.0,
                    z: 0.0,
                    time: None,
                }],
                looped: false,
                arrival_radius: 0.1,
                start_index: 0,
            },
            channel: "ros2goal/robot_1".into(),
            first_sent: now,
            last_sent: now,
            ack: None,
            unacked: false,
        }
    }

    #[test]
    fn a_goal_is_resent_until_acknowledged_and_given_up_in_time() {
        let (retry, give_up) = (Duration::from_millis(200), Duration::from_secs(5));
        let t0 = Instant::now();
        let mut f = Fleet::default();
        f.update("robot_1", telemetry(0.0, 0.0), 1, t0);
        f.get_mut("robot_1").unwrap().goal = Some(goal(t0));
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        assert_eq!(
            f.goals_due(at(100), retry, give_up),
            GoalsDue::default(),
            "not yet"
        );
        let due = f.goals_due(at(200), retry, give_up);
        assert_eq!(due.resend.len(), 1);
        assert_eq!(
            (due.resend[0].1.as_str(), due.resend[0].2.id),
            ("ros2goal/robot_1", 5)
        );
        assert!(
            f.goals_due(at(300), retry, give_up).resend.is_empty(),
            "sent at 200 ms"
        );
        assert_eq!(f.goals_due(at(400), retry, give_up).resend.len(), 1);
        let due = f.goals_due(at(5_001), retry, give_up);
        assert_eq!(due.given_up, vec![("robot_1".to_string(), 5)]);
        assert!(due.resend.is_empty());
        assert_eq!(
            f.goals_due(at(6_000), retry, give_up),
            GoalsDue::default(),
            "given up once"
        );

        f.get_mut("robot_1").unwrap().goal = Some(goal(at(6_000)));
        f.get_mut("robot_1").unwrap().goal.as_mut().unwrap().ack = Some((true, String::new()));
        assert_eq!(
            f.goals_due(at(7_000), retry, give_up),
            GoalsDue::default(),
            "acknowledged"
        );
    }

    #[test]
    fn the_fleet_is_estopped_when_every_robot_says_so() {
        let now = Instant::now();
        let mut f = Fleet::default();
        let mut stopped = telemetry(0.0, 0.0);
        stopped.failsafe = FailsafeState::EStopped;
        f.update("robot_1", stopped.clone(), 1, now);
        f.update("robot_2", telemetry(0.0, 0.0), 1, now);
        assert!(!f.all_estopped());
        f.update("robot_2", stopped, 2, now);
        assert!(f.all_estopped());
    }

    #[test]
    fn ros_names_are_tokens() {
        for ok in ["robot_1", "r", "_hidden", "Kiwi2"] {
            assert!(ros_name_ok(ok), "{ok}");
        }
        for bad in ["", "1robot", "px4-1", "a/b", "a__b", "robot 1", "é"] {
            assert!(!ros_name_ok(bad), "{bad}");
        }
    }

    #[test]
    fn robots_are_known_from_their_first_sample_and_rates_are_per_second() {
        let mut f = Fleet::default();
        let t0 = Instant::now();
        assert!(!f.knows("robot_1"));
        assert!(f.update("robot_1", telemetry(0.0, 0.0), 1, t0));
        for i in 1..=20u64 {
            assert!(!f.update(
                "robot_1",
                telemetry(0.1, 0.0),
                1 + i,
                t0 + Duration::from_millis(50 * i)
            ));
        }
        let now = t0 + Duration::from_millis(1000);
        let r = f.get("robot_1").unwrap();
        assert_eq!(r.rate_hz(now), 20, "the samples of the last second");
        assert_eq!(r.telemetry.pose.x, 0.1);
        assert!(!r.stale(now, Duration::from_millis(500)));
        assert!(r.stale(now + Duration::from_secs(2), Duration::from_millis(500)));
        assert_eq!(f.len(), 1);
    }
}
