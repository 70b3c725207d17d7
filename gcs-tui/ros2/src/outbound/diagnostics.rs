//! `/diagnostics` (diagnostic_msgs/DiagnosticArray): one status per robot
//! (failsafe, health, route, fix quality, and how its telemetry reaches the
//! bridge) and one for the bridge itself (every counter of [`Stats`]).
//!
//! A robot's link is what the bridge sees (its telemetry rate and the age
//! of its latest sample) and, when the bridge is attached to the station
//! ([`crate::station`]), what the station's router measures: link state,
//! loss, round trip, rates each way and the live links (`station_*`).
//!
//! [`Stats`]: crate::stats::Stats

use std::time::{Duration, Instant};

use mech_proto::{FailsafeState, Health};

use mech_core::event::LinkState;

use crate::fleet::Robot;
use crate::msgs::diagnostic::{self, DiagnosticStatus, KeyValue};
use crate::station::RobotLink;
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
    /// Its link as the station measures it (the bridge is attached).
    pub link: Option<&'a RobotLink>,
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
    let (level, message) = match cx.link.map(|l| l.state) {
        Some(LinkState::Lost) if level < diagnostic::ERROR => {
            (diagnostic::ERROR, "the station lost its link".to_string())
        }
        Some(LinkState::Stale) if level < diagnostic::WARN => (
            diagnostic::WARN,
            "its link to the station is stale".to_string(),
        ),
        _ => (level, message),
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
        ]
        .into_iter()
        .chain(cx.link.map(station_link).into_iter().flatten())
        .collect(),
    }
}

/// A robot's link as the station measures it, as key-values: `unknown`
/// where the window held nothing to measure.
fn station_link(l: &RobotLink) -> Vec<KeyValue> {
    let q = &l.quality;
    let unknown = || "unknown".to_string();
    let mut out = vec![
        kv("station_link", l.state.as_str()),
        kv(
            "station_loss",
            q.loss.map_or_else(unknown, |f| format!("{f:.3}")),
        ),
        kv(
            "station_rtt_ms",
            q.rtt
                .map_or_else(unknown, |d| format!("{:.1}", d.as_secs_f64() * 1000.0)),
        ),
        kv("station_rx_hz", format!("{:.1}", q.rx_hz)),
        kv("station_tx_hz", format!("{:.1}", q.tx_hz)),
        kv("station_lost", q.lost),
    ];
    if !l.links.is_empty() {
        out.push(kv("station_links", &l.links));
    }
    out
}

/// The bridge's own status: its counters; a warning once anything was
/// refused or lost.
pub fn bridge_status(
    name: &str,
    robots: usize,
    attached: Option<bool>,
    stats: &StatsSnapshot,
) -> DiagnosticStatus {
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
    let (level, message) = match attached {
        Some(false) if level == diagnostic::OK => (
            diagnostic::WARN,
            format!("{message}; not attached to the station: no link quality, no arena"),
        ),
        _ => (level, message),
    };
    let attach = attached.map_or("not asked", |a| if a { "yes" } else { "no" });
    let mut values = vec![kv("robots", robots), kv("station_attached", attach)];
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
            link: None,
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
    fn attached_a_robot_status_has_its_link_as_the_station_measures_it() {
        let now = Instant::now();
        let mut f = Fleet::default();
        f.update("robot_1", telemetry(0.0, 0.0), 1, now);
        let mut link = RobotLink {
            state: LinkState::Connected,
            quality: mech_core::counters::LinkQuality {
                loss: Some(0.0125),
                rtt: Some(Duration::from_micros(2_340)),
                rx_hz: 52.0,
                tx_hz: 21.5,
                lost: 3,
                ..Default::default()
            },
            links: "wifi*+radio 14Hz".into(),
        };
        fn cx(now: Instant, link: Option<&RobotLink>) -> RobotContext<'_> {
            RobotContext {
                cmd_channel: "ros2/robot_1",
                goal_channel: "ros2goal/robot_1",
                now,
                stale_after: Duration::from_secs(1),
                link,
            }
        }
        let s = robot_status("robot_1", f.get("robot_1").unwrap(), cx(now, Some(&link)));
        assert_eq!(s.level, diagnostic::OK);
        let got: Vec<(&str, &str)> = [
            "station_link",
            "station_loss",
            "station_rtt_ms",
            "station_rx_hz",
            "station_tx_hz",
            "station_lost",
            "station_links",
        ]
        .iter()
        .map(|k| (*k, value(&s, k)))
        .collect();
        assert_eq!(
            got,
            [
                ("station_link", "connected"),
                ("station_loss", "0.013"),
                ("station_rtt_ms", "2.3"),
                ("station_rx_hz", "52.0"),
                ("station_tx_hz", "21.5"),
                ("station_lost", "3"),
                ("station_links", "wifi*+radio 14Hz"),
            ]
        );
        link.state = LinkState::Lost;
        link.quality.loss = None;
        let s = robot_status("robot_1", f.get("robot_1").unwrap(), cx(now, Some(&link)));
        assert_eq!(
            (s.level, s.message.as_str(), value(&s, "station_loss")),
            (diagnostic::ERROR, "the station lost its link", "unknown")
        );
        let s = robot_status("robot_1", f.get("robot_1").unwrap(), cx(now, None));
        assert!(s.values.iter().all(|kv| !kv.key.starts_with("station_")));
    }

    #[test]
    fn the_bridge_status_lists_every_counter_and_warns_on_refusals() {
        let mut stats = StatsSnapshot::default();
        let s = bridge_status("ros2", 4, None, &stats);
        assert_eq!(s.level, diagnostic::OK);
        assert_eq!(s.values.len(), 2 + stats.pairs().len());
        assert_eq!(value(&s, "station_attached"), "not asked");
        let s = bridge_status("ros2", 4, Some(false), &stats);
        assert_eq!(
            (s.level, value(&s, "station_attached")),
            (diagnostic::WARN, "no")
        );
        stats.refused_not_finite = 2;
        let s = bridge_status("ros2", 4, Some(true), &stats);
        assert_eq!(s.level, diagnostic::WARN);
        assert_eq!(value(&s, "refused_not_finite"), "2");
    }
}
