//! What the bridge publishes on ROS 2, made from the station's telemetry:
//! odometry and transforms ([`odom`]), battery state ([`battery`]),
//! `/diagnostics` ([`diagnostics`]) and rviz2 markers ([`markers`]). Pure
//! functions of the telemetry, the bridge's fleet view and its counters.

pub mod battery;
pub mod diagnostics;
pub mod markers;
pub mod odom;

use std::time::{Duration, Instant};

use crate::config::Ros2Config;
use crate::fleet::Fleet;
use crate::msgs::builtin::Time;
use crate::msgs::diagnostic::DiagnosticStatus;
use crate::msgs::sensor::BatteryState;
use crate::msgs::visualization::Marker;
use crate::station::StationView;
use diagnostics::RobotContext;

/// What goes out once a second for the robots (the bridge adds its own
/// status).
#[derive(Debug, Default)]
pub struct Periodic {
    /// (robot, its battery), stamped with the sample it comes from.
    pub batteries: Vec<(String, BatteryState)>,
    /// One status per robot.
    pub status: Vec<DiagnosticStatus>,
    pub markers: Vec<Marker>,
}

/// The once-a-second messages for `fleet` at `now` (`stamp` on the
/// markers). A robot the station no longer reports (no telemetry for
/// `stale_after`) keeps its STALE status, but its battery is not repeated
/// and its markers are not renewed, so rviz2 drops them.
pub fn periodic(
    fleet: &Fleet,
    station: &StationView,
    config: &Ros2Config,
    now: Instant,
    stamp: Time,
) -> Periodic {
    let stale_after = Duration::from_secs_f64(config.stale_after);
    let map = config.map_frame.as_str();
    let mut out = Periodic::default();
    if let Some(arena) = &station.arena {
        out.markers
            .extend(markers::arena_markers(arena, map, stamp));
    }
    for (i, (name, r)) in fleet.iter().enumerate() {
        let (cmd, goal) = (config.cmd_channel(name), config.goal_channel(name));
        let cx = RobotContext {
            cmd_channel: &cmd,
            goal_channel: &goal,
            now,
            stale_after,
            link: station.robots.get(name),
        };
        out.status.push(diagnostics::robot_status(name, r, cx));
        if r.stale(now, stale_after) {
            continue;
        }
        let frames = Frames::new(map, name);
        let sampled = Time::from_micros(r.stamp_us);
        out.batteries.push((
            name.clone(),
            battery::battery(name, &r.telemetry, sampled, &frames),
        ));
        if let Some(m) = station.missions.get(name) {
            out.markers.extend(markers::mission_markers(
                i as i32,
                m,
                &r.telemetry,
                map,
                stamp,
            ));
        }
        out.markers.extend(markers::robot_markers(
            i as i32,
            name,
            &r.telemetry,
            r.goal.as_ref(),
            map,
            stamp,
        ));
    }
    out
}

/// The frames of one robot (REP 105, one namespace per robot).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frames {
    /// The world frame, `map`.
    pub map: String,
    /// `<robot>/base_link`.
    pub base: String,
}

impl Frames {
    pub fn new(map: &str, robot: &str) -> Frames {
        Frames {
            map: map.to_string(),
            base: format!("{robot}/base_link"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fleet::tests::telemetry;

    #[test]
    fn a_robot_gone_quiet_keeps_its_status_but_no_battery_or_markers() {
        let t0 = Instant::now();
        let mut fleet = Fleet::default();
        fleet.update("robot_1", telemetry(0.0, 0.0), 1_700_000_000_000_000, t0);
        fleet.update("robot_2", telemetry(1.0, 0.0), 1_700_000_000_000_000, t0);
        let later = t0 + Duration::from_millis(1500);
        fleet.update("robot_2", telemetry(1.1, 0.0), 1_700_000_001_500_000, later);
        let config = Ros2Config::default();
        let out = periodic(
            &fleet,
            &StationView::default(),
            &config,
            later,
            Time::default(),
        );
        assert_eq!(out.status.len(), 2);
        assert_eq!(out.status[0].level, crate::msgs::diagnostic::STALE);
        let robots: Vec<&str> = out.batteries.iter().map(|(r, _)| r.as_str()).collect();
        assert_eq!(robots, vec!["robot_2"]);
        assert_eq!(
            out.batteries[0].1.header.stamp,
            Time::from_micros(1_700_000_001_500_000),
            "stamped with its sample"
        );
        assert!(out.markers.iter().all(|m| m.id == 1), "robot_2's only");
        assert!(!out.markers.is_empty());
    }
}
