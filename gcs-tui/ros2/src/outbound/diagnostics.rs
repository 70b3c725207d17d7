//! `/diagnostics` (diagnostic_msgs/DiagnosticArray): one status per robot
//! (failsafe, health, route, fix quality, and how its telemetry reaches the
//! bridge) and one for the bridge itself (every counter of [`Stats`]).
//!
//! The station's own measure of each robot's link (loss, round trip) is
//! not in the protocol an external client speaks, so a robot's link here
//! is what the bridge sees: its telemetry rate and the age of its latest
//! sample.
//!
//! [`Stats`]: crate::stats::Stats

use std::time::{Duration, Instant};

use mech_proto::{FailsafeState, Health};

use crate::fleet::Robot;
use crate::msgs::diagnostic::{self, DiagnosticStatus, KeyValue};
use crate::stats::StatsSnapshot;

/// What a robot's status says beside its telemetry.
#[derive(Debug, Clone, Copy)]
pub struct RobotContext<'a> {
    /// The channel its cmd_vel is forwarded on (`ros2/robot_1`).
    pub cmd_channel: &'a str,
    /// The channel its goals are sent on.
    pub goal_channel: &'a str,
    pub now: Instant,
    pub stale_after: Duration,
}

fn kv(key: &str, value: impl ToString) -> KeyValue {
    KeyValue {
        key: key.to_string(),
        value: value.to_string(),
    }
}

/// The status of robot `name`.
pub fn robot_status(name: &str, r: &Robot, cx: RobotContext<'_>) -> DiagnosticStatus {
    let t = &r.telemetry;
    let age = cx.now.saturating_duration_since(r.received);
    let stale = r.stale(cx.now, cx.stale_after);
    let (level, message) = if stale {
        (
            diagnostic::STALE,
            format!("no telemetry for {:.1} s", age.as_secs_f64()),
        )
    } else {
        match (t.failsafe, t.health) {
            (FailsafeState::EStopped, _) => (diagnostic::ERROR, "e-stopped".to_string()),
            (FailsafeState::Fault, _) | (_, Health::Fault) => {
                (diagnostic::ERROR, "fault".to_string())
            }
            (FailsafeState::RouterLost, _) => (diagnostic::ERROR, "router lost".to_string()),
            (FailsafeState::ChannelSilent, _) => (
                diagnostic::WARN,
                "its channel is silent: holding still".to_string(),
            ),
            (_, Health::Degraded) => (diagnostic::WARN, "degraded".to_string()),
            _ => (diagnostic::OK, "ok".to_string()),
        }
    };
    let route = if t.channel.is_empty() {
        "none"
    } else {
        t.channel.as_str()
    };
    let mission = t.mission.map_or("none".to_string(), |m| {
        format!("{} at {}/{}", m.id, m.next, m.total)
    });
    let battery = t
        .battery
        .map_or("unknown".to_string(), |b| format!("{b:.2}"));
    DiagnosticStatus {
        level,
        name: format!("mech: {name}"),
        message,
        hardware_id: name.to_string(),
        values: vec![
            kv("failsafe", t.failsafe.as_str()),
            kv("health", t.health.as_str()),
            kv("mode", t.mode.as_str()),
            kv("route", route),
            kv("obeys_cmd_vel", t.channel == cx.cmd_channel),
            kv("obeys_goal_pose", t.channel == cx.goal_channel),
            kv("position_quality", format!("{:.2}", t.position_quality)),
            kv("battery", battery),
            kv("mission", mission),
            kv("stale_ignored", t.stale),
            kv("telemetry_hz", r.rate_hz(cx.now)),
            kv("telemetry_age_ms", age.as_millis()),
            kv("cmd_vel_forwarded", r.cmd_forwarded),
        ],
    }
}

/// The bridge's own status: its counters; a warning once anything was
/// refused or lost.
pub fn bridge_status(name: &str, robots: usize, stats: &StatsSnapshot) -> DiagnosticStatus {
    let troubles = stats.refused()
        + stats.publish_failed
        + stats.link_rejected
        + stats.send_failed
        + stats.goals_unacked
        + stats.estops_refused;
    let (level, message) = if troubles == 0 {
        (diagnostic::OK, format!("{robots} robots"))
    } else {
        (
            diagnostic::WARN,
            format!("{robots} robots; {} inputs refused", stats.refused()),
        )
    };
    let mut values = vec![kv("robots", robots)];
    values.extend(stats.pairs().into_iter().map(|(k, v)| kv(k, v)));
    DiagnosticStatus {
        level,
        name: format!("mech: {name} bridge"),
        message,
        hardware_id: name.to_string(),
        values,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fleet::Fleet;
    use crate::fleet::tests::telemetry;

    fn value<'a>(s: &'a DiagnosticStatus, key: &str) -> &'a str {
        s.values
            .iter()
            .find(|kv| kv.key == key)
            .map(|kv| kv.value.as_str())
            .unwrap_or_else(|| panic!("{key} in {s:?}"))
    }

    #[test]
    fn a_robot_status_says_its_failsafe_route_and_link() {
        let now = Instant::now();
        let mut f = Fleet::default();
        let mut t = telemetry(0.0, 0.0);
        t.channel = "ros2/robot_1".into();
        f.update("robot_1", t.clone(), 1, now);
        let cx = RobotContext {
            cmd_channel: "ros2/robot_1",
            goal_channel: "ros2goal/robot_1",
            now,
            stale_after: Duration::from_secs(1),
        };
        let s = robot_status("robot_1", f.get("robot_1").unwrap(), cx);
        assert_eq!(
            (s.level, s.name.as_str()),
            (diagnostic::OK, "mech: robot_1")
        );
        assert_eq!(value(&s, "route"), "ros2/robot_1");
        assert_eq!(value(&s, "obeys_cmd_vel"), "true");
        assert_eq!(value(&s, "telemetry_hz"), "1");

        t.failsafe = FailsafeState::EStopped;
        f.update("robot_1", t, 2, now);
        let s = robot_status("robot_1", f.get("robot_1").unwrap(), cx);
        assert_eq!(
            (s.level, value(&s, "failsafe")),
            (diagnostic::ERROR, "estopped")
        );

        let later = RobotContext {
            now: now + Duration::from_secs(3),
            ..cx
        };
        let s = robot_status("robot_1", f.get("robot_1").unwrap(), later);
        assert_eq!(s.level, diagnostic::STALE);
    }

    #[test]
    fn the_bridge_status_lists_every_counter_and_warns_on_refusals() {
        let mut stats = StatsSnapshot::default();
        let s = bridge_status("ros2", 4, &stats);
        assert_eq!(s.level, diagnostic::OK);
        assert_eq!(s.values.len(), 1 + stats.pairs().len());
        stats.not_finite = 2;
        let s = bridge_status("ros2", 4, &stats);
        assert_eq!(s.level, diagnostic::WARN);
        assert_eq!(value(&s, "refused_not_finite"), "2");
    }
}
