//! The robots as the bridge sees them through the station's telemetry
//! fan-out: the latest sample of each, how often samples arrive, and the
//! goal the bridge last sent it. The bridge knows a robot once its
//! telemetry has arrived; a command for any other name is refused.

use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

use mech_proto::{Mission, Telemetry, Waypoint};

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
        }
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
